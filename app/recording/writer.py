"""Writing a recording (``Recorder``, a pipeline sink): every dataset created up front,
then SWMR mode, rows buffered and appended + flushed every ``flush_interval``; a disk
fault stops the recording, not the session (the package docstring says why)."""

from __future__ import annotations

import functools
import json
import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.live import LivePose, Sink
from app.recording.format import (
    CAL_META,
    EVENT_DETAIL,
    EVENT_FIELDS,
    EVENT_KIND,
    FORMAT,
    INSOLE_FIELDS,
    POSITION_FIELD,
    RECON_FIELDS,
    SITE_FIELDS,
    VERSION,
    calibration_fields,
    fault_text,
    fill_value,
    fit_text,
    fixed_attr,
)
from calibration import Calibration
from calibration.core import quat_of
from drivers.hub import HubFrame
from inference.body.skeleton import N_SEGMENTS

CHUNKS_CACHED = 2
"""Chunks each dataset of a recording keeps in memory while writing: the one being filled
(so appending never reads it back from disk) and one more. HDF5 2.0 gives every dataset an
8 MiB chunk cache by default, and a recording appends to ~40 datasets, so an hour-long
session's memory grew with what it had written until each dataset's cache was full (+93 MB
in 60 minutes, ``docs/robustness.md``). Fully written chunks go first (``rdcc_w0 = 1``)."""


_NO_POSITION = np.full(3, np.nan)


def _ds(g: h5py.Group, name: str, tail: tuple[int, ...], dtype: Any, chunk: int) -> h5py.Dataset:
    chunk_bytes = chunk * int(np.prod(tail, dtype=np.int64)) * np.dtype(dtype).itemsize
    return g.create_dataset(name, shape=(0,) + tail, maxshape=(None,) + tail, chunks=(chunk,) + tail, dtype=dtype,
                            fletcher32=True, fillvalue=fill_value(dtype), rdcc_nbytes=CHUNKS_CACHED * chunk_bytes,
                            rdcc_w0=1.0)


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
    crash can lose); position_sites: the sites whose positions are kept (a VR rig's: the
    hub's ``HubFrame.position``), each a ``position`` dataset beside its other channels.

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
                 on_error: Callable[[float, str], None] | None = None,
                 position_sites: Sequence[str] = ()) -> None:
        self._lock = threading.RLock()
        self.path = Path(path)
        self.sites = tuple(sites)
        unknown = [s for s in position_sites if s not in self.sites]
        if unknown:
            raise ValueError(f"position site(s) {unknown} are not among the recording's sites {self.sites}")
        # (index in the frame, site) of each site whose positions are kept
        self._positions = [(k, s) for k, s in enumerate(self.sites) if s in set(position_sites)]
        self.flush_interval = flush_interval
        self.clock = clock
        self.on_error = on_error
        self.error: str | None = None
        S = len(self.sites)
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            f = h5py.File(self.path, "w", libver="latest")
        except OSError as exc:
            raise OSError(f"cannot create the recording {self.path}: {fault_text(exc)}") from None
        self._f: h5py.File | None = f
        try:
            fixed_attr(f, "format", FORMAT)
            f.attrs["version"] = VERSION
            fixed_attr(f, "created", time.strftime("%Y-%m-%dT%H:%M:%S%z"))
            fixed_attr(f, "sites", json.dumps(list(self.sites)))
            fixed_attr(f, "metadata", json.dumps(metadata or {}, default=str))
            raw = f.create_group("raw")
            self._raw: dict[str, h5py.Dataset] = {"t": _ds(raw, "t", (), "f8", chunk),
                                                  "index": _ds(raw, "index", (), "i8", chunk)}
            for s in self.sites:
                g = raw.create_group(s)
                for name, tail, dt in SITE_FIELDS:
                    self._raw[f"{s}/{name}"] = _ds(g, name, tail, dt, chunk)
                if s in set(position_sites):
                    name, tail, dt = POSITION_FIELD
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
            raise OSError(f"cannot create the recording {self.path}: {fault_text(exc)}") from None
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
        for k, s in self._positions:
            b[f"{s}/position"].append(_NO_POSITION if frame.position is None else frame.position[k])
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
        b["cal/meta"].append(fit_text(json.dumps(calibration.meta, default=str), CAL_META))
        self.flush()  # rare and precious

    @_locked
    def on_event(self, t: float, kind: str, detail: str = "") -> None:
        """A marker, a note, a device lost or back: written at the next flush (markers at once)."""
        if self.closed:
            return
        self._buf["ev/t"].append(t)
        self._buf["ev/kind"].append(fit_text(kind, EVENT_KIND))
        self._buf["ev/detail"].append(fit_text(detail, EVENT_DETAIL))
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
            self._fail(fault_text(exc))
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
            self._fail(f"cannot finish the file: {fault_text(exc)}")

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
            return f"its folder {self.path.parent} cannot be reached ({fault_text(exc)})"
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
            self._fail(f"{problem}, and the data could not be rescued ({fault_text(exc)})")
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
            tried.append(f"{folder}: {fault_text(exc)}")
    return None, "; ".join(tried)
