from __future__ import annotations

import numpy as np
import torch

from inference.body.rotations import matrix_about_axis, so3_exp
from inference.body.skeleton import N_SEGMENTS
from inference.poser.joint_constraints import KNEE_AXIS, KNEES, constrain_knees, hinge_angle


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
