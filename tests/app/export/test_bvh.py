"""BVH export: our own loader reads the file back to the same motion."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from app.export.bvh import BVH_NAMES, bvh_text, write_motion_bvh
from inference.body.body import Body
from inference.body.rotations import matrix_angle_between
from inference.evaluation.runner import synthetic_motion
from inference.loaders import load_motion
from inference.metrics.errors import global_angle_error


def _motion(body: Body):
    m = synthetic_motion(seconds=1.5, fps=30.0, height=body.height, turn_deg_per_s=40.0, seed=2)
    return replace(m, body=body).floor_aligned()


def test_round_trip_same_orientations_and_positions(tmp_path):
    m = _motion(Body.from_height(1.72))
    path = write_motion_bvh(tmp_path / "clip.bvh", m)
    back = load_motion(path)
    assert back.n_frames == m.n_frames and abs(back.fps - m.fps) < 1e-6
    assert back.meta["units"] == "m" and back.meta["skeleton"] == "cmu31"
    ang = np.rad2deg(matrix_angle_between(back.rot, m.rot))
    assert ang.max() < 0.1, ang.max()
    assert global_angle_error(back.rot, m.rot).max() < 0.1
    assert np.abs(back.joints() - m.joints()).max() < 1e-3


def test_round_trip_of_a_retargeted_body(tmp_path):
    """A body whose bones come from another skeleton (here: ours, exported and read back
    once) survives a second round trip unchanged."""
    m = _motion(Body.from_height(1.6))
    once = load_motion(write_motion_bvh(tmp_path / "a.bvh", m))
    twice = load_motion(write_motion_bvh(tmp_path / "b.bvh", once))
    assert np.abs(twice.joints() - once.joints()).max() < 1e-3
    assert np.rad2deg(matrix_angle_between(twice.rot, once.rot)).max() < 0.1


def test_file_layout():
    m = _motion(Body.from_height(1.72))
    text = bvh_text(m.rot[:3], m.root[:3], m.body, 20.0)
    lines = text.splitlines()
    assert lines[0] == "HIERARCHY" and lines[1] == "ROOT Hips"
    assert "Frames: 3" in lines and "Frame Time: 0.050000000000" in lines
    for name in BVH_NAMES.values():
        assert f" {name}" in text
    data = lines[lines.index("Frames: 3") + 2:]
    assert len(data) == 3 and all(len(r.split()) == 6 + 23 * 3 for r in data)
    # Y up: the root's second channel is the pelvis height
    assert abs(float(data[0].split()[1]) - m.root[0, 2]) < 1e-5
