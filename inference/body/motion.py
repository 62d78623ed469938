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

    def held(self, before_s: float = 0.0, after_s: float = 0.0, settle_s: float = 0.0) -> Motion:
        """The same movement with the subject standing still before and after it for
        ``before_s`` / ``after_s`` seconds. Training augmentation: the clips are cut round the
        movement, so a window of a long stand after a walk (what a real session holds at its
        end) is rare in them, and a model that never saw one let unmeasured thighs stay bent
        through seconds of stillness (docs/real_signals.md, "A standing body").

        ``settle_s`` = 0: the first and last frames are held as they are (for clips that
        start and end standing). ``settle_s`` > 0: the subject steps over ``settle_s`` seconds
        from the N-pose, facing as the pelvis does, into the first frame, and from the last
        frame back into it (for clips cut mid-stride, whose end frames are no stand)."""
        if before_s < 0 or after_s < 0 or settle_s < 0:
            raise ValueError(f"hold lengths must not be negative, got {before_s}, {after_s}, {settle_s}")
        nb, na = int(round(before_s * self.fps)), int(round(after_s * self.fps))
        if nb == 0 and na == 0:
            return self
        ns = max(int(round(settle_s * self.fps)), 1) if settle_s > 0 else 0

        def stand(frame: int, n: int) -> tuple[np.ndarray, np.ndarray]:
            # the end frame as it is, or the N-pose facing the pelvis's way, feet on the floor
            if not ns:
                return np.repeat(self.rot[frame:frame + 1 or None], n, 0), np.repeat(
                    self.root[frame:frame + 1 or None], n, 0)
            from inference.body.body import npose_rotations
            from inference.body.conventions import rot_z, yaw_of

            R = rot_z(yaw_of(self.rot[frame, 0])) @ npose_rotations(1)[0]
            z = -float(contact_points(R[None], forward_kinematics(R[None], np.zeros(3), self.body.offsets),
                                      self.body)[..., 2].min())
            xy = self.root[frame, :2]
            return np.repeat(R[None], n, 0), np.tile([xy[0], xy[1], z], (n, 1))

        def blend(R0: np.ndarray, p0: np.ndarray, R1: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            from scipy.spatial.transform import Rotation, Slerp

            w = (np.arange(ns) + 1) / (ns + 1)
            w = w * w * (3 - 2 * w)
            out = np.empty((ns, N_SEGMENTS, 3, 3))
            for k in range(N_SEGMENTS):
                out[:, k] = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([R0[k], R1[k]])))(w).as_matrix()
            return out, p0 + w[:, None] * (p1 - p0)

        rot, root = [self.rot], [self.root]
        if nb:
            Rs, ps = stand(0, nb)
            if ns:
                Rb, pb = blend(Rs[0], ps[0], self.rot[0], self.root[0])
                rot.insert(0, Rb)
                root.insert(0, pb)
            rot.insert(0, Rs)
            root.insert(0, ps)
        if na:
            Rs, ps = stand(-1, na)
            if ns:
                Ra, pa = blend(self.rot[-1], self.root[-1], Rs[0], ps[0])
                rot.append(Ra)
                root.append(pa)
            rot.append(Rs)
            root.append(ps)
        return replace(self, rot=np.concatenate(rot), root=np.concatenate(root),
                       meta={**self.meta, "held": (float(before_s), float(after_s), float(settle_s))})

    def turning(self, rate_deg_s: float) -> Motion:
        """The same movement with the whole body turning about the vertical at ``rate_deg_s``
        (positive: to the left), its path bent to match: each frame's orientations and its
        step of the root's horizontal path turned by the heading reached so far. A walk becomes
        a walk round a circle of radius speed / rate; a slow walk turned at 90-180 deg/s is a
        turn on the spot in small steps, which real sessions hold (13 of the OpenSense walk's
        22 s) and the motion capture's walks, straight or gently curved, hold little of.
        Training augmentation; the stance foot pivots as a turning foot does, and slides
        sideways by the rate times its distance from the pelvis (~0.2 m/s)."""
        from inference.body.conventions import rot_z

        yaw = np.radians(float(rate_deg_s)) * self.times
        Rz = rot_z(yaw)  # (T, 3, 3)
        step = np.diff(self.root, axis=0)
        step[:, 2] = 0.0
        turned = np.einsum("tij,tj->ti", Rz[:-1], step)
        root = self.root.copy()
        root[1:, :2] = self.root[0, :2] + np.cumsum(turned[:, :2], axis=0)
        return replace(self, rot=np.einsum("tij,tsjk->tsik", Rz, self.rot), root=root,
                       meta={**self.meta, "turning_deg_s": float(rate_deg_s)})

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
