"""One reconstructed motion, many file formats: the container every writer takes, how it is
built from a recording (or from a replay's poses), and the dispatch by file extension.

Why a container of its own: a recording stores quaternions, session-clock times and the
body only as metadata, a replay yields ``LivePose`` objects, and each writer needs the
same handful of arrays plus the body's bone offsets. ``ExportMotion`` is that common
ground, so ``imucap export`` (the recorded live reconstruction) and ``imucap replay --out``
(a re-run) write through the very same code.

Formats (by the output file's extension, case-insensitive):

    .bvh          app/export/bvh.py      skeleton animation (Blender, MotionBuilder, ...)
    .csv          app/export/csv_file.py      one row per 20 Hz frame, named columns
    .h5 / .hdf5   app/export/hdf5_file.py     arrays + attributes (units, names, provenance)
    .mot          app/export/opensim.py  OpenSim joint angles (Rajagopal-style coordinates)
    .c3d          app/export/c3d_file.py      virtual markers at the joint centres, contact events (ezc3d)
    .trc          app/export/trc_file.py      the same markers for OpenSim's marker IK
    NAME_orientations.sto  app/export/opensense.py  OpenSense IMU orientations (quaternion table)

Time in every export is seconds since the first raw frame of the recording (so a file
lines up with the recording it came from); the session-clock value subtracted is kept as
``time_origin`` in the HDF5 attributes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from app.export.bvh import write_bvh
from app.export.c3d_file import write_c3d
from app.export.common import ExportMotion
from app.export.csv_file import write_csv
from app.export.hdf5_file import write_hdf5
from app.export.opensense import SUFFIX as ORIENTATIONS_SUFFIX
from app.export.opensense import write_orientations_sto
from app.export.opensim import write_mot
from app.export.trc_file import write_trc
from inference.body.body import Body
from inference.body.skeleton import N_SEGMENTS

if TYPE_CHECKING:
    from app.live import LivePose
    from app.recording import Recording

DEFAULT_HEIGHT_M = 1.75


# ---------------------------------------------------------------------------- building


def body_for_recording(metadata: dict[str, Any], height: float | None = None) -> tuple[Body, str | None]:
    """The subject's Body for a recording: ``height`` if given, else the bone offsets the
    session stored (``metadata["body_offsets"]``, exact), else its ``body_height_m``
    (anthropometric proportions), else 1.75 m with a note to show the user."""
    if height is not None:
        return Body.from_height(float(height)), None
    offsets = metadata.get("body_offsets")
    h = metadata.get("body_height_m")
    if offsets is not None:
        return Body.from_offsets(np.asarray(offsets, dtype=np.float64), None if h is None else float(h)), None
    if h is not None:
        return Body.from_height(float(h)), None
    return Body.from_height(DEFAULT_HEIGHT_M), (
        f"the recording states no body height; using {DEFAULT_HEIGHT_M} m (pass --height to set it)")


def _time_origin(rec: Recording) -> float:
    t = rec.raw["t"]
    return float(t[0]) if len(t) else 0.0


def md_source(rec: Recording) -> str:
    """The system an imported recording came from ("" for one recorded here)."""
    return str(rec.metadata.get("source") or "")


def _provenance(rec: Recording) -> dict[str, Any]:
    md = rec.metadata
    out = {"source_recording": str(rec.path), "recorded_sensors": list(rec.sites),
           "created": rec.attrs.get("created"), "app_version": md.get("app_version")}
    if md.get("log_time_origin_s") is not None:  # an import: frame 0 on the original log's clock
        out["log_time_origin_s"] = float(md["log_time_origin_s"])
    return out


def motion_from_recording(rec: Recording, body: Body) -> ExportMotion:
    """The live reconstruction stored in a recording (``/recon``)."""
    r = rec.recon
    if len(r["t"]) == 0:
        what = "an imported log is calibrated, not reconstructed" if md_source(rec) else "was the session calibrated?"
        raise ValueError(f"{rec.path} holds no reconstructed frames ({what}); reconstruct and write it with: "
                         f"imucap replay {rec.path} --out FILE")
    md = rec.metadata
    t0 = _time_origin(rec)
    meta = {**_provenance(rec), "model": md.get("model"), "steps": md.get("steps"),
            "sensors": list(md.get("sensors") or rec.sites), "insoles": bool(md.get("insoles", False)),
            "time_origin": t0, "what": "recorded live reconstruction"}
    return ExportMotion(time=r["t"] - t0, rot=r["R"], root=r["root"], joints=r["joints"], contacts=r["contacts"],
                        contact_prob=r.get("contact_prob"), body=body, meta=meta, spread_deg=r.get("spread_deg"),
                        root_spread_m=r.get("root_spread_m"))


def motion_from_poses(poses: Sequence[LivePose], body: Body, rec: Recording | None = None,
                      meta: dict[str, Any] | None = None) -> ExportMotion:
    """Poses from a (re-)run of the pipeline, e.g. ``replay``; times relative to the
    recording's start when ``rec`` is given."""
    if not poses:
        raise ValueError("nothing to export: the replay produced no frames")
    t0 = _time_origin(rec) if rec is not None else float(poses[0].t)
    m = {**(_provenance(rec) if rec is not None else {}), "time_origin": t0, **(meta or {})}
    return ExportMotion(
        time=np.array([lp.t for lp in poses]) - t0,
        rot=np.stack([lp.pose.rot for lp in poses]), root=np.stack([lp.pose.root for lp in poses]),
        joints=np.stack([lp.pose.joints for lp in poses]), contacts=np.stack([lp.pose.contacts for lp in poses]),
        contact_prob=np.stack([lp.pose.contact_prob for lp in poses]), body=body, meta=m,
        spread_deg=np.stack([np.full(N_SEGMENTS, np.nan) if lp.pose.spread_deg is None else lp.pose.spread_deg
                             for lp in poses]),
        root_spread_m=np.array([np.nan if lp.pose.root_spread_m is None else lp.pose.root_spread_m for lp in poses]))


# ---------------------------------------------------------------------------- dispatch


BVH_SIDECAR = ".json"  # NAME.bvh -> NAME.bvh.json


def _write_bvh(path: Path, m: ExportMotion) -> Path:
    """BVH has no field for when its first frame was, and no comments: the time origin goes
    beside it in ``NAME.bvh.json`` (``bvh_sidecar``), as JSON any tool reads."""
    out = write_bvh(path, m.rot, m.root, m.body, m.fps)
    side = path.with_name(path.name + BVH_SIDECAR)
    tmp = side.with_name(side.name + ".tmp")
    tmp.write_text(json.dumps(bvh_sidecar(m), indent=1, default=str) + "\n")
    os.replace(tmp, side)
    return out


def bvh_sidecar(m: ExportMotion) -> dict[str, Any]:
    """What a BVH cannot say of its frames: frame 0's time on the recording's clock
    (``time_origin_s`` + the first frame's ``time``) and, for an import, on the original
    log's clock (``log_time_origin_s``); the frame time; where the motion came from."""
    t0 = float(m.meta.get("time_origin") or 0.0) + (float(m.time[0]) if m.n_frames else 0.0)
    out = {"format": "imucap-bvh-sidecar", "version": 1, "first_frame_time_s": round(t0, 6),
           "frame_time_s": 1.0 / m.fps, "frames": m.n_frames, "gaps_closed": m.gaps,
           **{k: v for k, v in m.meta.items() if k in ("source_recording", "model", "sensors", "what")}}
    if "log_time_origin_s" in m.meta:
        out["log_first_frame_time_s"] = round(float(m.meta["log_time_origin_s"]) + t0, 6)
    return out


def _write_csv(path: Path, m: ExportMotion) -> Path:
    return write_csv(path, m)


def _write_hdf5(path: Path, m: ExportMotion) -> Path:
    return write_hdf5(path, m)


def _write_mot(path: Path, m: ExportMotion) -> Path:
    return write_mot(path, m)


WRITERS: dict[str, Callable[[Path, ExportMotion], Path]] = {
    ".bvh": _write_bvh, ".csv": _write_csv, ".h5": _write_hdf5, ".hdf5": _write_hdf5, ".mot": _write_mot,
    ".c3d": write_c3d, ".trc": write_trc,
}
# formats named by the end of the file name, not its extension alone (checked first)
NAME_WRITERS: dict[str, Callable[[Path, ExportMotion], Path]] = {ORIENTATIONS_SUFFIX: write_orientations_sto}


def supported_extensions() -> str:
    return ", ".join([*WRITERS, *(f"NAME{s}" for s in NAME_WRITERS)])


def writer_for(path: Path) -> Callable[[Path, ExportMotion], Path] | None:
    name = path.name.lower()
    for end, writer in NAME_WRITERS.items():
        if name.endswith(end) and len(name) > len(end):
            return writer
    return WRITERS.get(path.suffix.lower())


def check_export_path(path: str | os.PathLike) -> Path:
    """The path if its extension names a format we write, else a ValueError listing the
    supported ones. Called before a long replay, so a typo fails at once, not at the end."""
    p = Path(path)
    if writer_for(p) is None:
        raise ValueError(f"cannot export to {p.name!r}: unknown extension {p.suffix or '(none)'!r}; "
                         f"supported: {supported_extensions()}")
    return p


def export_motion(path: str | os.PathLike, motion: ExportMotion) -> Path:
    """Write ``motion`` in the format its extension names; returns the path."""
    p = check_export_path(path)
    if motion.n_frames < 1:
        raise ValueError(f"nothing to export to {p}: no frames")
    return writer_for(p)(p, motion)


