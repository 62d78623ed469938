"""How much of the model's own thigh twist a thigh rebuilt from its shank keeps: more while the body turns.

The knee hinge (``joint_constraints``) rebuilds an unmeasured thigh from its measured shank:
the thigh then turns about its long axis exactly as the shin does. A living knee lets the shin
turn under the thigh, and most when the body pivots on a planted foot: the pelvis turns, the foot
on the floor does not, and the knee takes part of the difference. The motion capture the model
learned from cannot show that (its knees are 1-DoF hinges), so on it any twist away from the
hinge costs; on the real logs the thighs' sensors turn with the model's own thigh more than
with the shank in the turns (OpenSense walk, pelvis + shanks, turning: thighs 14.7 / 14.5 deg
with the strict hinge, 11.0 / 11.5 with this share; docs/real_signals.md, "The knee's twist").

So the share grows with how fast the pelvis turns about the vertical, measured over
``span_s`` (about a stride, so the pelvis's swing in each step cancels, as the evaluation's
phases measure a turn): none standing, the full ``share`` at ``full_deg_s`` and above. A stand
keeps the strict hinge the motion capture rewards; a walk gets a little from its pelvis's swing
and its path's curves (0.15 on average over the gait check's 20 walks), a turn the most.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from inference.body.conventions import wrap_angle, yaw_of
from inference.signals.resample import FPS_MODEL

# the largest share of the model's own thigh twist kept (while turning at FULL_TURN_DEG_S or faster);
# a model file's meta ``knee_twist`` or ``Poser(knee_twist=...)`` overrides it, 0 is the strict hinge
KNEE_TWIST = 0.5
FULL_TURN_DEG_S = 30.0


@dataclass
class TurnShare:
    """Per-frame state: the pelvis's recent headings, and the twist share they give."""

    share: float = KNEE_TWIST
    full_deg_s: float = FULL_TURN_DEG_S
    span_s: float = 1.2
    fps: float = FPS_MODEL

    def __post_init__(self) -> None:
        if not 0.0 <= self.share <= 1.0:
            raise ValueError(f"knee_twist {self.share}: a share from 0 (the strict hinge) to 1")
        self._n = max(2, round(self.span_s * self.fps) + 1)
        self.reset()

    def reset(self) -> None:
        self._headings: deque[float] = deque(maxlen=self._n)  # unwrapped: turned through, not wrapped
        self.now = 0.0

    def __call__(self, pelvis: np.ndarray) -> float:
        """The share for this frame, given its pelvis's global orientation (3, 3); kept as ``now``
        for the frames a late answer cleans before the next one (``Poser._clean_earlier``)."""
        if self.share == 0.0:
            return 0.0
        h = float(yaw_of(pelvis))
        if self._headings:  # on from the last heading by the shortest way round
            h = self._headings[-1] + float(wrap_angle(h - self._headings[-1]))
        self._headings.append(h)
        if len(self._headings) < 2:
            self.now = 0.0
            return 0.0
        rate = abs(np.degrees(h - self._headings[0])) * self.fps / (len(self._headings) - 1)
        self.now = self.share * min(1.0, rate / self.full_deg_s)
        return self.now


__all__ = ["FULL_TURN_DEG_S", "KNEE_TWIST", "TurnShare"]
