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
        latency_ms (M,) (NaN when not live)
    /events/t (E,), kind (E,), detail (E,): what happened during the session, in order:
        markers (detail = label), notes, devices lost and back, recording errors

Strings are fixed-length UTF-8 (JSON in ``meta``): SWMR appends to fixed-size types only.

Why it survives ``kill -9``: every dataset is created up front (chunked, resizable), then
the file switches to SWMR mode, where HDF5 orders its writes so that the file on disk is
always a consistent snapshot of the last ``flush``. Data is buffered in memory and
appended + flushed every ``flush_interval`` s. A file whose writer died is read with
``swmr=True`` (``open_recording`` does that by itself), which is also how a second
process can follow a recording live.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.pipeline import LivePose, Sink
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


def _fit(text: str, dtype: str) -> bytes:
    """UTF-8 bytes cut to the field's size (on a character boundary)."""
    limit = int(dtype[1:])
    raw = text.encode("utf-8")
    return raw if len(raw) <= limit else raw[:limit].decode("utf-8", "ignore").encode("utf-8")


def _ds(g: h5py.Group, name: str, tail: tuple[int, ...], dtype: Any, chunk: int) -> h5py.Dataset:
    return g.create_dataset(name, shape=(0,) + tail, maxshape=(None,) + tail, chunks=(chunk,) + tail, dtype=dtype)


class Recorder(Sink):
    """A pipeline sink writing the session to ``path`` (see the module docstring).

    sites: the suit's sites in the hub's order; metadata: JSON-able dict stored as the
    root attribute ``metadata``; flush_interval: seconds between flushes (the most a
    crash can lose).
    """

    def __init__(self, path: str | os.PathLike, sites: Sequence[str], metadata: dict[str, Any] | None = None,
                 flush_interval: float = 1.0, chunk: int = 256, clock=time.monotonic) -> None:
        self.path = Path(path)
        self.sites = tuple(sites)
        self.flush_interval = flush_interval
        self.clock = clock
        self.path.parent.mkdir(parents=True, exist_ok=True)
        S = len(self.sites)
        f = h5py.File(self.path, "w", libver="latest")
        self._f = f
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        f.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        f.attrs["sites"] = json.dumps(list(self.sites))
        f.attrs["metadata"] = json.dumps(metadata or {}, default=str)
        raw = f.create_group("raw")
        self._raw: dict[str, h5py.Dataset] = {"t": _ds(raw, "t", (), "f8", chunk),
                                              "index": _ds(raw, "index", (), "i8", chunk)}
        for s in self.sites:
            g = raw.create_group(s)
            for name, tail, dt in (("quat", (4,), "f4"), ("free_acc", (3,), "f4"), ("acc", (3,), "f4"),
                                   ("gyro", (3,), "f4"), ("present", (), "?")):
                self._raw[f"{s}/{name}"] = _ds(g, name, tail, dt, chunk)
        g = raw.create_group("insoles")
        for name, tail, dt in (("force", (2,), "f4"), ("contacts", (N_CONTACTS,), "?"), ("present", (), "?")):
            self._raw[f"insoles/{name}"] = _ds(g, name, tail, dt, chunk)
        cal = f.create_group("calibration")
        self._cal = {name: _ds(cal, name, tail, dt, 4) for name, tail, dt in (
            ("t", (), "f8"), ("R_WG", (S, 3, 3), "f8"), ("R_SB", (S, 3, 3), "f8"), ("acc_offset", (S, 3), "f8"),
            ("valid", (S,), "?"), ("residual_world_deg", (S,), "f8"), ("residual_tpose_deg", (S,), "f8"),
            ("meta", (), CAL_META))}
        rec = f.create_group("recon")
        self._rec = {name: _ds(rec, name, tail, dt, max(chunk // 3, 16)) for name, tail, dt in (
            ("t", (), "f8"), ("index", (), "i8"), ("rot", (N_SEGMENTS, 4), "f4"), ("root", (3,), "f4"),
            ("joints", (N_SEGMENTS, 3), "f4"), ("contacts", (N_CONTACTS,), "?"), ("contact_prob", (N_CONTACTS,), "f4"),
            ("observed_sites", (N_SITES,), "?"), ("insoles", (), "?"), ("latency_ms", (), "f4"))}
        ev = f.create_group("events")
        self._ev = {name: _ds(ev, name, (), dt, 16) for name, dt in (("t", "f8"), ("kind", EVENT_KIND),
                                                                     ("detail", EVENT_DETAIL))}
        f.swmr_mode = True  # from here on the file on disk is always consistent
        self._buf: dict[str, list] = {k: [] for k in (*self._raw, *(f"cal/{k}" for k in self._cal),
                                                      *(f"rec/{k}" for k in self._rec),
                                                      *(f"ev/{k}" for k in self._ev))}
        self._last_flush = self.clock()
        self.frames = 0
        self.poses = 0
        self.flushes = 0
        self.closed = False

    # ------------------------------------------------------------------ sink
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
        self.frames += 1
        self._maybe_flush()

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

    def on_event(self, t: float, kind: str, detail: str = "") -> None:
        """A marker, a note, a device lost or back: written at the next flush (markers at once)."""
        if self.closed:
            return
        self._buf["ev/t"].append(t)
        self._buf["ev/kind"].append(_fit(kind, EVENT_KIND))
        self._buf["ev/detail"].append(_fit(detail, EVENT_DETAIL))
        if kind == "marker":
            self.flush()

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
        self.poses += 1
        self._maybe_flush()

    # ------------------------------------------------------------------ writing
    def _maybe_flush(self) -> None:
        if self.clock() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self) -> None:
        """Append everything buffered and make it durable."""
        if self.closed:
            return
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
        self.flushes += 1
        self._last_flush = self.clock()

    def close(self) -> None:
        if self.closed:
            return
        self.flush()
        self.closed = True
        self._f.close()


# ---------------------------------------------------------------------------- reading


def open_recording(path: str | os.PathLike) -> h5py.File:
    """Open a recording read-only, also one whose writer was killed or is still writing
    (SWMR read)."""
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        if "open for write" not in str(exc) and "consistency flags" not in str(exc):
            raise
        f = h5py.File(path, "r", libver="latest", swmr=True)
    if f.attrs.get("format") != FORMAT:
        f.close()
        raise ValueError(f"{path} is not an imucap session recording")
    return f


@dataclass
class Recording:
    """A recording in memory. raw: ``t``, ``index`` and per site dicts (quat, free_acc,
    acc, gyro, present) plus ``insoles``; calibrations: (t, Calibration) in order;
    recon: arrays as in the file, ``rot`` also as matrices under ``R``."""

    path: Path
    sites: tuple[str, ...]
    metadata: dict[str, Any]
    raw: dict[str, Any]
    calibrations: list[tuple[float, Calibration]]
    recon: dict[str, np.ndarray]
    attrs: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)

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


def read_recording(path: str | os.PathLike) -> Recording:
    """Everything flushed so far (a live or killed file included)."""
    with open_recording(path) as f:
        sites = tuple(json.loads(f.attrs["sites"]))
        meta = json.loads(f.attrs.get("metadata", "{}"))
        g = f["raw"]
        n = min([g["t"].shape[0], g["index"].shape[0]] + [g[s][k].shape[0] for s in sites for k in g[s]]
                + [g["insoles"][k].shape[0] for k in g["insoles"]])
        raw: dict[str, Any] = {"t": g["t"][:n], "index": g["index"][:n]}
        for s in (*sites, "insoles"):
            raw[s] = {k: g[s][k][:n] for k in g[s]}
        c = f["calibration"]
        k_cal = min(c[k].shape[0] for k in c)
        cals = []
        for i in range(k_cal):
            cal_meta = json.loads(c["meta"][i].decode("utf-8") or "{}") if "meta" in c else {}
            cals.append((float(c["t"][i]), Calibration(
                sites=sites, R_WG=c["R_WG"][i], R_SB=c["R_SB"][i], acc_offset=c["acc_offset"][i],
                valid=c["valid"][i], residual_world_deg=c["residual_world_deg"][i],
                residual_tpose_deg=c["residual_tpose_deg"][i], meta=cal_meta)))
        events = []
        if "events" in f:
            e = f["events"]
            k_ev = min(e[k].shape[0] for k in e)
            events = [(float(e["t"][i]), e["kind"][i].decode("utf-8"), e["detail"][i].decode("utf-8"))
                      for i in range(k_ev)]
        r = f["recon"]
        m = min(r[k].shape[0] for k in r)
        recon = {k: r[k][:m] for k in r}
        attrs = {k: (v if not isinstance(v, bytes) else v.decode()) for k, v in f.attrs.items()}
    recon["R"] = quat_to_matrix(recon["rot"].astype(np.float64)) if m else np.zeros((0, N_SEGMENTS, 3, 3))
    return Recording(Path(path), sites, meta, raw, cals, recon, attrs, events)


def replay(path: str | os.PathLike, poser, calibration: Calibration | None = None) -> list[LivePose]:
    """Run a recording's raw stream through the pipeline again (with its first calibration
    unless one is given): offline re-reconstruction with another model or steps."""
    from app.pipeline import Pipeline

    rec = read_recording(path)
    cal = calibration or (rec.calibrations[0][1] if rec.calibrations else None)
    if cal is None:
        raise ValueError(f"{path} holds no calibration; pass one")
    pipe = Pipeline(poser, rec.sites, calibration=cal, insoles=bool(rec.metadata.get("insoles", False)))
    t_cal = rec.calibrations[0][0] if rec.calibrations and calibration is None else -np.inf
    out: list[LivePose] = []
    for fr in rec.hub_frames():
        if fr.t > t_cal:
            out += pipe.push(fr)
    return out


__all__ = ["Recorder", "Recording", "read_recording", "open_recording", "replay", "FORMAT", "VERSION", "SITES"]
