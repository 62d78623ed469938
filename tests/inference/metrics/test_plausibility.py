from __future__ import annotations

import numpy as np
import pytest

from inference.body.body import Body, tpose
from inference.body.motion import Motion
from inference.body.rotations import axis_angle_to_matrix, matrix_about_axis
from inference.body.skeleton import SEGMENT_INDEX
from inference.metrics.plausibility import (
    REPAIR_MARGIN_S,
    ankle_angles,
    implausible_feature_frames,
    implausible_frames,
    repair_feet,
)
from inference.training.dataset import FeatureDataset, motion_to_features
from inference.training.splits import drop_implausible_clips


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


def squat(T: int = 120) -> Motion:
    m = squat_then_flipped_foot(T, flip_from=T)
    # the toes bent up 20 deg against the foot, so keeping their own rotation shows
    m.rot[:, SEGMENT_INDEX["r_toes"]] = m.rot[:, SEGMENT_INDEX["r_foot"]] @ axis_angle_to_matrix(
        np.array([0.0, -np.radians(20.0), 0.0]))
    return m


def test_a_foot_turned_half_a_turn_about_its_own_bone_is_turned_back():
    good = squat()
    bad = squat()
    toes = SEGMENT_INDEX["r_toes"]
    bone = good.body.offsets[toes] / np.linalg.norm(good.body.offsets[toes])
    half = matrix_about_axis(bone, np.pi)
    for seg in ("r_foot", "r_toes"):  # the toes ride along, as the solver wrote them
        i = SEGMENT_INDEX[seg]
        bad.rot[:, i] = good.rot[:, SEGMENT_INDEX["r_foot"]] @ half @ good.rot[:, SEGMENT_INDEX["r_foot"]].swapaxes(
            -1, -2) @ good.rot[:, i]
    assert implausible_frames(bad.rot).all()
    np.testing.assert_allclose(bad.joints(), good.joints(), atol=1e-9)  # invisible in joint positions

    fixed, report = repair_feet(bad)
    assert report.twisted == len(bad.rot) and report.interpolated == 0 and report.left_broken == 0
    np.testing.assert_allclose(fixed.rot, good.rot, atol=1e-9)


def test_a_brief_failure_is_interpolated_from_the_plausible_frames_around_it():
    good = squat()
    bad = squat()
    foot = SEGMENT_INDEX["r_foot"]
    flip = axis_angle_to_matrix(np.array([0.0, np.pi, 0.0]))  # no twist about the bone undoes this
    bend = good.rot[0, foot].T @ good.rot[0, SEGMENT_INDEX["r_toes"]]
    bad.rot[50:60, foot] = flip
    bad.rot[50:60, SEGMENT_INDEX["r_toes"]] = flip @ bend
    assert implausible_frames(bad.rot)[50:60].all()

    fixed, report = repair_feet(bad)
    margin = round(REPAIR_MARGIN_S * bad.fps)
    lo, hi = 50 - margin, 60 + margin
    assert report.interpolated == hi - lo and report.twisted == 0
    assert not implausible_frames(fixed.rot).any()
    # everything outside the stretch and its margin, and every other segment, is untouched
    keep = np.ones(len(bad.rot), dtype=bool)
    keep[lo:hi] = False
    np.testing.assert_array_equal(fixed.rot[keep], bad.rot[keep])
    others = [i for i in range(fixed.rot.shape[1]) if i not in (foot, SEGMENT_INDEX["r_toes"])]
    np.testing.assert_array_equal(fixed.rot[:, others], bad.rot[:, others])
    # the ankle inside moves smoothly between its neighbours' values: the squat's own ankle
    # is within a few degrees of the repair
    ang = ankle_angles(fixed.rot)[:, 1]
    assert np.abs(np.diff(ang[lo - 1:hi + 1])).max() < 2.0
    np.testing.assert_allclose(ang[lo:hi], ankle_angles(good.rot)[lo:hi, 1], atol=2.5)  # linear in a curve
    # the toes keep their bend against the foot
    rel = fixed.rot[:, foot].swapaxes(-1, -2) @ fixed.rot[:, SEGMENT_INDEX["r_toes"]]
    np.testing.assert_allclose(rel[lo:hi], np.broadcast_to(rel[0], rel[lo:hi].shape), atol=1e-9)


def test_a_clip_broken_throughout_is_reported_and_left_as_it_is():
    bad = squat_then_flipped_foot(60, flip_from=0)
    fixed, report = repair_feet(bad)
    assert report.left_broken == 60 and report.changed == 0
    np.testing.assert_array_equal(fixed.rot, bad.rot)
    plain = squat()
    same, none = repair_feet(plain)
    assert none.changed == 0 and none.left_broken == 0
    np.testing.assert_array_equal(same.rot, plain.rot)
