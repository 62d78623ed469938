"""Schedule, noising, step lists and the inpainting loop (paper Algorithm 1)."""

from __future__ import annotations

import pytest
import torch

from inference.model.diffusion import (
    PAPER_STEPS_10D,
    Schedule,
    cosine_alpha_bar,
    even_steps,
    inpaint,
    paper_steps,
    parse_steps,
    sample,
    validate_steps,
)


class Oracle(torch.nn.Module):
    """Predicts a fixed x0 whatever the input: a perfect denoiser for that target."""

    def __init__(self, x0: torch.Tensor) -> None:
        super().__init__()
        self.x0 = x0
        self.calls: list[int] = []

    def forward(self, z, t, h):
        assert z.shape == self.x0.shape and t.shape == (z.shape[0],) and h.shape == (z.shape[0],)
        self.calls.append(int(t[0]))
        return self.x0.clone()


class Mean(torch.nn.Module):
    def forward(self, z, t, h):
        return z.mean(dim=1, keepdim=True).expand_as(z) * 0.5


def test_cosine_schedule_endpoints_and_monotone():
    ab = cosine_alpha_bar(1000)
    assert ab.shape == (1001,)
    assert ab[0] == 1.0
    assert ab[-1] < 1e-4
    assert torch.all(ab[1:] < ab[:-1])
    assert torch.all(ab > 0)
    s = Schedule.cosine()
    assert s.T == 1000
    assert s.sqrt_ab(0) == 1.0 and s.sqrt_1mab(0) == 0.0


def test_q_sample_statistics():
    s = Schedule.cosine()
    g = torch.Generator().manual_seed(0)
    x0 = torch.full((20000, 4), 2.0)
    for t in (0, 100, 500, 900):
        z = s.q_sample(x0, t, generator=g)
        ab = float(s.alpha_bar[t])
        assert abs(z.mean().item() - 2.0 * ab**0.5) < 0.02
        assert abs(z.std().item() - (1 - ab) ** 0.5) < 0.02
    # per-element levels (training)
    t = torch.tensor([0, 1000])
    z = s.q_sample(torch.ones(2, 3), t, noise=torch.zeros(2, 3))
    assert torch.allclose(z[0], torch.ones(3))
    assert z[1].abs().max() < 0.01


def test_step_lists():
    assert paper_steps() == [1000, 850, 700, 550, 400, 250, 100, 10, 2, 0] == list(PAPER_STEPS_10D)
    for k in (2, 5, 10, 30, 100, 1001):
        st = even_steps(k)
        assert len(st) == k and st[0] == 1000 and st[-1] == 0
        validate_steps(st)
    assert even_steps(1) == [1000]
    assert parse_steps("paper") == paper_steps()
    assert parse_steps("10") == even_steps(10)
    assert parse_steps(5) == even_steps(5)
    assert parse_steps("100,10,0") == [100, 10, 0]
    assert parse_steps("10D:10") == paper_steps()
    assert parse_steps("10d:5") == [1000, 700, 400, 10, 0]
    assert parse_steps("paper:2") == [1000, 0]
    for k in range(2, 11):
        st = parse_steps(f"10D:{k}")
        assert len(st) == k and st[0] == 1000 and st[-1] == 0 and set(st) <= set(PAPER_STEPS_10D)
    with pytest.raises(ValueError):
        parse_steps("10,100")
    with pytest.raises(ValueError):
        validate_steps([1001, 0])


def _window(seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(2, 61, 190, generator=g)
    mask = torch.rand(2, 61, 190, generator=g) < 0.5
    mask[:, :60] = True
    return x, mask


@pytest.mark.parametrize("mode", ["paper", "replace", "ddim"])
def test_inpaint_keeps_observed_exactly(mode):
    x, mask = _window()
    out = inpaint(Mean(), x, mask, torch.full((2,), 1.7), paper_steps(), generator=torch.Generator().manual_seed(1),
                  mode=mode)
    assert out.shape == x.shape
    assert torch.equal(out[mask], x[mask])
    assert not torch.equal(out[~mask], x[~mask])


@pytest.mark.parametrize("mode", ["paper", "replace", "ddim"])
def test_inpaint_with_perfect_denoiser_recovers_target(mode):
    x, mask = _window()
    target = torch.randn_like(x)
    oracle = Oracle(target)
    out = inpaint(oracle, x, mask, torch.full((2,), 1.7), [1000, 500, 10, 0], mode=mode)
    assert oracle.calls == [1000, 500, 10, 0]  # one model call per step, in order
    assert torch.equal(out[~mask], target[~mask])
    assert torch.equal(out[mask], x[mask])


class Recorder(torch.nn.Module):
    """Keeps every z it is called with; predicts zeros."""

    def __init__(self) -> None:
        super().__init__()
        self.seen: list[tuple[int, torch.Tensor]] = []

    def forward(self, z, t, h):
        self.seen.append((int(t[0]), z.clone()))
        return torch.zeros_like(z)


@pytest.mark.parametrize("mode", ["paper", "replace"])
def test_replace_mode_shows_the_model_clean_measurements(mode):
    x, mask = _window()
    rec = Recorder()
    inpaint(rec, x, mask, torch.ones(2), [1000, 400, 10, 0], generator=torch.Generator().manual_seed(0), mode=mode)
    for t, z in rec.seen:
        clean = torch.equal(z[mask], x[mask])
        # replace: known entries exact at every level; paper (Algorithm 1): noised except at t = 0
        assert clean == (mode == "replace" or t == 0), (mode, t)
        if t > 0:
            assert not torch.equal(z[~mask], torch.zeros_like(z[~mask]))  # unknowns are re-noised


@pytest.mark.parametrize("mode", ["paper", "replace", "ddim", "replace-ddim"])
def test_mean_start_shows_the_first_level_no_noise(mode):
    """start="mean": the first call sees sqrt(ab_T) x in the unknown entries (the prior's mean
    around the current guess, no draw); later levels of the re-noising modes still draw."""
    x, mask = _window()
    sched = Schedule.cosine()
    rec = Recorder()
    gen = torch.Generator().manual_seed(0)
    inpaint(rec, x, mask, torch.ones(2), [1000, 400, 0], generator=gen, mode=mode, start="mean")
    t0, z0 = rec.seen[0]
    assert t0 == 1000
    assert torch.allclose(z0[~mask], sched.sqrt_ab(1000) * x[~mask])
    t1, z1 = rec.seen[1]
    renoised = mode in ("paper", "replace")
    assert (not torch.allclose(z1[~mask], torch.zeros(()).expand_as(z1[~mask]), atol=1e-3)) == renoised, mode
    # a drawn start differs from the mean start at the first level
    rec2 = Recorder()
    inpaint(rec2, x, mask, torch.ones(2), [1000, 400, 0], generator=torch.Generator().manual_seed(0), mode=mode)
    assert not torch.allclose(rec2.seen[0][1][~mask], z0[~mask])
    with pytest.raises(ValueError, match="inpainting start"):
        inpaint(rec, x, mask, torch.ones(2), [1000, 0], mode=mode, start="median")


def test_mean_start_ddim_is_deterministic_without_a_generator():
    x, mask = _window()
    a = inpaint(Mean(), x, mask, torch.ones(2), [1000, 400, 0], mode="replace-ddim", start="mean")
    torch.manual_seed(123)
    b = inpaint(Mean(), x, mask, torch.ones(2), [1000, 400, 0], mode="replace-ddim", start="mean")
    assert torch.equal(a, b)


def test_inpaint_reproducible_with_generator_and_inference_mode():
    x, mask = _window()
    a = inpaint(Mean(), x, mask, torch.ones(2), even_steps(5), generator=torch.Generator().manual_seed(3))
    b = inpaint(Mean(), x, mask, torch.ones(2), even_steps(5), generator=torch.Generator().manual_seed(3))
    assert torch.equal(a, b)
    assert a.is_inference()


def test_sample_ddim_deterministic_oracle():
    target = torch.randn(3, 61, 190)
    out = sample(Oracle(target), target.shape, torch.ones(3), even_steps(6), generator=torch.Generator().manual_seed(0))
    assert torch.allclose(out, target)
