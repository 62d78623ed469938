"""A still, upright stand straightens the knees the sensors leave open.

With a shank measured and its thigh not, the knee hinge (``joint_constraints``) rebuilds
the thigh from the shank and leaves only the knee's flexion to the model. Standing still,
that flexion is the model's estimate of a stand, and the training data's stands are
bent-kneed (60 Bandai clips' still frames: shanks 12-15 deg forward, thighs 7-11 back) or
not stands at all: with the pelvis and both shanks exactly upright and still the shipped
model holds each thigh 5 deg bent, and on the real x-IMU3 log's closing stand it bends the
right thigh 8.7 deg forward while its sensor hangs straight (docs/real_signals.md, "A
standing body"). The inpainting then keeps that pose: it is its own history.

So when every measured segment has been still for a moment and a measured shank hangs
upright, the knee's flexion is taken down to zero over the next ``settle_s`` (a leg whose
shank is upright and whose knee is straight is a standing leg); the straightened thigh
goes into the history, so the model goes on from the stand the sensors imply. A shank that
leans (a bent-kneed stance, a squat held still), a knee the model bends far (sitting with
the shank upright) or any motion leaves the model's flexion as it is, at once.

A worn thigh with its shank left open is the same knee the other way round: the hinge
rebuilds the shank from the thigh with the model's flexion, and the shipped model bends
it in a stand as it does with the shanks worn (the OpenSense walk's stand with pelvis +
thighs: shanks 12 deg off; the x-IMU3 log's 18-21). A still thigh hanging upright
straightens its shank the same way (shanks 2.3-2.5 and 5-11 deg).

A standing leg's foot is flat: in a settled stand an unworn foot below the straightened knee
loses its tilt and keeps its heading (``level``; the stands' feet 0.6-1.5 deg on the
OpenSense walk where the 21-frame model's mirror-free answer left 4.2-4.7; docs/real_signals.md,
"A standing body"). A foot the model tilts further than ``max_foot_tilt_deg`` (on its toes)
is left as it is.

A standing body's trunk is upright too. Over a worn pelvis that stands upright, with a settled
leg under it, the unworn spine and neck lose their tilt the same way (heading kept). The
21-frame `fast` file leaned the OpenSense walk's standing torso forward from 7 to 21 deg over
its 1.8 s (the default 6 deg), the sensor upright; a trunk the model bends further than
``max_trunk_tilt_deg`` (a stoop held still) is left as it is.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from inference.body.conventions import swing_twist_z, yaw_of
from inference.body.rotations import matrix_about_axis_np, matrix_angle_between
from inference.body.skeleton import SEGMENT_INDEX
from inference.poser.joint_constraints import BONE_AXIS, KNEE_AXIS, KNEES, hinge_angle
from inference.signals.resample import FPS_MODEL

FEET = tuple(SEGMENT_INDEX[f"{side}_foot"] for side in "lr")  # in the order of KNEES
PELVIS = SEGMENT_INDEX["pelvis"]
TRUNK = tuple(SEGMENT_INDEX[s] for s in ("spine1", "spine2", "spine3", "neck"))  # upright in the rest pose


def tilt_of(R: np.ndarray) -> float:
    """How far (rad) a foot's orientation ``R`` is from level: the angle of its swing off the vertical."""
    return float(np.arccos(np.clip(R[2, 2], -1.0, 1.0)))


def level(R: np.ndarray, w: float) -> np.ndarray:
    """A foot's orientation ``R`` with ``w`` of its tilt taken away, its heading kept: in the
    body's rest pose a foot is level, so a foot flat on the floor is its heading alone."""
    from scipy.spatial.transform import Rotation

    heading, tilt = swing_twist_z(R)
    return heading @ Rotation.from_rotvec((1.0 - w) * Rotation.from_matrix(tilt).as_rotvec()).as_matrix()


@dataclass
class StandPrior:
    """Per-frame state: how long the measured segments have been still.

    still_deg_s: the fastest a measured segment may turn and still count as still, judged
    over ``span_s`` (frame to frame, a sensor's own orientation noise reads as turning).
    upright_deg: the most the worn segment's long axis (a shank's, or a thigh's with its shank
    unworn) may lean from vertical.
    onset_s / settle_s: still over ``span_s`` and then for ``onset_s`` before the flexion
    starts to go, gone ``settle_s`` later (by default a second after the body stopped).
    max_flexion_deg: a knee bent further than this is not straightened (sitting, kneeling).
    level_feet / max_foot_tilt_deg: level the unworn feet of the settled legs, unless the model
    tilts them further than this.
    upright_trunk / max_trunk_tilt_deg: with a settled leg under a worn pelvis that stands
    upright, the unworn spine and neck lose their tilt (heading kept), unless the model tilts
    a segment further than this (a stoop held still).
    """

    still_deg_s: float = 15.0
    span_s: float = 0.25
    upright_deg: float = 8.0
    onset_s: float = 0.0
    settle_s: float = 0.75
    max_flexion_deg: float = 30.0
    level_feet: bool = True
    max_foot_tilt_deg: float = 20.0
    upright_trunk: bool = True
    max_trunk_tilt_deg: float = 30.0
    fps: float = FPS_MODEL

    def __post_init__(self) -> None:
        self._axis = np.asarray(KNEE_AXIS)
        self._bone = np.asarray(BONE_AXIS)
        self._span = max(1, round(self.span_s * self.fps))
        self._still_rad = np.radians(self.still_deg_s * self._span / self.fps)
        self._cos_upright = np.cos(np.radians(self.upright_deg))
        self._max_flexion = np.radians(self.max_flexion_deg)
        self._max_foot_tilt = np.radians(self.max_foot_tilt_deg)
        self._max_trunk_tilt = np.radians(self.max_trunk_tilt_deg)
        self.reset()

    def reset(self) -> None:
        self._recent: deque[np.ndarray] = deque(maxlen=self._span)  # the measured segments' last frames
        self._prev_measured: np.ndarray | None = None
        self.still_frames = 0

    def weight(self) -> float:
        """How much of the knee's flexion goes now: 0 moving, 1 settled."""
        t = self.still_frames / self.fps - self.onset_s
        return float(np.clip(t / self.settle_s, 0.0, 1.0))

    def __call__(self, R: np.ndarray, measured: np.ndarray) -> np.ndarray:
        """``R`` (24, 3, 3) global orientations after the knee hinge, ``measured`` (24,)
        bool. Returns ``R`` with the settled knees straightened (a copy when changed)."""
        self._update(R, measured)
        return self.settle(R, measured)

    def settle(self, R: np.ndarray, measured: np.ndarray) -> np.ndarray:
        """``R`` with the knees straightened as far as the stillness counted so far says,
        without counting ``R`` as a frame: for the answers a lagged poser gives for frames
        just before the newest (``Poser(answer_lag=k)``)."""
        w = self.weight()
        if w <= 0.0:
            return R
        out = R
        standing = False  # a worn leg segment hangs upright with its knee near straight
        for (t, s), f in zip(KNEES, FEET):
            if measured[t] == measured[s]:
                continue  # both worn: nothing to settle; neither: no upright segment to go by
            worn, free = (s, t) if measured[s] else (t, s)
            if R[worn, 2, 2] < self._cos_upright:
                continue
            theta = hinge_angle(R[t].T @ R[s], self._axis)
            if abs(theta) > self._max_flexion:
                continue
            standing = True
            if out is R:
                out = R.copy()
            if free == t:
                # the thigh's twist the hinge kept (``knee_twist``) goes with the flexion: a straight
                # knee locks the shin's turn, and fading both together leaves no jump at the onset
                hinged = R[s] @ matrix_about_axis_np(self._axis, theta).T
                psi = yaw_of(hinged.T @ R[t])  # the twist about the bone the hinge kept
                out[t] = (R[s] @ matrix_about_axis_np(self._axis, (1.0 - w) * theta).T
                          @ matrix_about_axis_np(self._bone, (1.0 - w) * psi))
            else:
                # a worn thigh: the shank the hinge rebuilt from it (the thigh turned by the
                # model's flexion) straightened
                out[s] = R[t] @ matrix_about_axis_np(self._axis, (1.0 - w) * theta)
            if self.level_feet and not measured[f] and tilt_of(R[f]) <= self._max_foot_tilt:
                out[f] = level(R[f], w)
        if self.upright_trunk and standing and measured[PELVIS] and R[PELVIS, 2, 2] >= self._cos_upright:
            for k in TRUNK:
                if not measured[k] and tilt_of(R[k]) <= self._max_trunk_tilt:
                    out[k] = level(R[k], w)
        return out

    def _update(self, R: np.ndarray, measured: np.ndarray) -> None:
        idx = np.flatnonzero(measured)
        if self._prev_measured is None or not np.array_equal(self._prev_measured, measured) or len(idx) == 0:
            self._recent.clear()  # another set of sensors: start counting again
            self.still_frames = 0
        self._prev_measured = measured.copy()
        now = R[idx]
        if len(self._recent) == self._span:
            then = self._recent[0]
            turned = np.asarray(matrix_angle_between(then, now))  # each measured segment's turn over the span
            self.still_frames = self.still_frames + 1 if bool(np.all(turned <= self._still_rad)) else 0
        self._recent.append(now.copy())
