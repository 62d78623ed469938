"""The constant / dynamic split of a left-out segment's error (app/evaluation/offset.py) on
rotations whose constant offset is known."""

from __future__ import annotations

import numpy as np
import pytest

from app.evaluation.offset import constant_and_dynamic
from inference.body.rotations import matrix_about_axis, matrix_angle_between


def _random_rotations(rng, n, max_angle=np.pi):
    axes = rng.normal(size=(n, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return matrix_about_axis(axes, rng.uniform(0.0, max_angle, n))


def test_a_pure_mounting_offset_is_all_constant():
    rng = np.random.default_rng(0)
    R_ref = _random_rotations(rng, 400)  # the segment moves anyhow
    C = matrix_about_axis(np.array([0.0, 0.6, 0.8]), np.deg2rad(12.0))
    constant, dynamic = constant_and_dynamic(R_ref @ C, R_ref)
    assert constant == pytest.approx(12.0, abs=1e-6)
    assert dynamic == pytest.approx(0.0, abs=1e-6)
    # the whole error, as held_out_errors gives it, is the offset's angle
    assert np.degrees(matrix_angle_between(R_ref @ C, R_ref)).mean() == pytest.approx(12.0, abs=1e-6)


def test_offset_and_frame_by_frame_error_come_apart():
    rng = np.random.default_rng(1)
    R_ref = _random_rotations(rng, 2000)
    C = matrix_about_axis(np.array([1.0, 0.0, 0.0]), np.deg2rad(15.0))
    noise = _random_rotations(rng, 2000, max_angle=np.deg2rad(6.0))  # zero-mean: random axes
    R_pred = R_ref @ C @ noise
    constant, dynamic = constant_and_dynamic(R_pred, R_ref)
    assert constant == pytest.approx(15.0, abs=0.3)
    assert dynamic == pytest.approx(np.degrees(matrix_angle_between(noise, np.eye(3))).mean(), abs=0.3)
    total = np.degrees(matrix_angle_between(R_pred, R_ref)).mean()
    assert dynamic < total < constant + dynamic


def test_an_offset_in_the_world_frame_is_not_constant_in_the_segments():
    """A heading error of the reference (a turn on the left) is constant only while the
    segment does not turn: the split is about the segment's own frame, as mounting is."""
    rng = np.random.default_rng(2)
    R_ref = _random_rotations(rng, 500)
    H = matrix_about_axis(np.array([0.0, 0.0, 1.0]), np.deg2rad(20.0))
    constant, dynamic = constant_and_dynamic(H @ R_ref, R_ref)
    assert constant < 10.0 and dynamic > 10.0


def test_no_offset_no_error():
    R = _random_rotations(np.random.default_rng(3), 50)
    assert constant_and_dynamic(R, R) == pytest.approx((0.0, 0.0), abs=1e-6)
    with pytest.raises(ValueError):
        constant_and_dynamic(R[:0], R[:0])
