"""An MVN take's segments as motion (``inference.loaders.mvnx``): the body and posture MVN
stored come back as ours, a skipped frame keeps the clock, and a take that is not a full
body is named."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.motion import MotionFormatError
from inference.body.rotations import matrix_angle_between
from inference.loaders import load_motion
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate
from sim_devices.xsens_export import write_mvnx

LABELS = {"pelvis": "Pelvis", "r_shank": "RightLowerLeg"}


@pytest.fixture(scope="module")
def walk():
    return generate("walk", seconds=3.0, heading_deg=35.0)


def _take(motion, path, **kw):
    sig = synthesize(motion, NoiseModel(), rng=3, sites=tuple(LABELS))
    return write_mvnx(sig, path, LABELS, motion=motion, **kw)


def test_the_suits_posture_and_body_come_back_as_ours(walk, tmp_path):
    m = load_motion(_take(walk, tmp_path / "walk.mvnx"))
    assert m.fps == walk.fps and m.n_frames == walk.n_frames and m.meta["layout"] == "mvn23"
    assert m.meta["first_index"] == 0 and m.meta["held"] == 0
    assert np.degrees(matrix_angle_between(m.rot, walk.rot)).max() < 0.01  # every segment, every frame
    assert np.allclose(m.body.offsets, walk.body.offsets, atol=1e-5)
    assert np.allclose(m.root - m.root[0], walk.root - walk.root[0], atol=1e-3)
    feet = m.joints()[:, [7, 8], 2]  # l_foot, r_foot joints (ankles): on the floor's side of the knees
    assert feet.min() > -0.01 and feet.min() < 0.15 and 1.6 < m.body.height < 1.9


def test_a_frame_mvn_left_out_holds_the_one_before_so_the_clock_stays(walk, tmp_path):
    m = load_motion(_take(walk, tmp_path / "gap.mvnx", drop=[50, 51]))
    assert m.n_frames == walk.n_frames and m.meta["held"] == 2
    assert np.allclose(m.rot[50], m.rot[49]) and np.allclose(m.rot[52], walk.rot[52], atol=1e-5)


def test_a_take_without_the_whole_body_is_named(walk, tmp_path):
    sig = synthesize(walk, NoiseModel(), rng=3, sites=tuple(LABELS))
    path = write_mvnx(sig, tmp_path / "sensors_only.mvnx", LABELS)  # no segments but the sensors'
    with pytest.raises(MotionFormatError, match="not a full-body MVN take: no segment"):
        load_motion(path)


def test_a_take_missing_most_of_its_frames_is_refused(walk, tmp_path):
    """Holding frames over a gap keeps the clock; a take whose indices span far more frames
    than it holds (a damaged index) is named instead of filled."""
    with pytest.raises(MotionFormatError, match="more than half the take is missing"):
        load_motion(_take(walk, tmp_path / "holes.mvnx", drop=range(10, 170)))
