"""benchmarks/vr_baseline.py reads the devices the way the MLP was trained on them: the
simulated rig without noise gives the geometry of inference/body/tracked.py on the 20 Hz
truth, and with its noise the same clip seed gives the same draws."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks.vr_baseline import rig_points  # noqa: E402
from inference.body.tracked import point_locals  # noqa: E402
from inference.evaluation.runner import clip_input, face_forward, synthetic_motion  # noqa: E402
from inference.model.agrol_mlp import device_poses  # noqa: E402
from sim_devices.devices.vr_rig import NO_NOISE  # noqa: E402


def test_rig_points_are_the_training_geometry():
    m = face_forward(synthetic_motion(seconds=3.0, turn_deg_per_s=40.0))
    inp = clip_input(m, [], align=False)
    pos, rot = rig_points(m, 0, NO_NOISE)
    p2, r2 = device_poses(inp.rot, inp.joints, point_locals(m.body.offsets, m.body.height))
    assert pos.shape == p2.shape == (inp.rot.shape[0], 3, 3)
    assert np.abs(pos - p2).max() < 0.002  # interpolation from the rig's 72 Hz only
    assert np.abs(rot - r2).max() < 0.01
    noisy, _ = rig_points(m, 5)
    again, _ = rig_points(m, 5)
    np.testing.assert_array_equal(noisy, again)
    assert 0.001 < np.abs(noisy - pos).mean() < 0.02  # jitter, wander and 15 ms of latency
