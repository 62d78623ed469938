"""Coverage-guided fuzzing of every input surface imucap reads, with atheris (libFuzzer).

    python benchmarks/fuzz.py list
    python benchmarks/fuzz.py TARGET --runs 1000000        # one target, N inputs
    python benchmarks/fuzz.py TARGET --seconds 600         # or for a while
    python benchmarks/fuzz.py TARGET --replay FILE...      # re-run saved inputs, print what escapes

Why this exists: the property tests in CI (hypothesis, tests/drivers/test_protocols.py)
try a few hundred shaped inputs per decoder; a recording, a motion file or a setup file
from someone else's disk can be anything. libFuzzer mutates inputs towards new code
paths, so it reaches the corners of a reader that no hand-written case names.

The contract checked: a reader given bad bytes raises its own one-line error (the
exceptions the CLI prints as ``error: ...``: MotionFormatError, SetupError,
RecordingError, ExportError, LogError, or OSError for files), and a device's read path
raises nothing at all (decode errors are counted in its stats, never thrown at the hub's
reader thread). Anything else escaping, a bare ValueError from deep inside numpy
included (its message names no file and no line), an input slower than ``--timeout``
or a process above ``--rss-mb`` is a finding; libFuzzer saves the input under
``cache/fuzz/TARGET/`` and the run stops. ``--lenient`` accepts any ValueError.

Seeds are valid inputs the script makes itself (the drivers' ``encode``, our BVH and
AMASS writers, a recorder, the example setup); the ASF/AMC seed needs the HDM05 skeleton
from the shared data. The corpus grows in ``cache/fuzz/TARGET/corpus`` and is reused by
the next run. Not for CI: a run is minutes to hours (docs/robustness.md has the counts).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

Run = Callable[[bytes], None]
Errors = tuple[type[BaseException], ...]


class UnclearError(AssertionError):
    """A ValueError or OSError that is not the reader's own error class: allowed by type,
    but its message (from numpy, struct, h5py...) names no file, line or field."""


class DecodeEscaped(AssertionError):
    """A decode error that left a device's read path (the hub's reader thread would die)."""


@dataclass(frozen=True)
class Target:
    name: str
    what: str
    setup: Callable[[Path], tuple[Run, list[bytes], Errors]]  # scratch folder -> (run one input, seeds, own errors)
    max_len: int = 4096
    timeout: int = 10  # s per input
    # the modules that parse the input: each must be instrumented, or libFuzzer mutates
    # without seeing which branches of the parser an input reached
    surface: tuple[str, ...] = ()


def _scratch(name: str) -> Path:
    """A folder for the per-input files: in memory when the system has one (opening a
    file on this disk costs ~1.5 ms, most of a text reader's time per input)."""
    shm = Path("/dev/shm")
    base = str(shm) if shm.is_dir() and os.access(shm, os.W_OK) else None
    return Path(tempfile.mkdtemp(prefix=f"imucap-fuzz-{name}-", dir=base))


def _data_root() -> Path:
    return Path(os.environ.get("IMUCAP_DATA", REPO.parent / "shared" / "data"))


def _split(data: bytes, parts: int) -> list[bytes]:
    """Cut one input into ``parts`` pieces with 2-byte little-endian length prefixes (the
    last piece takes the rest), so one fuzz input can be two files or a datagram list."""
    out = []
    for _ in range(parts - 1):
        n = int.from_bytes(data[:2], "little") if len(data) >= 2 else 0
        out.append(data[2:2 + n])
        data = data[2 + n:]
    out.append(data)
    return out


def _join(*pieces: bytes) -> bytes:
    return b"".join(len(p).to_bytes(2, "little") + p for p in pieces[:-1]) + pieces[-1]


def _chunks(data: bytes) -> list[bytes]:
    """A byte stream as the reads a serial port might return: the first byte picks the
    read size, so a frame split across reads is exercised too."""
    if not data:
        return []
    size = 1 + data[0] % 64
    body = data[1:]
    return [body[i:i + size] for i in range(0, len(body), size)]


class _Clock:
    """A session clock that advances a little per reading: deterministic and no sleeps."""

    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        self.t += 0.001
        return self.t


# --------------------------------------------------------------------------------------- wire formats
def _serial_run(make_device: Callable[[], object], pure: Callable[[bytes], None]) -> Run:
    """Run one input through a serial device's real read path (``read_many``) with the
    port replaced by the input's chunks, after the pure decode functions on the raw bytes."""

    def run(data: bytes) -> None:
        pure(data)
        dev = make_device()
        chunks = _chunks(data)
        dev._open = dev._reset_parser  # no port: the parser is all an open resets
        dev._read_bytes = lambda timeout: chunks.pop(0) if chunks else b""
        dev.open()
        while True:
            for s in dev.read_many(0.0):
                _check_sample(s)
            if not chunks and not dev._pending:
                break
        dev.close()

    return run


def _check_sample(s) -> None:  # type: ignore[no-untyped-def]
    """What the hub assumes of a sample: float vectors of the right length, unit quaternion."""
    import numpy as np

    for name, n in (("quat", 4), ("free_acc", 3), ("acc", 3), ("gyro", 3)):
        v = getattr(s, name)
        if v is not None and (v.shape != (n,) or v.dtype != np.float64):
            raise AssertionError(f"sample {name} has shape {v.shape} {v.dtype}")
    if s.quat is not None and np.isfinite(s.quat).all() and abs(float(np.linalg.norm(s.quat)) - 1.0) > 1e-6:
        raise AssertionError(f"sample quaternion is not unit: {s.quat}")


def _xbus(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.xbus import protocol as xb
    from drivers.xbus.driver import XbusDevice

    def pure(data: bytes) -> None:
        for fn in (xb.decode, xb.decode_mtdata2, xb.decode_output_configuration):
            try:
                fn(data)
            except xb.XbusError:
                pass
        try:
            xb.decode_mtdata2(data[4:-1])
        except xb.XbusError:
            pass

    def device() -> XbusDevice:
        return XbusDevice("/dev/null-fuzz", configure=False, reconnect=False, clock=_Clock())

    seeds = []
    for k, prec in enumerate(xb.Precision):
        for frame in xb.CoordFrame:
            d = xb.MTData2(packet_counter=k, sample_time_fine=1000 * k, quat=(0.7, 0.1, -0.7, 0.1),
                           acc=(0.1, 0.2, 9.8), free_acc=(0.0, 0.1, -0.1), gyro=(0.01, -0.02, 0.3), status=3,
                           precision=prec, frame=frame)
            pkt = xb.encode(xb.MID.MTData2, xb.encode_mtdata2(d))
            seeds.append(bytes([len(pkt) - 1]) + pkt + pkt)
    bare = xb.encode_mtdata2(xb.MTData2(packet_counter=1, quat=(1, 0, 0, 0)))
    seeds.append(b"\x07" + xb.encode(xb.MID.MTData2, bare))
    seeds.append(b"\x00" + xb.encode(xb.MID.ReqDID, b"") + xb.encode(0x11, b"\x00" * 300))
    return _serial_run(device, pure), seeds, ()


def _bno08x(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.bno08x import protocol as rvc
    from drivers.bno08x.driver import Bno08xRvcDevice

    def pure(data: bytes) -> None:
        for piece in (data, data[:rvc.FRAME_LEN], data[1:1 + rvc.FRAME_LEN]):
            try:
                rvc.decode(piece)
            except rvc.RvcError:
                pass

    def device() -> Bno08xRvcDevice:
        return Bno08xRvcDevice("/dev/null-fuzz", reconnect=False, clock=_Clock())

    frames = [rvc.encode(rvc.RvcFrame(k, 170.0 * k - 180, 30.0 - 20 * k, 90.0 * k, (12.0, -40.0, 990.0)))
              for k in range(4)]
    seeds = [b"\x12" + b"".join(frames), b"\x05" + frames[0] + b"\xaa" + frames[1][3:] + frames[2]]
    return _serial_run(device, pure), seeds, ()


def _xsens_can(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    import can

    from drivers.xsens_can import protocol as xcan
    from drivers.xsens_can.driver import XsensCanDevice

    class Bus:
        """python-can's ``recv`` over the frames of one input."""

        def __init__(self, msgs: list[can.Message]) -> None:
            self.msgs = msgs

        def recv(self, timeout: float | None = None) -> can.Message | None:
            return self.msgs.pop(0) if self.msgs else None

        def shutdown(self) -> None:
            pass

    def frames(data: bytes) -> list[can.Message]:
        """Records of: flags (bit 7 error frame), 11-bit id (2 bytes), length (0-15), payload."""
        out, i = [], 0
        while i + 4 <= len(data):
            flags, ident, n = data[i], int.from_bytes(data[i + 1:i + 3], "little") & 0x7FF, data[i + 3] & 0x0F
            payload = data[i + 4:i + 4 + n]
            out.append(can.Message(arbitration_id=ident, data=payload, is_extended_id=False,
                                   is_error_frame=bool(flags & 0x80), check=False))
            i += 4 + n
        return out

    def run(data: bytes) -> None:
        msgs = frames(data)
        for m in msgs:
            try:
                xcan.decode(m.arbitration_id, bytes(m.data), 0x100)
            except xcan.CanDecodeError:
                pass
        dev = XsensCanDevice("virtual", "fuzz", id_offset=0x100, reconnect=False, clock=_Clock())
        dev._open = lambda: setattr(dev, "_bus", Bus(msgs))
        dev.open()
        while msgs:
            for s in dev.read_many(0.0):
                _check_sample(s)
        dev.close()

    seeds = []
    for k in range(3):
        g = xcan.CanGroup(sample_time_us=10_000 * k, counter=k, status=1, quat=(0.9, 0.1, -0.3, 0.2),
                          gyro=(0.1, 0.2, -0.3), acc=(0.5, -0.2, 9.8), free_acc=(0.1, 0.0, -0.1))
        seeds.append(b"".join(b"\x00" + i.to_bytes(2, "little") + bytes([len(p)]) + p
                              for _ in range(2) for i, p in xcan.encode(g, 0x100)))
    return run, seeds, ()


def _dualsense(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.dualsense import protocol as ds
    from drivers.dualsense.driver import DualSenseDevice

    class Hid:
        """The driver's HID seam over one input: calibration report, then input reports."""

        def __init__(self, data: bytes) -> None:
            self.cal = data[:ds.CALIBRATION_REPORT_LEN]
            body = data[ds.CALIBRATION_REPORT_LEN:]
            self.reports = [body[i:i + ds.INPUT_REPORT_LEN] for i in range(0, len(body), ds.INPUT_REPORT_LEN)]

        def read(self, size: int, timeout: float | None) -> bytes:
            return self.reports.pop(0) if self.reports else b""

        def get_feature_report(self, report_id: int, size: int) -> bytes:
            return self.cal

        def close(self) -> None:
            pass

    def run(data: bytes) -> None:
        for fn in (ds.decode_input_report, ds.decode_calibration):
            try:
                fn(data)
            except ds.DualSenseError:
                pass
        hid = Hid(data)
        dev = DualSenseDevice(lambda: hid, reconnect=False, clock=_Clock())
        try:
            dev.open()
        except OSError:  # a bad calibration report: the device refuses to open, as it should
            return
        while hid.reports:
            for s in dev.read_many(0.0):
                _check_sample(s)
        dev.close()

    cal = ds.encode_calibration(ds.DsCalibration(gyro_bias=(3, -2, 1), acc_plus=(8100, 8300, 8200)))
    reps = [ds.encode_input_report(ds.DsInput(k, (10 * k, -5, 300), (100, 8000 - 50 * k, -200), 3000 * k, 55.0,
                                              k % 2 == 0)) for k in range(4)]
    return run, [cal + b"".join(reps), cal + reps[0] + reps[0]], ()


def _moticon(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    import numpy as np

    from drivers.moticon import protocol as mot
    from drivers.moticon.driver import MoticonUdpDevice

    def run(data: bytes) -> None:
        """Datagrams separated by newlines, through decode and the device's conversion (what
        its ``_read_many`` does per datagram, without the socket)."""
        dev = MoticonUdpDevice("127.0.0.1", 9, reconnect=False, clock=_Clock())
        for dgram in data.split(b"\n"):
            try:
                f = mot.decode(dgram)
            except mot.MoticonError:
                continue
            dev._finish(dev._to_sample(f), 0.0)

    rng = np.random.default_rng(0)
    frames = []
    for k in range(3):
        frames.append(mot.encode(mot.InsoleFrame(0.01 * k, rng.normal(size=(2, 3)), rng.normal(size=(2, 3)),
                                                 rng.uniform(-0.5, 0.5, (2, 2)), rng.uniform(0, 20, (2, 16)),
                                                 np.array([400.0 * k, 10.0]))))
    return run, [b"\n".join(frames), frames[0] + b"\n" + frames[2]], ()


def _movella_dot(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.movella_dot import protocol as dot
    from drivers.movella_dot.driver import MovellaDotDevice

    class Link:
        """The BLE seam over one input: the battery characteristic (2 bytes), then
        notifications of the medium payload characteristic (40 bytes each)."""

        def __init__(self, data: bytes) -> None:
            self.data, self.notify = data, {}

        def read(self, char: str, timeout: float = 2.0) -> bytes:
            return self.data[:2] if char == dot.BATTERY else self.data[2:34]

        def write(self, char: str, data: bytes, timeout: float = 2.0) -> None:
            pass

        def start_notify(self, char: str, callback, timeout: float = 2.0) -> None:  # type: ignore[no-untyped-def]
            self.notify[char] = callback

        def disconnect(self) -> None:
            pass

    class Seam:
        def __init__(self, data: bytes) -> None:
            self.link = Link(data)

        def scan(self, timeout: float) -> list:
            return []

        def connect(self, address: str, on_lost, timeout: float) -> Link:  # type: ignore[no-untyped-def]
            return self.link

    def run(data: bytes) -> None:
        for mode in dot.MODES:
            try:
                dot.decode(data, mode)
            except dot.DotError:
                pass
        for fn in (dot.decode_control, dot.decode_battery):
            try:
                fn(data)
            except dot.DotError:
                pass
        seam = Seam(data)
        dev = MovellaDotDevice("D4:22:CD:00:00:01", seam, reconnect=False, clock=_Clock())  # type: ignore[arg-type]
        dev.open()
        body, notify = data[2:], seam.link.notify[dot.MEDIUM_PAYLOAD]
        for i in range(0, len(body), 40):
            notify(body[i:i + 40])
        while dev.has_buffered():
            for s in dev.read_many(0.0):
                _check_sample(s)
        dev.close()

    ms = [dot.encode(dot.DotMeasurement(16_667 * k, (0.9, 0.1, -0.3, 0.2), (0.1, 0.0, -0.1 * k))) for k in range(4)]
    battery = dot.encode_battery(dot.DotBattery(87, False))
    return run, [battery + b"".join(ms), battery + ms[0] + ms[3]], ()


def _ximu3_live(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.ximu3 import protocol as x3
    from drivers.ximu3.driver import Ximu3Device

    def run(data: bytes) -> None:
        """A UDP payload: split into messages, each decoded, the decoded ones through the
        live device's pairing and conversion (the items x-io's parser hands it)."""
        dev = Ximu3Device("udp", {"ip": "127.0.0.1", "receive_port": 9, "send_port": 9}, reconnect=False,
                          clock=_Clock())
        msgs, _rest = x3.split(data)
        for msg in msgs:
            try:
                m = x3.decode(msg)
            except x3.Ximu3Error:
                continue
            if m.kind == x3.INERTIAL:
                item: tuple = ("I", m.timestamp_us, m.values[:3], m.values[3:])
            elif m.kind == x3.QUATERNION:
                item = ("Q", m.timestamp_us, m.values)
            else:
                item = ("B", m.timestamp_us, m.values[0])
            s = dev._handle(item)
            if s is not None:
                _check_sample(dev._finish(s, 0.0))

    seeds = []
    for binary in (True, False):
        seeds.append(b"".join(x3.encode(x3.Message(k, 10_000 * i, v), binary) for i in range(3) for k, v in (
            (x3.INERTIAL, (1.0, -2.0, 3.0, 0.0, 0.1, 1.0)), (x3.QUATERNION, (0.9, 0.1, -0.3, 0.2)),
            (x3.BATTERY, (80.0, 3.9, 0.0)))))
    return run, seeds, ()


# ------------------------------------------------------------------------------------------ log files
def _ximu3(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.ximu3.log import LogError, read_log

    root = tmp / "log"
    dev = root / "x-IMU3 65577B35 (USB)"
    dev.mkdir(parents=True, exist_ok=True)

    def run(data: bytes) -> None:
        inertial, quats = _split(data, 2)
        (dev / "Inertial.csv").write_bytes(inertial)
        (dev / "Quaternion.csv").write_bytes(quats)
        for log in read_log(root):
            _check_log(log)

    head_i = b"Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s)," \
             b"Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n"
    head_q = b"Timestamp (us),W,X,Y,Z\n"
    rows_i = b"".join(b"%d,0.1,-0.2,0.3,0.01,0.02,0.99\n" % (10000 * k) for k in range(5))
    rows_q = b"".join(b"%d,0.99,0.01,0.1,0.0\n" % (10000 * k) for k in range(5))
    return run, [_join(head_i + rows_i, head_q + rows_q), _join(head_i + rows_i[:60], head_q + rows_q[10:])], \
        (LogError, OSError)


def _check_log(log) -> None:  # type: ignore[no-untyped-def]
    """A DeviceLog the import can use: time-ordered rows, matching lengths, finite times."""
    import numpy as np

    n = len(log.t)
    if log.quat.shape != (n, 4) or log.acc.shape != (n, 3) or log.gyro.shape != (n, 3):
        raise AssertionError(f"DeviceLog arrays disagree: {log.t.shape} {log.quat.shape} {log.acc.shape}")
    if n and not (np.isfinite(log.t).all() and (np.diff(log.t) > 0).all()):
        raise AssertionError("DeviceLog times not finite and increasing")


def _xsens_export(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.xsens_export.reader import detect_layout, read_export
    from drivers.xsens_export.table import ExportError

    path = tmp / "export.txt"

    def run(data: bytes) -> None:
        path.write_bytes(data)
        detect_layout(path)
        _check_log(read_export(path))

    mt = ("// General information:\n//  MT Manager version: 2022.0.0\n//  XDA version: 2022.0.0\n"
          "// Device information:\n//  DeviceId: 00B4A1B2\n//  ProductCode: MTi-630\n"
          "// Device settings:\n//  Filter Profile: general(50.1)\n//  Option Flags: AHS Disabled\n"
          "// Sample rate: 100\n// Coordinate system: ENU\n"
          "PacketCounter\tSampleTimeFine\tAcc_X\tAcc_Y\tAcc_Z\tFreeAcc_X\tFreeAcc_Y\tFreeAcc_Z\t"
          "Gyr_X\tGyr_Y\tGyr_Z\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n")
    mt += "".join(f"{k}\t{1000 + 100 * k}\t0.1\t0.2\t9.8\t0.0\t0.1\t-0.1\t0.01\t0.02\t0.03\t0.99\t0.01\t0.1\t0.0\n"
                  for k in range(5))
    dot = ("sep=,\nXsens DOT,,\nDevice tag:,left wrist,,\nFirmware Version:,2.0.0,,\n"
           "PacketCounter,SampleTimeFine,Euler_X,Euler_Y,Euler_Z,FreeAcc_X,FreeAcc_Y,FreeAcc_Z,Status\n")
    dot += "".join(f"{k},{16667 * k},1.5,-2.0,{10 * k},0.01,0.02,-0.03,0\n" for k in range(5))
    csv = "PacketCounter;SampleTimeFine;Mat[1][1];Mat[2][1];Mat[3][1];Mat[1][2];Mat[2][2];Mat[3][2];" \
          "Mat[1][3];Mat[2][3];Mat[3][3];Acc_X;Acc_Y;Acc_Z\n"
    csv += "".join(f"{k};{1000 * k};1,0;0,0;0,0;0,0;1,0;0,0;0,0;0,0;1,0;0,1;0,2;9,8\n" for k in range(4))
    return run, [mt.encode(), dot.encode(), csv.encode()], (ExportError, OSError)


# ------------------------------------------------------------------------------------------ setup file
def _mvnx(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from drivers.xsens_export.mvnx import MvnxError, is_mvnx, read_mvnx
    from inference.body.motion import MotionFormatError
    from inference.loaders.mvnx import parse_mvnx

    path = tmp / "take.mvnx"

    def run(data: bytes) -> None:
        path.write_bytes(data)
        is_mvnx(path)
        try:
            parse_mvnx(path)  # the segments, as motion (a take without the full body is refused)
        except MotionFormatError:
            pass
        for log in read_mvnx(path).logs:
            _check_log(log)

    frames = "".join(
        f'<frame time="{17 * k}" index="{k}" type="normal"><orientation>1 0 0 0 1 0 0 0</orientation>'
        f"<sensorFreeAcceleration>0.1 0 -0.2 0 0.3 0.1</sensorFreeAcceleration>"
        f"<sensorOrientation>0.99 0.01 0.1 0 1 0 0 0</sensorOrientation></frame>" for k in range(4))
    take = ('<?xml version="1.0" encoding="UTF-8"?>\n<mvnx xmlns="http://www.xsens.com/mvn/mvnx" version="4">'
            '<mvn version="2022.0.0"/><subject label="s" frameRate="60" segmentCount="2"><segments>'
            '<segment label="Pelvis" id="1"/></segments><sensors><sensor label="Pelvis"/><sensor label="T8"/>'
            '</sensors><frames segmentCount="2" sensorCount="2"><frame time="0" type="tpose">'
            f"<orientation>1 0 0 0 1 0 0 0</orientation></frame>{frames}</frames></subject></mvnx>\n")
    return run, [take.encode(), take[: len(take) * 2 // 3].encode()], (MvnxError, OSError)


def _setup(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from app.capture.setup_file import SetupError, load_setup

    path = tmp / "setup.toml"

    def run(data: bytes) -> None:
        path.write_bytes(data)
        s = load_setup(path)
        s.urls()
        s.recordings_dir()

    example = (REPO / "examples" / "setup_example.toml").read_bytes()
    small = (b'[subject]\nheight = 1.8\n[sensors]\npelvis = "xbus:///dev/ttyUSB0"\n'
             b'l_wrist = { url = "dualsense://", serial = "ab" }\n[model]\nname = "floor"\n')
    return run, [example, small], (SetupError, OSError)


# ------------------------------------------------------------------------------------------ motion files
def _short_motion(frames: int = 4):  # type: ignore[no-untyped-def]
    from sim_devices.motions import generate

    return generate("walk", seconds=1.0, seed=1, fps=30.0).slice(0, frames)


def _bvh(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    import gzip

    from app.export.bvh import write_motion_bvh
    from inference.loaders import MotionFormatError, load_motion

    path = tmp / "clip.bvh"

    def run(data: bytes) -> None:
        path.write_bytes(data)
        load_motion(path)

    write_motion_bvh(tmp / "seed.bvh", _short_motion())
    seeds = [(tmp / "seed.bvh").read_bytes()]
    # the CMU conversions' rigs (Daz names, iClone's CC_Base with twist bones) reach their own
    # joint maps and rest-pose turns: three frames of the first take of each, where the data is
    for layout in ("bvh_cgspeed", "bvh_iclone"):
        take = next(iter(sorted((_data_root() / "cmu" / layout).glob("*.bvh.gz"))), None)
        if take is not None:
            seeds.append(_first_frames_bvh(gzip.decompress(take.read_bytes()), 3))
    return run, seeds, (MotionFormatError, OSError)


def _first_frames_bvh(text: bytes, n: int) -> bytes:
    lines = text.splitlines()
    m = next(i for i, ln in enumerate(lines) if ln.strip().upper() == b"MOTION")
    head = lines[:m + 1] + [b"Frames: %d" % n]
    timing = next(ln for ln in lines[m + 1:m + 4] if ln.strip().lower().startswith(b"frame time"))
    body = [ln for ln in lines[m + 1:] if ln.strip() and not ln.strip().lower().startswith(b"frame")][:n]
    return b"\n".join(head + [timing] + body) + b"\n"


def _asf_amc(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    import gzip

    from inference.loaders import MotionFormatError, load_motion

    folder = tmp / "hdm05"
    folder.mkdir(exist_ok=True)
    asf, amc = folder / "HDM_zz.asf", folder / "HDM_zz_fuzz_001_120.amc"

    def run(data: bytes) -> None:
        a, b = _split(data, 2)
        asf.write_bytes(a)
        amc.write_bytes(b)
        load_motion(amc)

    src = _data_root() / "hdm05" / "dg"
    skel = (src / "HDM_dg.asf").read_bytes()
    take = next(iter(sorted(src.glob("HDM_dg_*_120.amc.gz"))))
    lines = gzip.decompress(take.read_bytes()).split(b"\n")
    starts = [i for i, ln in enumerate(lines) if ln.strip().isdigit()]
    seeds = [_join(skel, b"\n".join(lines[:starts[3]]) + b"\n"), _join(skel, b"\n".join(lines[:starts[2]]) + b"\n")]
    return run, seeds, (MotionFormatError, OSError)


def _amass(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    from inference.loaders import MotionFormatError, load_motion
    from sim_devices.motions import write_amass_npz

    path = tmp / "clip.npz"

    def run(data: bytes) -> None:
        path.write_bytes(data)
        load_motion(path)

    write_amass_npz(_short_motion(), tmp / "seed.npz")
    return run, [(tmp / "seed.npz").read_bytes()], (MotionFormatError, OSError)


def _amass_arrays(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    """The .npz members as the input (name, then .npy bytes), zipped with correct CRCs:
    a raw .npz mutation almost always dies at the zip checksum; this one reaches the
    array headers, shapes, dtypes and values the loader has to judge."""
    import warnings

    import numpy as np

    from inference.loaders import MotionFormatError, load_motion
    from sim_devices.motions import write_amass_npz

    warnings.filterwarnings("ignore", "Duplicate name", UserWarning)  # a repeated member name is a fine input
    path = tmp / "clip.npz"

    def run(data: bytes) -> None:
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_STORED) as z:
            i = 0
            while i + 3 <= len(data):
                n = data[i]
                name = re.sub(r"[^0-9A-Za-z_]", "", data[i + 1:i + 1 + n].decode("ascii", "replace")) or "x"
                i += 1 + n
                m = int.from_bytes(data[i:i + 2], "little")
                z.writestr(name + ".npy", data[i + 2:i + 2 + m])
                i += 2 + m
        path.write_bytes(buf.getvalue())
        load_motion(path)

    write_amass_npz(_short_motion(3), tmp / "seed.npz")
    seed = b""
    with np.load(tmp / "seed.npz") as z:
        for k in z.files:
            arr = io.BytesIO()
            np.save(arr, z[k])
            b = arr.getvalue()
            seed += bytes([len(k)]) + k.encode() + len(b).to_bytes(2, "little") + b
    return run, [seed], (MotionFormatError, OSError)


# ------------------------------------------------------------------------------------------ recordings
def _recording(tmp: Path) -> tuple[Run, list[bytes], Errors]:
    import numpy as np

    import app.recording.libhdf5 as libhdf5
    import app.recording.reader as reader
    from app.recording import Recorder, RecordingError, read_recording
    from drivers.hub import HubFrame

    # The reader's waits for a live writer (HDF5 re-reading metadata that fails its checksum,
    # up to 24 times with growing sleeps; a chunk retried after 10 ms) take the same code
    # paths with one try and no pause, and a fuzzed file has no writer: with them an input
    # took 325 ms of wall clock for 30 ms of CPU, and the run mostly slept.
    libhdf5.SWMR_READ_ATTEMPTS = 1
    reader.IN_FLIGHT_RETRY_S = 0.0
    path = tmp / "rec.h5"

    def run(data: bytes) -> None:
        path.write_bytes(data)
        r = read_recording(path)
        r.hub_frames()

    seeds = []
    for n_frames, sites in ((3, ("pelvis",)), (6, ("pelvis", "head"))):
        p = tmp / f"seed{n_frames}.h5"
        ticks = iter(range(10_000))
        rec = Recorder(p, sites, metadata={"model": "floor"}, flush_interval=1.0, chunk=4,
                       clock=lambda ticks=ticks: float(next(ticks)))
        S = len(sites)
        for i in range(n_frames):
            v = np.full((S, 3), float(i))
            rec.on_frame(HubFrame(t=i / 60, index=i, sites=sites, quat=np.tile([1.0, 0, 0, 0], (S, 1)),
                                  free_acc=v, acc=v, gyro=v, present=np.ones(S, bool), insole_force=np.zeros(2),
                                  contacts=np.zeros(4, bool), insole_present=False))
        rec.on_event(0.01, "note", "fuzz seed")
        rec.close()
        seeds.append(p.read_bytes())
    return run, seeds, (RecordingError, OSError)


# ------------------------------------------------------------------------------------------ references
def _reference(suffix: str) -> Callable[[Path], tuple[Run, list[bytes], Errors]]:
    """A lab's reference file for imucap validate (app.validate.reference.read_reference):
    seeded with our own export of a short walk in that format."""

    def setup(tmp: Path) -> tuple[Run, list[bytes], Errors]:
        import numpy as np

        from app.export.common import ExportMotion
        from app.export.formats import export_motion
        from app.validate.reference import read_reference
        from inference.body.motion import MotionFormatError

        path = tmp / f"reference{suffix}"

        def run(data: bytes) -> None:
            path.write_bytes(data)
            read_reference(path)

        m = _short_motion(6)
        joints = m.joints()
        em = ExportMotion(time=np.arange(m.n_frames) / m.fps, rot=m.rot, root=m.root, joints=joints,
                          contacts=np.zeros((m.n_frames, 4), bool), body=m.body, fps=m.fps)
        seed = export_motion(tmp / f"seed{suffix}", em)
        return run, [seed.read_bytes()], (MotionFormatError,)

    return setup


TARGETS: dict[str, Target] = {t.name: t for t in (
    Target("xbus", "Xsens Xbus: stream parser, frame, MTData2 and config decoders, XbusDevice.read_many", _xbus,
           surface=("drivers.xbus.protocol", "drivers.xbus.driver")),
    Target("bno08x-rvc", "BNO08x UART-RVC: frame decoder and Bno08xRvcDevice.read_many", _bno08x,
           surface=("drivers.bno08x.protocol", "drivers.bno08x.driver")),
    Target("xsens-can", "Xsens MTi CAN (DBC via cantools): frame decoder, group assembly, "
           "XsensCanDevice.read_many", _xsens_can,
           surface=("drivers.xsens_can.protocol", "drivers.xsens_can.driver")),
    Target("dualsense", "DualSense HID: input and calibration reports, DualSenseDevice open + read_many "
           "(calibration, AHRS)", _dualsense,
           surface=("drivers.dualsense.protocol", "drivers.dualsense.driver")),
    Target("moticon", "Moticon UDP datagrams: decoder and the insole device's conversion", _moticon,
           surface=("drivers.moticon.protocol", "drivers.moticon.driver")),
    Target("movella-dot", "Movella DOT BLE: payload, control and battery decoders, MovellaDotDevice open + "
           "read_many through a seam fed the input", _movella_dot,
           surface=("drivers.movella_dot.protocol", "drivers.movella_dot.driver")),
    Target("ximu3-live", "x-IMU3 data messages (ASCII and binary): split + decode, Ximu3Device pairing",
           _ximu3_live, surface=("drivers.ximu3.protocol", "drivers.ximu3.driver")),
    Target("ximu3", "x-IMU3 GUI log folder (Inertial.csv + Quaternion.csv): drivers.ximu3.read_log", _ximu3,
           max_len=8192,
           surface=("drivers.ximu3.log",)),
    Target("xsens-export", "Xsens MT Manager / DOT export: detect_layout + read_export", _xsens_export,
           max_len=8192,
           surface=("drivers.xsens_export.reader", "drivers.xsens_export.table", "drivers.xsens_export.samples")),
    Target("mvnx", "Xsens MVN take (MVNX XML): is_mvnx + read_mvnx, and its segments by parse_mvnx", _mvnx,
           max_len=8192, surface=("drivers.xsens_export.mvnx", "inference.loaders.mvnx")),
    Target("setup", "setup TOML: app.capture.setup_file.load_setup (parse_setup)", _setup,
           surface=("app.capture.setup_file", "app.capture.setup_lines")),
    Target("bvh", "BVH via inference.loaders.load_motion", _bvh, max_len=16384, timeout=20,
           surface=("inference.loaders", "inference.loaders.bvh", "inference.loaders.joint_maps",
                    "inference.loaders.retarget")),
    Target("asf-amc", "ASF + AMC pair via load_motion (needs HDM_dg.asf for the seed)", _asf_amc,
           max_len=16384, timeout=20,
           surface=("inference.loaders", "inference.loaders.asf_amc", "inference.loaders.joint_maps",
                    "inference.loaders.retarget")),
    Target("amass", "AMASS .npz bytes via load_motion", _amass, max_len=32768, timeout=20,
           surface=("inference.loaders", "inference.loaders.amass", "inference.loaders.amass_frames")),
    Target("amass-arrays", "AMASS .npz members (npy headers and data) via load_motion", _amass_arrays,
           max_len=32768, timeout=20,
           surface=("inference.loaders", "inference.loaders.amass", "inference.loaders.amass_frames")),
    Target("recording", "HDF5 session recording: app.recording.read_recording + hub_frames", _recording,
           max_len=65536, timeout=20,
           surface=("app.recording.format", "app.recording.header", "app.recording.libhdf5", "app.recording.reader")),
    Target("reference-c3d", "C3D markers as an imucap validate reference (ezc3d, then the joint-centre mapping)",
           _reference(".c3d"), max_len=16384, timeout=20,
           surface=("app.validate.reference", "app.validate.markers")),
    Target("reference-trc", "TRC markers as an imucap validate reference", _reference(".trc"), max_len=16384,
           timeout=20, surface=("app.validate.reference", "app.validate.markers")),
    Target("reference-mot", "OpenSim .mot coordinates as an imucap validate reference", _reference(".mot"),
           max_len=16384, timeout=20, surface=("app.validate.reference",)),
)}


# ------------------------------------------------------------------------------------------ running
def _checked(target: Target, run: Run, errors: Errors, lenient: bool) -> Run:
    def one(data: bytes) -> None:
        try:
            run(data)
        except errors:
            return
        except (ValueError, OSError) as exc:
            if lenient:
                return
            if not errors:
                raise DecodeEscaped(f"{type(exc).__name__}: {exc}") from exc
            raise UnclearError(f"{type(exc).__name__}: {exc}") from exc

    return one


INSTRUMENTED = ("drivers", "app", "inference", "sim_devices", "calibration")


def _ours() -> set[str]:
    return {name for name, mod in sys.modules.items()
            if name.split(".")[0] in INSTRUMENTED and getattr(mod, "__file__", None)}


def _child(args: argparse.Namespace) -> None:
    """The fuzzing process: libFuzzer exits when done, so it cannot report back itself."""
    import atheris

    target = TARGETS[args.target]
    work = Path(args.workdir) / target.name
    scratch = _scratch(target.name)
    before = _ours()
    if before:  # imported outside the block: libFuzzer would not see into them
        raise SystemExit(f"fuzz {target.name}: imported before instrumentation: {', '.join(sorted(before))}")
    with atheris.instrument_imports(include=list(INSTRUMENTED)):
        run, seeds, errors = target.setup(scratch)
        # The readers import their parsers when first called (load_motion picks BVH, ASF/AMC or
        # AMASS by the file name): each seed is run once here so those imports happen inside
        # the block. Imported later, the parser's code gives libFuzzer no coverage, and the
        # run mutates blind.
        warm = _checked(target, run, errors, lenient=True)
        for s in seeds:
            try:
                warm(s)
            except Exception:  # noqa: BLE001 - a seed that fails is libFuzzer's to report
                pass
    instrumented = _ours()
    blind = [m for m in target.surface if m not in instrumented]
    if blind:
        raise SystemExit(f"fuzz {target.name}: not instrumented (imported outside the block or never): "
                         f"{', '.join(blind)}")
    seed_dir, corpus = work / "seeds", work / "corpus"
    seed_dir.mkdir(parents=True, exist_ok=True)
    corpus.mkdir(parents=True, exist_ok=True)
    (work / "instrumented.txt").write_text("\n".join(sorted(instrumented)) + "\n")
    for i, s in enumerate(seeds):
        (seed_dir / f"seed-{i}").write_bytes(s)
    max_len = max(target.max_len, *(len(s) for s in seeds))
    argv = [sys.argv[0], str(corpus), str(seed_dir), f"-max_len={max_len}",
            f"-timeout={args.timeout or target.timeout}", f"-rss_limit_mb={args.rss_mb}",
            f"-artifact_prefix={work}/", "-print_final_stats=1", "-print_pcs=0", f"-seed={args.seed}"]
    if args.runs:
        argv.append(f"-runs={args.runs}")
    if args.seconds:
        argv.append(f"-max_total_time={args.seconds}")
    atheris.Setup(argv, _checked(target, run, errors, args.lenient))
    atheris.Fuzz()


_STAT = re.compile(r"stat::(\w+):\s+(\d+)")


def _parent(args: argparse.Namespace) -> int:
    """Run the fuzzer in a child, keep its log, print one JSON line of what it reached."""
    work = Path(args.workdir) / args.target
    work.mkdir(parents=True, exist_ok=True)
    log = work / "fuzz.log"
    cmd = [sys.executable, __file__, args.target, "--child", "--workdir", args.workdir, "--rss-mb", str(args.rss_mb),
           "--seed", str(args.seed)]
    for flag in ("runs", "seconds", "timeout"):
        if getattr(args, flag):
            cmd += [f"--{flag}", str(getattr(args, flag))]
    if args.lenient:
        cmd.append("--lenient")
    before = set(work.glob("crash-*")) | set(work.glob("timeout-*")) | set(work.glob("oom-*"))
    t0 = time.monotonic()
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(log, "w") as fh:
        rc = subprocess.call(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=REPO)
    wall = time.monotonic() - t0
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    # on shared cores at nice 19 wall-clock rates say more about the neighbours than the
    # target: the rate per CPU second is what another machine would see per core
    cpu = (cpu1.ru_utime - cpu0.ru_utime) + (cpu1.ru_stime - cpu0.ru_stime)
    text = log.read_text(errors="replace")
    stats = {k: int(v) for k, v in _STAT.findall(text)}
    found = sorted((set(work.glob("crash-*")) | set(work.glob("timeout-*")) | set(work.glob("oom-*"))) - before)
    runs = stats.get("number_of_executed_units", 0)
    summary = {
        "target": args.target, "runs": runs, "exec_per_s": round(runs / wall, 1) if wall else None,
        "exec_per_cpu_s": round(runs / cpu, 1) if cpu else None, "cpu_s": round(cpu, 1),
        "libfuzzer_exec_per_s": stats.get("average_exec_per_sec"), "seconds": round(wall, 1),
        "corpus": len(list((work / "corpus").iterdir())) if (work / "corpus").exists() else 0,
        "peak_rss_mb": stats.get("peak_rss_mb"), "findings": [str(p) for p in found], "exit": rc, "log": str(log),
    }
    if found:
        tail = [ln for ln in text.splitlines() if "Error" in ln or "Exception" in ln or "==" in ln][-6:]
        summary["what"] = tail
    elif rc:  # stopped before fuzzing (a surface module not instrumented, a seed missing): say why
        summary["what"] = text.strip().splitlines()[-1:]
    print(json.dumps(summary))
    return 0 if not found and rc == 0 else 1


def _replay(args: argparse.Namespace) -> int:
    """Run saved inputs without the fuzzer and show what escapes each (for fixing)."""
    import traceback

    target = TARGETS[args.target]
    run, _, errors = target.setup(_scratch(target.name))
    one = _checked(target, run, errors, args.lenient)
    bad = 0
    for f in args.replay:
        data = Path(f).read_bytes()
        t0 = time.monotonic()
        try:
            one(data)
            print(f"{f}: ok ({time.monotonic() - t0:.3f} s)")
        except Exception:  # noqa: BLE001 - showing the escape is the point
            bad += 1
            print(f"{f}: ESCAPED")
            traceback.print_exc()
    return 1 if bad else 0


def _resident_mb() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _memory(args: argparse.Namespace) -> int:
    """The reader's own memory over many inputs, without the fuzzer: the corpus mutated by
    a few random bytes each, run uninstrumented, resident memory after each sixth. A fuzzing
    process grows by itself (atheris' instrumentation keeps per-input state: +10 MB per
    30,000 asf-amc inputs instrumented, nothing without), so its peak RSS cannot tell a
    reader that leaks from one that does not; this can."""
    import random

    target = TARGETS[args.target]
    run, seeds, errors = target.setup(_scratch(target.name))
    one = _checked(target, run, errors, lenient=True)
    corpus_dir = Path(args.workdir) / target.name / "corpus"
    pool = [p.read_bytes() for p in sorted(corpus_dir.iterdir())] if corpus_dir.is_dir() else []
    pool += seeds
    rnd = random.Random(args.seed)

    def mutated() -> bytes:
        b = bytearray(rnd.choice(pool))
        for _ in range(rnd.randint(1, 4)):
            if b:
                b[rnd.randrange(len(b))] = rnd.randrange(256)
        return bytes(b)

    for _ in range(min(500, args.memory)):  # warm-up: lazy imports, caches, the allocator's arenas
        try:
            one(mutated())
        except AssertionError:
            pass
    slices, escaped = [round(_resident_mb(), 1)], 0
    step = max(1, args.memory // 6)
    for _ in range(6):
        for _ in range(step):
            try:
                one(mutated())
            except AssertionError:  # what the fuzzer would call a finding; counted, not chased here
                escaped += 1
        slices.append(round(_resident_mb(), 1))
    grew = slices[-1] - slices[1]
    print(json.dumps({"target": target.name, "inputs": 6 * step, "corpus": len(pool), "rss_mb": slices,
                      "growth_mb_after_first_sixth": round(grew, 1), "escaped": escaped}))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("target", help="a target name, or 'list'")
    ap.add_argument("--runs", type=int, default=0, help="inputs to run (libFuzzer -runs)")
    ap.add_argument("--seconds", type=int, default=0, help="stop after this long (libFuzzer -max_total_time)")
    ap.add_argument("--timeout", type=int, default=0, help="seconds one input may take (default per target)")
    ap.add_argument("--rss-mb", type=int, default=2048, help="memory limit of the fuzzing process")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workdir", default=str(REPO / "cache" / "fuzz"))
    ap.add_argument("--lenient", action="store_true", help="let any ValueError pass, not only the reader's own")
    ap.add_argument("--replay", nargs="+", metavar="FILE", help="run these inputs once and show what escapes")
    ap.add_argument("--memory", type=int, default=0, metavar="N",
                    help="no fuzzing: run N mutated corpus inputs uninstrumented, print resident memory per sixth")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.target == "list":
        for t in TARGETS.values():
            print(f"{t.name:14s} {t.what}")
        return 0
    if args.target not in TARGETS:
        ap.error(f"unknown target {args.target!r}; one of: {', '.join(TARGETS)}")
    if args.replay:
        return _replay(args)
    if args.memory:
        return _memory(args)
    if args.child:
        _child(args)
        return 0
    if not args.runs and not args.seconds:
        ap.error("give --runs N or --seconds S")
    return _parent(args)


if __name__ == "__main__":
    sys.exit(main())
