"""One type for motion from any source: global segment orientations plus root path on our
24-segment body, in our world frame (Z up, X forward at rest), SI units.

Every loader retargets into this, so synthesis, training and evaluation never see a
file format.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from inference.body.body import Body, contact_points, forward_kinematics, site_positions
from inference.body.skeleton import N_SEGMENTS


class MotionFormatError(ValueError):
    """A motion file that cannot be read; the message names the file and line."""

    def __init__(self, path: str, message: str, line: int | None = None):
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line


@dataclass
class Motion:
    """rot: (T, 24, 3, 3) global segment orientations R_WB; root: (T, 3) pelvis joint
    position (m); fps: frames per second; body: the bone geometry of this subject."""

    rot: np.ndarray
    root: np.ndarray
    fps: float
    body: Body
    name: str = ""
    source: str = ""
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.rot = np.asarray(self.rot, dtype=np.float64)
        self.root = np.asarray(self.root, dtype=np.float64)
        T = self.rot.shape[0]
        if self.rot.shape != (T, N_SEGMENTS, 3, 3) or self.root.shape != (T, 3):
            raise ValueError(
                f"motion {self.name!r}: expected rot (T,24,3,3) and root (T,3), got {self.rot.shape} "
                f"and {self.root.shape}"
            )
        if T < 2:
            raise ValueError(f"motion {self.name!r} has {T} frame(s); at least 2 are needed")
        if not (np.all(np.isfinite(self.rot)) and np.all(np.isfinite(self.root))):
            raise ValueError(f"motion {self.name!r} contains NaN or infinite values")
        if not self.fps > 0:
            raise ValueError(f"motion {self.name!r}: fps must be positive, got {self.fps}")

    @property
    def n_frames(self) -> int:
        return int(self.rot.shape[0])

    @property
    def duration(self) -> float:
        return (self.n_frames - 1) / self.fps

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.fps

    def joints(self) -> np.ndarray:
        """(T, 24, 3) joint positions."""
        return forward_kinematics(self.rot, self.root, self.body.offsets)

    def sites(self, joints: np.ndarray | None = None) -> np.ndarray:
        """(T, 13, 3) sensor site positions."""
        return site_positions(self.rot, self.joints() if joints is None else joints, self.body)

    def contacts(self, joints: np.ndarray | None = None) -> np.ndarray:
        """(T, 4, 3) heel/toe point positions."""
        return contact_points(self.rot, self.joints() if joints is None else joints, self.body)

    def floor_aligned(self) -> Motion:
        """Shift vertically so the lowest foot point over the clip touches z = 0: sources
        put their floor anywhere (or nowhere), and contact heights must mean the same."""
        z_min = float(self.contacts()[..., 2].min())
        root = self.root.copy()
        root[:, 2] -= z_min
        return replace(self, root=root)

    def resample(self, fps: float) -> Motion:
        """Same motion at another frame rate: slerp for orientations, linear for the root."""
        from inference.body.rotations import matrix_to_quat, quat_slerp, quat_to_matrix

        if abs(fps - self.fps) < 1e-9:
            return self
        t_old = self.times
        n_new = int(np.floor(self.duration * fps + 1e-9)) + 1
        t_new = np.arange(n_new) / fps
        pos = np.clip(t_new * self.fps, 0, self.n_frames - 1)
        i0 = np.minimum(np.floor(pos).astype(int), self.n_frames - 2)
        w = pos - i0
        q = matrix_to_quat(self.rot)
        q_new = quat_slerp(q[i0], q[i0 + 1], w[:, None])
        root = np.stack([np.interp(t_new, t_old, self.root[:, k]) for k in range(3)], axis=-1)
        return replace(self, rot=quat_to_matrix(q_new), root=root, fps=float(fps))

    def at_speed(self, factor: float) -> Motion:
        """The same movement performed ``factor`` times as fast (same frames, shorter
        duration). Training augmentation: people do a squat or a kick at their own tempo,
        and two actors' tempi are all a model learns of that from HDM05."""
        if not factor > 0:
            raise ValueError(f"speed factor must be positive, got {factor}")
        return replace(self, fps=self.fps * float(factor), meta={**self.meta, "speed": float(factor)})

    def scaled(self, factor: float) -> Motion:
        """The same joint angles and timing on a body ``factor`` times as large: bones, skin
        sites and root path scale, orientations do not. Training augmentation: the data
        has few body sizes, so a model conditioned on height can read the actor from it."""
        if not factor > 0:
            raise ValueError(f"scale factor must be positive, got {factor}")
        body = Body.from_offsets(self.body.offsets * float(factor), self.body.height * float(factor))
        return replace(self, root=self.root * float(factor), body=body,
                       meta={**self.meta, "body_scale": float(factor) * self.meta.get("body_scale", 1.0)})

    def slice(self, start: int, stop: int) -> Motion:
        return replace(self, rot=self.rot[start:stop], root=self.root[start:stop])
