"""One reconstructed motion, many file formats: the container every writer takes, how it is
built from a recording (or from a replay's poses), and the dispatch by file extension.

Why a container of its own: a recording stores quaternions, session-clock times and the
body only as metadata, a replay yields ``LivePose`` objects, and each writer needs the
same handful of arrays plus the body's bone offsets. ``ExportMotion`` is that common
ground, so ``imucap export`` (the recorded live reconstruction) and ``imucap replay --out``
(a re-run) write through the very same code.

Formats (by the output file's extension, case-insensitive):

    .bvh          app/export_bvh.py      skeleton animation (Blender, MotionBuilder, ...)
    .csv          app/export_csv.py      one row per 20 Hz frame, named columns
    .h5 / .hdf5   app/export_hdf5.py     arrays + attributes (units, names, provenance)
    .mot          app/export_opensim.py  OpenSim joint angles (Rajagopal-style coordinates)

Time in every export is seconds since the first raw frame of the recording (so a file
lines up with the recording it came from); the session-clock value subtracted is kept as
``time_origin`` in the HDF5 attributes.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from inference.body.body import Body
from inference.body.skeleton import N_CONTACTS, N_SEGMENTS
from inference.features.layout import FPS_MODEL

if TYPE_CHECKING:
    from app.pipeline import LivePose
    from app.recording import Recording

DEFAULT_HEIGHT_M = 1.75


@dataclass
class ExportMotion:
    """A reconstructed motion ready to be written.

    time: (T,) s since the recording's first raw frame; rot: (T, 24, 3, 3) global segment
    orientations R_WB (world: Z up, X forward at calibration); root: (T, 3) pelvis joint
    (m); joints: (T, 24, 3) joint positions (m), joint i = start of segment i; contacts:
    (T, 4) bool (l_heel, l_toe, r_heel, r_toe); contact_prob: (T, 4) or None; body: the
    bone geometry the poses were made with; fps: the nominal frame rate (20 Hz); meta:
    provenance (source recording, model, steps, sensors, insoles, time_origin, ...).
    """

    time: np.ndarray
    rot: np.ndarray
    root: np.ndarray
    joints: np.ndarray
    contacts: np.ndarray
    body: Body
    fps: float = float(FPS_MODEL)
    contact_prob: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.time = np.asarray(self.time, dtype=np.float64)
        self.rot = np.asarray(self.rot, dtype=np.float64)
        self.root = np.asarray(self.root, dtype=np.float64)
        self.joints = np.asarray(self.joints, dtype=np.float64)
        self.contacts = np.asarray(self.contacts, dtype=bool)
        T = self.time.shape[0]
        shapes = {"rot": (self.rot.shape, (T, N_SEGMENTS, 3, 3)), "root": (self.root.shape, (T, 3)),
                  "joints": (self.joints.shape, (T, N_SEGMENTS, 3)),
                  "contacts": (self.contacts.shape, (T, N_CONTACTS))}
        bad = {k: got for k, (got, want) in shapes.items() if got != want}
        if self.time.ndim != 1 or bad:
            raise ValueError(f"export: inconsistent motion arrays for {T} frames: {bad or self.time.shape}")
        if self.contact_prob is not None:
            self.contact_prob = np.asarray(self.contact_prob, dtype=np.float64).reshape(T, N_CONTACTS)

    @property
    def n_frames(self) -> int:
        return int(self.time.shape[0])

    @property
    def duration(self) -> float:
        """Seconds covered: first to last frame plus one frame period (0 when empty)."""
        return float(self.time[-1] - self.time[0] + 1.0 / self.fps) if self.n_frames else 0.0

    def gaps(self) -> int:
        """Frames missing in the 20 Hz sequence (live poses dropped while the poser was behind).
        Formats with a fixed frame time (BVH) close such gaps up; the others keep real times."""
        if self.n_frames < 2:
            return 0
        step = np.diff(self.time) * self.fps
        return int(np.sum(np.maximum(np.rint(step) - 1, 0)))


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


def _provenance(rec: Recording) -> dict[str, Any]:
    md = rec.metadata
    return {"source_recording": str(rec.path), "recorded_sensors": list(rec.sites),
            "created": rec.attrs.get("created"), "app_version": md.get("app_version")}


def motion_from_recording(rec: Recording, body: Body) -> ExportMotion:
    """The live reconstruction stored in a recording (``/recon``)."""
    r = rec.recon
    if len(r["t"]) == 0:
        raise ValueError(f"{rec.path} holds no reconstructed frames (was the session calibrated?)")
    md = rec.metadata
    t0 = _time_origin(rec)
    meta = {**_provenance(rec), "model": md.get("model"), "steps": md.get("steps"),
            "sensors": list(md.get("sensors") or rec.sites), "insoles": bool(md.get("insoles", False)),
            "time_origin": t0, "what": "recorded live reconstruction"}
    return ExportMotion(time=r["t"] - t0, rot=r["R"], root=r["root"], joints=r["joints"], contacts=r["contacts"],
                        contact_prob=r.get("contact_prob"), body=body, meta=meta)


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
        contact_prob=np.stack([lp.pose.contact_prob for lp in poses]), body=body, meta=m)


# ---------------------------------------------------------------------------- dispatch


def _write_bvh(path: Path, m: ExportMotion) -> Path:
    from app.export.bvh import write_bvh

    return write_bvh(path, m.rot, m.root, m.body, m.fps)


def _write_csv(path: Path, m: ExportMotion) -> Path:
    from app.export.csv_file import write_csv

    return write_csv(path, m)


def _write_hdf5(path: Path, m: ExportMotion) -> Path:
    from app.export.hdf5_file import write_hdf5

    return write_hdf5(path, m)


def _write_mot(path: Path, m: ExportMotion) -> Path:
    from app.export.opensim import write_mot

    return write_mot(path, m)


WRITERS: dict[str, Callable[[Path, ExportMotion], Path]] = {
    ".bvh": _write_bvh, ".csv": _write_csv, ".h5": _write_hdf5, ".hdf5": _write_hdf5, ".mot": _write_mot,
}


def supported_extensions() -> str:
    return ", ".join(WRITERS)


def check_export_path(path: str | os.PathLike) -> Path:
    """The path if its extension names a format we write, else a ValueError listing the
    supported ones. Called before a long replay, so a typo fails at once, not at the end."""
    p = Path(path)
    if p.suffix.lower() not in WRITERS:
        raise ValueError(f"cannot export to {p.name!r}: unknown extension {p.suffix or '(none)'!r}; "
                         f"supported: {supported_extensions()}")
    return p


def export_motion(path: str | os.PathLike, motion: ExportMotion) -> Path:
    """Write ``motion`` in the format its extension names; returns the path."""
    p = check_export_path(path)
    if motion.n_frames < 1:
        raise ValueError(f"nothing to export to {p}: no frames")
    return WRITERS[p.suffix.lower()](p, motion)


def atomic_target(path: Path) -> Path:
    """A temporary sibling to write to before ``os.replace``: a crash never leaves a
    truncated export under the real name."""
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.with_name(path.name + ".tmp")


__all__ = [
    "ExportMotion", "WRITERS", "body_for_recording", "motion_from_recording", "motion_from_poses",
    "check_export_path", "export_motion", "supported_extensions", "atomic_target", "DEFAULT_HEIGHT_M",
]
