from __future__ import annotations

import numpy as np
import torch

from inference.poser.smoothing import OneEuroConfig, VectorOneEuro, smoothing_gain


def _run(f: VectorOneEuro, xs: np.ndarray) -> np.ndarray:
    return np.stack([f(torch.as_tensor(x)).numpy() for x in xs])


def test_gain_is_a_first_order_low_pass():
    # cutoff at the Nyquist-ish end passes almost everything, a tiny cutoff almost nothing
    assert float(smoothing_gain(1000.0, 0.05)) > 0.99
    assert float(smoothing_gain(0.01, 0.05)) < 0.01
    dt, fc = 0.05, 2.0
    tau = 1 / (2 * np.pi * fc)
    assert abs(float(smoothing_gain(fc, dt)) - 1 / (1 + tau / dt)) < 1e-6


def test_constant_passes_and_steps_converge_without_overshoot():
    f = VectorOneEuro(20.0)
    xs = np.concatenate([np.zeros((5, 3)), np.ones((60, 3))])
    ys = _run(f, xs)
    np.testing.assert_allclose(ys[:5], 0.0)
    assert 0.0 < ys[5, 0] < 1.0  # the jump is smoothed...
    assert np.all(np.diff(ys[5:, 0]) >= 0) and ys.max() <= 1.0 + 1e-12  # ...monotonically
    np.testing.assert_allclose(ys[-1], 1.0, atol=1e-3)  # and reached


def test_noise_is_reduced_and_fast_motion_lags_less_than_a_fixed_filter():
    rng = np.random.default_rng(0)
    n = 400
    still = rng.normal(scale=0.005, size=(n, 3))
    ys = _run(VectorOneEuro(20.0), still)
    third = lambda a: np.linalg.norm(np.diff(a, 3, axis=0), axis=1).mean()  # noqa: E731
    assert third(ys) < 0.3 * third(still)
    # a fast ramp (2 m/s): the adaptive cutoff trails it less than the same filter with beta 0
    t = np.arange(n)[:, None] / 20.0
    ramp = np.concatenate([2.0 * t, np.zeros((n, 2))], axis=1)
    lag_adaptive = (ramp - _run(VectorOneEuro(20.0, OneEuroConfig(beta=0.5)), ramp))[-1, 0]
    lag_fixed = (ramp - _run(VectorOneEuro(20.0, OneEuroConfig(beta=0.0)), ramp))[-1, 0]
    assert 0.0 < lag_adaptive < 0.8 * lag_fixed


def test_reset_restarts_from_the_next_sample():
    f = VectorOneEuro(20.0)
    _run(f, np.zeros((10, 2)))
    f.reset()
    np.testing.assert_allclose(f(torch.tensor([3.0, -1.0], dtype=torch.float64)).numpy(), [3.0, -1.0])


def test_rotation_filter_smooths_unmeasured_and_passes_measured():
    from inference.body.rotations import so3_exp, so3_log
    from inference.poser.smoothing import RotationOneEuro

    rng = np.random.default_rng(1)
    n = 200
    base = so3_exp(torch.as_tensor(rng.normal(size=(2, 3))))
    wobble = so3_exp(torch.as_tensor(rng.normal(scale=0.02, size=(n, 2, 3))))  # ~1 deg noise
    Rs = base[None] @ wobble
    f = RotationOneEuro(20.0)
    keep = torch.tensor([False, True])
    out = torch.stack([f(R, keep) for R in Rs])
    torch.testing.assert_close(out[:, 1], Rs[:, 1])  # measured: untouched
    err_in = so3_log(base[0].T @ Rs[20:, 0]).norm(dim=-1).mean()
    err_out = so3_log(base[0].T @ out[20:, 0]).norm(dim=-1).mean()
    assert err_out < 0.6 * err_in
    # still valid rotations
    eye = torch.eye(3, dtype=out.dtype).expand(n, 3, 3)
    torch.testing.assert_close(out[:, 0].transpose(-1, -2) @ out[:, 0], eye)
    # a steady turn is followed, not stopped: after settling it trails by a bounded angle
    turn = so3_exp(torch.tensor([[0.0, 0.0, 0.1]], dtype=torch.float64) * torch.arange(n, dtype=torch.float64)[:, None])
    f = RotationOneEuro(20.0)
    out = torch.stack([f(R[None])[0] for R in turn])
    lag = so3_log(out[-1].T @ turn[-1]).norm()
    assert 0.0 < float(lag) < 0.15
