"""A simulated device's signals loop over their clip; where the clip wraps, the sensor is
turned back to its first orientation and the gyro measures the turn, so an orientation
the driver integrates itself (the DualSense's AHRS) follows the loop."""

from __future__ import annotations

import numpy as np

from calibration.protocol import Protocol, synthesize_session
from inference.body.rotations import matrix_angle_between, quat_exp, quat_multiply, quat_to_matrix
from sim_devices.devices.base import LOOP_BLEND_S, SignalSource
from sim_devices.motions import generate


def test_the_gyro_carries_the_sensor_across_the_wrap():
    act = generate("walk", seconds=4.0, seed=2)
    sig, _ = synthesize_session(act, Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.15), rng=1,
                                sites=("r_wrist",))
    src = SignalSource(sig, "r_wrist")
    nb = int(round(LOOP_BLEND_S * src.fps))
    a = src.n - nb - 1
    # integrate the body-frame gyro from the last untouched frame, through the wrap
    q = src.quat[a].copy()
    for k in range(a, src.n):
        q = quat_multiply(q, quat_exp(src.gyro[k] / src.fps))
    err = np.rad2deg(matrix_angle_between(quat_to_matrix(q), quat_to_matrix(src.quat[0])))
    assert err < 0.01
    # no frame-to-frame jump bigger than the blend's steps, and still (gravity only) meanwhile
    steps = np.rad2deg(matrix_angle_between(quat_to_matrix(src.quat[a:]), quat_to_matrix(np.r_[src.quat[a + 1:],
                                                                                              src.quat[:1]])))
    total = np.rad2deg(matrix_angle_between(quat_to_matrix(src.quat[a]), quat_to_matrix(src.quat[0])))
    assert steps.max() <= total / nb + 1e-6
    assert np.allclose(np.linalg.norm(src.specific_force[a + 1:], axis=-1), 9.80665)
    assert np.all(src.free_acc[a + 1:] == 0.0)
