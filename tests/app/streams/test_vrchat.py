"""VRChat OSC trackers: positions and Euler angles as VRChat reads them (Unity frame,
metres, degrees, Z then X then Y), converted back here to our frame."""

from __future__ import annotations

import numpy as np
import pytest

from app.streams import make_stream_sinks
from app.streams.vrchat import HEAD_OFFSET, VrchatSink
from inference.body.conventions import rot_z
from inference.body.skeleton import SEGMENT_INDEX

from .conftest import Barrier, run_pipeline

A = np.column_stack([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # v_unity = A v_ours
# tracker -> (segment whose joint it sits on, segment it turns with)
EXPECTED = {1: ("pelvis", "pelvis"), 2: ("spine3", "spine3"), 3: ("l_foot", "l_foot"), 4: ("r_foot", "r_foot"),
            5: ("l_shank", "l_shank"), 6: ("r_shank", "r_shank"), 7: ("l_forearm", "l_upperarm"),
            8: ("r_forearm", "r_upperarm")}


def unity_euler_to_matrix(x_deg: float, y_deg: float, z_deg: float) -> np.ndarray:
    """Unity's Quaternion.Euler: about Z, then X, then Y."""
    x, y, z = np.radians([x_deg, y_deg, z_deg])
    Rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    return Ry @ Rx @ rot_z(z)


def angle_deg(Ra: np.ndarray, Rb: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(Ra.T @ Rb) - 1) / 2, -1, 1))))


def check(box, poses) -> None:
    frames = box.frames("/tracking/trackers/1/position")
    assert len(frames) == len(poses)
    for lp, msgs in zip(poses, frames):
        by = dict(msgs)
        assert len(by) == len(msgs) == 18  # 8 trackers + head, position and rotation each
        R, J = lp.pose.rot, lp.pose.joints
        for n, (pseg, rseg) in EXPECTED.items():
            p = A.T @ np.array(by[f"/tracking/trackers/{n}/position"])
            np.testing.assert_allclose(p, J[SEGMENT_INDEX[pseg]], atol=1e-3, err_msg=str(n))
            Ru = unity_euler_to_matrix(*by[f"/tracking/trackers/{n}/rotation"])
            assert angle_deg(A.T @ Ru @ A, R[SEGMENT_INDEX[rseg]]) < 0.5, n
        h = SEGMENT_INDEX["head"]
        eyes = J[h] + R[h] @ np.array(HEAD_OFFSET)
        np.testing.assert_allclose(A.T @ np.array(by["/tracking/trackers/head/position"]), eyes, atol=1e-3)
        assert angle_deg(A.T @ unity_euler_to_matrix(*by["/tracking/trackers/head/rotation"]) @ A, R[h]) < 0.5


def test_trackers_carry_the_emitted_joints(suit, inbox):
    (sink,) = make_stream_sinks(f"vrchat:{inbox.port}")
    assert isinstance(sink, VrchatSink)
    poses, pipe = run_pipeline(suit, [sink, Barrier(inbox, "/tracking/trackers/head/rotation")])
    pipe.close()
    assert len(poses) > 40
    check(inbox, poses)


def test_trackers_follow_a_walk(walk_poses, inbox):
    sink = VrchatSink("127.0.0.1", inbox.port)
    barrier = Barrier(inbox, "/tracking/trackers/head/rotation")
    for lp in walk_poses:
        sink.on_pose(lp)
        barrier.on_pose(lp)
    sink.close()
    check(inbox, walk_poses)
    hips = [a for f in inbox.frames("/tracking/trackers/1/position") for addr, a in f
            if addr == "/tracking/trackers/1/position"]
    assert np.ptp([h[2] for h in hips]) > 0.5  # walking forward is Unity +Z
    assert min(h[1] for h in hips) > 0.5  # hips above the floor: +Y is up


def test_a_subset_keeps_its_numbers(walk_poses, inbox):
    sink = VrchatSink("127.0.0.1", inbox.port, trackers=("hip", "l_foot", "r_foot"), head=False)
    sink.on_pose(walk_poses[0])
    inbox.wait_for("/tracking/trackers/4/rotation", 1)
    sink.close()
    assert {a for a, _ in inbox.messages} == {f"/tracking/trackers/{n}/{k}" for n in (1, 3, 4)
                                              for k in ("position", "rotation")}
    with pytest.raises(ValueError, match="unknown VRChat tracker"):
        VrchatSink("127.0.0.1", inbox.port, trackers=("tail",))
