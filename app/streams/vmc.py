"""The body as a VMC protocol performer (https://protocol.vmc.info): any VMC marionette
(VSeeFace, VMagicMirror, Warudo, EVMC4U in Unity, VMC4B in Blender) moves an avatar with it.

Per 20 Hz pose, one OSC bundle to the marionette (default 127.0.0.1:39539):
``/VMC/Ext/T`` (sender time, s), ``/VMC/Ext/Root/Pos "root"``, one ``/VMC/Ext/Bone/Pos``
per humanoid bone we reconstruct and ``/VMC/Ext/OK 1 3 0 1`` (model loaded, calibrated,
normal mode, tracking). The spec's marionette page says Bone/Pos carries the bone's
*local* transform (relative to its parent, as Unity's ``localPosition``/``localRotation``)
named as Unity's ``HumanBodyBones``, in Unity's frame.

Why local rotation is just ``R_parent^T R_child`` here: our T-pose has every segment at
identity, and so does a VRM avatar's normalised T-pose (facing +Z, arms along X), so the
rest offset a retargeter would need is identity on both sides; only the change of basis
to Unity's frame remains (``app/streams/unity.py``). Bone positions are our bone offsets
(the child joint in its parent's frame); a marionette that copies positions
(EVMC4U's "Bone Position Synchronize") then takes our proportions: turn that off for an
avatar built differently. The walk goes into the root (the pelvis on the floor, no
rotation), the pelvis height into the Hips' local position, so a receiver that ignores
bone positions still walks the avatar around.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np

from app.live import LivePose, Sink
from app.streams.osc import OscTarget, message
from app.streams.unity import rot_to_unity, unity_quat, vec_to_unity
from inference.body.skeleton import PARENTS, SEGMENT_INDEX

DEFAULT_PORT = 39539

# our segment -> Unity HumanBodyBones; the fingers have no single humanoid bone and stay out
HUMANOID_BONES: dict[str, str] = {
    "pelvis": "Hips", "spine1": "Spine", "spine2": "Chest", "spine3": "UpperChest", "neck": "Neck", "head": "Head",
    "l_thigh": "LeftUpperLeg", "l_shank": "LeftLowerLeg", "l_foot": "LeftFoot", "l_toes": "LeftToes",
    "r_thigh": "RightUpperLeg", "r_shank": "RightLowerLeg", "r_foot": "RightFoot", "r_toes": "RightToes",
    "l_collar": "LeftShoulder", "l_upperarm": "LeftUpperArm", "l_forearm": "LeftLowerArm", "l_hand": "LeftHand",
    "r_collar": "RightShoulder", "r_upperarm": "RightUpperArm", "r_forearm": "RightLowerArm", "r_hand": "RightHand",
}
_SEG = np.array([SEGMENT_INDEX[s] for s in HUMANOID_BONES])
_PAR = np.array([PARENTS[i] for i in _SEG])
_NAMES = list(HUMANOID_BONES.values())


def vmc_frame(pose: LivePose) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Root position (3,), bone local positions (B, 3) and local rotations (B, 4, x y z w),
    all in Unity's frame, bones in ``HUMANOID_BONES`` order."""
    R, J = pose.pose.rot, pose.pose.joints
    root = J[SEGMENT_INDEX["pelvis"]]
    is_root = _PAR < 0
    Rp = np.where(is_root[:, None, None], np.eye(3), R[np.maximum(_PAR, 0)])
    local_R = np.swapaxes(Rp, -1, -2) @ R[_SEG]
    jp = np.where(is_root[:, None], np.array([root[0], root[1], 0.0]), J[np.maximum(_PAR, 0)])
    local_p = (np.swapaxes(Rp, -1, -2) @ (J[_SEG] - jp)[..., None])[..., 0]
    return vec_to_unity([root[0], root[1], 0.0]), vec_to_unity(local_p), unity_quat(rot_to_unity(local_R))


class VmcSink(Sink):
    """Sends every pose to one VMC marionette at ``host:port``."""

    kind = "vmc"

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.target = OscTarget(host, port)
        self._clock = clock
        self._t0 = clock()

    def on_pose(self, pose: LivePose) -> None:
        root, pos, rot = vmc_frame(pose)
        msgs = [message("/VMC/Ext/T", [float(self._clock() - self._t0)]),
                message("/VMC/Ext/Root/Pos", ["root", *map(float, root), 0.0, 0.0, 0.0, 1.0])]
        for name, p, q in zip(_NAMES, pos.tolist(), rot.tolist()):
            msgs.append(message("/VMC/Ext/Bone/Pos", [name, *p, *q]))
        msgs.append(message("/VMC/Ext/OK", [1, 3, 0, 1]))
        self.target.send_bundle(msgs)

    def close(self) -> None:
        self.target.close()

    def summary(self) -> dict[str, Any]:
        return {"kind": self.kind, **self.target.summary()}
