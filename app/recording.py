"""Session recording to HDF5, written incrementally so a crash loses at most one second.

Layout (``FORMAT`` / ``VERSION`` in the root attributes, with ``metadata``: a JSON object
with the sensor configuration, model, steps, app version, ...):

    /raw/t (N,) float64 session time of each 60 Hz hub frame, /raw/index (N,) int64
    /raw/<site>/quat (N,4) (w,x,y,z) R_GS as the device sent it, free_acc (N,3) in the
        device's reference frame, acc (N,3) specific force, gyro (N,3), present (N,) bool
        -- raw, *before* calibration, so a replay can recalibrate
    /raw/insoles/force (N,2), contacts (N,4) bool, present (N,) bool
    /calibration/t (K,), R_WG (K,S,3,3), R_SB (K,S,3,3), acc_offset (K,S,3), valid (K,S),
        residual_world_deg, residual_tpose_deg (K,S): every calibration that took effect
        meta (K,) JSON: the protocol and the quality report of each calibration
    /recon/t (M,), index (M,), rot (M,24,4) quaternions R_WB, root (M,3), joints (M,24,3),
        contacts (M,4) bool, contact_prob (M,4), observed_sites (M,13) bool, insoles (M,),
        latency_ms (M,) (NaN when not live), spread_deg (M,24) and root_spread_m (M,): the
        poser's per-segment confidence (inference/poser/confidence.py; NaN when off)
    /events/t (E,), kind (E,), detail (E,): what happened during the session, in order:
        markers (detail = label), notes, devices lost and back, recording errors, and
        ``recalibration`` where a dropped calibration stopped the posing (a replay pauses
        there until the next calibration)

Strings are fixed-length UTF-8 (JSON in ``meta``): SWMR appends to fixed-size types only.

Why it survives ``kill -9``: every dataset is created up front (chunked, resizable), then
the file switches to SWMR mode, where HDF5 orders its writes so that the file on disk is
always a consistent snapshot of the last ``flush``. Data is buffered in memory and
appended + flushed every ``flush_interval`` s. A file whose writer died is read with
``swmr=True`` (``open_recording`` does that by itself), which is also how a second
process can follow a recording live.

Why every chunk carries a Fletcher32 checksum: a session cannot be recorded again, and
without one a flipped block of bytes on a failing disk or a bad copy reads as motion.
``read_recording`` verifies each chunk, skips the ones that fail, keeps all the rest and
lists what it skipped in ``Recording.damage``. Unwritten rows read back as NaN times
(the datasets' fill value), so a file cut short by a full disk cannot pass zeros off as
data either. Files written before the checksums read as they always did.

Why a write error does not raise: the recorder is one sink among the live view's; a full
disk or a vanished folder must stop the recording, loudly (``Recorder.error``,
``on_error``), not the session.
"""

from __future__ import annotations

import ctypes
import errno
import functools
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.live import LivePose, Sink
from calibration import Calibration
from calibration.core import quat_of
from drivers.hub import HubFrame
from inference.body.rotations import quat_to_matrix
from inference.body.skeleton import N_CONTACTS, N_SEGMENTS, N_SITES, SITES

FORMAT = "imucap-session"
VERSION = 1
CAL_META = "S8192"
EVENT_KIND = "S32"
EVENT_DETAIL = "S512"

# (name, per-row shape, dtype) of every dataset; the reader needs them to stand in for one
# it cannot open
SITE_FIELDS = (("quat", (4,), "f4"), ("free_acc", (3,), "f4"), ("acc", (3,), "f4"), ("gyro", (3,), "f4"),
               ("present", (), "?"))
INSOLE_FIELDS = (("force", (2,), "f4"), ("contacts", (N_CONTACTS,), "?"), ("present", (), "?"))
RECON_FIELDS = (("t", (), "f8"), ("index", (), "i8"), ("rot", (N_SEGMENTS, 4), "f4"), ("root", (3,), "f4"),
                ("joints", (N_SEGMENTS, 3), "f4"), ("contacts", (N_CONTACTS,), "?"),
                ("contact_prob", (N_CONTACTS,), "f4"), ("observed_sites", (N_SITES,), "?"), ("insoles", (), "?"),
                ("latency_ms", (), "f4"), ("spread_deg", (N_SEGMENTS,), "f4"), ("root_spread_m", (), "f4"))
# recon fields recordings from before they existed lack (read back as NaN)
RECON_NEWER = ("spread_deg", "root_spread_m")
EVENT_FIELDS = (("t", (), "f8"), ("kind", (), EVENT_KIND), ("detail", (), EVENT_DETAIL))


def calibration_fields(n_sites: int) -> tuple[tuple[str, tuple[int, ...], str], ...]:
    S = n_sites
    return (("t", (), "f8"), ("R_WG", (S, 3, 3), "f8"), ("R_SB", (S, 3, 3), "f8"), ("acc_offset", (S, 3), "f8"),
            ("valid", (S,), "?"), ("residual_world_deg", (S,), "f8"), ("residual_tpose_deg", (S,), "f8"),
            ("meta", (), CAL_META))


def _fit(text: str, dtype: str) -> bytes:
    """UTF-8 bytes cut to the field's size (on a character boundary)."""
    limit = int(dtype[1:])
    raw = text.encode("utf-8")
    return raw if len(raw) <= limit else raw[:limit].decode("utf-8", "ignore").encode("utf-8")


def _fill(dtype: Any) -> Any:
    """What a row nobody wrote reads as: NaN times and values, index -1, False flags, so a
    reader can tell a row that never reached the disk from a real one (HDF5's default,
    zero, would pass for time 0 and a motionless sensor)."""
    kind = np.dtype(dtype).kind
    return np.nan if kind == "f" else -1 if kind in "iu" else False if kind == "b" else b""


CHUNKS_CACHED = 2
"""Chunks each dataset of a recording keeps in memory while writing: the one being filled
(so appending never reads it back from disk) and one more. HDF5 2.0 gives every dataset an
8 MiB chunk cache by default, and a recording appends to ~40 datasets, so an hour-long
session's memory grew with what it had written until each dataset's cache was full (+93 MB
in 60 minutes, ``docs/robustness.md``). Fully written chunks go first (``rdcc_w0 = 1``)."""


def _ds(g: h5py.Group, name: str, tail: tuple[int, ...], dtype: Any, chunk: int) -> h5py.Dataset:
    chunk_bytes = chunk * int(np.prod(tail, dtype=np.int64)) * np.dtype(dtype).itemsize
    return g.create_dataset(name, shape=(0,) + tail, maxshape=(None,) + tail, chunks=(chunk,) + tail, dtype=dtype,
                            fletcher32=True, fillvalue=_fill(dtype), rdcc_nbytes=CHUNKS_CACHED * chunk_bytes,
                            rdcc_w0=1.0)


_ERRNO_WORDS = {28: "the disk is full", 27: "the file size limit is reached",
                122: "the disk quota is used up", 30: "the disk became read-only", 13: "permission denied",
                5: "the disk failed (input/output error)", 2: "the file or its folder is gone"}


def _why(exc: BaseException) -> str:
    """One short line out of an OSError or HDF5's multi-part message (which carries the
    system's errno and text buried in a paragraph)."""
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    num = exc.errno if isinstance(exc, OSError) and exc.errno else None
    m = re.search(r"errno = (\d+)", text)
    if num is None and m:
        num = int(m.group(1))
    m = re.search(r"error message = '([^']*)'", text)
    detail = m.group(1) if m else (exc.strerror if isinstance(exc, OSError) and exc.strerror else None)
    if detail is None:
        detail = " ".join(text.split("\n")[0].split())[:200] or type(exc).__name__
    word = _ERRNO_WORDS.get(num) if num is not None else None
    return f"{word} ({detail})" if word and word.lower() not in detail.lower() else detail


def _locked(method: Callable[..., Any]) -> Callable[..., Any]:
    """Run a Recorder method under its lock. Frames and poses arrive on the pipeline's thread,
    device events on the hub's reader threads, and a session's stop closes from its own: a
    flush clearing a buffer another thread is appending to wrote half a row (seen on stop:
    "Can't broadcast (0,) -> (0, 24)")."""

    @functools.wraps(method)
    def run(self: Recorder, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            return method(self, *args, **kwargs)

    return run


class Recorder(Sink):
    """A pipeline sink writing the session to ``path`` (see the module docstring).

    sites: the suit's sites in the hub's order; metadata: JSON-able dict stored as the
    root attribute ``metadata``; flush_interval: seconds between flushes (the most a
    crash can lose).

    Faults while recording (disk full, the disk gone read-only, an I/O error, the file or
    its folder removed) never raise into the pipeline: the recorder stops writing, sets
    ``error`` (one line: what happened, how much of the session the file keeps and where
    it is), prints that line on stderr and calls ``on_error(t, error)`` once, ``t`` being
    the session time of the last frame it received. ``failed`` is then True and
    ``closed`` too, the other sinks (the live view) carry on. A file removed from under
    the recorder still lives in the open handle: it is finished there and copied back to
    ``path`` (its folder made again), else to ``~/imucap-rescued/`` or the temporary
    folder; ``path`` then names the copy. Creating the file is the one place that raises
    (OSError naming the file), so a session cannot start a recording that goes nowhere.
    """

    def __init__(self, path: str | os.PathLike, sites: Sequence[str], metadata: dict[str, Any] | None = None,
                 flush_interval: float = 1.0, chunk: int = 256, clock: Callable[[], float] = time.monotonic,
                 on_error: Callable[[float, str], None] | None = None) -> None:
        self._lock = threading.RLock()
        self.path = Path(path)
        self.sites = tuple(sites)
        self.flush_interval = flush_interval
        self.clock = clock
        self.on_error = on_error
        self.error: str | None = None
        S = len(self.sites)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            f = h5py.File(self.path, "w", libver="latest")
        except OSError as exc:
            raise OSError(f"cannot create the recording {self.path}: {_why(exc)}") from None
        self._f: h5py.File | None = f
        try:
            _fixed_attr(f, "format", FORMAT)
            f.attrs["version"] = VERSION
            _fixed_attr(f, "created", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
            _fixed_attr(f, "sites", json.dumps(list(self.sites)))
            _fixed_attr(f, "metadata", json.dumps(metadata or {}, default=str))
            raw = f.create_group("raw")
            self._raw: dict[str, h5py.Dataset] = {"t": _ds(raw, "t", (), "f8", chunk),
                                                  "index": _ds(raw, "index", (), "i8", chunk)}
            for s in self.sites:
                g = raw.create_group(s)
                for name, tail, dt in SITE_FIELDS:
                    self._raw[f"{s}/{name}"] = _ds(g, name, tail, dt, chunk)
            g = raw.create_group("insoles")
            for name, tail, dt in INSOLE_FIELDS:
                self._raw[f"insoles/{name}"] = _ds(g, name, tail, dt, chunk)
            cal = f.create_group("calibration")
            self._cal = {name: _ds(cal, name, tail, dt, 4) for name, tail, dt in calibration_fields(S)}
            rec = f.create_group("recon")
            self._rec = {name: _ds(rec, name, tail, dt, max(chunk // 3, 16)) for name, tail, dt in RECON_FIELDS}
            ev = f.create_group("events")
            self._ev = {name: _ds(ev, name, tail, dt, 16) for name, tail, dt in EVENT_FIELDS}
            f.swmr_mode = True  # from here on the file on disk is always consistent
            st = os.fstat(f.id.get_vfd_handle())
        except (OSError, RuntimeError) as exc:
            self._close_quietly()
            raise OSError(f"cannot create the recording {self.path}: {_why(exc)}") from None
        self._inode = (st.st_dev, st.st_ino)  # to notice the file removed or replaced under us
        self._buf: dict[str, list] = {k: [] for k in (*self._raw, *(f"cal/{k}" for k in self._cal),
                                                      *(f"rec/{k}" for k in self._rec),
                                                      *(f"ev/{k}" for k in self._ev))}
        self._last_flush = self.clock()
        self._t_first: float | None = None  # session time of the first frame
        self._t_last: float | None = None  # ... of the last frame received
        self._t_saved: float | None = None  # ... of the last frame on disk
        self.frames = 0
        self.poses = 0
        self.flushes = 0
        self.closed = False

    @property
    def failed(self) -> bool:
        return self.error is not None

    # ------------------------------------------------------------------ sink
    @_locked
    def on_frame(self, frame: HubFrame) -> None:
        if self.closed:
            return
        if frame.sites != self.sites:
            raise ValueError(f"recorder sites {self.sites} differ from the frame's {frame.sites}")
        b = self._buf
        b["t"].append(frame.t)
        b["index"].append(frame.index)
        for k, s in enumerate(self.sites):
            b[f"{s}/quat"].append(frame.quat[k])
            b[f"{s}/free_acc"].append(frame.free_acc[k])
            b[f"{s}/acc"].append(frame.acc[k])
            b[f"{s}/gyro"].append(frame.gyro[k])
            b[f"{s}/present"].append(bool(frame.present[k]))
        b["insoles/force"].append(frame.insole_force)
        b["insoles/contacts"].append(frame.contacts)
        b["insoles/present"].append(bool(frame.insole_present))
        if self._t_first is None:
            self._t_first = float(frame.t)
        self._t_last = float(frame.t)
        self.frames += 1
        self._maybe_flush()

    @_locked
    def on_calibration(self, calibration: Calibration, t: float) -> None:
        if self.closed:
            return
        idx = calibration.index(self.sites)
        b = self._buf
        S = len(self.sites)
        b["cal/t"].append(t)
        b["cal/R_WG"].append(calibration.R_WG[idx])
        b["cal/R_SB"].append(calibration.R_SB[idx])
        b["cal/acc_offset"].append(calibration.acc_offset[idx])
        b["cal/valid"].append(calibration.valid[idx])
        for name in ("residual_world_deg", "residual_tpose_deg"):
            v = getattr(calibration, name)
            b[f"cal/{name}"].append(np.full(S, np.nan) if v is None else v[idx])
        b["cal/meta"].append(_fit(json.dumps(calibration.meta, default=str), CAL_META))
        self.flush()  # rare and precious

    @_locked
    def on_event(self, t: float, kind: str, detail: str = "") -> None:
        """A marker, a note, a device lost or back: written at the next flush (markers at once)."""
        if self.closed:
            return
        self._buf["ev/t"].append(t)
        self._buf["ev/kind"].append(_fit(kind, EVENT_KIND))
        self._buf["ev/detail"].append(_fit(detail, EVENT_DETAIL))
        if kind == "marker":
            self.flush()

    @_locked
    def on_pose(self, pose: LivePose) -> None:
        if self.closed:
            return
        p = pose.pose
        b = self._buf
        b["rec/t"].append(pose.t)
        b["rec/index"].append(pose.index)
        b["rec/rot"].append(quat_of(p.rot))
        b["rec/root"].append(p.root)
        b["rec/joints"].append(p.joints)
        b["rec/contacts"].append(p.contacts)
        b["rec/contact_prob"].append(p.contact_prob)
        b["rec/observed_sites"].append(pose.observed_sites)
        b["rec/insoles"].append(pose.insoles)
        b["rec/latency_ms"].append(np.nan if pose.latency_ms is None else pose.latency_ms)
        b["rec/spread_deg"].append(np.full(N_SEGMENTS, np.nan) if p.spread_deg is None else p.spread_deg)
        b["rec/root_spread_m"].append(np.nan if p.root_spread_m is None else p.root_spread_m)
        self.poses += 1
        self._maybe_flush()

    # ------------------------------------------------------------------ writing
    def _maybe_flush(self) -> None:
        if self.clock() - self._last_flush >= self.flush_interval:
            self.flush()

    def _write(self) -> None:
        """Append everything buffered and flush the file (raises what the disk says)."""
        assert self._f is not None
        last_t = self._buf["t"][-1] if self._buf["t"] else None
        for key, vals in self._buf.items():
            if not vals:
                continue
            if key.startswith("cal/"):
                ds = self._cal[key[4:]]
            elif key.startswith("ev/"):
                ds = self._ev[key[3:]]
            elif key.startswith("rec/"):
                ds = self._rec[key[4:]]
            else:
                ds = self._raw[key]
            arr = np.asarray(vals, dtype=ds.dtype)
            n = ds.shape[0]
            ds.resize(n + len(arr), axis=0)
            ds[n:] = arr
            vals.clear()
        self._f.flush()
        if last_t is not None:
            self._t_saved = float(last_t)

    @_locked
    def flush(self) -> None:
        """Append everything buffered and make it durable; a disk fault stops the recording
        (see the class docstring) instead of raising."""
        if self.closed:
            return
        gone = self._gone()
        if gone is not None:
            self._rescue(gone)
            return
        try:
            self._write()
        except (OSError, RuntimeError) as exc:  # h5py reports a failed write as either
            self._fail(_why(exc))
            return
        self.flushes += 1
        self._last_flush = self.clock()

    @_locked
    def close(self) -> None:
        if self.closed:
            return
        self.flush()
        if self.closed:  # the flush met a fault and dealt with it
            return
        self.closed = True
        try:
            self._close_file()
        except (OSError, RuntimeError) as exc:
            self.closed = False
            self._fail(f"cannot finish the file: {_why(exc)}")

    # ------------------------------------------------------------------ faults
    def _gone(self) -> str | None:
        """Why ``path`` no longer leads to the file being written, if it does not: writes to
        a deleted file succeed (into a file nobody can open), so only a look at the path
        tells."""
        try:
            st = os.stat(self.path)
        except FileNotFoundError:
            if not self.path.parent.exists():
                return f"its folder {self.path.parent} was removed"
            return f"the file {self.path} was deleted"
        except OSError as exc:
            return f"its folder {self.path.parent} cannot be reached ({_why(exc)})"
        if (st.st_dev, st.st_ino) != self._inode:
            return f"the file {self.path} was replaced by another one"
        return None

    def _close_file(self) -> None:
        f, self._f = self._f, None
        self._raw, self._rec, self._cal, self._ev = {}, {}, {}, {}
        if f is not None:
            f.close()

    def _close_quietly(self) -> None:
        """Let go of a file that cannot be written any more; HDF5 tries to write what it
        still holds on close and fails again, which is nothing new to report."""
        try:
            self._close_file()
        except Exception:  # noqa: BLE001 - the fault was reported already
            pass

    def _abandon(self) -> None:
        """Let go of a file the disk refused: HDF5 still holds metadata it will try to write
        on close and again at exit, failing each time (and at exit, crashing). Its file
        descriptor is pointed at /dev/null first, so those writes go nowhere and the file
        on disk stays as the last writes left it -- the state of a killed writer, which
        ``read_recording`` reads."""
        if self._f is not None:
            try:
                fd = self._f.id.get_vfd_handle()
                null = os.open(os.devnull, os.O_RDWR)
                try:
                    os.dup2(null, fd)
                finally:
                    os.close(null)
            except (OSError, RuntimeError, ValueError):
                pass
        self._close_quietly()

    def _kept(self) -> str:
        if self._t_saved is None or self._t_first is None:
            return "no frame"
        return f"the first {self._t_saved - self._t_first:.1f} s"

    def _fail(self, problem: str, where: Path | None = None) -> None:
        self.closed = True
        for vals in self._buf.values():
            vals.clear()
        self._abandon()
        dur = (self._t_last - self._t_first) if self._t_first is not None and self._t_last is not None else 0.0
        where = where or self.path
        self.error = (f"recording stopped after {dur:.1f} s: {problem}; {where} keeps {self._kept()} "
                      f"of the session")
        self._report()

    def _rescue(self, problem: str) -> None:
        """The file was unlinked from under us (its folder removed, say): finish it in the
        still open handle, then copy it somewhere it can be found."""
        assert self._f is not None
        try:
            keep = os.dup(self._f.id.get_vfd_handle())  # keeps the orphaned file alive past close
        except (OSError, RuntimeError) as exc:
            self._fail(f"{problem}, and the data could not be rescued ({_why(exc)})")
            return
        try:
            t = self._t_last if self._t_last is not None else float("nan")
            self.on_event(t, "error", f"recording stopped: {problem}")
            try:
                self._write()
                self._close_file()
            except (OSError, RuntimeError):
                self._close_quietly()  # what the last flush left is still a consistent file
            self.closed = True
            target, why = _copy_out(keep, self.path)
        finally:
            os.close(keep)
        if target is None:
            self.error = (f"recording stopped: {problem}, and the data could not be saved anywhere "
                          f"({why})")
            self._report()
            return
        remade = target.parent == self.path.parent
        self.path = target
        self._fail(problem + ("; the folder was made again to save it" if remade else ""), where=target)

    def _report(self) -> None:
        print(f"imucap: {self.error}", file=sys.stderr, flush=True)
        if self.on_error is not None:
            t = self._t_last if self._t_last is not None else float("nan")
            try:
                self.on_error(t, self.error or "")
            except Exception as exc:  # noqa: BLE001 - the recorder must not raise into the pipeline
                print(f"imucap: recording error callback failed: {exc}", file=sys.stderr)


def _copy_out(fd: int, wanted: Path) -> tuple[Path | None, str]:
    """Copy the file behind ``fd`` to ``wanted`` (its folder made again), else to
    ``~/imucap-rescued/`` or the temporary folder, never over an existing file."""
    tried = []
    for folder in (wanted.parent, Path.home() / "imucap-rescued", Path(tempfile.gettempdir()) / "imucap-rescued"):
        try:
            folder.mkdir(parents=True, exist_ok=True)
            target = folder / wanted.name
            k = 1
            while target.exists():
                target = folder / f"{wanted.stem}.rescued-{k}{wanted.suffix}"
                k += 1
            part = target.with_name(target.name + ".part")
            with open(part, "wb") as out:
                pos = 0
                while True:
                    block = os.pread(fd, 1 << 20, pos)
                    if not block:
                        break
                    out.write(block)
                    pos += len(block)
                out.flush()
                os.fsync(out.fileno())
            os.replace(part, target)
            return target, ""
        except OSError as exc:
            tried.append(f"{folder}: {_why(exc)}")
    return None, "; ".join(tried)


# ---------------------------------------------------------------------------- reading


class RecordingError(ValueError):
    """A file imucap cannot take for a recording; the message is one line naming the file
    and the problem, which the CLI prints as it is."""

    def __init__(self, path: str | os.PathLike, problem: str) -> None:
        super().__init__(f"{path}: {problem}")
        self.path = Path(path)
        self.problem = problem


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def open_recording(path: str | os.PathLike) -> h5py.File:
    """Open a recording read-only, also one whose writer was killed or is still writing
    (SWMR read) or one cut short: HDF5 refuses a file shorter than its superblock says,
    but what it still holds is worth reading. Anything that is not a recording this
    version can read is a ``RecordingError``."""
    return open_recording_header(path)[0]


# A Recorder holds a new file locked while it lays out its datasets, until it switches to
# SWMR mode (milliseconds); a reader that comes in between waits this long for it
LOCKED_WAIT_S = 2.0


def _locked(exc: OSError) -> bool:
    return getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK) or \
        "Resource temporarily unavailable" in str(exc) or "unable to lock file" in str(exc)


def open_recording_header(path: str | os.PathLike) -> tuple[h5py.File, dict[str, Any]]:
    """``open_recording``, and the root's attributes read safely (``root_attributes``)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"recording {path} not found")
    if path.is_dir():
        raise RecordingError(path, "a folder, not a recording")
    try:
        with open(path, "rb") as fh:
            fh.read(8)
    except OSError as exc:
        raise RecordingError(path, f"cannot be read ({_why(exc)})") from None
    try:
        f = h5py.File(path, "r")
    except OSError:
        if not h5py.is_hdf5(path):
            raise RecordingError(path, "truncated or not an HDF5 file") from None
        deadline = time.monotonic() + LOCKED_WAIT_S
        while True:
            try:
                f = _open_swmr(path)
                break
            except OSError as exc:
                if not _locked(exc):
                    raise RecordingError(path, f"truncated or not an HDF5 file ({_why(exc)})") from None
                if time.monotonic() > deadline:
                    raise RecordingError(path, "locked by the program writing it, which has not made it readable "
                                               "yet; try again in a moment") from None
                time.sleep(0.05)
    try:
        attrs = root_attributes(f, path)
        _check_header(attrs, path)
    except BaseException:
        f.close()
        raise
    return f, attrs


# HDF5 re-reads metadata that fails its checksum up to 100 times in SWMR mode, doubling a
# sleep each time, in case a live writer is half way through it: on a damaged or cut file
# that is a hang of hours. This many tries still give a live writer ~20 ms.
SWMR_READ_ATTEMPTS = 24
# a chunk of a file still (or last) open for writing that fails its read is tried again
# twice after this pause, in case the writer was rewriting it
IN_FLIGHT_RETRY_S = 0.01


@functools.cache
def _hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py already runs on (the very instance: property lists are ids
    into it), for the one setting h5py does not expose; None when it cannot be found.
    Looked up once: scanning the process's memory map cost ~8 ms per damaged file opened."""
    candidates: list[str] = []
    try:
        with open("/proc/self/maps") as fh:
            candidates += sorted({line.split()[-1] for line in fh
                                  if re.search(r"/libhdf5[-.][^/]*$", line.strip())})
    except OSError:
        pass
    base = Path(h5py.__file__).parent
    for folder in (base.parent / "h5py.libs", base / ".dylibs"):
        candidates += sorted(str(c) for c in folder.glob("libhdf5[-.]*"))
    for c in candidates:
        try:
            lib = ctypes.CDLL(c, mode=getattr(os, "RTLD_NOLOAD", 0))
        except OSError:
            continue
        if hasattr(lib, "H5Pset_metadata_read_attempts"):
            return lib
    return None


def _open_swmr(path: Path) -> h5py.File:
    """SWMR read (a writer killed or still at work, or a file cut short), with few retries."""
    lib = _hdf5_library()
    if lib is None:
        return h5py.File(path, "r", libver="latest", swmr=True)
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    lib.H5Pset_metadata_read_attempts.argtypes = (ctypes.c_int64, ctypes.c_uint)
    if lib.H5Pset_metadata_read_attempts(fapl.id, SWMR_READ_ATTEMPTS) < 0:
        return h5py.File(path, "r", libver="latest", swmr=True)
    fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)


def _fixed_attr(f: h5py.File, name: str, text: str) -> None:
    """A string attribute of fixed length (UTF-8): it lives in the object header, where a
    variable-length one lives in HDF5's global heap (see ``root_attributes``)."""
    b = text.encode("utf-8")
    f.attrs.create(name, np.array(b, dtype=h5py.string_dtype("utf-8", max(len(b), 1))))


# HDF5 (2.0) can loop forever deserializing a damaged global heap, where variable-length
# strings live (a fuzzed recording hung it in H5HG__cache_heap_deserialize): such values are
# read by a child process that is given this long
HEAP_READ_TIMEOUT_S = 10.0

_ATTRS_CHILD = r"""
import json, sys
import h5py, numpy as np
path = sys.argv[1]
try:
    f = h5py.File(path, "r")
except OSError:
    f = h5py.File(path, "r", libver="latest", swmr=True)
def plain(v):
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        return [plain(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        return plain(v.item())
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v if isinstance(v, (str, int, float, bool)) or v is None else str(v)
print(json.dumps({k: plain(v) for k, v in f.attrs.items()}))
"""


def _in_heap(t: Any) -> bool:
    """Whether values of HDF5 type ``t`` are stored in the global heap."""
    if isinstance(t, h5py.h5t.TypeStringID):
        return bool(t.is_variable_str())
    if isinstance(t, h5py.h5t.TypeVlenID):
        return True
    if isinstance(t, h5py.h5t.TypeCompoundID):
        return any(_in_heap(t.get_member_type(i)) for i in range(t.get_nmembers()))
    if isinstance(t, h5py.h5t.TypeArrayID):
        return _in_heap(t.get_super())
    return False


def fixed_dataset(f: h5py.File, name: str, path: str | os.PathLike) -> h5py.Dataset:
    """``f[name]``, refused when its values would be read from the global heap (see
    ``root_attributes``): not what the Recorder writes, and a damaged heap can hang HDF5."""
    ds = f[name]
    if not isinstance(ds, h5py.Dataset) or _in_heap(ds.id.get_type()):
        raise RecordingError(Path(path), f"damaged: {name} is not the dataset a recording holds")
    return ds


def _decoded(v: Any) -> Any:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.generic):
        return _decoded(v.item())
    return v


def root_attributes(f: h5py.File, path: str | os.PathLike) -> dict[str, Any]:
    """The root's attributes, strings decoded. The Recorder writes fixed-length strings;
    recordings from before that (and foreign files) hold variable-length ones in the global
    heap, read by a child process with ``HEAP_READ_TIMEOUT_S``: a damaged heap costs that
    wait and a one-line error, never a hang of the caller (the window lists recordings)."""
    path = Path(path)
    try:
        names = list(f.attrs)
        heap = any(_in_heap(h5py.h5a.open(f.id, n.encode()).get_type()) for n in names)
        if not heap:
            return {n: _decoded(f.attrs[n]) for n in names}
    except (OSError, RuntimeError, KeyError, ValueError, TypeError):
        raise RecordingError(path, "truncated or not an HDF5 file (its header cannot be read)") from None
    try:
        out = subprocess.run([sys.executable, "-c", _ATTRS_CHILD, os.fspath(path)], capture_output=True, text=True,
                             timeout=HEAP_READ_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise RecordingError(path, f"damaged: its header cannot be read (HDF5 did not return within "
                                   f"{HEAP_READ_TIMEOUT_S:g} s)") from None
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no reason given"])[-1]
        raise RecordingError(path, f"truncated or not an HDF5 file (its header cannot be read: {last})")
    try:
        attrs = json.loads(out.stdout)
    except ValueError:
        raise RecordingError(path, "damaged: its header cannot be read") from None
    return attrs if isinstance(attrs, dict) else {}


def _check_header(attrs: dict[str, Any], path: Path) -> None:
    fmt = attrs.get("format")
    version = attrs.get("version")
    if fmt != FORMAT:
        if fmt == "imucap-motion":
            raise RecordingError(path, "an exported motion (imucap export/replay --out), not a session recording")
        what = f"format {fmt!r}" if fmt is not None else "no 'format' attribute"
        raise RecordingError(path, f"an HDF5 file but not an imucap session recording ({what})")
    try:
        v = int(version)
    except (TypeError, ValueError):
        raise RecordingError(path, f"damaged: format version {version!r} is not a number") from None
    if v > VERSION:
        raise RecordingError(path, f"written by a newer imucap (format version {v}); update imucap")


@dataclass
class Recording:
    """A recording in memory. raw: ``t``, ``index`` and per site dicts (quat, free_acc,
    acc, gyro, present) plus ``insoles``; calibrations: (t, Calibration) in order;
    recon: arrays as in the file, ``rot`` also as matrices under ``R``.

    damage: one line per stretch that could not be read (a chunk whose checksum failed,
    a part cut off, rows never written), e.g. ``raw/l_wrist/quat frames 1024-1279
    (t 17.1-21.3 s): checksum failed, skipped``, t in seconds from the first raw frame as
    in exports. What it names is not in the arrays: raw frames without a readable time
    are dropped, a site's damaged samples are not ``present`` (NaN), damaged poses,
    calibrations and events are dropped. checksums: every dataset carried Fletcher32
    (recordings from before the checksums did not, and were read unverified)."""

    path: Path
    sites: tuple[str, ...]
    metadata: dict[str, Any]
    raw: dict[str, Any]
    calibrations: list[tuple[float, Calibration]]
    recon: dict[str, np.ndarray]
    attrs: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)
    damage: list[str] = field(default_factory=list)
    checksums: bool = True

    def markers(self) -> list[tuple[float, str]]:
        return [(t, d) for t, k, d in self.events if k == "marker"]

    @property
    def n_frames(self) -> int:
        return int(len(self.raw["t"]))

    def hub_frames(self) -> list[HubFrame]:
        """The raw stream as hub frames, to replay through a ``Pipeline``."""
        S = len(self.sites)
        r = self.raw
        out = []
        for i in range(self.n_frames):
            quat = np.stack([r[s]["quat"][i] for s in self.sites]).astype(np.float64) if S else np.zeros((0, 4))
            vec = {n: np.stack([r[s][n][i] for s in self.sites]).astype(np.float64) if S else np.zeros((0, 3))
                   for n in ("free_acc", "acc", "gyro")}
            present = np.array([bool(r[s]["present"][i]) for s in self.sites])
            ins = r["insoles"]
            out.append(HubFrame(t=float(r["t"][i]), index=int(r["index"][i]), sites=self.sites, quat=quat,
                                free_acc=vec["free_acc"], acc=vec["acc"], gyro=vec["gyro"], present=present,
                                insole_force=ins["force"][i].astype(np.float64), contacts=ins["contacts"][i].copy(),
                                insole_present=bool(ins["present"][i])))
        return out


CHECKSUM_FAILED = "checksum failed"
UNREADABLE = "unreadable"
CUT_OFF = "beyond the end of the file (truncated)"
NEVER_WRITTEN = "never written"
MISSING = "missing"
ZEROED = "zeroed on disk"
# datasets in which a whole chunk of zeros cannot be data (times, indices, rotations): a
# block the disk zeroed passes Fletcher32, whose sums start at zero, and is caught here
NEVER_ZERO = frozenset({"t", "index", "quat", "rot", "R_WG", "R_SB"})


@dataclass
class _Column:
    """One dataset as read: its rows (fill values where lost) and the stretches lost."""

    name: str
    data: np.ndarray | None
    lost: list[tuple[int, int, str]]

    def fit(self, n: int, tail: tuple[int, ...], dtype: str) -> None:
        """Cut to the group's common length; a dataset that could not be opened stands in
        as n lost rows."""
        if self.data is None:
            self.data = np.full((n,) + tail, _fill(dtype), dtype=dtype)
            self.lost = [(0, n, self.lost[0][2] if self.lost else UNREADABLE)]
            return
        self.data = self.data[:n]
        self.lost = [(a, min(b, n), why) for a, b, why in self.lost if a < n]

    def bad(self) -> np.ndarray:
        assert self.data is not None
        m = np.zeros(len(self.data), bool)  # a (0, 0) entry: could not be opened, no rows to mark
        for a, b, _ in self.lost:
            m[a:b] = True
        return m


def _runs(spans: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for a, b in spans:
        if out and out[-1][1] == a:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _stretches(mask: np.ndarray) -> list[tuple[int, int]]:
    """[a, b) runs of True."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _chunk_places(ds: h5py.Dataset) -> dict[int, tuple[int, int]] | None:
    """First row of each chunk on disk -> (byte offset, size); None when HDF5 cannot list
    them (the chunk index itself damaged)."""
    places: dict[int, tuple[int, int]] = {}

    def visit(info: Any) -> None:
        places[int(info.chunk_offset[0])] = (int(info.byte_offset), int(info.size))

    try:
        ds.id.chunk_iter(visit)
    except (AttributeError, NotImplementedError):  # HDF5 older than 1.12.3: the slow way
        try:
            for i in range(ds.id.get_num_chunks()):
                visit(ds.id.get_chunk_info(i))
        except (OSError, RuntimeError):
            return None
    except (OSError, RuntimeError):
        return None
    return places


class _Reader:
    """Reads a recording chunk by chunk where it must, so that one bad chunk costs its own
    rows and not the dataset, the group or the file."""

    def __init__(self, f: h5py.File, path: Path) -> None:
        self.f = f
        self.size = os.path.getsize(path)
        flags, self.stored_eof = _superblock(path)
        # a writer has it open, or died with it open: the rows at the end of a dataset that
        # are not on disk yet were in flight, not lost from a finished file
        self.in_flight = bool(flags)
        self.checksums = True
        self.fields: dict[str, int] = {}  # group -> how many datasets it has
        # (group, dataset, first row, end row, why, unit, times of the first and last row)
        self.entries: list[tuple[str, str, int, int, str, str, float | None, float | None]] = []

    def column(self, name: str, tail: tuple[int, ...], dtype: str) -> _Column:
        try:
            ds = self.f.get(name)  # one lookup where the dataset is there (most of a read's time was lookups)
            if ds is None:  # absent, or linked but its object unreadable
                return _Column(name, None, [(0, 0, UNREADABLE if name in self.f else MISSING)])
            # a type in the global heap is never what the Recorder writes, and a damaged heap
            # can hang HDF5 (root_attributes)
            if not isinstance(ds, h5py.Dataset) or ds.shape[1:] != tail or _in_heap(ds.id.get_type()):
                return _Column(name, None, [(0, 0, UNREADABLE)])
            return _Column(name, *self._read(ds))
        except (OSError, RuntimeError, KeyError, ValueError):
            return _Column(name, None, [(0, 0, UNREADABLE)])

    def _read(self, ds: h5py.Dataset) -> tuple[np.ndarray, list[tuple[int, int, str]]]:
        shape, dtype = ds.shape, ds.dtype  # each a call into HDF5
        L = shape[0]
        out = np.full(shape, _fill(dtype), dtype=dtype)
        if L == 0:
            return out, []
        if ds.chunks is None:  # not written by the Recorder; nothing to go by but HDF5's word
            try:
                out[...] = ds[...]
                return out, []
            except (OSError, RuntimeError):
                return out, [(0, L, UNREADABLE)]
        checked = bool(ds.fletcher32)
        self.checksums &= checked
        rows = ds.chunks[0]
        places = _chunk_places(ds)
        lost: list[tuple[int, int, str]] = []
        good: list[tuple[int, int]] = []
        # only chunks known to lie inside the file are read: past a cut, HDF5 reads zeros,
        # and zeros pass Fletcher32 (its sums start at 0)
        for a in range(0, L, rows):
            b = min(a + rows, L)
            if places is not None:
                place = places.get(a)
            else:  # the index cannot be walked whole (cut or damaged): ask chunk by chunk
                try:
                    info = ds.id.get_chunk_info_by_coord((a,) + (0,) * (ds.ndim - 1))
                except (OSError, RuntimeError, ValueError):
                    lost.append((a, b, UNREADABLE))
                    continue
                place = None if info.byte_offset is None else (int(info.byte_offset), int(info.size))
            if place is None:
                lost.append((a, b, NEVER_WRITTEN))
            elif place[0] + place[1] > self.size:
                lost.append((a, b, CUT_OFF))
            else:
                good.append((a, b))
        why = CHECKSUM_FAILED if checked else UNREADABLE
        for ra, rb in _runs(good):
            try:
                out[ra:rb] = ds[ra:rb]
                continue
            except (OSError, RuntimeError):
                pass
            for a in range(ra, rb, rows):  # find the bad chunk(s) in the run
                b = min(a + rows, rb)
                for attempt in range(3 if self.in_flight else 1):  # a live writer may be rewriting it
                    try:
                        out[a:b] = ds[a:b]
                        break
                    except (OSError, RuntimeError):
                        if attempt == (2 if self.in_flight else 0):
                            lost.append((a, b, why))
                        else:
                            time.sleep(IN_FLIGHT_RETRY_S)
        if ds.name.rsplit("/", 1)[-1] in NEVER_ZERO:
            bad = {(a, b) for a, b, _ in lost}
            for a, b in good:
                if (a, b) not in bad and not np.any(out[a:b]):
                    out[a:b] = _fill(ds.dtype)
                    lost.append((a, b, ZEROED))
        return out, sorted(lost)

    def group(self, group: str, fields: Sequence[tuple[str, tuple[int, ...], str]], optional: bool = False,
              newer: Sequence[str] = ()) -> tuple[dict[str, _Column], int]:
        """Every field of ``group`` cut to their common length (a killed writer leaves them
        a few rows apart). optional: the group may be absent altogether; newer: fields
        that recordings made before they existed lack (no damage, fill values)."""
        cols = {name: self.column(f"{group}/{name}", tail, dt) for name, tail, dt in fields}
        self.fields[group] = len(cols)
        absent = {name for name, c in cols.items() if c.data is None and c.lost[0][2] == MISSING}
        if optional and len(absent) == len(cols):
            return {}, 0
        lengths = [self._written(name, c) for name, c in cols.items() if c.data is not None]
        n = min(lengths) if lengths else 0
        for (name, tail, dt), c in zip(fields, cols.values()):
            c.fit(n, tail, dt)
            if name in absent and name in newer:
                c.lost = []
        return cols, n

    def _written(self, name: str, c: _Column) -> int:
        """Rows of ``c`` to take: all of them, but in a file still (or last) open for
        writing not the ones at the end that have not reached the disk yet (no chunk, a
        chunk past the end of the file, times and indices still the fill value)."""
        assert c.data is not None
        n = len(c.data)
        if not self.in_flight:
            return n
        for a, b, why in sorted(c.lost, reverse=True):
            if b != n or why not in (CUT_OFF, NEVER_WRITTEN):
                break
            n = a
        if name in ("t", "index"):
            ok = np.flatnonzero(np.isfinite(c.data[:n]) if name == "t" else c.data[:n] >= 0)
            n = int(ok[-1]) + 1 if len(ok) else 0
        return n

    def note(self, cols: dict[str, _Column], group: str, unit: str, times: np.ndarray) -> None:
        """Remember the lost stretches of ``cols``, timed by ``times`` (NaN where unknown,
        estimated from the neighbours)."""
        t = np.asarray(times, dtype=np.float64)
        ok = np.flatnonzero(np.isfinite(t))
        step = float(np.median(np.diff(t[ok]) / np.diff(ok))) if len(ok) > 1 else 0.0

        def at(i: int) -> float:
            if i < ok[0]:
                return float(t[ok[0]] - (ok[0] - i) * step)
            if i > ok[-1]:
                return float(t[ok[-1]] + (i - ok[-1]) * step)
            return float(np.interp(i, ok, t[ok]))

        for c in cols.values():
            for a, b, why in c.lost:
                ta = tb = None
                if len(ok) and b > a:
                    ta, tb = at(a), at(b - 1)
                self.entries.append((group, c.name, a, b, why, unit, ta, tb))

    def damage(self, origin: float) -> list[str]:
        """One line per damaged stretch: the same stretch lost in several datasets of a
        group (a cut-off file, a bad block across interleaved chunks) is one line."""
        out = []
        keyed: dict[tuple[str, str, str], list] = {}
        for g, name, a, b, why, unit, ta, tb in self.entries:
            keyed.setdefault((g, why, unit), []).append([a, b, {name}, ta, tb])
        for (g, why, unit), items in keyed.items():
            items.sort(key=lambda it: (it[0], it[1]))
            merged: list[list] = []
            for a, b, names, ta, tb in items:
                m = merged[-1] if merged else None
                if m is not None and a <= m[1]:
                    m[1] = max(m[1], b)
                    m[2] |= names
                    m[3] = ta if m[3] is None else (m[3] if ta is None else min(m[3], ta))
                    m[4] = tb if m[4] is None else (m[4] if tb is None else max(m[4], tb))
                else:
                    merged.append([a, b, set(names), ta, tb])
            for a, b, names, ta, tb in merged:
                line = _damage_line(g, sorted(names), self.fields.get(g, 0), a, b, why, unit, ta, tb, origin)
                out.append((_GROUP_ORDER.index(g) if g in _GROUP_ORDER else 9, a, line))
        return [line for *_, line in sorted(out)]


_GROUP_ORDER = ("raw", "calibration", "events", "recon")


def _damage_line(group: str, names: list[str], total: int, a: int, b: int, why: str, unit: str,
                 ta: float | None, tb: float | None, origin: float) -> str:
    parents = {n.rsplit("/", 1)[0] for n in names}
    if len(names) == 1:
        what = names[0]
    elif len(names) == total:
        what = group
    elif len(parents) == 1:
        what = f"{parents.pop()}/{','.join(n.rsplit('/', 1)[1] for n in names)}"
    else:
        what = f"{group} ({len(names)} of {total} datasets)"
    rows = f"{unit[:-1]} {a}" if b - a == 1 else f"{unit} {a}-{b - 1}"
    when = ""
    if ta is not None and tb is not None:
        ta, tb = ta - origin, tb - origin
        when = f" (t {ta:.1f} s)" if f"{ta:.1f}" == f"{tb:.1f}" else f" (t {ta:.1f}-{tb:.1f} s)"
    if why == MISSING:
        return f"{what}: missing from the file, skipped"
    if b <= a:  # could not even be opened: how many rows it had is not known
        return f"{what}: {why}, skipped"
    return f"{what} {rows}{when}: {why}, skipped"


def _superblock(path: Path) -> tuple[int, int | None]:
    """(file consistency flags, file length) as HDF5's superblock (version 2 or 3, what
    the Recorder writes) states them: flags are non-zero while a writer has the file open
    and stay so if it dies. (0, None) for other superblocks."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(36)
    except OSError:
        return 0, None
    if len(head) < 36 or head[:8] != HDF5_SIGNATURE or head[8] not in (2, 3) or head[9] != 8:
        return 0, None
    return head[11], int.from_bytes(head[28:36], "little")


def _never_written(cols: dict[str, _Column], mask: np.ndarray, names: Sequence[str] = ("t",)) -> None:
    """Rows that read as the fill value (NaN time, index -1) were allocated but never
    reached the disk (the writer failed or died mid-flush): lost like a bad chunk, and
    charged to ``names[0]`` unless one of ``names`` lost them already."""
    bad = np.zeros(len(mask), bool)
    for name in names:
        bad |= cols[name].bad()
    extra = mask & ~bad
    cols[names[0]].lost += [(a, b, NEVER_WRITTEN) for a, b in _stretches(extra)]


def read_recording(path: str | os.PathLike) -> Recording:
    """Everything flushed so far (a live or killed file included), minus what cannot be
    trusted: a chunk that fails its checksum, a part cut off or never written is skipped
    and listed in ``Recording.damage`` (see there for what becomes of those rows), so one
    bad block costs seconds of a session, not the session."""
    path = Path(path)
    f, attrs = open_recording_header(path)
    with f:
        rd = _Reader(f, path)
        try:
            sites = tuple(json.loads(attrs["sites"]))
            meta = json.loads(attrs.get("metadata", "{}"))
        except (KeyError, ValueError, TypeError) as exc:
            raise RecordingError(path, f"damaged: its root attributes cannot be read ({_why(exc)})") from None
        S = len(sites)

        # raw: a frame without a readable time or index is dropped, a site's damaged samples
        # are marked not present
        raw_fields = [("t", (), "f8"), ("index", (), "i8")]
        raw_fields += [(f"{s}/{k}", tail, dt) for s in sites for k, tail, dt in SITE_FIELDS]
        raw_fields += [(f"insoles/{k}", tail, dt) for k, tail, dt in INSOLE_FIELDS]
        cols, n = rd.group("raw", raw_fields)
        t_raw = cols["t"].data.astype(np.float64)
        idx = cols["index"].data.astype(np.int64)
        _never_written(cols, ~np.isfinite(t_raw) | (idx < 0), ("t", "index"))
        drop = cols["t"].bad() | cols["index"].bad()
        t_raw[cols["t"].bad()] = np.nan
        rd.note(cols, "raw", "frames", t_raw)
        keep = ~drop
        raw: dict[str, Any] = {"t": t_raw[keep], "index": idx[keep]}
        for s, fields in [(s, SITE_FIELDS) for s in sites] + [("insoles", INSOLE_FIELDS)]:
            sub = {k: cols[f"{s}/{k}"] for k, _, _ in fields}
            hurt = np.zeros(n, bool)
            for c in sub.values():
                hurt |= c.bad()
            out = {}
            for k, c in sub.items():
                a = c.data
                if hurt.any():
                    a = a.copy()
                    a[hurt] = _fill(a.dtype)
                out[k] = a[keep]
            raw[s] = out

        # calibrations: a damaged row is dropped (replay then keeps the one before); a
        # damaged protocol/quality report alone costs only the report
        cols, k_cal = rd.group("calibration", calibration_fields(S), newer=("meta",))
        t_cal = cols["t"].data.astype(np.float64)
        _never_written(cols, ~np.isfinite(t_cal))
        meta_bad = cols["meta"].bad()
        drop_cal = np.zeros(k_cal, bool)
        for name, c in cols.items():
            if name != "meta":
                drop_cal |= c.bad()
        rd.note(cols, "calibration", "rows", t_cal)
        cals = []
        for i in np.flatnonzero(~drop_cal):
            cal_meta: dict[str, Any] = {}
            if not meta_bad[i]:
                try:
                    cal_meta = json.loads(cols["meta"].data[i].decode("utf-8") or "{}")
                except (UnicodeDecodeError, ValueError):
                    cal_meta = {}
            c = {name: col.data[i] for name, col in cols.items()}
            cals.append((float(c["t"]), Calibration(
                sites=sites, R_WG=c["R_WG"], R_SB=c["R_SB"], acc_offset=c["acc_offset"], valid=c["valid"],
                residual_world_deg=c["residual_world_deg"], residual_tpose_deg=c["residual_tpose_deg"],
                meta=cal_meta)))

        # events (recordings from before events had none)
        events = []
        cols, k_ev = rd.group("events", EVENT_FIELDS, optional=True)
        if cols:
            t_ev = cols["t"].data.astype(np.float64)
            _never_written(cols, ~np.isfinite(t_ev))
            drop_ev = np.zeros(k_ev, bool)
            for c in cols.values():
                drop_ev |= c.bad()
            rd.note(cols, "events", "rows", t_ev)
            events = [(float(t_ev[i]), cols["kind"].data[i].decode("utf-8", "replace"),
                       cols["detail"].data[i].decode("utf-8", "replace")) for i in np.flatnonzero(~drop_ev)]

        # recon: a damaged pose is dropped whole (export shows it as a gap)
        cols, m = rd.group("recon", RECON_FIELDS, newer=RECON_NEWER)
        t_rec = cols["t"].data.astype(np.float64)
        _never_written(cols, ~np.isfinite(t_rec))
        drop_rec = np.zeros(m, bool)
        for c in cols.values():
            drop_rec |= c.bad()
        rd.note(cols, "recon", "frames", t_rec)
        recon = {k: c.data[~drop_rec] for k, c in cols.items()}

        finite = raw["t"][np.isfinite(raw["t"])]
        origin = float(finite[0]) if len(finite) else (float(recon["t"][0]) if len(recon["t"]) else 0.0)
        damage = rd.damage(origin)
        eof = rd.stored_eof
        if eof is not None and rd.size < eof and not rd.in_flight:
            damage.insert(0, f"file truncated: {rd.size} of its {eof} bytes are there, what was in the rest is lost")
        checksums = rd.checksums
    m = len(recon["t"])
    recon["R"] = quat_to_matrix(recon["rot"].astype(np.float64)) if m else np.zeros((0, N_SEGMENTS, 3, 3))
    return Recording(path, sites, meta, raw, cals, recon, attrs, events, damage, checksums)


__all__ = ["Recorder", "Recording", "RecordingError", "read_recording", "open_recording", "open_recording_header",
           "root_attributes", "fixed_dataset", "FORMAT",
           "VERSION", "SITES"]
