"""A VR rig's positions in the live chain: from the hub's frame (the rig's own frame) into
the model's world, and the arms' reach onto the controllers after the poser's answer.

Why a rotation about Z and nothing else: every device of a rig reports in one frame that
is Z up with its floor at z = 0 (SteamVR's standing universe, as ours); what differs from
the model's world is its yaw, which the calibration finds for each tracked site as it
finds an IMU's heading reference (``Calibration.R_WG``, the site's reference frame ->
world), and its origin, which ``point_features`` removes (each point is read against the
headset's floor projection). The three sites' yaws are one yaw found three times
(docs/vr_input.md); one mean turns all the points, so the hands keep their place relative
to the headset however far from the room's origin the user stands (two yaws 2 deg apart
would move a hand 7 cm against the headset 2 m out).

Which hand orientation the reach takes (``reach_hands``' ``hands``): the calibrated
orientation of the wrist site's controller, the measurement the poser was given for the
forearm. A controller is held in the fist, so it turns with the hand, and the
calibration's N-pose maps it onto the arm as the hand hung (hand and forearm in line, as
the model's N-pose has them). The model's own hand is a guess (no site is on the hand),
and the reach's target is the grip minus the grip's offset in the hand (10-15 cm) turned
by that orientation: a guessed hand puts the wrist that far off where the controller says.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from app.live.frame import N_POINTS
from calibration import Calibration
from inference.body.conventions import mean_angle, rot_z, yaw_of
from inference.body.reach import reach_hands
from inference.body.skeleton import SITE_INDEX
from inference.body.tracked import TRACKED_POINTS

if TYPE_CHECKING:
    from drivers.hub import HubFrame
    from inference.body.body import Body
    from inference.poser.poser import PoseFrame

# the hub's site a rig's device is routed to (drivers.vmc.device.MODEL_SITES) -> the tracked point
SITE_POINT: dict[str, str] = {"head": "head", "l_wrist": "l_hand", "r_wrist": "r_hand", "pelvis": "pelvis"}
HAND_SITE: dict[str, str] = {"l_hand": "l_wrist", "r_hand": "r_wrist"}


def rig_yaw(calibration: Calibration, sites: Sequence[str]) -> np.ndarray | None:
    """(3, 3) the turn about Z from the rig's frame to the model's world: the mean of the
    yaws the calibration found for ``sites`` (the rig's sites it calibrated), None when it
    calibrated none of them."""
    use = [s for s in sites if s in calibration.sites and calibration.valid[calibration.sites.index(s)]]
    if not use:
        return None
    R = calibration.R_WG[calibration.index(use)]
    # each site's turn about Z (yaw_of: robust to a small tilt), then their circular mean
    return rot_z(mean_angle(yaw_of(R)))


class RigPoints:
    """The tracked points of a frame over ``sites`` (the hub's order), in the model's world:
    the live frame's ``positions`` input (``app.live.frame.FrameInput``).

    ``points(calibration, position, ok)``: (4, 3) in ``TRACKED_POINTS`` order, NaN where a
    point is not tracked or its site not usable in this frame (``ok``: present and active),
    from the frame's positions (S, 3) in the rig's frame. The rig's sites are those that
    have sent a position (an IMU at the pelvis site has none, and its heading reference is
    not the rig's): the yaw is the mean over them, taken again when one joins."""

    def __init__(self, sites: Sequence[str]) -> None:
        self.sites = tuple(sites)
        self._rows = [(k, TRACKED_POINTS.index(SITE_POINT[s])) for k, s in enumerate(self.sites) if s in SITE_POINT]
        self._seen = np.zeros(len(self.sites), bool)
        self._key: tuple[Calibration, bytes] | None = None
        self._R: np.ndarray | None = None

    def yaw(self, calibration: Calibration) -> np.ndarray | None:
        seen = self._seen.tobytes()
        if self._key is None or self._key[0] is not calibration or self._key[1] != seen:
            self._key = (calibration, seen)
            self._R = rig_yaw(calibration, [s for s, seen in zip(self.sites, self._seen, strict=True) if seen])
        return self._R

    def enter(self, frame: np.ndarray, hub: HubFrame, calibration: Calibration, ok: np.ndarray) -> None:
        if hub.position is not None:
            frame["positions"] = self.points(calibration, hub.position, ok)

    def points(self, calibration: Calibration, position: np.ndarray | None, ok: np.ndarray) -> np.ndarray:
        out = np.full((N_POINTS, 3), np.nan)
        if position is None or not self._rows:
            return out
        fin = np.isfinite(position).all(axis=-1)
        for k, _ in self._rows:
            self._seen[k] |= fin[k]
        R = self.yaw(calibration)
        if R is None:
            return out
        for k, j in self._rows:
            if ok[k] and fin[k]:
                out[j] = R @ position[k]
        return out


def reach(pose: PoseFrame, body: Body, features: np.ndarray | None, R13: np.ndarray,
          observed: np.ndarray) -> PoseFrame | None:
    """The poser's answer with each tracked hand's arm reaching its controller, or None when
    the frame has nothing to reach for (no position input, or no controller in it).
    ``features``: the frame's position input (``Observation.points``); ``R13`` (13, 3, 3) its calibrated site
    orientations, ``observed`` (13,) which of them hold (the hands' orientations)."""
    if features is None:
        return None
    flags = features[3 * N_POINTS:] > 0.5
    if not (flags[1] or flags[2]):
        return None
    hands = {}
    for name, site in HAND_SITE.items():
        k = SITE_INDEX[site]
        if flags[TRACKED_POINTS.index(name)] and observed[k] and np.isfinite(R13[k]).all():
            hands[name] = R13[k][None]
    R, joints = reach_hands(pose.rot[None], pose.root[None], body, hands, features[None])
    return dataclasses.replace(pose, rot=R[0], joints=joints[0])


__all__ = ["HAND_SITE", "RigPoints", "SITE_POINT", "reach", "rig_yaw"]
