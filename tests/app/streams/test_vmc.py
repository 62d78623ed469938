"""VMC: what an OSC receiver gets, read back the way a Unity marionette applies it
(local transforms chained from the root, in Unity's left-handed Y-up frame), converted to
our frame here from first principles, rebuilds the emitted body."""

from __future__ import annotations

import numpy as np
import pytest

from app.streams import make_stream_sinks
from app.streams.vmc import VmcSink
from inference.body.skeleton import SEGMENT_INDEX

from .conftest import Barrier, run_pipeline

# Unity's humanoid hierarchy (HumanBodyBones), parent first; our segment for each
UNITY_PARENT = {
    "Hips": None, "Spine": "Hips", "Chest": "Spine", "UpperChest": "Chest", "Neck": "UpperChest", "Head": "Neck",
    "LeftShoulder": "UpperChest", "LeftUpperArm": "LeftShoulder", "LeftLowerArm": "LeftUpperArm",
    "LeftHand": "LeftLowerArm", "RightShoulder": "UpperChest", "RightUpperArm": "RightShoulder",
    "RightLowerArm": "RightUpperArm", "RightHand": "RightLowerArm", "LeftUpperLeg": "Hips",
    "LeftLowerLeg": "LeftUpperLeg", "LeftFoot": "LeftLowerLeg", "LeftToes": "LeftFoot", "RightUpperLeg": "Hips",
    "RightLowerLeg": "RightUpperLeg", "RightFoot": "RightLowerLeg", "RightToes": "RightFoot",
}
OURS = {
    "Hips": "pelvis", "Spine": "spine1", "Chest": "spine2", "UpperChest": "spine3", "Neck": "neck", "Head": "head",
    "LeftShoulder": "l_collar", "LeftUpperArm": "l_upperarm", "LeftLowerArm": "l_forearm", "LeftHand": "l_hand",
    "RightShoulder": "r_collar", "RightUpperArm": "r_upperarm", "RightLowerArm": "r_forearm", "RightHand": "r_hand",
    "LeftUpperLeg": "l_thigh", "LeftLowerLeg": "l_shank", "LeftFoot": "l_foot", "LeftToes": "l_toes",
    "RightUpperLeg": "r_thigh", "RightLowerLeg": "r_shank", "RightFoot": "r_foot", "RightToes": "r_toes",
}
# where our axes point in Unity: forward (X) is Unity +Z, left (Y) is Unity -X, up (Z) is Unity +Y
A = np.column_stack([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # v_unity = A v_ours


def quat_xyzw_to_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))))


def check_frames(box, poses) -> None:
    frames = box.frames("/VMC/Ext/T")
    assert len(frames) == len(poses)
    times = []
    for lp, msgs in zip(poses, frames):
        by = {}
        for addr, args in msgs:
            by.setdefault(addr, []).append(args)
        assert by["/VMC/Ext/OK"] == [(1, 3, 0, 1)]
        times.append(by["/VMC/Ext/T"][0][0])
        (root,) = by["/VMC/Ext/Root/Pos"]
        assert root[0] == "root"
        bones = {a[0]: a[1:] for a in by["/VMC/Ext/Bone/Pos"]}
        assert set(bones) == set(UNITY_PARENT)
        G: dict[str, np.ndarray] = {}
        P: dict[str, np.ndarray] = {}
        for name, parent in UNITY_PARENT.items():  # parents come first
            Gp, Pp = ((quat_xyzw_to_matrix(*root[4:8]), np.array(root[1:4])) if parent is None
                      else (G[parent], P[parent]))
            G[name] = Gp @ quat_xyzw_to_matrix(*bones[name][3:7])
            P[name] = Pp + Gp @ np.array(bones[name][0:3])
        for name, seg in OURS.items():
            i = SEGMENT_INDEX[seg]
            assert angle_deg(A.T @ G[name] @ A, lp.pose.rot[i]) < 0.5, name
            np.testing.assert_allclose(A.T @ P[name], lp.pose.joints[i], atol=1e-3, err_msg=name)
    assert np.all(np.diff(times) >= 0)


def test_vmc_bones_rebuild_the_pipeline_pose(suit, inbox):
    (sink,) = make_stream_sinks(f"vmc:{inbox.port}")
    assert isinstance(sink, VmcSink)
    poses, pipe = run_pipeline(suit, [sink, Barrier(inbox, "/VMC/Ext/OK")])
    pipe.close()
    assert len(poses) > 40
    moving = np.ptp(np.stack([p.pose.joints for p in poses]), axis=0).max()
    assert moving > 0.2  # a moving body, not a standing one
    check_frames(inbox, poses)
    assert sink.summary()["bundles"] == len(poses) and sink.summary()["errors"] == 0


def test_vmc_walks_the_root(walk_poses, inbox):
    sink = VmcSink("127.0.0.1", inbox.port)
    barrier = Barrier(inbox, "/VMC/Ext/OK")
    for lp in walk_poses:
        sink.on_pose(lp)
        barrier.on_pose(lp)
    sink.close()
    check_frames(inbox, walk_poses)
    roots = [a for f in inbox.frames("/VMC/Ext/T") for addr, a in f if addr == "/VMC/Ext/Root/Pos"]
    z = np.array([r[3] for r in roots])  # Unity forward = our X: the walk
    assert np.ptp(z) > 0.5 and np.allclose([r[2] for r in roots], 0.0)  # the root stays on the floor


def test_a_receiver_that_is_not_there_costs_nothing(walk_poses):
    import socket

    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nobody listens there now
    sink = VmcSink("127.0.0.1", port)
    for lp in walk_poses[:20]:
        sink.on_pose(lp)  # must not raise
    sink.close()
    assert sink.summary()["bundles"] + sink.summary()["errors"] == 20


@pytest.mark.parametrize("port", [0, 70000])
def test_bad_port(port):
    with pytest.raises(ValueError, match="port"):
        VmcSink("127.0.0.1", port)
