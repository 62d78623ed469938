"""The arms' reach onto tracked controllers: a hand the model put elsewhere ends on its
controller, wherever the model put the body, and nothing but the two arm bones moves."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.body import forward_kinematics
from inference.body.reach import reach_hands, two_bone
from inference.body.rotations import axis_angle_to_matrix
from inference.body.skeleton import SEGMENT_INDEX
from inference.body.tracked import point_features, point_locals, point_positions, presence
from inference.signals.synthesis import kinematics
from sim_devices.motions import generate

ARM = [SEGMENT_INDEX[s] for s in ("l_upperarm", "r_upperarm", "l_forearm", "r_forearm")]


def _walk():
    m = generate("walk", seconds=2.0, seed=3)
    kin = kinematics(m)
    return m.body, kin.rot, kin.root


def _turned(R: np.ndarray, rng: np.random.Generator, deg: float) -> np.ndarray:
    out = R.copy()
    for seg in ARM:
        axis = rng.normal(size=3)
        out[:, seg] = axis_angle_to_matrix(np.radians(deg) * axis / np.linalg.norm(axis)) @ R[:, seg]
    return out


@pytest.mark.parametrize("deg", [15.0, 40.0])
def test_a_misplaced_hand_ends_on_its_controller(deg):
    body, R, root = _walk()
    locals_ = point_locals(body.offsets, body.height)
    truth = point_positions(R, forward_kinematics(R, root, body.offsets), locals_)
    feats = point_features(truth, presence(["head", "l_hand", "r_hand"]))
    wrong = _turned(R, np.random.default_rng(0), deg)
    # the model's body elsewhere on the floor and a little low: the headset anchors it
    drift = root + np.array([0.4, -0.3, -0.02])
    before = point_positions(wrong, forward_kinematics(wrong, drift, body.offsets), locals_)
    R2, j2 = reach_hands(wrong, drift, body, {}, feats)
    after = point_positions(R2, j2, locals_)
    anchor = after[:, :1] - truth[:, :1]
    err_before = np.linalg.norm(before[:, 1:3] - (truth[:, 1:3] + (before[:, :1] - truth[:, :1])), axis=-1)
    err_after = np.linalg.norm(after[:, 1:3] - (truth[:, 1:3] + anchor), axis=-1)
    assert err_before.mean() > 0.03
    assert err_after.max() < 1e-3  # the arm reaches: the controller is where a hand can be
    moved = [s for s in range(24) if not np.allclose(R2[:, s], wrong[:, s])]
    assert set(moved) <= set(ARM) | {SEGMENT_INDEX["l_collar"], SEGMENT_INDEX["r_collar"]}


def test_the_elbow_keeps_the_models_swivel_and_an_unreachable_target_straightens_the_arm():
    s = np.zeros((1, 3))
    e = np.array([[0.0, 0.2, -0.2]])
    w = np.array([[0.0, 0.4, -0.4]])
    target = np.array([[0.3, 0.0, -0.3]])
    e2, w2 = two_bone(s, e, w, target, 0.3, 0.25)
    assert np.allclose(np.linalg.norm(e2 - s), 0.3) and np.allclose(np.linalg.norm(w2 - e2), 0.25)
    assert np.allclose(w2, target)
    normal = np.cross(target[0] - s[0], e[0] - s[0])
    assert abs(np.dot(e2[0] - s[0], normal)) < 1e-9  # the plane of shoulder, target and old elbow
    far = np.array([[2.0, 0.0, 0.0]])
    e3, w3 = two_bone(s, e, w, far, 0.3, 0.25)
    assert np.allclose(w3[0], [0.55, 0.0, 0.0], atol=1e-3)


def test_the_controllers_orientation_is_the_hands_and_no_headset_is_refused():
    body, R, root = _walk()
    locals_ = point_locals(body.offsets, body.height)
    truth = point_positions(R, forward_kinematics(R, root, body.offsets), locals_)
    feats = point_features(truth, presence(["head", "l_hand", "r_hand"]))
    wrong = _turned(R, np.random.default_rng(1), 30.0)
    wrong[:, SEGMENT_INDEX["l_hand"]] = axis_angle_to_matrix(np.array([0.5, 0.0, 0.0])) @ R[:, SEGMENT_INDEX["l_hand"]]
    R2, j2 = reach_hands(wrong, root, body, {"l_hand": R[:, SEGMENT_INDEX["l_hand"]]}, feats)
    assert np.allclose(R2[:, SEGMENT_INDEX["l_hand"]], R[:, SEGMENT_INDEX["l_hand"]])
    after = point_positions(R2, j2, locals_)
    assert np.linalg.norm(after[:, 1] - truth[:, 1] - (after[:, :1] - truth[:, :1])[:, 0], axis=-1).max() < 1e-3
    no_head = point_features(truth, presence(["l_hand", "r_hand"]))
    with pytest.raises(ValueError, match="headset"):
        reach_hands(wrong, root, body, {}, no_head)


def test_a_controller_beyond_the_arm_turns_the_collar_but_no_more_than_a_collar_turns():
    from inference.body.reach import COLLAR_MAX_DEG
    from inference.body.rotations import matrix_angle_between

    body, R, root = _walk()
    locals_ = point_locals(body.offsets, body.height)
    truth = point_positions(R, forward_kinematics(R, root, body.offsets), locals_)
    feats = point_features(truth, presence(["head", "l_hand", "r_hand"]))
    # the model turned the chest 46 deg about the vertical and left the head where it is: the
    # controllers are now beyond the arms' length
    lean = R.copy()
    lean[:, SEGMENT_INDEX["spine3"]] = axis_angle_to_matrix(np.array([0.0, 0.0, 0.8])) @ R[:, SEGMENT_INDEX["spine3"]]
    R2, j2 = reach_hands(lean, root, body, {}, feats)
    after = point_positions(R2, j2, locals_)
    err = np.linalg.norm(after[:, 1:3] - truth[:, 1:3] - (after[:, :1] - truth[:, :1]), axis=-1)
    assert err.mean() < 0.02
    for side in ("l", "r"):
        c = SEGMENT_INDEX[f"{side}_collar"]
        turned = np.degrees(matrix_angle_between(R2[:, c], lean[:, c]))
        assert turned.max() <= COLLAR_MAX_DEG + 1e-6 and turned.max() > 1.0


def test_a_right_forearm_with_a_wrong_upper_arm_comes_back_whole():
    """The swivel comes from the model's forearm: with the shoulder and the forearm right and
    only the upper arm wrong, the reach restores the true arm."""
    from inference.body.rotations import matrix_angle_between

    body, R, root = _walk()
    locals_ = point_locals(body.offsets, body.height)
    truth = point_positions(R, forward_kinematics(R, root, body.offsets), locals_)
    feats = point_features(truth, presence(["head", "l_hand", "r_hand"]))
    wrong = R.copy()
    rng = np.random.default_rng(5)
    for seg in (SEGMENT_INDEX["l_upperarm"], SEGMENT_INDEX["r_upperarm"]):
        axis = rng.normal(size=3)
        wrong[:, seg] = axis_angle_to_matrix(np.radians(25.0) * axis / np.linalg.norm(axis)) @ R[:, seg]
    R2, _ = reach_hands(wrong, root, body, {}, feats)
    for side in ("l", "r"):
        for seg in (f"{side}_upperarm", f"{side}_forearm"):
            k = SEGMENT_INDEX[seg]
            # the bone's direction is the truth's (a bone's twist is not the reach's to fix)
            b = body.offsets[SEGMENT_INDEX[{"upperarm": f"{side}_forearm", "forearm": f"{side}_hand"}[seg[2:]]]]
            got, want = (R2[:, k] @ b), (R[:, k] @ b)
            assert np.degrees(np.arccos(np.clip(np.sum(got * want, -1) / np.linalg.norm(b) ** 2, -1, 1))).max() < 0.1
        assert np.degrees(matrix_angle_between(R2[:, SEGMENT_INDEX[f"{side}_forearm"]],
                                               R[:, SEGMENT_INDEX[f"{side}_forearm"]])).max() < 0.1
