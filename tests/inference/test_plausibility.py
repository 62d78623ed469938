from __future__ import annotations

import numpy as np
import pytest

from inference.body import Body, tpose
from inference.dataset import FeatureDataset, motion_to_features
from inference.motion import Motion
from inference.plausibility import ankle_angles, implausible_feature_frames, implausible_frames
from inference.rotations import axis_angle_to_matrix
from inference.skeleton import SEGMENT_INDEX
from inference.splits import drop_implausible_clips


def squat_then_flipped_foot(T: int = 120, flip_from: int = 90) -> Motion:
    """Shanks tilting forward 40 deg with the feet flat (a deep squat's ankles), then the
    right foot turned 180 deg about its lateral axis from frame ``flip_from`` on (what HDM05's
    solver wrote in bd's kick clips)."""
    R = tpose(T)
    tilt = np.radians(40.0) * np.sin(np.linspace(0, np.pi, T))
    shank = axis_angle_to_matrix(np.stack([np.zeros(T), tilt, np.zeros(T)], -1))
    for s in ("l_shank", "r_shank"):
        R[:, SEGMENT_INDEX[s]] = shank
    flip = axis_angle_to_matrix(np.array([0.0, np.pi, 0.0]))
    R[flip_from:, SEGMENT_INDEX["r_foot"]] = flip
    root = np.tile([0.0, 0.0, 0.9], (T, 1))
    return Motion(rot=R, root=root, fps=60.0, body=Body.from_height(1.7), name="squat_flip")


def test_a_deep_squat_passes_and_a_flipped_foot_does_not():
    m = squat_then_flipped_foot()
    ang = ankle_angles(m.rot)
    assert ang[:90].max() == pytest.approx(40.0, abs=0.5)  # the squat: feet flat, shanks at 40 deg
    assert ang[90:, 1].min() > 140.0 and ang[90:, 0].max() < 41.0  # flip combined with the shank's tilt
    bad = implausible_frames(m.rot)
    assert not bad[:90].any() and bad[90:].all()


def test_the_check_reads_feature_rows_too():
    m = squat_then_flipped_foot()
    x = motion_to_features(m)  # 20 Hz: frame 90 at 60 Hz is row 30
    bad = implausible_feature_frames(x)
    assert not bad[:30].any() and bad[30:].all()


def test_training_split_never_draws_a_clip_with_an_implausible_frame():
    good = Motion(rot=tpose(120), root=np.tile([0.0, 0.0, 0.9], (120, 1)), fps=60.0,
                  body=Body.from_height(1.7), name="standing")
    ds = FeatureDataset.from_motions([good, squat_then_flipped_foot(), good], names=["a", "flip", "b"])
    assert drop_implausible_clips(ds) == ["flip"]
    assert ds.weights[1] == 0.0 and ds.weights.sum() == pytest.approx(1.0)
    drawn = np.concatenate([ds.sample(np.random.default_rng(k), 8, 61)["clip"] for k in range(20)])
    assert set(drawn.tolist()) == {0, 2}
    with pytest.raises(ValueError, match="nothing left"):
        drop_implausible_clips(FeatureDataset.from_motions([squat_then_flipped_foot()], names=["flip"]))
