"""The simulated protocols join standing and moving without a jolt: the root's velocity is continuous
through every blend, so no sensor reads an acceleration the motion does not have (a smoothstep blend
stopped the root at both ends, and the pelvis read 113 m/s^2 for one sample where the walk began)."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import Protocol, synthesize_session
from calibration.protocol import (
    WalkProtocol,
    root_blend,
    session_motion,
    walk_session_motion,
)
from sim_devices.motions import generate


def _largest_velocity_step(root: np.ndarray, fps: float) -> float:
    """The largest change of the horizontal root velocity from one frame to the next (m/s)."""
    v = np.diff(root[:, :2], axis=0) * fps
    return float(np.linalg.norm(np.diff(v, axis=0), axis=1).max())


def test_root_blend_joins_position_and_velocity():
    p0, v0 = np.array([0.0, 0.0, 0.9]), np.zeros(3)
    p1, v1 = np.array([0.5, 0.1, 0.95]), np.array([1.0, 0.2, 0.0])
    fps, n = 60.0, 59
    path = root_blend(p0, v0, p1, v1, n, fps)
    full = np.vstack([p0, path, p1])
    v = np.diff(full, axis=0) * fps
    np.testing.assert_allclose(v[0], v0, atol=0.05)  # leaves at rest
    np.testing.assert_allclose(v[-1], v1, atol=0.05)  # arrives moving as the motion after it
    # placed v * duration / 2 apart, the speed ramps evenly: a straight line in velocity
    speed = np.linalg.norm(v[:, :2], axis=1)
    assert np.all(np.diff(speed) > 0)
    assert np.ptp(np.diff(speed)) < 1e-6


@pytest.mark.parametrize("seed", [0, 3])
def test_a_session_starts_its_activity_without_a_jolt(seed):
    act = generate("walk", seconds=12, seed=seed)
    motion = session_motion(act, Protocol())
    walk_own = _largest_velocity_step(act.root, act.fps)
    assert _largest_velocity_step(motion.root, motion.fps) <= walk_own + 0.05
    sig, _ = synthesize_session(act, Protocol(), rng=seed, sites=("pelvis", "head"))
    a = np.linalg.norm(sig.meta["free_acc_raw"], axis=-1)
    start = int(round(Protocol().prefix * sig.fps))
    walking = a[start + int(sig.fps):]
    assert a[start - int(sig.fps): start + int(sig.fps)].max() <= walking.max()  # 113 m/s^2 before


def test_the_walk_protocol_joins_its_walk_and_stands_without_a_jolt():
    act, walk = generate("walk", seconds=5, seed=1), generate("walk", seconds=6, seed=0)
    motion = walk_session_motion(act, walk, WalkProtocol())
    worst = max(_largest_velocity_step(m.root, m.fps) for m in (act, walk))
    assert _largest_velocity_step(motion.root, motion.fps) <= worst + 0.05
    # the stands are still: the subject stops, stands, then starts
    (_, _), (_, walk_end), (_, stand_end) = motion.meta["walk_windows"]
    still = motion.root[walk_end:stand_end, :2]
    assert np.ptp(still, axis=0).max() < 1e-9
