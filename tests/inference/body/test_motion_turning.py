"""Motion.turning: a movement with the whole body turning about the vertical, its path bent
to match (training augmentation for turns on the spot, docs/model.md)."""

import numpy as np

from inference.body.conventions import yaw_of
from inference.evaluation.runner import synthetic_motion


def test_turning_turns_every_segment_by_the_heading_reached():
    m = synthetic_motion(seconds=2.0, fps=60.0)
    t = m.turning(90.0)
    turned = np.degrees(np.unwrap(yaw_of(t.rot[:, 0])) - np.unwrap(yaw_of(m.rot[:, 0])))
    np.testing.assert_allclose(turned, 90.0 * m.times, atol=1e-6)
    # the body's own shape is kept: each segment relative to the pelvis as before
    rel = np.einsum("tji,tsjk->tsik", t.rot[:, 0], t.rot)
    rel0 = np.einsum("tji,tsjk->tsik", m.rot[:, 0], m.rot)
    np.testing.assert_allclose(rel, rel0, atol=1e-9)
    assert t.meta["turning_deg_s"] == 90.0


def test_turning_bends_the_path_keeping_its_speed_and_height():
    m = synthetic_motion(seconds=4.0, fps=60.0)
    t = m.turning(120.0)
    step, step0 = np.diff(t.root, axis=0), np.diff(m.root, axis=0)
    np.testing.assert_allclose(np.linalg.norm(step[:, :2], axis=1), np.linalg.norm(step0[:, :2], axis=1), atol=1e-9)
    np.testing.assert_allclose(t.root[:, 2], m.root[:, 2])
    np.testing.assert_allclose(t.root[0], m.root[0])
    # a path that went somewhere now circles: it ends nearer its start than the straight one
    went = np.linalg.norm(m.root[-1, :2] - m.root[0, :2])
    assert went > 3.0
    assert np.linalg.norm(t.root[-1, :2] - t.root[0, :2]) < 0.25 * went
    # a step's direction turned by the heading at its start
    k = len(step) // 2
    a = np.arctan2(step[k, 1], step[k, 0]) - np.arctan2(step0[k, 1], step0[k, 0])
    assert np.linalg.norm(step0[k, :2]) > 1e-3
    assert np.isclose(np.angle(np.exp(1j * (a - np.radians(120.0) * m.times[k]))), 0.0, atol=1e-6)
