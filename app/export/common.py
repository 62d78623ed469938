"""What every exporter writes from: the motion to export and the atomic write. Below the
writers and the format dispatch, so no writer imports the dispatch that calls it."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from inference.body.body import Body
from inference.body.rotations import matrix_to_quat
from inference.body.skeleton import N_CONTACTS, N_SEGMENTS
from inference.signals.resample import FPS_MODEL


@dataclass
class ExportMotion:
    """A reconstructed motion ready to be written.

    time: (T,) s since the recording's first raw frame; rot: (T, 24, 3, 3) global segment
    orientations R_WB (world: Z up, X forward at calibration); root: (T, 3) pelvis joint
    (m); joints: (T, 24, 3) joint positions (m), joint i = start of segment i; contacts:
    (T, 4) bool (l_heel, l_toe, r_heel, r_toe); contact_prob: (T, 4) or None; body: the
    bone geometry the poses were made with; fps: the nominal frame rate (20 Hz); meta:
    provenance (source recording, model, steps, sensors, insoles, time_origin, ...);
    spread_deg (T, 24) and root_spread_m (T,): the poser's confidence per segment (deg)
    and for the root (m), NaN where it was off, or None when no frame has one.
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
    spread_deg: np.ndarray | None = None
    root_spread_m: np.ndarray | None = None

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
        if self.spread_deg is not None or self.root_spread_m is not None:
            seg = np.full((T, N_SEGMENTS), np.nan) if self.spread_deg is None else self.spread_deg
            root = np.full(T, np.nan) if self.root_spread_m is None else self.root_spread_m
            self.spread_deg = np.asarray(seg, dtype=np.float64).reshape(T, N_SEGMENTS)
            self.root_spread_m = np.asarray(root, dtype=np.float64).reshape(T)
            if not (np.isfinite(self.spread_deg).any() or np.isfinite(self.root_spread_m).any()):
                self.spread_deg = self.root_spread_m = None  # confidence was off throughout

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


def atomic_target(path: Path) -> Path:
    """A temporary sibling to write to before ``os.replace``: a crash never leaves a
    truncated export under the real name."""
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.with_name(path.name + ".tmp")



def continuous_quaternions(rot: np.ndarray) -> np.ndarray:
    """(T, S, 4) quaternions of (T, S, 3, 3) rotations, w >= 0 at the first frame and each
    later one on the hemisphere of its predecessor (no sign flips between frames)."""
    q = matrix_to_quat(np.asarray(rot, dtype=np.float64))
    if len(q) == 0:
        return q
    q[0] *= np.where(q[0, :, :1] < 0, -1.0, 1.0)
    for t in range(1, len(q)):
        flip = np.sum(q[t] * q[t - 1], axis=-1, keepdims=True) < 0
        q[t] = np.where(flip, -q[t], q[t])
    return q
