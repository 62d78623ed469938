"""60 -> 20 Hz resampling: streaming equals batch exactly; irregular timestamps to the grid."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from inference.body.conventions import heading_of
from inference.body.rotations import axis_angle_to_quat, quat_to_matrix
from inference.signals.resample import STEP, StreamingResampler, downsample, moving_average, to_grid


def _stream(acc: np.ndarray, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[int]]:
    r = StreamingResampler()
    frames = []
    for i in range(acc.shape[0]):
        out = r.push(acc[i], rest[i], t=i / 60)
        assert len(out) <= 1
        frames += out
    frames += r.flush()
    return (np.stack([f.acc for f in frames]), np.stack([f.rest for f in frames]), [f.index for f in frames])


@settings(max_examples=40, deadline=None)
@given(T=st.integers(1, 45), seed=st.integers(0, 10_000), nan_frac=st.sampled_from([0.0, 0.2]))
def test_streaming_equals_batch_bit_for_bit(T, seed, nan_frac):
    rng = np.random.default_rng(seed)
    acc = rng.normal(size=(T, 13, 3)) * 5
    acc[rng.random(T) < nan_frac] = np.nan  # dropped samples
    rest = rng.normal(size=(T, 24, 6))
    a_b, r_b = downsample(acc, rest)
    a_s, r_s, idx = _stream(acc, rest)
    assert idx == list(range(len(idx)))
    assert a_s.shape == a_b.shape == (len(range(0, T, STEP)), 13, 3)
    np.testing.assert_array_equal(a_s, a_b)  # identical, NaN where the centre is missing
    np.testing.assert_array_equal(r_s, r_b)


def test_streaming_latency_is_five_samples():
    r = StreamingResampler()
    ready_at = []
    for i in range(20):
        if r.push(np.zeros(3)):
            ready_at.append(i)
    assert ready_at == [5, 8, 11, 14, 17]  # frame k (sample 3k) leaves when sample 3k+5 is in


def test_moving_average_values_and_edges():
    x = np.arange(30.0)[:, None]
    ma = moving_average(x)
    np.testing.assert_allclose(ma[5:-5, 0], x[5:-5, 0])  # linear ramp: centred mean is exact inside
    # edge: replicate padding -> frame 0 averages five copies of x0 and x0..x5
    assert ma[0, 0] == pytest.approx((5 * 0 + sum(range(6))) / 11)
    np.testing.assert_allclose(moving_average(np.full((7, 2), 3.5)), 3.5)


def test_to_grid_interpolates_and_marks_gaps():
    rng = np.random.default_rng(0)
    # a device at ~100 Hz with jitter, a 0.3 s dropout in the middle
    t = np.cumsum(0.01 + 0.002 * rng.random(300)) + 0.0123
    t = t[(t < 1.0) | (t > 1.3)]
    omega = 2.0
    quat = axis_angle_to_quat(np.stack([np.zeros_like(t), np.zeros_like(t), omega * t], -1))
    acc = np.stack([t, 2 * t, -t], -1)
    tg, qg, ag, valid = to_grid(t, quat, acc, fps=60, max_gap=0.1)
    np.testing.assert_allclose(np.diff(tg), 1 / 60, atol=1e-12)
    assert abs(tg[0] * 60 - round(tg[0] * 60)) < 1e-9 and tg[0] >= t[0]
    gap = (tg > t[t < 1.0][-1]) & (tg < t[t > 1.3][0])
    assert not valid[gap].any() and valid[~gap].all()
    assert np.isnan(qg[gap]).all() and np.isnan(ag[gap]).all()
    np.testing.assert_allclose(ag[valid], np.stack([tg, 2 * tg, -tg], -1)[valid], atol=1e-12)
    # slerp of a constant-rate rotation is exact
    R = quat_to_matrix(qg[valid])
    ang = heading_of(R[:, :2, 0])
    np.testing.assert_allclose(np.unwrap(ang), omega * tg[valid], atol=1e-9)


def test_to_grid_rejects_bad_timestamps():
    with pytest.raises(ValueError):
        to_grid(np.array([0.0, 0.0]), np.zeros((2, 4)) + [1, 0, 0, 0], np.zeros((2, 3)))
