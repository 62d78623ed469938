"""Metrics on hand-computed cases (definitions in inference/metrics/errors.py)."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.body import Body, forward_kinematics
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.metrics.errors import (
    EVAL_SEGMENTS,
    ClipMetrics,
    evaluate_clip,
    global_angle_error,
    jitter,
    joint_position_error,
    local_angle_error,
    paired_difference,
    root_error,
    summarize,
)

Z = np.array([0.0, 0.0, 1.0])


def _identity(T: int = 3) -> np.ndarray:
    return np.broadcast_to(np.eye(3), (T, N_SEGMENTS, 3, 3)).copy()


def test_eighteen_segments_are_evaluated():
    assert len(EVAL_SEGMENTS) == 18
    for name in ("l_toes", "r_toes", "l_hand", "r_hand", "l_fingers", "r_fingers"):
        assert SEGMENT_INDEX[name] not in EVAL_SEGMENTS


def test_global_angle_one_segment_and_excluded_segment():
    Rt = _identity()
    Rp = _identity()
    Rp[:, SEGMENT_INDEX["head"]] = matrix_about_axis(Z, np.pi / 2)  # 90 deg on 1 of 18 segments
    Rp[:, SEGMENT_INDEX["l_hand"]] = matrix_about_axis(Z, 1.0)  # excluded: no effect
    np.testing.assert_allclose(global_angle_error(Rp, Rt), 90.0 / 18, atol=1e-9)


def test_local_vs_global_angle():
    Rt = _identity()
    # turn the whole body 30 deg: every global orientation is off, only the root's local one
    Rp = np.broadcast_to(matrix_about_axis(Z, np.deg2rad(30.0)), Rt.shape).copy()
    np.testing.assert_allclose(global_angle_error(Rp, Rt), 30.0, atol=1e-9)
    np.testing.assert_allclose(local_angle_error(Rp, Rt), 30.0 / 18, atol=1e-9)
    # turn the left leg from the hip: thigh, shank, foot (toes excluded) globally, hip locally
    Rp = _identity()
    for n in ("l_thigh", "l_shank", "l_foot", "l_toes"):
        Rp[:, SEGMENT_INDEX[n]] = matrix_about_axis(Z, np.deg2rad(30.0))
    np.testing.assert_allclose(global_angle_error(Rp, Rt), 3 * 30.0 / 18, atol=1e-9)
    np.testing.assert_allclose(local_angle_error(Rp, Rt), 30.0 / 18, atol=1e-9)


def test_joint_position_error_is_root_relative():
    body = Body.from_height(1.75)
    R = _identity(2)
    jt = forward_kinematics(R, np.zeros((2, 3)), body.offsets)
    jp = jt + np.array([3.0, -1.0, 0.5])  # translated: no error
    np.testing.assert_allclose(joint_position_error(jp, jt), 0.0, atol=1e-12)
    jp = jt.copy()
    jp[:, SEGMENT_INDEX["head"]] += [0.23, 0.0, 0.0]  # one of 23 joints off by 23 cm
    np.testing.assert_allclose(joint_position_error(jp, jt), 0.01, atol=1e-12)


def test_jitter_of_a_cubic():
    fps = 20.0
    t = np.arange(10) / fps
    j = np.zeros((10, 4, 3))
    j[:, 2, 0] = 2.0 * t**3  # third derivative 12 m/s^3, exact for finite differences
    np.testing.assert_allclose(jitter(j, fps), 12.0 / 4, rtol=1e-9)
    assert jitter(j[:3], fps).shape == (0,)


def test_root_error_over_horizons():
    fps = 20.0
    T = 101  # 5 s
    rt = np.zeros((T, 3))
    rt[:, 0] = np.arange(T) / fps * 1.5  # walks 1.5 m/s
    rp = np.zeros((T, 3))
    rp[:, 2] = 7.0  # height never counts
    e2 = root_error(rp, rt, 2, fps)
    assert e2.shape == (T - 40,)
    np.testing.assert_allclose(e2, 3.0)
    np.testing.assert_allclose(root_error(rt + [5.0, -2.0, 0.0], rt, 5, fps), 0.0, atol=1e-12)
    assert root_error(rp, rt, 10, fps) is None


def test_summary_pools_frames_and_reports_none():
    fps = 20.0
    T1, T2 = 50, 150
    Rt1, Rt2 = _identity(T1), _identity(T2)
    Rp1 = Rt1.copy()
    Rp1[:, SEGMENT_INDEX["head"]] = matrix_about_axis(Z, np.pi / 2)  # GA 5 deg on clip 1
    rng = np.random.default_rng(0)
    j1 = np.cumsum(rng.normal(size=(T1, 24, 3)), 0) * 0.01
    j2 = np.cumsum(rng.normal(size=(T2, 24, 3)), 0) * 0.01
    r1, r2 = np.zeros((T1, 3)), np.zeros((T2, 3))
    c1 = evaluate_clip("a", Rp1, r1, j1, Rt1, r1, j1, fps)
    c2 = evaluate_clip("b", Rt2, r2, 2 * j2, Rt2, r2, j2, fps)
    s = summarize([c1, c2])
    assert s["clips"] == 2 and s["frames"] == 200
    assert s["ga_deg"] == pytest.approx(5.0 * T1 / (T1 + T2))
    assert s["re2_m"] == pytest.approx(0.0)
    assert s["re5_m"] == pytest.approx(0.0)  # only clip b (7.5 s) is long enough
    assert s["re10_m"] is None
    jr = (c1.jitter_pred_sum + c2.jitter_pred_sum) / (c1.jitter_true_sum + c2.jitter_true_sum)
    assert s["jitter_ratio"] == pytest.approx(jr)
    assert 1.0 < s["jitter_ratio"] < 2.0
    empty = summarize([])
    assert empty["ga_deg"] is None and empty["jitter_ratio"] is None and empty["frames"] == 0


def _clips(ga_per_frame, frames, prefix="c") -> list[ClipMetrics]:
    """Clip metrics with the given per-clip mean GA (deg) and lengths; other sums zero."""
    return [ClipMetrics(f"{prefix}{k}", int(n), float(g) * int(n), 0.0, 0.0, 0.0, 0.0, 0)
            for k, (g, n) in enumerate(zip(ga_per_frame, frames, strict=True))]


def test_paired_difference_of_a_constant_offset_is_exact():
    frames = np.arange(20, 80)
    ga = np.linspace(10.0, 40.0, len(frames))
    a, b = _clips(ga, frames), _clips(ga + 2.0, frames)
    d = paired_difference(a, b)
    assert d.difference == pytest.approx(-2.0)
    assert (d.low, d.high) == pytest.approx((-2.0, -2.0))
    assert d.decided and d.a_lower == len(frames) and d.clips == len(frames)
    same = paired_difference(a, a)
    assert same.difference == 0.0 and not same.decided and same.a_lower == 0


def test_paired_interval_covers_the_lead_with_the_width_the_clip_sample_allows():
    rng = np.random.default_rng(3)
    widths = {}
    for n in (60, 240):
        frames = rng.integers(20, 60, n)
        hard = rng.uniform(10.0, 50.0, n)  # clip difficulty, shared by both models
        lead = 1.0 + rng.normal(0.0, 3.0, n)  # B worse than A by 1 deg on average, clip to clip sd 3
        d = paired_difference(_clips(hard, frames), _clips(hard + lead, frames))
        pooled = -np.sum(lead * frames) / np.sum(frames)
        assert d.difference == pytest.approx(pooled)
        assert d.low < pooled < d.high
        widths[n] = d.high - d.low
    # a mean over n clips: the interval is about 2 x 1.96 x 3 / sqrt(n) wide, and halves with 4x the clips
    assert 0.9 < widths[60] < 2.4
    assert 1.5 < widths[60] / widths[240] < 2.7


def test_pairing_removes_the_clip_difficulty_from_the_interval():
    """Two models 0.5 deg apart on every clip, on clips from 5 to 60 deg: paired, the lead is
    certain; resampling the models' clips independently would bury it in the spread."""
    rng = np.random.default_rng(0)
    n = 60
    frames = rng.integers(20, 60, n)
    hard = rng.uniform(5.0, 60.0, n)
    d = paired_difference(_clips(hard, frames), _clips(hard + 0.5 + rng.normal(0, 0.1, n), frames))
    assert d.decided and d.high < -0.4 and d.low > -0.6


def test_paired_difference_rejects_unpaired_clips_and_pooled_ratios():
    a = _clips([10.0, 12.0], [30, 40])
    with pytest.raises(ValueError, match="same clips"):
        paired_difference(a, _clips([10.0, 12.0], [30, 41]))
    with pytest.raises(ValueError, match="same clips"):
        paired_difference(a, _clips([10.0, 12.0], [30, 40], prefix="x"))
    with pytest.raises(ValueError, match="per-frame"):
        paired_difference(a, a, metric="jitter_ratio")


def test_ga_is_also_given_over_the_frames_whose_truth_a_body_can_make():
    from inference.body.body import tpose
    from inference.body.rotations import axis_angle_to_matrix
    from inference.body.skeleton import SEGMENT_INDEX

    T = 10
    R_true = tpose(T)
    R_true[6:, SEGMENT_INDEX["r_foot"]] = axis_angle_to_matrix(np.array([0.0, np.pi, 0.0]))  # solver's flip
    R_pred = tpose(T)  # a model that keeps the foot where a foot can be
    z = np.zeros((T, 3))
    j = np.zeros((T, 24, 3))
    cm = evaluate_clip("c", R_pred, z, j, R_true, z, j, fps=20.0)
    s = summarize([cm])
    assert cm.implausible == 4 and s["implausible_truth_share"] == pytest.approx(0.4)
    assert s["ga_deg"] == pytest.approx(0.4 * 180.0 / len(EVAL_SEGMENTS))
    assert s["ga_deg_plausible_truth"] == pytest.approx(0.0, abs=1e-6)


def test_paired_block_difference_resamples_whole_blocks_and_names_bad_input():
    """Blocks of 40 frames, the last one shorter; a constant difference has nothing to
    resample; series of different lengths are refused."""
    from inference.metrics.errors import paired_block_difference

    a = np.linspace(5.0, 9.0, 90)
    d = paired_block_difference(a + 0.5, a, 40)
    assert d.clips == 3 and d.difference == pytest.approx(0.5) and d.low == d.high == pytest.approx(0.5)
    noisy = paired_block_difference(a + np.random.default_rng(0).normal(0, 1, 90), a, 10)
    assert noisy.clips == 9 and noisy.low < noisy.difference < noisy.high
    with pytest.raises(ValueError, match="same"):
        paired_block_difference(a, a[:-1], 40)
