"""Physics checks of the synthesized sensor signals (issue 2, "Must show")."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from inference.body.body import Body, forward_kinematics, npose_rotations, tpose
from inference.body.motion import Motion
from inference.body.rotations import axis_angle_to_matrix, quat_to_matrix
from inference.body.skeleton import PARENTS, SITE_SEGMENT_INDEX, SITES
from inference.loaders.amass_frames import (
    SMPL_TO_OURS,
    amass_poses_to_global,
    global_to_amass_poses,
    ours_to_smpl_rest,
    smpl_rest_to_ours,
)
from inference.signals.synthesis import NoiseModel, body_mass, kinetic_energy, synthesize

FPS = 60.0
EDGE = 12  # frames at each clip end touched by the moving-average edge padding


def _rz(a: np.ndarray) -> np.ndarray:
    return axis_angle_to_matrix(np.stack([np.zeros_like(a), np.zeros_like(a), a], -1))


def spinning_motion(omega: float = np.pi / 2, seconds: float = 6.0) -> Motion:
    """The whole T-posed body turning about the vertical through the pelvis at `omega`."""
    T = int(seconds * FPS) + 1
    t = np.arange(T) / FPS
    R = _rz(omega * t)[:, None] @ tpose(T)
    return Motion(rot=R, root=np.tile([0.0, 0.0, 1.0], (T, 1)), fps=FPS, body=Body.from_height(1.75))


def test_spinning_segment_gives_centripetal_free_acceleration_within_1_percent():
    """Every site of a body spinning at a constant rate w about the vertical through the
    root has free acceleration -w^2 r (r: horizontal vector from the axis). Frames near the
    clip ends are excluded (filter edge). The 11-frame moving average itself attenuates a
    rotating vector by sin(5.5 x)/(11 sin(x/2)), x = w/60: 0.3% at w = pi/2 rad/s."""
    omega = np.pi / 2
    m = spinning_motion(omega)
    sig = synthesize(m)
    pos = m.resample(FPS).sites()
    r = pos.copy()
    r[..., 2] = 0.0
    r[..., :2] -= m.root[:, None, :2]
    expected = -(omega**2) * r
    sl = slice(EDGE, -EDGE)
    radius = np.linalg.norm(r[0], axis=-1)
    for k in np.flatnonzero(radius > 0.05):
        err = np.linalg.norm(sig.free_acc[sl, k] - expected[sl, k], axis=-1)
        assert np.all(err <= 0.01 * np.linalg.norm(expected[sl, k], axis=-1)), SITES[k]
    # the gyro of every sensor reads the spin about its (vertical) z axis
    np.testing.assert_allclose(sig.gyro[:, :, 2], omega, rtol=1e-6)
    np.testing.assert_allclose(sig.gyro[:, :, :2], 0.0, atol=1e-9)


@pytest.mark.parametrize("pose", ["tpose", "npose"])
def test_still_pose_gives_zero_free_acceleration_and_all_contacts(pose):
    T = 90
    R = tpose(T) if pose == "tpose" else npose_rotations(T)
    body = Body.from_height(1.8)
    m = Motion(rot=R, root=np.tile([0.3, -0.2, 0.95], (T, 1)), fps=30.0, body=body)
    sig = synthesize(m)
    np.testing.assert_allclose(sig.free_acc, 0.0, atol=1e-9)
    np.testing.assert_allclose(sig.gyro, 0.0, atol=1e-9)
    assert sig.contacts.all()
    # a still accelerometer reads +g along world up, expressed in the sensor frame
    Rs = R[0][list(SITE_SEGMENT_INDEX)]
    expected = np.einsum("sji,j->si", Rs, [0.0, 0.0, 9.81])
    np.testing.assert_allclose(sig.specific_force, np.broadcast_to(expected, sig.specific_force.shape),
                               atol=1e-9)
    np.testing.assert_allclose(sig.insole_force.sum(-1), body_mass(1.8) * 9.81, rtol=1e-9)
    np.testing.assert_allclose(sig.insole_force[:, 0], sig.insole_force[:, 1])
    np.testing.assert_allclose(kinetic_energy(m), 0.0, atol=1e-12)


def test_free_fall():
    """Issue 2 says "free fall gives -g in specific force". We read that as: the body's
    free (world, gravity-removed) acceleration is g = (0, 0, -9.81), so the specific
    force, a - g, which an accelerometer reads, is zero -- a falling accelerometer reads
    nothing. Both are checked; and no insole carries load once the feet move."""
    T = 61
    t = np.arange(T) / FPS
    root = np.stack([np.zeros(T), np.zeros(T), 30.0 - 0.5 * 9.81 * t**2], -1)
    m = Motion(rot=npose_rotations(T), root=root, fps=FPS, body=Body.from_height())
    sig = synthesize(m)
    g = np.broadcast_to([0.0, 0.0, -9.81], sig.free_acc.shape)
    np.testing.assert_allclose(sig.free_acc, g, atol=1e-6)
    np.testing.assert_allclose(sig.specific_force, 0.0, atol=1e-6)
    late = sig.t > 0.3 / 9.81 + 0.05  # feet faster than the contact threshold
    assert not sig.contacts[late].any()
    np.testing.assert_allclose(sig.insole_force[late], 0.0)


def _random_rot(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    return axis_angle_to_matrix(rng.normal(size=shape + (3,)))


def test_fk_preserves_bone_lengths():
    rng = np.random.default_rng(1)
    body = Body.from_height(1.62)
    R = _random_rot(rng, (20, 24))
    j = forward_kinematics(R, rng.normal(size=(20, 3)), body.offsets)
    par = np.array([max(p, 0) for p in PARENTS])
    lengths = np.linalg.norm(j[:, 1:] - j[:, par[1:]], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(body.bone_lengths()[1:], lengths.shape), atol=1e-12)


def test_fk_numpy_and_torch_agree():
    rng = np.random.default_rng(2)
    body = Body.from_height(1.9)
    R = _random_rot(rng, (4, 7, 24))
    root = rng.normal(size=(4, 7, 3))
    jn = forward_kinematics(R, root, body.offsets)
    jt = forward_kinematics(torch.as_tensor(R), torch.as_tensor(root), body.offsets)
    np.testing.assert_allclose(jt.numpy(), jn, atol=1e-6)
    f32 = torch.float32
    jt32 = forward_kinematics(torch.as_tensor(R, dtype=f32), torch.as_tensor(root, dtype=f32), body.offsets)
    np.testing.assert_allclose(jt32.numpy(), jn, atol=1e-5)


def _walking_like(T: int = 300, fps: float = 60.0) -> Motion:
    t = np.arange(T) / fps
    R = tpose(T)
    R[:, 0] = _rz(0.3 * np.sin(2 * t))
    R[:, 1] = R[:, 0] @ axis_angle_to_matrix(np.stack([np.zeros(T), 0.5 * np.sin(4 * t), np.zeros(T)], -1))
    root = np.stack([0.8 * t, 0.1 * np.sin(3 * t), 0.93 + 0.02 * np.sin(8 * t)], -1)
    return Motion(rot=R, root=root, fps=fps, body=Body.from_height())


def test_noise_mounting_and_heading_are_recorded_and_invertible():
    """With only mounting and heading errors, the calibration identity of the paper,
    R_WB = R_WG R_GS R_SB, recovers the true segment orientation from the reported
    quaternion and the stored meta; R_WG maps the reported free acceleration back to world."""
    m = _walking_like()
    clean = synthesize(m)
    noisy = synthesize(m, NoiseModel(mounting_deg=30, heading_deg=180), rng=3)
    R_GS = quat_to_matrix(noisy.quat)
    R_WB = noisy.meta["R_WG"][None] @ R_GS @ noisy.meta["R_SB"][None]
    np.testing.assert_allclose(R_WB, quat_to_matrix(clean.quat), atol=1e-9)
    back = np.einsum("sij,tsj->tsi", noisy.meta["R_WG"], noisy.free_acc)
    np.testing.assert_allclose(back, clean.free_acc, atol=1e-9)
    assert np.abs(noisy.meta["heading_rad"]).max() > 0.1


def test_noise_is_reproducible_and_plausible():
    m = _walking_like()
    a = synthesize(m, NoiseModel.typical(), rng=7)
    b = synthesize(m, NoiseModel.typical(), rng=7)
    np.testing.assert_array_equal(a.quat, b.quat)
    np.testing.assert_array_equal(a.specific_force, b.specific_force)
    np.testing.assert_allclose(np.linalg.norm(a.quat, axis=-1), 1.0, atol=1e-12)
    clean = synthesize(m)
    assert 0 < np.abs(a.gyro - np.einsum("sji,tsj->tsi", a.meta["R_SB"].transpose(0, 2, 1),
                                         clean.gyro)).mean() < 0.1


def test_synthesize_site_subset_and_shapes():
    m = _walking_like(T=100, fps=30.0)
    sig = synthesize(m, sites=("pelvis", "l_wrist"))
    T = len(sig)
    assert sig.quat.shape == (T, 2, 4) and sig.free_acc.shape == (T, 2, 3)
    assert sig.contacts.shape == (T, 4) and sig.insole_force.shape == (T, 2)
    assert sig.fps == 60.0 and T == 199
    assert set(sig.site("l_wrist")) == {"t", "quat", "free_acc", "specific_force", "gyro"}


def test_amass_frames_round_trip():
    rng = np.random.default_rng(4)
    R = _random_rot(rng, (5, 24))
    R[:, 22] = R[:, 20]  # fingers carry no own rotation in SMPL-H body joints
    R[:, 23] = R[:, 21]
    poses = global_to_amass_poses(R)
    assert poses.shape == (5, 156)
    np.testing.assert_allclose(amass_poses_to_global(poses), R, atol=1e-9)
    np.testing.assert_allclose(smpl_rest_to_ours(ours_to_smpl_rest(R)), R, atol=1e-12)
    # at our T-pose the AMASS root orientation stands a Y-up SMPL body up in Z-up world
    tp = global_to_amass_poses(tpose(1))
    root = axis_angle_to_matrix(tp[0, :3])
    np.testing.assert_allclose(root, SMPL_TO_OURS, atol=1e-12)
    np.testing.assert_allclose(root @ [0, 1, 0], [0, 0, 1], atol=1e-12)  # SMPL up -> world up
    np.testing.assert_allclose(root @ [0, 0, 1], [1, 0, 0], atol=1e-12)  # SMPL forward -> +X
    np.testing.assert_allclose(tp[0, 3:], 0.0, atol=1e-12)


def test_chunked_synthesis_equals_whole_clip(monkeypatch):
    """synthesize() works in time chunks for memory; the result must not depend on them."""
    import inference.signals.synthesis as syn

    m = _walking_like(T=250)
    whole = synthesize(m, NoiseModel.typical(), rng=5)
    monkeypatch.setattr(syn, "_CHUNK", 37)
    chunked = synthesize(m, NoiseModel.typical(), rng=5)
    for name in ("quat", "free_acc", "specific_force", "gyro", "contacts", "insole_force"):
        np.testing.assert_allclose(getattr(chunked, name), getattr(whole, name), atol=1e-10, err_msg=name)


def test_a_30_fps_capture_gives_smooth_60_hz_accelerations():
    """Double-differencing the slerped 30 -> 60 Hz path alternates between twice the
    acceleration and zero (a 30 Hz component as large as the signal); the spline paths
    do not, and after the model's moving average they are nearer the same motion
    captured at 120 Hz."""
    from dataclasses import replace

    from inference.evaluation.runner import synthetic_motion
    from inference.signals.resample import moving_average
    from inference.signals.synthesis import kinematics, second_difference

    fine = synthetic_motion(seconds=4.0, fps=120.0, seed=3)
    coarse = replace(fine, rot=fine.rot[::4], root=fine.root[::4], fps=30.0)
    a_fine = kinematics(fine.resample(60.0)).site_acc_raw
    a_spline = synthesize(coarse).meta["free_acc_raw"]
    assert np.allclose(kinematics(coarse).site_acc_raw, a_spline)
    m = coarse.resample(60.0)
    a_slerp = second_difference(m.sites(m.joints()), 60.0)
    n = min(len(a_fine), len(a_spline))
    inner = slice(12, n - 12)

    def alternating(a):
        return np.sqrt(np.mean((a[1:-1] - 0.5 * (a[2:] + a[:-2]))[inner] ** 2))

    assert alternating(a_spline) < 0.2 * alternating(a_slerp)

    def off(a):
        return np.sqrt(np.mean((moving_average(a[:n]) - moving_average(a_fine[:n]))[inner] ** 2))

    assert off(a_spline) < off(a_slerp)
