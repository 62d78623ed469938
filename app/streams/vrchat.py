"""The body as VRChat OSC trackers (docs.vrchat.com "OSC Trackers"): up to eight
world-space trackers VRChat's calibrated full-body IK follows, default 127.0.0.1:9000.

The documentation asks for ``/tracking/trackers/{1..8}/position`` and ``/rotation``, each
three floats: positions in metres and rotations as Euler angles in degrees, in Unity's
frame (left-handed, +Y up); the angles are Unity's (``Transform.eulerAngles``: Z, then X,
then Y). It lists the roles it supports: hip, chest, both feet, both knees, both elbows
(upper arms) -- the numbers 1..8 carry no role, VRChat assigns them at its own calibration
(the user stands in its T-pose), so a tracker's rotation only has to be consistent, not
match a convention. The optional ``/tracking/trackers/head/...`` pair lets VRChat align
our tracking space to the headset's; it should sit where a headset sits, so it is the
head segment's joint (chin level) moved to the eyes by ``head_offset`` in the head's frame.

Fewer trackers can work better (the documentation's own advice when the data drifts):
``trackers`` picks a subset; the number of each role stays the same whatever is sent.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from app.live import LivePose, Sink
from app.streams.osc import OscTarget, message
from app.streams.unity import rot_to_unity, unity_euler_deg, vec_to_unity
from inference.body.skeleton import SEGMENT_INDEX

DEFAULT_PORT = 9000

# role -> (tracker number, segment whose joint is the position, segment whose orientation is the rotation)
TRACKERS: dict[str, tuple[int, str, str]] = {
    "hip": (1, "pelvis", "pelvis"),
    "chest": (2, "spine3", "spine3"),
    "l_foot": (3, "l_foot", "l_foot"),
    "r_foot": (4, "r_foot", "r_foot"),
    "l_knee": (5, "l_shank", "l_shank"),
    "r_knee": (6, "r_shank", "r_shank"),
    "l_elbow": (7, "l_forearm", "l_upperarm"),
    "r_elbow": (8, "r_forearm", "r_upperarm"),
}
# eyes relative to our head joint (chin level) in the head frame, m: forward, left, up.
# Drillis & Contini put the eyes at 0.936 H and the chin at 0.870 H: 0.066 H ~ 0.11 m at 1.75 m.
HEAD_OFFSET = (0.07, 0.0, 0.11)


class VrchatSink(Sink):
    """Sends the chosen trackers (and the head, for alignment) to VRChat at ``host:port``."""

    kind = "vrchat"

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 trackers: Sequence[str] = tuple(TRACKERS), head: bool = True,
                 head_offset: Sequence[float] = HEAD_OFFSET) -> None:
        bad = [t for t in trackers if t not in TRACKERS]
        if bad:
            raise ValueError(f"unknown VRChat tracker(s) {bad}; choose from {', '.join(TRACKERS)}")
        self.target = OscTarget(host, port)
        self.trackers = tuple(trackers)
        self.head = head
        self.head_offset = np.asarray(head_offset, dtype=np.float64)
        self._num = [TRACKERS[t][0] for t in self.trackers]
        self._pos = np.array([SEGMENT_INDEX[TRACKERS[t][1]] for t in self.trackers], dtype=int)
        self._rot = np.array([SEGMENT_INDEX[TRACKERS[t][2]] for t in self.trackers], dtype=int)

    def on_pose(self, pose: LivePose) -> None:
        R, J = pose.pose.rot, pose.pose.joints
        pos = vec_to_unity(J[self._pos]).tolist()
        eul = unity_euler_deg(rot_to_unity(R[self._rot])).tolist()
        msgs = []
        for n, p, e in zip(self._num, pos, eul):
            msgs.append(message(f"/tracking/trackers/{n}/position", p))
            msgs.append(message(f"/tracking/trackers/{n}/rotation", e))
        if self.head:
            h = SEGMENT_INDEX["head"]
            eyes = J[h] + R[h] @ self.head_offset
            msgs.append(message("/tracking/trackers/head/position", vec_to_unity(eyes).tolist()))
            msgs.append(message("/tracking/trackers/head/rotation", unity_euler_deg(rot_to_unity(R[h])).tolist()))
        self.target.send_bundle(msgs)

    def close(self) -> None:
        self.target.close()

    def summary(self) -> dict[str, Any]:
        return {"kind": self.kind, **self.target.summary(), "trackers": list(self.trackers)}
