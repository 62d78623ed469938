"""Gaussian diffusion for DiffusionPoser: cosine schedule, forward noising, respaced
x0-parameterised sampling and the inpainting loop of the paper's Algorithm 1.

Conventions
-----------
Diffusion levels are integers ``t`` in ``0..T`` (T = 1000). ``alpha_bar[0] == 1`` means
"clean" and ``alpha_bar[T]`` is ~0 ("pure noise"), so the paper's step list
1000/850/700/550/400/250/100/10/2/0 is used literally: its last step (t = 0) hands the
model an un-noised window and simply asks for one more x0 prediction, which is what the
paper does with its last step too. Training draws ``t`` uniformly from ``0..T`` as the
paper does (section 3.2.3).

The denoiser predicts x0 (not epsilon), so every sampler here is written in terms of the
predicted x0: no retraining is needed for any step list.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

T_DEFAULT = 1000

# Table 6, "10D": best root error, small cost in angle error and jitter.
PAPER_STEPS_10D: tuple[int, ...] = (1000, 850, 700, 550, 400, 250, 100, 10, 2, 0)


def cosine_alpha_bar(T: int = T_DEFAULT, s: float = 0.008, max_beta: float = 0.999) -> Tensor:
    """Cumulative signal fraction ``alpha_bar[t]`` for t = 0..T (float64, length T+1).

    Nichol & Dhariwal's cosine schedule: ``f(t) = cos(((t/T + s)/(1 + s)) * pi/2)^2``,
    ``alpha_bar = f(t)/f(0)``. Per-step betas are clipped to ``max_beta`` (as they do) so
    that the last level is not exactly zero noise-free signal, which would make the
    epsilon/x0 relation singular; the result stays strictly decreasing with
    ``alpha_bar[0] == 1``.
    """
    t = torch.arange(T + 1, dtype=torch.float64)
    f = torch.cos(((t / T + s) / (1 + s)) * math.pi / 2) ** 2
    ab = f / f[0]
    betas = (1 - ab[1:] / ab[:-1]).clamp(min=0.0, max=max_beta)
    out = torch.ones(T + 1, dtype=torch.float64)
    out[1:] = torch.cumprod(1 - betas, dim=0)
    return out


@dataclass
class Schedule:
    """A noise schedule; holds ``alpha_bar`` for t = 0..T and its square roots.

    Python float copies (``_sa``, ``_s1ma``) are kept for the inference loop: reading a
    scalar from a tensor per step costs more than the arithmetic it feeds on small CPU
    models.
    """

    alpha_bar: Tensor  # (T+1,) float64

    def __post_init__(self) -> None:
        self.alpha_bar = self.alpha_bar.to(torch.float64)
        self._sa = [math.sqrt(a) for a in self.alpha_bar.tolist()]
        self._s1ma = [math.sqrt(max(0.0, 1.0 - a)) for a in self.alpha_bar.tolist()]

    @classmethod
    def cosine(cls, T: int = T_DEFAULT) -> Schedule:
        return cls(cosine_alpha_bar(T))

    @property
    def T(self) -> int:
        return int(self.alpha_bar.shape[0]) - 1

    def sqrt_ab(self, t: int) -> float:
        return self._sa[t]

    def sqrt_1mab(self, t: int) -> float:
        return self._s1ma[t]

    def q_sample(self, x0: Tensor, t: Tensor | int, noise: Tensor | None = None,
                 generator: torch.Generator | None = None) -> Tensor:
        """Draw ``z_t ~ N(sqrt(ab_t) x0, (1 - ab_t) I)``.

        ``t`` is an int (same level for the batch) or a (B,) integer tensor (one level per
        batch element, as in training).
        """
        if noise is None:
            noise = torch.randn(x0.shape, generator=generator, dtype=x0.dtype, device=x0.device)
        if isinstance(t, int):
            return self._sa[t] * x0 + self._s1ma[t] * noise
        ab = self.alpha_bar.to(x0.device)[t].to(x0.dtype)
        shape = (-1,) + (1,) * (x0.dim() - 1)
        return ab.sqrt().view(shape) * x0 + (1 - ab).sqrt().view(shape) * noise


# --------------------------------------------------------------------- step lists

def paper_steps() -> list[int]:
    """The paper's irregular "10D" list: 1000/850/700/550/400/250/100/10/2/0."""
    return list(PAPER_STEPS_10D)


def paper_like_steps(k: int) -> list[int]:
    """``k`` (2..10) levels taken from the paper's 10D list, evenly by position, always
    keeping its first (1000: lets the model move dp away from the copied frame, the
    root-error gain of Table 6) and last (0) entries; for cutting steps to meet a CPU
    budget without losing the shape of 10D."""
    full = list(PAPER_STEPS_10D)
    if not 2 <= k <= len(full):
        raise ValueError(f"paper-like step lists have 2..{len(full)} steps, not {k}")
    idx = sorted({round(i * (len(full) - 1) / (k - 1)) for i in range(k)})
    return [full[i] for i in idx]


def even_steps(k: int, T: int = T_DEFAULT) -> list[int]:
    """``k`` evenly spaced levels from ``T`` down to 0 inclusive (distinct, descending).

    ``k == 1`` gives ``[T]`` only makes sense for pure generation; for inpainting prefer
    k >= 2 so that the final prediction comes from a low noise level.
    """
    if k < 1:
        raise ValueError("need at least one step")
    if k == 1:
        return [T]
    vals = [round(T - i * T / (k - 1)) for i in range(k)]
    out: list[int] = []
    for v in vals:
        if not out or v < out[-1]:
            out.append(int(v))
    return out


def parse_steps(spec: str | int | Sequence[int], T: int = T_DEFAULT) -> list[int]:
    """Parse a step specification as used on command lines.

    ``"paper"``/``"10D"`` -> the paper's list; ``"10D:K"`` -> ``paper_like_steps(K)``; an
    int or digit string K -> ``even_steps(K)``; a comma/slash separated list -> that list
    (validated).
    """
    if isinstance(spec, int):
        return even_steps(spec, T)
    if isinstance(spec, str):
        s = spec.strip()
        if s.lower() in ("paper", "10d"):
            return paper_steps()
        if s.lower().startswith(("10d:", "paper:")):
            return paper_like_steps(int(s.split(":", 1)[1]))
        if s.isdigit():
            return even_steps(int(s), T)
        spec = [int(v) for v in s.replace("/", ",").split(",") if v.strip()]
    steps = [int(v) for v in spec]
    validate_steps(steps, T)
    return steps


def validate_steps(steps: Sequence[int], T: int = T_DEFAULT) -> None:
    if not steps:
        raise ValueError("empty step list")
    if any(s < 0 or s > T for s in steps):
        raise ValueError(f"steps must lie in 0..{T}: {list(steps)}")
    if any(b >= a for a, b in zip(steps, steps[1:])):
        raise ValueError(f"steps must be strictly decreasing: {list(steps)}")


# --------------------------------------------------------------------- samplers

def _call(model, z: Tensor, t: int, height: Tensor, mask: Tensor | None = None,
          points: Tensor | None = None) -> Tensor:
    tt = torch.full((z.shape[0],), t, dtype=torch.long, device=z.device)
    if points is not None:  # a model with a position input (ModelConfig.points), which reads the mask too
        return model(z, tt, height, mask, points=points)
    if mask is not None:
        return model(z, tt, height, mask)
    return model(z, tt, height)


def wants_mask(model) -> bool:
    """Whether a denoiser reads the known/unknown mask (ModelConfig.mask_input)."""
    return bool(getattr(getattr(model, "config", None), "mask_input", False))


def sample(model, shape: tuple[int, ...], height: Tensor, steps: Sequence[int],
           schedule: Schedule | None = None, eta: float = 0.0,
           generator: torch.Generator | None = None) -> Tensor:
    """Unconditional generation over a respaced step list (x0-parameterised DDIM).

    Why DDIM: with an x0-predicting model, the DDIM update
    ``z_s = sqrt(ab_s) x0 + sqrt(1 - ab_s - sigma^2) eps_hat + sigma * noise`` is valid for
    any decreasing subsequence of levels, so one trained model serves every step list.
    ``eta = 0`` is deterministic (what we use for reproducible tests and benchmarks);
    ``eta = 1`` makes sigma equal the DDPM posterior std of the *respaced* betas, i.e. it
    is exactly ancestral DDPM sampling on the respaced chain.
    """
    schedule = schedule or Schedule.cosine()
    validate_steps(steps, schedule.T)
    with torch.inference_mode():
        z = torch.randn(shape, generator=generator)
        x0 = z
        for i, t in enumerate(steps):
            x0 = _call(model, z, t, height)
            s = steps[i + 1] if i + 1 < len(steps) else None
            if s is None:
                break
            z = ddim_step(schedule, z, x0, t, s, eta, generator)
        return x0


def ddim_step(schedule: Schedule, z: Tensor, x0: Tensor, t: int, s: int, eta: float = 0.0,
              generator: torch.Generator | None = None) -> Tensor:
    """Move ``z`` from level t to the lower level s given the predicted ``x0``."""
    ab_t = float(schedule.alpha_bar[t])
    ab_s = float(schedule.alpha_bar[s])
    if ab_t >= 1.0:
        return x0 * 1.0  # a new tensor (or numpy array: the live loop's ``_replace_ddim_mean_np`` calls this too)
    eps = (z - math.sqrt(ab_t) * x0) / math.sqrt(1 - ab_t)
    sigma = eta * math.sqrt(max(0.0, (1 - ab_s) / (1 - ab_t) * (1 - ab_t / ab_s)))
    out = math.sqrt(ab_s) * x0 + math.sqrt(max(0.0, 1 - ab_s - sigma**2)) * eps
    if sigma > 0:
        out = out + sigma * torch.randn(z.shape, generator=generator, dtype=z.dtype)
    return out


INPAINT_MODES = ("paper", "replace", "ddim", "replace-ddim")
INPAINT_STARTS = ("sample", "mean")


def inpaint(model, x_input: Tensor, mask: Tensor, height: Tensor, steps: Sequence[int],
            generator: torch.Generator | None = None, schedule: Schedule | None = None,
            mode: str = "paper", mask_input: bool | None = None, start: str = "sample",
            points: Tensor | None = None, start_at: Tensor | None = None) -> Tensor:
    """Inpaint the unobserved features of a window (the paper's Algorithm 1).

    x_input: (B, N, F) normalised features; unobserved entries hold an initial guess (the
    poser copies the previous frame there). mask: (B, N, F) bool, True = observed/known.
    height: (B,) metres. Returns (B, N, F); observed entries equal ``x_input`` exactly.

    ``mode="paper"`` (default) is Algorithm 1 verbatim: for each level t,
    ``z = q_sample(x, t)`` (fresh noise around the *current* estimate), ``x0 = f(z, t, h)``,
    ``x = m*x_input + (1-m)*x0``. Because every step re-noises the current estimate, the
    initial guess of the unobserved features feeds the first step, which is why the
    paper's high-noise start (10D) lets the model move dp away from the copied frame.
    ``mode="ddim"`` instead carries the latent with deterministic DDIM updates and
    re-noises only the known part (RePaint-style, without resampling); it is here for
    comparison in evaluation.
    ``mode="replace"`` is Algorithm 1 with the known entries left clean in ``z`` (only the
    current estimate of the unknown ones is re-noised), for models trained the same way
    (``TrainConfig.cond_prob``): the model then always sees the measurements exactly
    instead of a noisy copy of them, which a small CPU-trained model needs (docs/model.md, 'Inference').
    ``mode="replace-ddim"``: the same, but one noise draw at the first level and then
    deterministic DDIM updates of the unknown entries (no fresh noise per step), so the
    frame-to-frame randomness of the live output is one draw instead of one per step.

    ``start="mean"``: the first level's noised entries hold their mean ``sqrt(ab_t0) x`` (no
    draw; ~0 at t0 = T, the prior's mean): the unknown entries in the replacement modes, every
    entry in "paper" and "ddim". With a high first level (t0 = T) the first call then gives
    the model's estimate of the *mean* unknown features given the known ones, where a drawn
    start gives one sample whose error about the truth is larger wherever the measurements
    leave the pose open (arms with only the shanks worn: HDM05 dg, 2 sites, GA 35.5 -> 31.0
    deg; 6 sites 16.6 -> 15.7; docs/model.md, "Inference: steps, start, noise, mirror,
    history"). With the DDIM modes the whole run is then deterministic and draws nothing.
    ``start_at`` (F,) or broadcastable to (B, N, F), with ``start="mean"``: where the first
    level's draw sits instead of 0 (the prior's mean); ``symmetric_start`` gives the one start
    that is its own mirror image.

    ``mask_input``: hand the model the mask too (default: ``wants_mask(model)``; pass it
    for a traced model, which has no config). ``points`` (B or 1, N, 16): the tracked
    points' position input of a model that takes one (``ModelConfig.points``).

    One model call per step; per step cost beyond the model is a few elementwise ops.
    """
    schedule = schedule or Schedule.cosine()
    validate_steps(steps, schedule.T)
    if start not in INPAINT_STARTS:
        raise ValueError(f"unknown inpainting start {start!r} ({', '.join(INPAINT_STARTS)})")
    run_np = getattr(model, "run_np", None)
    if run_np is not None and mode == "replace-ddim" and start == "mean" and points is None:
        m_np = mask.numpy() if isinstance(mask, Tensor) else np.asarray(mask)
        use_mask = wants_mask(model) if mask_input is None else mask_input
        return torch.from_numpy(_replace_ddim_mean_np(
            run_np, x_input.detach().float().numpy(), m_np.astype(bool, copy=False),
            height.detach().float().numpy(), steps, schedule, use_mask,
            None if start_at is None else np.asarray(start_at, dtype=np.float32)))

    def draw(first: bool) -> Tensor:
        if first and start == "mean":
            zero = torch.zeros(x.shape, dtype=x.dtype)
            return zero if start_at is None else zero + torch.as_tensor(start_at, dtype=x.dtype)
        return torch.randn(x.shape, generator=generator, dtype=x.dtype)

    with torch.inference_mode():
        x_input = x_input.float()
        m = mask.to(dtype=torch.bool, device=x_input.device)
        height = height.to(x_input.dtype)
        mk = m if (wants_mask(model) if mask_input is None else mask_input) else None
        x = x_input
        if mode in ("paper", "replace"):
            for i, t in enumerate(steps):
                if t == 0:
                    z = x
                else:
                    z = schedule.sqrt_ab(t) * x + schedule.sqrt_1mab(t) * draw(i == 0)
                    if mode == "replace":
                        z = torch.where(m, x_input, z)
                x0 = _call(model, z, t, height, mk, points)
                x = torch.where(m, x_input, x0)
            return x
        if mode == "ddim":
            t0 = steps[0]
            z = schedule.sqrt_ab(t0) * x + schedule.sqrt_1mab(t0) * draw(True)
            for i, t in enumerate(steps):
                x0 = _call(model, z, t, height, mk, points)
                x = torch.where(m, x_input, x0)
                if i + 1 == len(steps):
                    break
                s = steps[i + 1]
                z = ddim_step(schedule, z, x, t, s)
                known = schedule.q_sample(x_input, s, generator=generator)
                z = torch.where(m, known, z)
            return x
        if mode == "replace-ddim":
            t0 = steps[0]
            z = torch.where(m, x_input, schedule.sqrt_ab(t0) * x + schedule.sqrt_1mab(t0) * draw(True))
            for i, t in enumerate(steps):
                x = torch.where(m, x_input, _call(model, z, t, height, mk, points))
                if i + 1 == len(steps):
                    break
                z = torch.where(m, x_input, ddim_step(schedule, z, x, t, steps[i + 1]))
            return x
        raise ValueError(f"unknown inpainting mode {mode!r} ({', '.join(INPAINT_MODES)})")


def _replace_ddim_mean_np(run, x_input: np.ndarray, mask: np.ndarray, height: np.ndarray, steps: Sequence[int],
                          schedule: Schedule, use_mask: bool, start_at: np.ndarray | None = None) -> np.ndarray:
    """``inpaint(mode="replace-ddim", start="mean")`` on numpy arrays, for a network that
    takes and gives numpy (``OnnxNet.run_np``: the live runtime). The same arithmetic as the
    torch loop; what it saves is per call: the tensors made and converted around a network
    that reads numpy anyway (~0.1-0.3 ms a call, three calls a live pose)."""
    x_input = np.ascontiguousarray(x_input, dtype=np.float32)
    mask = np.ascontiguousarray(mask)
    height = np.ascontiguousarray(height, dtype=np.float32)
    b = x_input.shape[0]
    z0 = np.float32(schedule.sqrt_ab(steps[0])) * x_input
    if start_at is not None:  # the draw's place at the first level (``inpaint``'s start_at)
        z0 = z0 + np.float32(schedule.sqrt_1mab(steps[0])) * start_at
    z = np.where(mask, x_input, z0)
    for i, t in enumerate(steps):
        x = np.where(mask, x_input, run(z, np.full(b, t, dtype=np.int64), height, mask if use_mask else None))
        if i + 1 == len(steps):
            return x
        z = np.where(mask, x_input, ddim_step(schedule, z, x, t, steps[i + 1]))  # float32 kept (Python scalars)
    raise AssertionError("unreachable: validate_steps refuses an empty step list")


def symmetric_start(norm_mean, norm_std) -> np.ndarray:
    """(F,) the mean start's symmetric midpoint in the normaliser's units: 1/2 (M(mu) - mu) / sigma,
    M the mirror image of a frame's features. The data mean (0 in these units) is not its own
    mirror image (some features move by a whole standard deviation), so a chain that starts
    there answers a symmetric body with a left/right bias; the default's mirror chains cancel
    it, one window does not (docs/model.md, "The fast model"). This start is its own mirror
    image: M(mu + sigma c) = mu + sigma c."""
    from inference.features.mirror import mirror_features

    mu = torch.as_tensor(np.asarray(norm_mean), dtype=torch.float32).reshape(1, 1, -1)
    sd = torch.as_tensor(np.asarray(norm_std), dtype=torch.float32).reshape(1, 1, -1)
    return (0.5 * (mirror_features(mu) - mu) / sd).reshape(-1).numpy()


def redraw(model, x_hat: Tensor, x_input: Tensor, mask: Tensor, height: Tensor, level: int, noise: Tensor,
           schedule: Schedule | None = None, mask_input: bool | None = None,
           points: Tensor | None = None) -> Tensor:
    """Other inpaintings near an answer: ``x_hat`` (B, N, F), normalised, re-noised to
    ``level`` with ``noise`` (B, N, F) and denoised by one model call, the known entries
    held at ``x_input`` throughout (as in ``mode="replace"``).

    Why not a fresh inpainting from pure noise: a model trained to start from the prior's
    mean at T (``TrainConfig.mean_start``) has never seen noise there, so its answers to a
    draw at T are not draws of its posterior. A middle level it was trained at is, and one
    call per draw keeps a per-frame spread affordable. Returns (B, N, F)."""
    schedule = schedule or Schedule.cosine()
    with torch.inference_mode():
        x_input = x_input.float()
        m = mask.to(dtype=torch.bool)
        z = torch.where(m, x_input, schedule.sqrt_ab(level) * x_hat.float() + schedule.sqrt_1mab(level) * noise)
        mk = m if (wants_mask(model) if mask_input is None else mask_input) else None
        return torch.where(m, x_input, _call(model, z, level, height.to(x_input.dtype), mk, points))


__all__ = [
    "T_DEFAULT", "PAPER_STEPS_10D", "Schedule", "cosine_alpha_bar", "paper_steps", "paper_like_steps",
    "even_steps", "redraw",
    "parse_steps", "validate_steps", "sample", "ddim_step", "inpaint", "wants_mask", "INPAINT_MODES",
    "INPAINT_STARTS", "symmetric_start",
]
