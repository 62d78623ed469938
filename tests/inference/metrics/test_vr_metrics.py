"""The three-point papers' metrics (inference/metrics/vr.py) on hand-computed cases, and
their pooling and paired comparison in errors.py."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.body import Body, forward_kinematics, global_from_local
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.metrics import vr
from inference.metrics.errors import VR_METRICS, evaluate_clip, paired_difference, summarize

X = np.array([1.0, 0.0, 0.0])
Z = np.array([0.0, 0.0, 1.0])
BODY = Body.from_height(1.75)
FPS = 20.0


def _identity(T: int) -> np.ndarray:
    return np.broadcast_to(np.eye(3), (T, N_SEGMENTS, 3, 3)).copy()


def _walk(T: int, v=(1.2, 0.3, 0.0)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A T-pose body gliding at constant velocity v (m/s): rotations, root, joints."""
    R = _identity(T)
    root = np.array([0.0, 0.0, 0.95]) + np.arange(T)[:, None] / FPS * np.asarray(v)
    return R, root, forward_kinematics(R, root, BODY.offsets)


def test_joint_sets_are_smpls_22_body_joints_split_as_agrol():
    assert vr.BODY_JOINTS == tuple(range(22))
    assert sorted(vr.UPPER_JOINTS + vr.LOWER_JOINTS) == list(range(22))  # a partition
    assert [SEGMENT_INDEX[n] for n in ("l_hand", "r_hand")] == list(vr.HAND_JOINTS)  # wrists
    assert SEGMENT_INDEX["head"] == vr.HEAD_JOINT and SEGMENT_INDEX["pelvis"] == vr.ROOT_JOINT
    lower = {n for n in SEGMENT_INDEX if SEGMENT_INDEX[n] in vr.LOWER_JOINTS}
    assert lower == {"pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot", "l_toes", "r_toes"}


def test_mpjre_of_one_joint_turned_about_an_axis():
    T = 3
    Lt = _identity(T)
    Lp = _identity(T)
    Lp[:, SEGMENT_INDEX["l_shank"]] = matrix_about_axis(X, np.deg2rad(30.0))
    # axis-angle (30 deg, 0, 0) on 1 of 21 joints x 3 components
    np.testing.assert_allclose(vr.mpjre_local(Lp, Lt), 30.0 / 63, atol=1e-9)
    # same from global orientations: the shank turn carries its children along
    np.testing.assert_allclose(vr.mpjre(global_from_local(Lp), global_from_local(Lt)), 30.0 / 63, atol=1e-9)
    # the root's orientation is not among the 21 joints
    Lp = _identity(T)
    Lp[:, 0] = matrix_about_axis(Z, 1.0)
    np.testing.assert_allclose(vr.mpjre_local(Lp, Lt), 0.0, atol=1e-12)
    # a turn about a diagonal axis counts its components: |(1,1,0)/sqrt2 * 60 deg| summed
    Lp = _identity(T)
    Lp[:, SEGMENT_INDEX["head"]] = matrix_about_axis(np.array([1.0, 1.0, 0.0]) / np.sqrt(2), np.deg2rad(60.0))
    np.testing.assert_allclose(vr.mpjre_local(Lp, Lt), 2 * 60.0 / np.sqrt(2) / 63, atol=1e-9)


def test_mpjre_component_differences_wrap_around_pi():
    Lt = _identity(1)
    Lp = _identity(1)
    Lt[:, SEGMENT_INDEX["l_thigh"]] = matrix_about_axis(X, np.deg2rad(170.0))
    Lp[:, SEGMENT_INDEX["l_thigh"]] = matrix_about_axis(X, np.deg2rad(-170.0))  # 20 deg away, not 340
    np.testing.assert_allclose(vr.mpjre_local(Lp, Lt), 20.0 / 63, atol=1e-9)


def test_translated_body_global_and_head_anchored():
    R, root, jt = _walk(5)
    jp = forward_kinematics(R, root + [0.03, 0.04, 0.0], BODY.offsets)  # 5 cm off, same pose
    np.testing.assert_allclose(vr.mpjpe(jp, jt, anchor=None), 0.05, atol=1e-12)
    np.testing.assert_allclose(vr.part_pe(jp, jt, (vr.ROOT_JOINT,), anchor=None), 0.05, atol=1e-12)
    np.testing.assert_allclose(vr.mpjre(R, R), 0.0, atol=1e-12)
    # the papers put the body under the tracked head: a rigid shift is no error there
    np.testing.assert_allclose(vr.mpjpe(jp, jt), 0.0, atol=1e-12)
    np.testing.assert_allclose(vr.part_pe(jp, jt, (vr.ROOT_JOINT,)), 0.0, atol=1e-12)
    with pytest.raises(ValueError, match="anchor"):
        vr.mpjpe(jp, jt, anchor="pelvis")


def test_root_pe_head_anchored_is_the_pelvis_off_the_head():
    _, _, jt = _walk(4)
    jp = jt.copy()
    jp[:, vr.ROOT_JOINT] += [0.0, 0.0, -0.1]  # only the pelvis joint 10 cm low
    np.testing.assert_allclose(vr.part_pe(jp, jt, (vr.ROOT_JOINT,)), 0.1, atol=1e-12)
    np.testing.assert_allclose(vr.mpjpe(jp, jt), 0.1 / 22, atol=1e-12)


def test_mpjve_of_an_alternating_offset():
    T, d = 8, 0.01
    _, _, jt = _walk(T)
    sign = (-1.0) ** np.arange(T)
    # the whole body +-1 cm along x every other frame, scored globally: each frame pair's
    # velocity is off by 2 d fps on every joint
    jp = jt + sign[:, None, None] * np.array([d, 0.0, 0.0])
    np.testing.assert_allclose(vr.mpjve(jp, jt, FPS, anchor=None), 2 * d * FPS, atol=1e-9)
    np.testing.assert_allclose(vr.mpjve(jp, jt, FPS), 0.0, atol=1e-9)  # the head takes it out
    # only the nine lower-body joints shaking: 9 of 22 joints, head-anchored too
    jp = jt.copy()
    jp[:, list(vr.LOWER_JOINTS)] += sign[:, None, None] * np.array([d, 0.0, 0.0])
    np.testing.assert_allclose(vr.mpjve(jp, jt, FPS), 2 * d * FPS * 9 / 22, atol=1e-9)
    assert vr.mpjve(jt[:1], jt[:1], FPS).shape == (0,)


def test_jerk_of_constant_acceleration_and_of_a_cubic():
    T = 12
    t = np.arange(T) / FPS
    j = np.zeros((T, N_SEGMENTS, 3))
    j[:] = 0.5 * 9.81 * t[:, None, None] ** 2 * Z + 1.3 * t[:, None, None] * X  # constant acceleration
    np.testing.assert_allclose(vr.mean_jerk(j, FPS), 0.0, atol=1e-6)
    j = np.zeros((T, N_SEGMENTS, 3))
    j[:, SEGMENT_INDEX["l_foot"], 0] = 2.0 * t**3  # jerk 12 m/s^3 on 1 of the 22 joints
    j[:, SEGMENT_INDEX["l_fingers"], 0] = 50.0 * t**3  # outside SMPL's 22 body joints
    np.testing.assert_allclose(vr.mean_jerk(j, FPS), 12.0 / 22, rtol=1e-9)
    assert vr.mean_jerk(j[:3], FPS).shape == (0,)


def test_a_leg_perturbation_is_lower_body_error_only():
    T = 4
    R, root, jt = _walk(T)
    Rp = R.copy()
    for n in ("l_thigh", "l_shank", "l_foot", "l_toes"):  # the left leg swung 40 deg from the hip
        Rp[:, SEGMENT_INDEX[n]] = matrix_about_axis(np.array([0.0, 1.0, 0.0]), np.deg2rad(40.0))
    jp = forward_kinematics(Rp, root, BODY.offsets)
    lower = vr.part_pe(jp, jt, vr.LOWER_JOINTS)
    assert np.all(lower > 0.01)
    np.testing.assert_allclose(vr.part_pe(jp, jt, vr.UPPER_JOINTS), 0.0, atol=1e-12)
    np.testing.assert_allclose(vr.part_pe(jp, jt, vr.HAND_JOINTS), 0.0, atol=1e-12)
    np.testing.assert_allclose(vr.part_pe(jp, jt, (vr.ROOT_JOINT,)), 0.0, atol=1e-12)
    # knee, ankle and toe base moved; their mean over 9 lower joints, and over 22 for MPJPE
    moved = np.linalg.norm(jp - jt, axis=-1)[:, [4, 7, 10]].sum(axis=1)
    np.testing.assert_allclose(lower, moved / 9, atol=1e-12)
    np.testing.assert_allclose(vr.mpjpe(jp, jt), moved / 22, atol=1e-12)
    np.testing.assert_allclose(vr.mpjre(Rp, R), 40.0 / 63, atol=1e-9)  # the hip turned, locally


def _clip(name: str, T: int, drop: float):
    """A clip whose prediction has the pelvis `drop` metres low (head in place)."""
    R, root, jt = _walk(T)
    jp = jt.copy()
    jp[:, vr.ROOT_JOINT, 2] -= drop
    return evaluate_clip(name, R, root, jp, R, root, jt, FPS)


def test_summarize_pools_the_papers_metrics_by_frames():
    a, b = _clip("a", 10, 0.02), _clip("b", 30, 0.06)
    s = summarize([a, b])
    root = (10 * 2.0 + 30 * 6.0) / 40  # cm, frame-weighted, not the clips' plain mean 4.0
    assert s["root_pe_cm"] == pytest.approx(root)
    assert s["lower_pe_cm"] == pytest.approx(root / 9)
    assert s["mpjpe_cm"] == pytest.approx(root / 22)
    assert s["upper_pe_cm"] == pytest.approx(0.0, abs=1e-9) and s["hand_pe_cm"] == pytest.approx(0.0, abs=1e-9)
    assert s["mpjre_deg"] == pytest.approx(0.0, abs=1e-9)
    assert s["mpjve_cms"] == pytest.approx(0.0, abs=1e-6)  # a constant offset has no velocity error
    assert s["jitter_1e2m_s3"] == pytest.approx(0.0, abs=1e-6)
    assert s["jitter_true_1e2m_s3"] == pytest.approx(0.0, abs=1e-6)
    assert a.summary()["root_pe_cm"] == pytest.approx(2.0)
    # the existing keys keep their own meaning: JPE moves both pelvises to the origin, so a
    # pelvis off by d shows on all 23 other joints
    assert s["jpe_cm"] == pytest.approx(root)
    empty = summarize([])
    assert all(empty[k] is None for k in VR_METRICS) and empty["jitter_true_1e2m_s3"] is None


def test_summarize_pools_mpjve_over_frame_pairs():
    T = [5, 21]
    clips = []
    for k, n in enumerate(T):
        R, root, jt = _walk(n)
        jp = jt.copy()
        jp[:, vr.ROOT_JOINT, 0] += 0.01 * (k + 1) * (-1.0) ** np.arange(n)
        clips.append(evaluate_clip(f"c{k}", R, root, jp, R, root, jt, FPS))
    per_pair = [2 * 0.01 * (k + 1) * FPS / 22 * 100 for k in range(2)]  # cm/s
    s = summarize(clips)
    assert s["mpjve_cms"] == pytest.approx((4 * per_pair[0] + 20 * per_pair[1]) / 24)
    assert [c.vel_n for c in clips] == [4, 20] and [c.jerk_n for c in clips] == [2, 18]


def test_paired_difference_on_the_papers_position_metrics():
    n = [10, 20, 30, 40]
    a = [_clip(f"c{k}", t, 0.02) for k, t in enumerate(n)]
    b = [_clip(f"c{k}", t, 0.05) for k, t in enumerate(n)]
    d = paired_difference(a, b, "root_pe_cm")
    assert d.difference == pytest.approx(-3.0) and (d.low, d.high) == pytest.approx((-3.0, -3.0))
    assert d.decided and d.a_lower == 4
    d = paired_difference(a, b, "lower_pe_cm")
    assert d.difference == pytest.approx(-3.0 / 9)
    d = paired_difference(a, b, "mpjve_cms")
    assert d.difference == pytest.approx(0.0, abs=1e-6) and not d.decided
    with pytest.raises(ValueError, match="per-frame metrics only"):
        paired_difference(a, b, "jitter_true_1e2m_s3")
