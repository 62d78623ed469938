"""Bad files and disk faults, on real files these tests write: a chunk whose bytes were
overwritten is detected by its checksum, named and skipped while the rest reads; a cut,
foreign, newer or missing recording, a broken model file and an absurd motion file are
one-line CLI errors (exit 2) naming the file; a full disk, a removed folder and a disk
that stops taking writes stop the recording, never the session, and leave a file that
opens and replays."""

from __future__ import annotations

import itertools
import json
import os
import shutil
import struct
import subprocess
import sys
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch

from app.cli.main import main
from app.live import CallbackSink, Pipeline, frames_from_signals
from app.recording import VERSION, Recorder, Recording, RecordingError, read_recording
from app.replay import replay_recording
from calibration import Calibrator, Protocol, synthesize_session
from inference.body.body import Body
from inference.features.layout import N_FEATURES
from inference.loaders import MotionFormatError, load_motion
from inference.model.config import ModelConfig
from inference.model.files import ModelFileError, build_model, load_model, save_model
from inference.poser.poser import make_poser
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

REPO = Path(__file__).resolve().parents[3]
SITES = ("pelvis", "l_wrist", "r_wrist", "l_shank")
PROTO = Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.15)
CHUNK = 64  # small chunks: a short recording spans several, so one can go bad in the middle


@dataclass
class Session:
    sig: object
    body: Body


@pytest.fixture(scope="module")
def session() -> Session:
    sig, truth = synthesize_session(generate("walk", seconds=4.0, seed=2), PROTO, noise=NoiseModel.typical(), rng=3,
                                    sites=SITES)
    return Session(sig, truth.body)


@dataclass
class Run:
    rec: Recorder
    poses_after_fault: int  # what the session's other sink got once the fault had happened
    sink_errors: int
    fault_t: float | None


def _record(path: Path, session: Session, fault: Callable[[Recorder], None] | None = None,
            on_error: Callable[[float, str], None] | None = None) -> Run:
    """A real session (self-calibrating pipeline, floor poser) recorded to ``path``, with
    ``fault`` done to it a few flushes after calibration, and a second sink standing in for
    the live view."""
    ticks = itertools.count(0.0, 0.01)  # a stepping clock: flushes do not depend on machine speed
    meta = {"model": "floor", "insoles": False, "body_height_m": float(session.body.height)}
    rec = Recorder(path, SITES, metadata=meta, flush_interval=0.1, chunk=CHUNK, clock=lambda: next(ticks),
                   on_error=on_error)
    seen: list[float] = []
    pipe = Pipeline(make_poser("floor", body=session.body), SITES,
                    calibrator=Calibrator(SITES, schedule=PROTO.schedule()),
                    sinks=[rec, CallbackSink(on_pose=lambda p: seen.append(p.t))])
    fault_t = None
    for f in frames_from_signals(session.sig, t0=100.0):
        pipe.push(f)
        if fault is not None and fault_t is None and pipe.calibration is not None and rec.poses > 30:
            fault_t = f.t
            fault(rec)
    pipe.close()
    after = sum(t > fault_t for t in seen) if fault_t is not None else len(seen)
    return Run(rec, after, pipe.stats.sink_errors, fault_t)


@pytest.fixture(scope="module")
def good(tmp_path_factory, session) -> Path:
    path = tmp_path_factory.mktemp("good") / "walk.h5"
    run = _record(path, session)
    assert run.rec.closed and not run.rec.failed
    return path


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def _one_line_error(err: str, *words: str) -> None:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert all(w in lines[0] for w in words), err


def _replays(rec: Recording, body: Body) -> int:
    return len(replay_recording(rec, make_poser("floor", body=body)).poses)


# ---------------------------------------------------------------------------- checksums


def _clobber(src: Path, dst: Path, dataset: str, row: int) -> None:
    """Copy ``src`` and overwrite 8 bytes in the middle of the chunk holding ``row``."""
    shutil.copy(src, dst)
    with h5py.File(src, "r") as f:
        ds = f[dataset]
        info = ds.id.get_chunk_info_by_coord((row,) + (0,) * (ds.ndim - 1))
    with open(dst, "r+b") as fh:
        fh.seek(info.byte_offset + info.size // 2)
        fh.write(b"\x13\x37\xde\xad\xbe\xef\x00\x01")


def test_every_dataset_carries_a_checksum(good):
    with h5py.File(good, "r") as f:
        sets = []
        f.visititems(lambda name, obj: sets.append(obj) if isinstance(obj, h5py.Dataset) else None)
        assert len(sets) > 30
        assert all(ds.fletcher32 and ds.chunks is not None and ds.maxshape[0] is None for ds in sets)
        assert np.isnan(f["raw/t"].fillvalue) and f["raw/index"].fillvalue == -1
    r = read_recording(good)
    assert r.checksums and r.damage == [] and r.n_frames > 4 * CHUNK and len(r.recon["t"]) > 40


def test_overwritten_bytes_are_detected_named_and_skipped(good, tmp_path):
    orig = read_recording(good)
    bad = tmp_path / "bad.h5"
    _clobber(good, bad, "raw/l_wrist/quat", 2 * CHUNK + 5)
    r = read_recording(bad)
    a, b = 2 * CHUNK, 3 * CHUNK
    t0 = orig.raw["t"][0]
    assert r.damage == [f"raw/l_wrist/quat frames {a}-{b - 1} (t {orig.raw['t'][a] - t0:.1f}-"
                        f"{orig.raw['t'][b - 1] - t0:.1f} s): checksum failed, skipped"]
    # the damaged stretch is not motion: that sensor is absent there, NaN as a live gap
    w = r.raw["l_wrist"]
    assert not w["present"][a:b].any() and np.isnan(w["quat"][a:b]).all()
    # everything else is as written
    assert r.n_frames == orig.n_frames and np.array_equal(r.raw["t"], orig.raw["t"])
    keep = np.r_[0:a, b:r.n_frames]
    assert np.array_equal(w["quat"][keep], orig.raw["l_wrist"]["quat"][keep])
    assert np.array_equal(w["present"][keep], orig.raw["l_wrist"]["present"][keep])
    for s in ("pelvis", "r_wrist"):
        assert np.array_equal(r.raw[s]["quat"], orig.raw[s]["quat"])
    assert np.array_equal(r.recon["rot"], orig.recon["rot"]) and len(r.calibrations) == 1


def test_a_dataset_whose_header_is_damaged_is_unreadable_not_missing(good, tmp_path):
    """The link to the dataset is intact but its object header is not: the file does hold
    it, so the damage line must not say it is missing (that reads as an older format)."""
    bad = tmp_path / "bad_header.h5"
    shutil.copy(good, bad)
    with h5py.File(good, "r") as f:
        addr = h5py.h5o.get_info(f["raw/r_wrist/gyro"].id).addr
    with open(bad, "r+b") as fh:
        fh.seek(addr)
        fh.write(b"\x13\x37\xde\xad\xbe\xef\x00\x01")
    r = read_recording(bad)
    lines = [d for d in r.damage if "gyro" in d]
    assert len(lines) == 1 and lines[0].startswith("raw/r_wrist/gyro frames 0-") and \
        lines[0].endswith(": unreadable, skipped"), r.damage
    assert np.isnan(r.raw["r_wrist"]["gyro"]).all() and len(r.raw["t"]) == read_recording(good).n_frames


def _with_heap_strings(src: Path, dst: Path) -> None:
    """``src`` as imucap wrote recordings before its string attributes were of fixed
    length: variable-length strings, kept in HDF5's global heap."""
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        for name in ("format", "created", "sites", "metadata"):
            text = f.attrs[name].decode()
            del f.attrs[name]
            f.attrs[name] = text  # a Python str: variable length


def test_string_attributes_are_written_of_fixed_length(good):
    with h5py.File(good, "r") as f:
        for name in ("format", "created", "sites", "metadata"):
            t = h5py.h5a.open(f.id, name.encode()).get_type()
            assert isinstance(t, h5py.h5t.TypeStringID) and not t.is_variable_str(), name


def test_recordings_with_heap_strings_still_read(good, tmp_path):
    old = tmp_path / "old.h5"
    _with_heap_strings(good, old)
    r, new = read_recording(old), read_recording(good)
    assert r.sites == new.sites and r.metadata == new.metadata and r.attrs["created"] == new.attrs["created"]
    assert np.array_equal(r.raw["t"], new.raw["t"]) and not r.damage


def test_a_damaged_global_heap_is_an_error_not_a_hang(good, tmp_path, monkeypatch, capsys):
    """The fuzzer found a recording whose global heap (the free space at its end, size 0)
    sent HDF5 2.0 into an endless loop reading the 'format' attribute: the read is given
    a time limit and the file a one-line error."""
    import app.recording.header as header

    old = tmp_path / "heap.h5"
    _with_heap_strings(good, old)
    data = bytearray(old.read_bytes())
    at = data.find(b"GCOL")
    assert at > 0
    p = at + 16
    while struct.unpack_from("<H", data, p)[0] != 0:  # walk the heap's objects to its free space
        p += 16 + (struct.unpack_from("<Q", data, p + 8)[0] + 7) // 8 * 8
    struct.pack_into("<Q", data, p + 8, 0)
    old.write_bytes(bytes(data))
    monkeypatch.setattr(header, "HEAP_READ_TIMEOUT_S", 3.0)
    with pytest.raises(RecordingError, match="did not return within 3 s"):
        read_recording(old)
    code, _, err = _run(capsys, "replay", str(old))
    assert code == 2
    _one_line_error(err, str(old), "header cannot be read")


def test_a_damaged_pose_is_dropped_and_the_rest_kept(good, tmp_path):
    orig = read_recording(good)
    bad = tmp_path / "bad_recon.h5"
    with h5py.File(good, "r") as f:
        rows = f["recon/rot"].chunks[0]
    _clobber(good, bad, "recon/rot", rows + 1)
    r = read_recording(bad)
    assert len(r.damage) == 1 and r.damage[0].startswith(f"recon/rot frames {rows}-{2 * rows - 1} (t ")
    assert r.damage[0].endswith("checksum failed, skipped")
    keep = np.r_[0:rows, 2 * rows:len(orig.recon["t"])]
    assert np.array_equal(r.recon["t"], orig.recon["t"][keep])
    assert np.array_equal(r.recon["rot"], orig.recon["rot"][keep])


def test_a_block_zeroed_on_disk_is_not_taken_for_data(good, tmp_path):
    """Zeros, checksum included, pass Fletcher32; where a chunk of zeros cannot be data
    (times, indices, rotations) they are caught all the same."""
    orig = read_recording(good)
    bad = tmp_path / "zeroed.h5"
    shutil.copy(good, bad)
    with h5py.File(good, "r") as f:
        info = f["raw/t"].id.get_chunk_info_by_coord((CHUNK,))
    with open(bad, "r+b") as fh:
        fh.seek(info.byte_offset)
        fh.write(bytes(info.size))
    r = read_recording(bad)
    assert len(r.damage) == 1 and r.damage[0].startswith(f"raw/t frames {CHUNK}-{2 * CHUNK - 1} (t ")
    assert r.damage[0].endswith("zeroed on disk, skipped")
    assert r.n_frames == orig.n_frames - CHUNK and np.all(r.raw["t"] > 0)  # frames without a time are dropped
    assert np.array_equal(r.raw["index"], np.r_[orig.raw["index"][:CHUNK], orig.raw["index"][2 * CHUNK:]])


def test_a_recording_being_written_reads_clean(tmp_path):
    """SWMR with checksums: a second process following a live recording sees it grow,
    consistent, with nothing reported damaged (rows not yet on disk are simply not there)."""
    from tests.app.recording.test_recording import CHILD

    path = tmp_path / "live.h5"
    proc = subprocess.Popen([sys.executable, "-c", CHILD.format(repo=str(REPO), path=str(path))],
                            stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        seen = []
        while len(seen) < 5:
            line = proc.stdout.readline()
            assert line, "the writer stopped"
            r = read_recording(path)
            assert r.damage == [] and r.checksums
            assert np.array_equal(r.raw["index"], np.arange(r.n_frames))
            seen.append(r.n_frames)
        assert seen[-1] > seen[0]
    finally:
        proc.kill()
        proc.wait()


def test_replay_and_export_warn_once_per_damaged_stretch(good, session, tmp_path, capsys):
    bad = tmp_path / "bad.h5"
    _clobber(good, bad, "raw/l_wrist/quat", CHUNK + 1)
    code, out, err = _run(capsys, "export", str(bad), "--out", str(tmp_path / "x.csv"), "--json")
    assert code == 0, err
    warnings = [line for line in err.splitlines() if "warning" in line and "checksum" in line]
    assert len(warnings) == 1 and str(bad) in warnings[0] and "raw/l_wrist/quat frames 64-127" in warnings[0]
    assert json.loads(out)["damage"] == [warnings[0].split(f"{bad}: ", 1)[1]]
    code, out, err = _run(capsys, "replay", str(bad), "--model", "floor", "--json", "--no-progress")
    assert code == 0, err
    assert sum("checksum failed" in line for line in err.splitlines()) == 1
    assert json.loads(out)["frames"] > 40 and "Traceback" not in err


def test_recordings_from_before_the_checksums_still_read(good, tmp_path, capsys):
    old = tmp_path / "old.h5"
    with h5py.File(good, "r") as src, h5py.File(old, "w", libver="latest") as dst:
        for k, v in src.attrs.items():
            dst.attrs[k] = v

        def copy(name: str, obj: object) -> None:
            if isinstance(obj, h5py.Dataset):
                dst.create_dataset(name, data=obj[...], maxshape=(None,) + obj.shape[1:], chunks=obj.chunks)
        src.visititems(copy)
    r, orig = read_recording(old), read_recording(good)
    assert not r.checksums and r.damage == []
    assert np.array_equal(r.raw["l_wrist"]["quat"], orig.raw["l_wrist"]["quat"])
    code, out, err = _run(capsys, "export", str(old), "--out", str(tmp_path / "old.csv"))
    assert code == 0 and "warning" not in err, err


# ---------------------------------------------------------------------------- bad files


def test_a_truncated_recording_gives_back_what_it_holds(good, session, tmp_path, capsys):
    data = good.read_bytes()
    cut = tmp_path / "cut.h5"
    cut.write_bytes(data[:int(len(data) * 0.6)])
    orig, r = read_recording(good), read_recording(cut)
    assert 0 < r.n_frames < orig.n_frames
    assert np.array_equal(r.raw["t"], orig.raw["t"][:r.n_frames])  # a prefix, exactly as written
    assert np.array_equal(r.raw["pelvis"]["quat"][r.raw["pelvis"]["present"]],
                          orig.raw["pelvis"]["quat"][:r.n_frames][r.raw["pelvis"]["present"]])
    assert r.damage[0] == f"file truncated: {len(data) * 6 // 10} of its {len(data)} bytes are there, what was " \
                          "in the rest is lost"
    assert len(r.damage) > 1 and all(line.endswith(", skipped") for line in r.damage[1:])
    # nothing past the cut passes for data: every time kept is one that was written
    assert np.isin(r.recon["t"], orig.recon["t"]).all() and np.isfinite(r.recon["R"]).all()
    assert len(r.calibrations) == 1 and _replays(r, session.body) > 0
    code, out, err = _run(capsys, "export", str(cut), "--out", str(tmp_path / "cut.csv"), "--json")
    assert code == 0, err
    assert sum("warning" in line for line in err.splitlines()) == len(r.damage)
    assert json.loads(out)["damage"] == r.damage


@pytest.mark.parametrize("size", [0, 100, 2000])
def test_a_recording_cut_before_its_data_is_one_line_error(good, tmp_path, capsys, size):
    cut = tmp_path / "stub.h5"
    cut.write_bytes(good.read_bytes()[:size])
    with pytest.raises(RecordingError, match="truncated or not an HDF5 file"):
        read_recording(cut)
    code, _, err = _run(capsys, "replay", str(cut), "--model", "floor")
    assert code == 2
    _one_line_error(err, "imucap replay: error:", str(cut), "truncated or not an HDF5 file")


def test_a_recording_from_a_newer_imucap(good, tmp_path, capsys):
    newer = tmp_path / "newer.h5"
    shutil.copy(good, newer)
    with h5py.File(newer, "a") as f:
        f.attrs["version"] = VERSION + 1
    code, _, err = _run(capsys, "export", str(newer), "--out", str(tmp_path / "n.csv"))
    assert code == 2
    _one_line_error(err, str(newer), f"written by a newer imucap (format version {VERSION + 1}); update imucap")


def test_hdf5_files_that_are_not_recordings(good, tmp_path, capsys):
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    code, _, err = _run(capsys, "replay", str(other), "--model", "floor")
    assert code == 2
    _one_line_error(err, str(other), "an HDF5 file but not an imucap session recording")
    exported = tmp_path / "motion.h5"
    assert _run(capsys, "export", str(good), "--out", str(exported))[0] == 0
    code, _, err = _run(capsys, "export", str(exported), "--out", str(tmp_path / "again.csv"))
    assert code == 2
    _one_line_error(err, str(exported), "an exported motion")
    text = tmp_path / "notes.h5"
    text.write_text("not even HDF5\n")
    code, _, err = _run(capsys, "export", str(text), "--out", str(tmp_path / "t.csv"))
    assert code == 2
    _one_line_error(err, str(text), "truncated or not an HDF5 file")


@pytest.fixture(scope="module")
def model_files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("models")
    torch.manual_seed(0)
    good = d / "tiny.pt"
    save_model(good, build_model("diffusion", ModelConfig.tiny()).eval(), "diffusion",
               np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32))
    data = good.read_bytes()
    files = {"good": good}
    files["truncated"] = d / "truncated.pt"
    files["truncated"].write_bytes(data[:len(data) * 6 // 10])
    files["flipped"] = d / "flipped.pt"
    with zipfile.ZipFile(good) as z:  # torch's format: a zip archive, one member per tensor
        big = max(z.infolist(), key=lambda i: i.file_size)
    name_len, extra_len = struct.unpack("<HH", data[big.header_offset + 26:big.header_offset + 30])
    at = big.header_offset + 30 + name_len + extra_len + big.file_size // 2  # inside the largest tensor
    flipped = bytearray(data)
    flipped[at:at + 8] = bytes(255 - v for v in flipped[at:at + 8])
    files["flipped"].write_bytes(bytes(flipped))
    files["tensor"] = d / "tensor.pt"
    torch.save(torch.zeros(3), files["tensor"])
    files["empty"] = d / "empty.pt"
    files["empty"].write_bytes(b"")
    return files


@pytest.mark.parametrize("kind,words", [("truncated", "truncated model file"), ("flipped", "damaged model file"),
                                        ("tensor", "not an imucap model file"), ("empty", "an empty file")])
def test_a_broken_model_file_is_named(good, model_files, capsys, kind, words):
    load_model(model_files["good"])
    with pytest.raises(ModelFileError, match=words) as exc:
        load_model(model_files[kind])
    assert str(model_files[kind]) in str(exc.value) and "\n" not in str(exc.value)
    code, _, err = _run(capsys, "replay", str(good), "--model", str(model_files[kind]), "--no-progress")
    assert code == 2
    _one_line_error(err, "imucap replay: error:", str(model_files[kind]), words)


def _write_npz(path: Path, trans: np.ndarray, height: float = 1.75, T: int = 40) -> None:
    poses = np.zeros((T, 156))
    poses[:, 3 * 18 + 2] = np.linspace(0, 0.5, T)  # an elbow bending: some motion
    np.savez(path, poses=poses, trans=trans, mocap_framerate=np.array(60.0), imucap_height_m=np.array(height))


def test_motion_files_with_impossible_values(tmp_path, capsys):
    from app.export.bvh import write_bvh

    m = generate("walk", seconds=1.0, seed=1)
    good_bvh = write_bvh(tmp_path / "walk.bvh", m.rot, m.root, m.body, m.fps)
    lines = good_bvh.read_text().splitlines()
    row = lines.index(next(ln for ln in lines if ln.startswith("Frame Time"))) + 5
    nan = tmp_path / "nan.bvh"
    vals = lines[row].split()
    vals[4] = "nan"
    nan.write_text("\n".join(lines[:row] + [" ".join(vals)] + lines[row + 1:]) + "\n")
    T = 40
    trans = np.zeros((T, 3))
    trans[:, 0] = np.linspace(0, 1, T)
    _write_npz(tmp_path / "fine.npz", trans)
    jump = trans.copy()
    jump[20:, 0] += 30.0  # 30 m in one 60 Hz frame
    _write_npz(tmp_path / "jump.npz", jump)
    _write_npz(tmp_path / "giant.npz", trans, height=7.0)
    load_motion(good_bvh)
    load_motion(tmp_path / "fine.npz")
    cases = {"nan.bvh": "NaN", "jump.npz": "m/s", "giant.npz": "height"}
    for name, words in cases.items():
        p = tmp_path / name
        with pytest.raises(MotionFormatError, match=words) as exc:
            load_motion(p)
        assert str(p) in str(exc.value)
        code, _, err = _run(capsys, "data", "inspect", str(p))
        assert code == 2
        _one_line_error(err, "imucap data: error:", str(p), words)
        code, _, err = _run(capsys, "evaluate", "--data", str(p), "--model", "floor", "--sensors", "pelvis,l_wrist",
                            "--no-progress", "--json")
        assert code == 2
        assert "Traceback" not in err and str(p) in err.strip().splitlines()[-1]


# ---------------------------------------------------------------------------- disk faults


DISK_FULL_CHILD = r"""
import json, os, resource, signal, sys
sys.path.insert(0, {repo!r})
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # past the limit a write fails with EFBIG instead of killing us
from tests.app.recording.test_recording_faults import _record, Session
from calibration import Protocol, synthesize_session
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate
from tests.app.recording.test_recording_faults import PROTO, SITES
sig, truth = synthesize_session(generate("walk", seconds=4.0, seed=2), PROTO, noise=NoiseModel.typical(), rng=3,
                                sites=SITES)
path = {path!r}
saved = {{}}
def fill_disk(rec):
    saved["frames"] = rec.frames - len(rec._buf["t"])
    resource.setrlimit(resource.RLIMIT_FSIZE, (os.path.getsize(path) + 4096, resource.RLIM_INFINITY))
calls = []
run = _record(path, Session(sig, truth.body), fill_disk, on_error=lambda t, d: calls.append([t, d]))
print(json.dumps({{"error": run.rec.error, "calls": calls, "after": run.poses_after_fault,
                  "sink_errors": run.sink_errors, "saved_frames": saved["frames"], "frames": run.rec.frames}}))
"""


def test_disk_full_stops_the_recording_not_the_session(tmp_path, session):
    path = tmp_path / "full.h5"
    code = DISK_FULL_CHILD.format(repo=str(REPO), path=str(path))
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr, proc.stderr
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    assert res["error"] and "File too large" in res["error"] and str(path) in res["error"]
    assert [d for _, d in res["calls"]] == [res["error"]]  # said once, at once
    assert f"imucap: {res['error']}" in proc.stderr
    assert res["after"] > 20 and res["sink_errors"] == 0  # the live view went on
    r = read_recording(path)  # what was written until then opens ...
    assert res["saved_frames"] <= r.n_frames <= res["frames"]
    # the flush the disk refused is left out like a killed writer's last one: nothing damaged
    assert r.damage == []
    assert np.all(np.diff(r.raw["t"]) > 0) and np.all(np.isfinite(r.raw["t"]))
    assert len(r.calibrations) == 1 and _replays(r, session.body) > 0  # ... and replays


def test_folder_removed_while_recording(tmp_path, session):
    path = tmp_path / "clinic" / "patient.h5"
    calls: list[tuple[float, str]] = []
    run = _record(path, session, lambda rec: shutil.rmtree(path.parent), on_error=lambda t, d: calls.append((t, d)))
    rec = run.rec
    assert rec.failed and rec.closed and "was removed" in rec.error and str(path) in rec.error
    assert len(calls) == 1 and calls[0][1] == rec.error
    assert run.fault_t <= calls[0][0] < run.fault_t + 0.5  # noticed at the next flush
    assert run.poses_after_fault > 20 and run.sink_errors == 0
    # the file lived on in the open handle and was put back where it belongs, whole
    assert rec.path == path and path.exists()
    r = read_recording(path)
    assert r.damage == [] and r.raw["t"][-1] == pytest.approx(calls[0][0])
    assert any(kind == "error" and "removed" in detail for _, kind, detail in r.events)
    assert _replays(r, session.body) > 0


def test_folder_made_read_only_while_recording(tmp_path, session):
    """An open file stays writable when its folder is made read-only: the recording goes on
    to its end."""
    folder = tmp_path / "ro"
    try:
        run = _record(folder / "s.h5", session, lambda rec: os.chmod(folder, 0o555))
    finally:
        os.chmod(folder, 0o755)
    assert not run.rec.failed and run.rec.closed
    r = read_recording(folder / "s.h5")
    assert r.n_frames == run.rec.frames and len(r.recon["t"]) == run.rec.poses and r.damage == []


def test_disk_that_stops_taking_writes(tmp_path, session):
    """A disk gone read-only (or any write error) under an open recording: the recorder's
    file descriptor is swapped for a read-only one, so every further write fails."""
    path = tmp_path / "s.h5"

    def read_only(rec: Recorder) -> None:
        fd = rec._f.id.get_vfd_handle()
        ro = os.open(path, os.O_RDONLY)
        os.dup2(ro, fd)
        os.close(ro)

    calls: list[tuple[float, str]] = []
    run = _record(path, session, read_only, on_error=lambda t, d: calls.append((t, d)))
    assert run.rec.failed and len(calls) == 1 and "keeps the first" in run.rec.error
    assert run.poses_after_fault > 20 and run.sink_errors == 0
    r = read_recording(path)
    assert 0 < r.n_frames < run.rec.frames and len(r.calibrations) == 1
    assert _replays(r, session.body) > 0


def test_a_recording_that_cannot_be_created_says_where(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    with pytest.raises(OSError, match=f"cannot create the recording {blocker / 'sub' / 's.h5'}"):
        Recorder(blocker / "sub" / "s.h5", SITES)
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir(mode=0o555)
        with pytest.raises(OSError, match="(?i)permission denied"):
            Recorder(ro / "s.h5", SITES)
