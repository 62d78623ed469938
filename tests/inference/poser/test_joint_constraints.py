from __future__ import annotations

import numpy as np
import torch

from inference.body.conventions import yaw_of
from inference.body.rotations import matrix_about_axis, so3_exp
from inference.body.skeleton import N_SEGMENTS
from inference.poser.joint_constraints import BONE_AXIS, KNEE_AXIS, KNEES, constrain_knees, hinge_angle


def _random_rotations(rng, n):
    return so3_exp(torch.as_tensor(rng.normal(size=(n, 3)) * 1.2))


def rotation_about(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    return matrix_about_axis(axis.expand(*angle.shape, 3), angle)


def test_hinge_angle_recovers_a_pure_hinge():
    axis = torch.tensor(KNEE_AXIS, dtype=torch.float64)
    angles = torch.linspace(-2.5, 2.5, 11, dtype=torch.float64)
    R = rotation_about(axis, angles)
    torch.testing.assert_close(hinge_angle(R, axis), angles)


def _pose(rng, flex):
    """A body whose knees are exact hinges with the given flexion angles (2,)."""
    R = _random_rotations(rng, N_SEGMENTS)
    axis = torch.tensor(KNEE_AXIS, dtype=torch.float64)
    for k, (t, s) in enumerate(KNEES):
        R[s] = R[t] @ rotation_about(axis, torch.tensor(flex[k], dtype=torch.float64))
    return R


def test_a_hinged_knee_is_left_alone():
    rng = np.random.default_rng(0)
    R = _pose(rng, [0.3, 1.4])
    for measured_segs in ([], [KNEES[0][1]], [KNEES[1][0]], [KNEES[0][0], KNEES[0][1]]):
        m = torch.zeros(N_SEGMENTS, dtype=torch.bool)
        m[measured_segs] = True
        torch.testing.assert_close(constrain_knees(R, m), R)


def test_measured_shank_fixes_the_thighs_twist_and_keeps_its_flexion():
    rng = np.random.default_rng(1)
    truth = _pose(rng, [0.9, 0.2])
    pred = truth.clone()
    t, s = KNEES[0]
    # the model got the flexion right but the thigh twisted 25 deg about its long axis
    # and abducted 10 deg: both impossible at the knee with this shank
    wrong = so3_exp(torch.tensor([0.0, 0.0, np.radians(25.0)], dtype=torch.float64)) @ so3_exp(
        torch.tensor([np.radians(10.0), 0.0, 0.0], dtype=torch.float64))
    pred[t] = truth[t] @ wrong
    m = torch.zeros(N_SEGMENTS, dtype=torch.bool)
    m[s] = True
    out = constrain_knees(pred, m)
    assert torch.equal(out[s], pred[s])  # the measurement is never touched
    err_before = torch.linalg.matrix_norm(pred[t] - truth[t])
    err_after = torch.linalg.matrix_norm(out[t] - truth[t])
    assert err_after < 0.25 * err_before
    # the result is a hinge again
    local = out[t].T @ out[s]
    axis = torch.tensor(KNEE_AXIS, dtype=torch.float64)
    torch.testing.assert_close(local, rotation_about(axis, hinge_angle(local, axis)))
    # the other leg, hinged already, is unchanged
    torch.testing.assert_close(out[KNEES[1][0]], pred[KNEES[1][0]])
    torch.testing.assert_close(out[KNEES[1][1]], pred[KNEES[1][1]])


def test_unmeasured_shank_is_rebuilt_from_the_thigh_and_batches_work():
    rng = np.random.default_rng(2)
    truth = torch.stack([_pose(rng, [0.5, 1.0]) for _ in range(3)])
    pred = truth.clone()
    t, s = KNEES[1]
    pred[:, s] = pred[:, s] @ so3_exp(torch.tensor([0.0, 0.0, 0.4], dtype=torch.float64))
    m = torch.zeros(3, N_SEGMENTS, dtype=torch.bool)
    m[:, t] = True
    out = constrain_knees(pred, m)
    assert torch.equal(out[:, t], pred[:, t])
    err_after = torch.linalg.matrix_norm(out[:, s] - truth[:, s])
    assert (err_after < torch.linalg.matrix_norm(pred[:, s] - truth[:, s])).all()


def test_the_twist_share_keeps_that_much_of_the_models_turn_about_the_thigh():
    """A thigh rebuilt from its shank with ``twist`` keeps that share of the model's own turn
    about the bone, on top of the hinge's answer; its flexion stays the hinge's (within a degree),
    and the numpy path (the live poser's) gives the torch path's answer."""
    rng = np.random.default_rng(3)
    truth = _pose(rng, [0.7, 1.1])
    t, s = KNEES[0]
    turn, abduct = np.radians(24.0), np.radians(8.0)
    pred = truth.clone()
    pred[t] = truth[t] @ so3_exp(torch.tensor([0.0, 0.0, turn], dtype=torch.float64)) @ so3_exp(
        torch.tensor([abduct, 0.0, 0.0], dtype=torch.float64))
    m = torch.zeros(N_SEGMENTS, dtype=torch.bool)
    m[s] = True
    hinged = constrain_knees(pred, m)
    bone = torch.tensor(BONE_AXIS, dtype=torch.float64)
    axis = torch.tensor(KNEE_AXIS, dtype=torch.float64)
    for share in (0.0, 0.5, 1.0):
        out = constrain_knees(pred, m, share)
        assert torch.equal(out[s], pred[s])
        # the hinge's thigh turned about the bone by the share of the model's twist from it
        kept = float(yaw_of(hinged[t].T @ out[t]))
        model_twist = float(yaw_of(hinged[t].T @ pred[t]))
        assert abs(model_twist - turn) < np.radians(3.0)  # the abduction leaks a little into the split
        assert abs(kept - share * model_twist) < 1e-9
        torch.testing.assert_close(hinged[t].T @ out[t], rotation_about(bone, torch.tensor(kept, dtype=torch.float64)))
        # the flexion about the knee's axis is the hinge's
        flex = hinge_angle(out[t].T @ out[s], axis)
        torch.testing.assert_close(flex, hinge_angle(hinged[t].T @ hinged[s], axis), atol=0.02, rtol=0)
        # the other knee, whose thigh and shank are both the model's, is untouched
        torch.testing.assert_close(out[KNEES[1][0]], pred[KNEES[1][0]])
        out_np = constrain_knees(pred.numpy(), m.numpy(), share)
        np.testing.assert_allclose(out_np, out.numpy(), atol=1e-12)
        batched = constrain_knees(np.stack([pred.numpy()] * 2), np.stack([m.numpy()] * 2), share)
        np.testing.assert_allclose(batched[1], out.numpy(), atol=1e-12)

