"""The causal (trailing) acceleration filter of the low-latency mode: it reads no future
sample, streaming equals batch, and adding it left the centred filter as it was."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from inference.signals.resample import (
    STEP,
    StreamingResampler,
    acc_filter_of,
    downsample,
    moving_average,
)


def _digest(x: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(x).tobytes()).hexdigest()


def _golden_input() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1234)
    acc = rng.normal(size=(97, 13, 3)) * 4
    acc[[3, 40, 41, 96]] = np.nan
    return acc, rng.normal(size=(97, 5))


def test_centred_filter_is_bit_identical_to_before_the_causal_option():
    """Digests of the centred outputs computed with the resampler as it was before the
    causal option existed (batch, every-sample and streaming)."""
    acc, rest = _golden_input()
    a, _ = downsample(acc, rest)
    s = StreamingResampler()
    frames = []
    for i in range(acc.shape[0]):
        frames += s.push(acc[i], rest[i], t=i / 60)
    frames += s.flush()
    assert _digest(a) == "137710de0877ef4a1439b398b768334789bc4f33fc784cb0f1ceda12901f6d6d"
    assert _digest(moving_average(acc)) == "8b99e64e77e9f6b031316d9eb664c373a7b39a93141ceca2c8d7eb4f22ac6cae"
    assert _digest(np.stack([f.acc for f in frames])) == _digest(a)


@settings(max_examples=30, deadline=None)
@given(T=st.integers(12, 60), k=st.integers(0, 59), seed=st.integers(0, 10_000))
def test_causal_output_ignores_every_later_sample(T, k, seed):
    """Change one sample: every output before it is unchanged (batch and streaming)."""
    k = k % T
    rng = np.random.default_rng(seed)
    acc = rng.normal(size=(T, 4, 3))
    changed = acc.copy()
    changed[k] = rng.normal(size=(4, 3)) * 100
    changed[min(k + 1, T - 1):] = np.nan  # and everything after it goes missing
    for step in (1, STEP):
        before = moving_average(acc, step, causal=True)
        after = moving_average(changed, step, causal=True)
        n = len(range(0, k, step))  # outputs standing for samples < k
        np.testing.assert_array_equal(after[:n], before[:n])
        if k % step == 0 and k + 1 < T:
            assert not np.array_equal(after[n], before[n])  # the sample itself does count


def test_causal_streaming_emits_with_the_frame_own_sample():
    r = StreamingResampler(causal=True)
    ready_at = [i for i in range(20) if r.push(np.zeros(3), t=i / 60)]
    assert ready_at == [0, 3, 6, 9, 12, 15, 18]  # frame k leaves when sample 3k is in: no look-ahead
    assert r.flush() == []  # nothing is ever left waiting


@settings(max_examples=30, deadline=None)
@given(T=st.integers(1, 45), seed=st.integers(0, 10_000), nan_frac=st.sampled_from([0.0, 0.2]))
def test_causal_streaming_equals_batch_bit_for_bit(T, seed, nan_frac):
    rng = np.random.default_rng(seed)
    acc = rng.normal(size=(T, 13, 3)) * 5
    acc[rng.random(T) < nan_frac] = np.nan
    rest = rng.normal(size=(T, 7))
    a_b, r_b = downsample(acc, rest, causal=True)
    r = StreamingResampler(causal=True)
    frames = []
    for i in range(T):
        frames += r.push(acc[i], rest[i], t=i / 60)
    frames += r.flush()
    assert [f.index for f in frames] == list(range(len(range(0, T, STEP))))
    np.testing.assert_array_equal(np.stack([f.acc for f in frames]), a_b)
    np.testing.assert_array_equal(np.stack([f.rest for f in frames]), r_b)
    assert [f.t for f in frames] == [i / 60 for i in range(0, T, STEP)]  # stamped with its own sample


def test_causal_values_edges_and_missing():
    x = np.arange(30.0)[:, None]
    ma = moving_average(x, causal=True)
    np.testing.assert_allclose(ma[10:, 0], x[10:, 0] - 5)  # a ramp lags by 5 samples: same smoothing, trailing
    assert ma[0, 0] == 0.0  # front padded with the first sample
    assert ma[3, 0] == pytest.approx(sum(range(4)) / 11)
    y = np.arange(20.0)[:, None].repeat(3, 1)
    y[12] = np.nan
    out = moving_average(y, causal=True)
    assert np.isnan(out[12]).all()  # missing only where its own sample is
    assert out[13, 0] == pytest.approx(np.mean([v for v in range(3, 14) if v != 12]))


def test_acc_filter_of_model_meta():
    assert acc_filter_of(None) == "centred"
    assert acc_filter_of({"default_steps": "10D:3"}) == "centred"  # files from before the option
    assert acc_filter_of({"acc_filter": "causal"}) == "causal"
    assert acc_filter_of({"train_config": {"causal": True}}) == "causal"
    with pytest.raises(ValueError):
        acc_filter_of({"acc_filter": "sideways"})
