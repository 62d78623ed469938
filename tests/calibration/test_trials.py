"""A walk trial calibrated from other trials: each sensor's heading in the walk, and the mounting
from the N-pose trial (by the walk's facing, or a leg cycle's flexion axis)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import CalibrationError
from calibration.trials import Trial, calibrate_from_trials, flexion_axes, stands
from inference.body.conventions import quat_z, rot_z, yaw_of
from inference.body.rotations import matrix_angle_between, quat_multiply
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.dot_session import SITES, walk_without_still_start
from sim_devices.motions import generate, leg_cycle

FPS = 60.0


def _trial(name, motion, heading, mounting_seed=5):
    sig = synthesize(motion, NoiseModel(mounting_deg=20.0), rng=mounting_seed, sites=SITES)
    quat = quat_multiply(quat_z(-np.asarray(heading))[None], sig.quat)
    return Trial(name, quat, sig.gyro, np.ones(quat.shape[:2], bool), FPS, sig.specific_force), sig


def test_headings_and_mountings_come_back_from_an_npose_and_a_walk_without_a_still_start():
    rng = np.random.default_rng(0)
    h_c, h_w = rng.uniform(-np.pi, np.pi, 7), rng.uniform(-np.pi, np.pi, 7)
    npose, sig = _trial("npose", generate("npose", seconds=3.0), h_c)
    walk, _ = _trial("walk_001", walk_without_still_start(2), h_w)
    tc = calibrate_from_trials(SITES, walk, [npose])
    err = np.degrees(yaw_of(tc.calibration.R_WG @ np.swapaxes(rot_z(h_w), -1, -2)))
    assert np.abs((err + 180) % 360 - 180).max() < 5.0
    assert np.degrees(matrix_angle_between(tc.calibration.R_SB, sig.meta["R_SB"])).max() < 6.0
    swings = [_trial(f"legcycle_{s}", leg_cycle(s), rng.uniform(-np.pi, np.pi, 7))[0] for s in ("l", "r")]
    axes, source = flexion_axes(SITES, [npose, *swings])
    assert source == [None, "legcycle_l", "legcycle_r", "legcycle_l", "legcycle_r", None, None]
    tc = calibrate_from_trials(SITES, walk, [npose, *swings])
    legs = [1, 2, 3, 4]
    assert np.degrees(matrix_angle_between(tc.calibration.R_SB[legs], sig.meta["R_SB"][legs])).max() < 1.0


def test_a_calibration_trial_without_a_still_stand_is_refused_saying_where_it_looked():
    walk, _ = _trial("walk_001", walk_without_still_start(2), np.zeros(7))
    with pytest.raises(CalibrationError, match=r"^no still stand of 1 s found in 0-\d+\.\d s of walk_001"):
        stands(SITES, [walk])
