"""Per-frame latency of the live inpainting loop on this CPU, for several model sizes,
step counts and speed levers (threads, TorchScript freezing, torch.compile, int8 dynamic
quantisation).

One live frame = one ``diffusion.inpaint`` call on a (1, 61, 190) window whose first 60
frames are known and whose last frame is observed at the paper's 6 sites, with K model
calls. Weights are random: latency does not depend on their values.

    .venv/bin/python benchmarks/bench_model.py                  # the default grid
    .venv/bin/python benchmarks/bench_model.py --quick --json   # a few rows, JSON lines

The machine is shared, so every row is measured after a warm-up, over up to --frames
frames or --budget seconds, and reported as p50 / p99 / min with the 1-minute load
average at the end of the row: min is what the hardware can do, p50/p99 what it did
under that load.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from inference.features.layout import N_FEATURES, WINDOW, observation_mask  # noqa: E402
from inference.model.config import ModelConfig, count_parameters  # noqa: E402
from inference.model.denoiser import Denoiser, freeze_for_cpu  # noqa: E402
from inference.model.diffusion import even_steps, inpaint, paper_like_steps  # noqa: E402

SIX = ["pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank"]


@dataclass
class Case:
    size: tuple[int, int, int]  # layers, d_model, ff
    steps: int
    threads: int
    lever: str = "eager"  # eager | script | compile | int8 | bf16

    @property
    def name(self) -> str:
        layers, d, ff = self.size
        return f"{layers}/{d}/{ff} K={self.steps} thr={self.threads} {self.lever}"


class _BF16(torch.nn.Module):
    """bfloat16 weights and activations (AVX512-BF16 on this CPU), float32 at the edges so
    the inpainting loop is unchanged."""

    def __init__(self, m: torch.nn.Module) -> None:
        super().__init__()
        self.m = m

    def forward(self, z, t, h):
        return self.m(z.to(torch.bfloat16), t, h.to(torch.bfloat16)).float()


def make_model(size: tuple[int, int, int], lever: str) -> torch.nn.Module:
    layers, d, ff = size
    cfg = ModelConfig(layers=layers, d_model=d, heads=max(1, d // 64), ff=ff, dropout=0.0)
    torch.manual_seed(0)
    m = Denoiser(cfg).eval()
    if lever == "bf16":
        m = _BF16(m.to(torch.bfloat16))
    elif lever == "int8":
        m = torch.ao.quantization.quantize_dynamic(m, {torch.nn.Linear}, dtype=torch.qint8)
    elif lever == "script":
        m = freeze_for_cpu(m)
    elif lever == "compile":
        m = torch.compile(m, dynamic=False)
    return m


def window(seed: int = 0) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    x = torch.randn(1, WINDOW, N_FEATURES, generator=g)
    mask = torch.ones(1, WINDOW, N_FEATURES, dtype=torch.bool)
    mask[:, -1] = torch.as_tensor(observation_mask(SIX))
    return x, mask, torch.tensor([1.75])


def steps_for(k: int) -> list[int]:
    return paper_like_steps(k) if 2 <= k <= 10 else even_steps(k)


def time_frames(model, k: int, n: int, gen: torch.Generator, budget_s: float = float("inf")) -> list[float]:
    x, mask, h = window()
    steps = steps_for(k)
    out: list[float] = []
    t_end = time.perf_counter() + budget_s
    while len(out) < n and (len(out) < 5 or time.perf_counter() < t_end):
        t0 = time.perf_counter()
        inpaint(model, x, mask, h, steps, generator=gen)
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def measure(case: Case, frames: int, warmup: int, budget_s: float, model=None) -> dict:
    """p50/p99 per-frame latency of one case (builds the model unless given)."""
    m = model if model is not None else make_model(case.size, case.lever)
    torch.set_num_threads(case.threads)
    gen = torch.Generator().manual_seed(0)
    time_frames(m, case.steps, warmup, gen)
    a = np.array(time_frames(m, case.steps, frames, gen, budget_s))
    params = count_parameters(m) if case.lever in ("eager", "int8") else None
    return {
        "model": "/".join(map(str, case.size)), "steps": case.steps, "threads": case.threads, "lever": case.lever,
        "p50_ms": round(float(np.percentile(a, 50)), 2), "p99_ms": round(float(np.percentile(a, 99)), 2),
        "min_ms": round(float(a.min()), 2), "per_step_ms": round(float(np.percentile(a, 50)) / case.steps, 2),
        "frames": len(a), "params_M": round(params / 1e6, 2) if params else None,
        "load1": round(os.getloadavg()[0], 2),
    }


def default_cases(quick: bool) -> list[Case]:
    if quick:
        return [Case((4, 128, 512), 10, 1), Case((2, 128, 512), 5, 1), Case((8, 512, 2048), 30, 1)]
    cases: list[Case] = []
    for size, ks in [((2, 128, 512), (5, 10, 30)), ((3, 128, 512), (5, 10)), ((4, 128, 512), (5, 10, 30)),
                     ((2, 256, 1024), (5, 10)), ((4, 256, 1024), (5, 10)), ((4, 512, 2048), (10,)),
                     ((8, 512, 2048), (10, 30))]:
        cases += [Case(size, k, 1) for k in ks]
    for size in [(2, 128, 512), (4, 128, 512), (4, 256, 1024)]:
        cases.append(Case(size, 10, 2))
        for lever in ("script", "int8", "bf16", "compile"):
            cases.append(Case(size, 10, 1, lever))
    return cases


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--frames", type=int, default=200, help="timed frames per row (at most)")
    ap.add_argument("--budget", type=float, default=20.0, help="seconds per row (at least 5 frames)")
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--levers", default="eager,script,int8,bf16,compile", help="subset of levers to include")
    ap.add_argument("--json", action="store_true", help="JSON lines instead of a table")
    args = ap.parse_args(argv)
    levers = set(args.levers.split(","))
    cases = [c for c in default_cases(args.quick) if c.lever in levers]
    if not args.json:
        print("| model L/d/FF | steps | threads | lever | p50 ms | p99 ms | min ms | ms/step | frames | params M "
              "| load |")
        print("|---|---|---|---|---|---|---|---|---|---|---|", flush=True)
    for c in cases:
        t0 = time.perf_counter()
        m = make_model(c.size, c.lever)
        build = time.perf_counter() - t0
        r = measure(c, args.frames, args.warmup, args.budget, model=m)
        if c.lever in ("script", "compile"):
            r["build_s"] = round(build, 1)
        if args.json:
            print(json.dumps(r), flush=True)
        else:
            print(f"| {r['model']} | {r['steps']} | {r['threads']} | {r['lever']} | {r['p50_ms']} | {r['p99_ms']} "
                  f"| {r['min_ms']} | {r['per_step_ms']} | {r['frames']} | {r['params_M'] or '-'} | {r['load1']} |",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
