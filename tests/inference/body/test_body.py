import numpy as np
import pytest
import torch

from inference.body.body import (
    Body,
    contact_points,
    estimate_height,
    forward_kinematics,
    global_from_local,
    local_from_global,
    npose_rotations,
    site_positions,
    tpose,
)
from inference.body.rotations import quat_to_matrix, random_quat
from inference.body.skeleton import PARENTS, SEGMENT_INDEX


def random_rotations(n, seed=0):
    return quat_to_matrix(random_quat((n, 24), rng=np.random.default_rng(seed)))


def test_anthropometric_body_matches_height_ratios():
    b = Body.from_height(1.80)
    j = b.rest_joints()
    sole = contact_points(tpose(1)[0], j, b)[:, 2].min()
    # Drillis & Contini: knee 0.285 H, shoulder 0.818 H above the floor
    assert j[SEGMENT_INDEX["l_shank"], 2] - sole == pytest.approx(0.285 * 1.80, abs=0.01)
    assert j[SEGMENT_INDEX["l_upperarm"], 2] - sole == pytest.approx(0.818 * 1.80, abs=0.01)
    assert estimate_height(b.offsets) == pytest.approx(1.80, rel=0.02)
    # left/right mirror
    assert np.allclose(j[SEGMENT_INDEX["l_hand"]] * [1, -1, 1], j[SEGMENT_INDEX["r_hand"]])


def test_fk_preserves_bone_lengths():
    b = Body.from_height(1.7)
    R = random_rotations(50)
    root = np.random.default_rng(1).normal(size=(50, 3))
    j = forward_kinematics(R, root, b.offsets)
    for i in range(1, 24):
        d = np.linalg.norm(j[:, i] - j[:, PARENTS[i]], axis=-1)
        assert np.allclose(d, np.linalg.norm(b.offsets[i]), atol=1e-12)
    assert np.allclose(j[:, 0], root)


def test_numpy_and_torch_fk_agree():
    b = Body.from_height(1.65)
    R = random_rotations(20, seed=3)
    root = np.random.default_rng(4).normal(size=(20, 3))
    jn = forward_kinematics(R, root, b.offsets)
    jt = forward_kinematics(torch.tensor(R, dtype=torch.float32), torch.tensor(root, dtype=torch.float32), b.offsets)
    assert np.abs(jt.numpy() - jn).max() < 1e-5  # float32 path
    jt64 = forward_kinematics(torch.tensor(R), torch.tensor(root), torch.tensor(b.offsets))
    assert np.abs(jt64.numpy() - jn).max() < 1e-6
    sn = site_positions(R, jn, b)
    st = site_positions(torch.tensor(R), jt64, b)
    assert np.abs(st.numpy() - sn).max() < 1e-6


def test_fk_is_differentiable_in_torch():
    b = Body.from_height(1.7)
    R = torch.tensor(random_rotations(2), requires_grad=True)
    j = forward_kinematics(R, torch.zeros(2, 3, dtype=torch.float64), b.offsets)
    j.sum().backward()
    assert torch.isfinite(R.grad).all() and R.grad.abs().sum() > 0


def test_local_global_round_trip():
    R = random_rotations(10, seed=5)
    assert np.allclose(global_from_local(local_from_global(R)), R, atol=1e-12)
    Rt = torch.tensor(R)
    assert torch.allclose(global_from_local(local_from_global(Rt)), Rt, atol=1e-12)


def test_sites_are_distal_on_limbs_and_npose_lowers_arms():
    b = Body.from_height(1.75)
    R = npose_rotations(1)[0]
    j = forward_kinematics(R, np.zeros(3), b.offsets)
    s = site_positions(R, j, b)
    from inference.body.skeleton import SITE_INDEX

    wrist, elbow, hand = s[SITE_INDEX["l_wrist"]], j[SEGMENT_INDEX["l_forearm"]], j[SEGMENT_INDEX["l_hand"]]
    # the wrist sensor sits in the distal part of the forearm
    assert np.linalg.norm(wrist - elbow) > 0.75 * np.linalg.norm(hand - elbow)
    assert j[SEGMENT_INDEX["l_hand"], 2] < j[SEGMENT_INDEX["l_upperarm"], 2] - 0.3


def test_bad_heights_and_offsets_rejected():
    with pytest.raises(ValueError):
        Body.from_height(0.1)
    off = Body.from_height(1.7).offsets.copy()
    off[3, 0] = np.nan
    with pytest.raises(ValueError):
        Body.from_offsets(off)
