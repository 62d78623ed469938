"""Per-frame latency of the live inpainting loop on this CPU, for several model sizes,
step counts and speed levers (threads, TorchScript freezing, torch.compile, int8 dynamic
quantisation).

One live frame = one ``diffusion.inpaint`` call on a (1, 61, 190) window whose first 60
frames are known and whose last frame is observed at the paper's 6 sites, with K model
calls. Weights are random: latency does not depend on their values.

    .venv/bin/python benchmarks/bench_model.py                  # the default grid
    .venv/bin/python benchmarks/bench_model.py --quick --json   # a few rows, JSON lines

The machine is shared, so every row is measured after a warm-up, over many frames, and
reported as p50 / p99; rows are interleaved per repetition rather than run back to back so
a burst of load from elsewhere smears over all rows instead of hitting one.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from inference.denoiser import Denoiser, ModelConfig, count_parameters  # noqa: E402
from inference.diffusion import even_steps, inpaint, paper_steps  # noqa: E402
from inference.features import N_FEATURES, WINDOW, observation_mask  # noqa: E402

SIX = ["pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank"]


@dataclass
class Case:
    size: tuple[int, int, int]  # layers, d_model, ff
    steps: int
    threads: int
    lever: str = "eager"  # eager | script | compile | int8

    @property
    def name(self) -> str:
        layers, d, ff = self.size
        return f"{layers}/{d}/{ff} K={self.steps} thr={self.threads} {self.lever}"


def make_model(size: tuple[int, int, int], lever: str) -> torch.nn.Module:
    layers, d, ff = size
    cfg = ModelConfig(layers=layers, d_model=d, heads=max(1, d // 64), ff=ff, dropout=0.0)
    torch.manual_seed(0)
    m = Denoiser(cfg).eval()
    if lever == "int8":
        m = torch.ao.quantization.quantize_dynamic(m, {torch.nn.Linear}, dtype=torch.qint8)
    elif lever == "script":
        z = torch.zeros(1, WINDOW, N_FEATURES)
        with torch.no_grad():
            m = torch.jit.freeze(torch.jit.trace(m, (z, torch.zeros(1, dtype=torch.long), torch.ones(1))))
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
    return paper_steps() if k == 10 else even_steps(k)


def time_frames(model, k: int, n: int, gen: torch.Generator) -> list[float]:
    x, mask, h = window()
    steps = steps_for(k)
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        inpaint(model, x, mask, h, steps, generator=gen)
        out.append((time.perf_counter() - t0) * 1e3)
    return out


def run(cases: list[Case], frames: int, reps: int, warmup: int) -> list[dict]:
    models: dict[tuple, torch.nn.Module] = {}
    samples: dict[str, list[float]] = {c.name: [] for c in cases}
    gen = torch.Generator().manual_seed(0)
    for c in cases:
        key = (c.size, c.lever)
        if key not in models:
            t0 = time.perf_counter()
            models[key] = make_model(c.size, c.lever)
            if c.lever in ("compile", "script"):
                print(f"# {c.size} {c.lever}: built in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        torch.set_num_threads(c.threads)
        time_frames(models[key], c.steps, warmup, gen)
    for _ in range(reps):
        for c in cases:
            torch.set_num_threads(c.threads)
            samples[c.name] += time_frames(models[(c.size, c.lever)], c.steps, max(1, frames // reps), gen)
    rows = []
    for c in cases:
        a = np.array(samples[c.name])
        m = models[(c.size, c.lever)]
        params = count_parameters(m) if c.lever in ("eager", "int8") else None
        rows.append({
            "model": "/".join(map(str, c.size)), "steps": c.steps, "threads": c.threads, "lever": c.lever,
            "p50_ms": round(float(np.percentile(a, 50)), 2), "p99_ms": round(float(np.percentile(a, 99)), 2),
            "per_step_ms": round(float(np.percentile(a, 50)) / c.steps, 2), "frames": len(a),
            "params_M": round(params / 1e6, 2) if params else None,
        })
    return rows


def default_cases(quick: bool) -> list[Case]:
    if quick:
        return [Case((4, 256, 1024), 10, 2), Case((2, 256, 1024), 10, 2), Case((8, 512, 2048), 30, 2)]
    cases: list[Case] = []
    for size in [(2, 128, 512), (2, 256, 1024), (3, 256, 1024), (4, 256, 1024), (4, 512, 2048), (8, 512, 2048)]:
        for k in (5, 10, 30) if size != (8, 512, 2048) else (10, 30):
            cases.append(Case(size, k, 2))
    for size in [(2, 256, 1024), (4, 256, 1024)]:
        cases.append(Case(size, 10, 1))
        for lever in ("script", "int8", "compile"):
            cases.append(Case(size, 10, 2, lever))
    return cases


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--frames", type=int, default=200, help="timed frames per row")
    ap.add_argument("--reps", type=int, default=4, help="interleaved repetitions")
    ap.add_argument("--warmup", type=int, default=10)
    ap.add_argument("--levers", default="eager,script,int8,compile", help="subset of levers to include")
    ap.add_argument("--json", action="store_true", help="JSON lines instead of a table")
    args = ap.parse_args(argv)
    levers = set(args.levers.split(","))
    cases = [c for c in default_cases(args.quick) if c.lever in levers]
    rows = run(cases, args.frames, args.reps, args.warmup)
    if args.json:
        for r in rows:
            print(json.dumps(r))
        return 0
    print("| model L/d/FF | steps | threads | lever | p50 ms | p99 ms | ms/step | params M |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['model']} | {r['steps']} | {r['threads']} | {r['lever']} | {r['p50_ms']} | {r['p99_ms']} "
              f"| {r['per_step_ms']} | {r['params_M'] if r['params_M'] is not None else '-'} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
