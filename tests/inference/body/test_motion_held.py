"""Motion.held: a movement with the subject standing still before and after it (training
augmentation for long stands, docs/real_signals.md)."""

import numpy as np
import pytest

from inference.body.body import npose_rotations
from inference.body.conventions import rot_z, yaw_of
from inference.evaluation.runner import synthetic_motion
from inference.signals.synthesis import kinematics


def test_held_freezes_the_end_frames():
    m = synthetic_motion(seconds=2.0, fps=60.0)
    h = m.held(0.5, 1.0)
    assert h.n_frames == m.n_frames + 30 + 60
    np.testing.assert_allclose(h.rot[:30], np.repeat(m.rot[:1], 30, 0))
    np.testing.assert_allclose(h.rot[30:30 + m.n_frames], m.rot)
    np.testing.assert_allclose(h.root[-60:], np.repeat(m.root[-1:], 60, 0))
    assert m.held() is m


def test_held_settles_into_an_npose_facing_the_pelvis_way():
    m = synthetic_motion(seconds=2.0, fps=60.0)
    h = m.held(0.0, 2.0, settle_s=0.5)
    assert h.n_frames == m.n_frames + 30 + 120
    end = h.rot[-1]
    want = rot_z(yaw_of(m.rot[-1, 0])) @ npose_rotations(1)[0]
    np.testing.assert_allclose(end, want, atol=1e-9)
    # standing still: no segment moves in the last second, the feet on the floor
    assert np.abs(np.diff(h.rot[-60:], axis=0)).max() < 1e-12
    k = kinematics(h)
    assert np.abs(k.site_acc_raw[-40:-5]).max() < 1e-6
    # the step into the stand is smooth: no frame turns a segment more than the walk itself does
    step = np.degrees(np.arccos(np.clip((np.einsum("tkij,tkij->tk", h.rot[1:], h.rot[:-1]) - 1) / 2, -1, 1)))
    walk = step[: m.n_frames - 1].max()
    assert step[m.n_frames - 1:].max() <= max(walk, 5.0)


def test_held_refuses_negative_lengths():
    m = synthetic_motion(seconds=1.0, fps=60.0)
    with pytest.raises(ValueError, match="negative"):
        m.held(-1.0, 0.0)
