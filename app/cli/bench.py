"""`imucap bench`: per-frame latency of the live loop (``Poser.step``: shift, inpaint,
root correction, FK) with the live default ("auto": at the bench's 6 sites the 21-frame int8
file; ``--model diffusion`` for the full model) and its steps, and of the paper-size model
(8 layers / 512 / FF 2048, 30 steps, random weights: latency does not depend on their
values) measured in the same run, so the two figures share the machine's load.

    imucap bench [--json] [--frames N] [--paper-frames N] [--threads N] [--model SPEC]
                 [--steps K] [--random-weights] [--no-paper] [--mirror/--no-mirror] [--no-onnx]
    imucap bench --sizes L/D/FF[,...] [--json] [--frames N] [--model SPEC] [--no-onnx]
    imucap bench --end-to-end [--json] [--seconds S] [--rounds R] [--model SPEC]

``onnx_p50_ms``/``onnx_p99_ms``: the same loop with the model call through ONNX Runtime
(when installed; what live sessions then use), right after the torch figures.
``reference``: the default step and the live settings it replaced (a 61-frame window, 3 steps
1000 / 400 / 0, mirror averaging: 6 network passes a pose) stepped in turn on the same frames
through the live runtime, with ``ratio_p50`` / ``ratio_p99`` (default over reference) and each
side's ``passes_per_pose``, window, steps and runtime: a ratio from one run, comparable between machines.
``variants``: the model call on torch and ONNX Runtime, on 1 and 2 intra-op threads, and with
the linear layers in int8 (ONNX Runtime's dynamic quantizer, torch's ``quantize_dynamic``),
all stepped in turn on the same frames, each row's p50 / p99 as a ratio to plain torch and its
poses' difference from torch's (``mean_deg``, ``max_deg``; ``--no-variants`` skips it).
``--sizes``: which larger denoiser would fit the live budget (the full model unless ``--model`` names
another): the loop with the model's own
settings (steps, mirror averaging, runtime) but random weights of each size, all stepped in
turn with the model itself, each row's p50 also as a ratio to it.
``stages``: the step split into the observation, the window's shift, the model call and the work after
it, each frame's thread CPU time (p50 ms), with the sum outside the model call.
``--end-to-end``: sensor-to-pose latency of the whole live path in both latency modes in
one run (``centred_p50_ms``, ``low_p50_ms``, ...; app/capture/end_to_end_bench.py, docs/latency.md).

The input is a generated walking clip observed at the paper's 6 sites, fed one 20 Hz frame
at a time, after a warm-up. benchmarks/bench_poser.py calls the same function. When the
poser mirror-averages (the model file says so, or ``--mirror``), the same loop without it
is timed too, under ``without_mirror``, so its cost is a ratio from one run. Beside the wall
times (``p50_ms``, ``p99_ms``), ``cpu_p50_ms`` / ``cpu_p99_ms`` are the stepping thread's
own CPU time, which a busy machine's waits do not inflate. The loop with
the per-segment spread on (``inference/poser/confidence.py``, its default settings) is
timed under ``confidence`` (a diffusion model only; ``--no-confidence`` skips it).
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from app.capture.setup_file import DEFAULT_MODEL
from app.cli.bench_loop import STAGES, interleaved_times, stage_times, walk_input


def bench_poser(model, steps=None, frames: int = 200, warmup: int = 10, label: str = "",
                seed: int = 0, mirror: bool | None = None, confidence=None, runtime: str = "torch") -> dict:
    """Time ``frames`` calls of ``Poser.step`` (after ``warmup`` untimed ones) for a
    LoadedModel (or None: the floor baseline). Returns p50_ms, p99_ms, mean_ms, max_ms,
    steps (model calls per frame), model, frames, threads, mirror (mirror averaging: each
    call a batch of two windows; None = the model file's own setting); ``confidence``
    goes to the poser (its settings are then reported too); ``runtime``: the model call's
    (``inference/model/onnx_runtime.py``: "torch" or "onnx")."""
    import torch

    from inference.poser.poser import Poser

    motion, inp = walk_input(frames + warmup, seed)
    poser = Poser(model, body=motion.body, steps=steps, seed=seed, mirror=mirror, confidence=confidence,
                  runtime=runtime)
    n = inp.features.shape[0]
    for i in range(warmup):
        poser.step(inp.features[i % n], inp.mask[i % n])
    times = np.empty(frames)
    cpu = np.empty(frames)
    for i in range(frames):
        k = (warmup + i) % n
        t0, c0 = time.perf_counter(), time.thread_time()
        poser.step(inp.features[k], inp.mask[k])
        times[i], cpu[i] = time.perf_counter() - t0, time.thread_time() - c0
    ms = times * 1e3
    kind = poser.kind
    return {
        "p50_ms": round(float(np.percentile(ms, 50)), 3), "p99_ms": round(float(np.percentile(ms, 99)), 3),
        # the thread's own CPU time: what the step costs, without the waits of a shared machine
        "cpu_p50_ms": round(float(np.percentile(cpu * 1e3, 50)), 3),
        "cpu_p99_ms": round(float(np.percentile(cpu * 1e3, 99)), 3),
        "mean_ms": round(float(ms.mean()), 3), "max_ms": round(float(ms.max()), 3),
        "steps": len(poser.steps) if kind == "diffusion" else (1 if kind == "regressor" else 0),
        "passes_per_pose": passes_per_pose(poser), "window": getattr(poser, "window", None),
        "model": label or kind, "frames": int(frames), "threads": torch.get_num_threads(),
        "mirror": poser.mirror, "runtime": poser.runtime, "int8": poser.int8,
        **({"draws": c.draws, "every": c.every, "pool": c.pool, "level": c.level}
           if (c := poser.confidence) is not None else {}),
    }


def bench_stages(model, steps=None, frames: int = 200, warmup: int = 10, seed: int = 0,
                 mirror: bool | None = None) -> dict:
    """The live step split into ``STAGES`` (``stage_times``, ONNX Runtime for the model call where
    live sessions take it): each stage's p50 thread CPU time (``<stage>_p50_ms``), and the
    p50 of the step's work outside the model call (``outside_model_p50_ms``)."""
    from inference.poser.poser import Poser

    motion, inp = walk_input(frames + warmup, seed)
    p = Poser(model, body=motion.body, steps=steps, seed=seed, mirror=mirror, runtime="auto")
    t = stage_times({"live": p}, inp, frames, warmup)["live"]
    out: dict = {f"{s}_p50_ms": round(float(np.median(t[f"{s}_cpu"])), 3) for s in STAGES}
    rest = sum(t[f"{s}_cpu"] for s in STAGES if s != "model")
    out.update(outside_model_p50_ms=round(float(np.median(rest)), 3), runtime=p.runtime, frames=int(frames),
               clock="thread CPU")
    return out


def bench_runtimes(model, steps=None, frames: int = 200, warmup: int = 10, seed: int = 0,
                   mirror: bool | None = None) -> dict:
    """``Poser.step`` with the model call on torch and on ONNX Runtime, the two posers
    stepped in turn on the same frames (``interleaved_times``). Returns torch_/onnx_ p50_ms,
    p99_ms and the speed-up of the medians."""
    from inference.poser.poser import Poser

    motion, inp = walk_input(frames + warmup, seed)
    posers = {rt: Poser(model, body=motion.body, steps=steps, seed=seed, mirror=mirror, runtime=rt)
              for rt in ("torch", "onnx")}
    ms = interleaved_times(posers, inp, frames, warmup)
    out: dict = {"frames": int(frames), "interleaved": True}
    for rt, v in ms.items():
        out[f"{rt}_p50_ms"] = round(float(np.percentile(v, 50)), 3)
        out[f"{rt}_p99_ms"] = round(float(np.percentile(v, 99)), 3)
    out["speedup_p50"] = round(out["torch_p50_ms"] / out["onnx_p50_ms"], 3)
    return out


VARIANTS = ("torch", "torch-2t", "onnx", "onnx-2t", "onnx-int8", "torch-int8")

# The live settings the 1-step sampler replaced (docs/latency.md, "Fewer passes"): a 61-frame
# window, the paper-like 3 levels 1000 / 400 / 0, whole-chain mirror averaging; 6 network
# passes per pose. ``bench_reference`` times them beside the default in one run.
REFERENCE_WINDOW = 61
REFERENCE_STEPS = "10D:3"
# ... and the network that made them: 4 layers, width 128, FF 512, 4 heads. A model of another
# size (a narrower student) is timed against a network of this size, so its ratio is to the
# shipped model's cost and not to its own weights run the old way
REFERENCE_SIZE = {"layers": 4, "d_model": 128, "ff": 512, "heads": 4}


def passes_per_pose(poser) -> int:
    """Windows the network evaluates per pose: one per step, two with mirror averaging
    (the pair goes in one call of batch 2, but it is twice the arithmetic)."""
    if poser.kind != "diffusion":
        return 1 if poser.kind == "regressor" else 0
    return len(poser.steps) * (2 if poser.mirror else 1)


def reference_model(model, spec=None, window: int = REFERENCE_WINDOW):
    """``model`` reading ``window`` frames: from its file again (``spec``) when it was trained
    on that many, so the reference is exactly the model the settings describe; otherwise the
    same weights with the missing frames' learned positions zero, whose answers differ but
    whose arithmetic per call is the same, which is all a timing needs."""
    from dataclasses import replace

    import torch

    from inference.model.files import LoadedModel, build_model, with_window
    from inference.poser.models import resolve_model

    if any(getattr(model.config, k) != v for k, v in REFERENCE_SIZE.items()):
        # the time of a call does not depend on the weights' values
        cfg = replace(model.config, window=window, **REFERENCE_SIZE)
        return LoadedModel(model=build_model(model.kind, cfg).eval(), kind=model.kind, config=cfg,
                           norm_mean=model.norm_mean, norm_std=model.norm_std, step=model.step,
                           meta=dict(model.meta or {}))
    trained = int((model.meta or {}).get("trained_window", model.config.window))
    if spec is not None and not isinstance(spec, LoadedModel) and trained >= window:
        return resolve_model(spec, window=window)
    if model.config.window >= window:
        return with_window(model, window)
    cfg = replace(model.config, window=window)
    net = build_model(model.kind, cfg).eval()
    sd = dict(model.model.state_dict())
    pos = sd["pos"]
    pad = torch.zeros(1, window - model.config.window, pos.shape[2], dtype=pos.dtype)
    sd["pos"] = torch.cat([pos[:, :2], pad, pos[:, 2:]], dim=1)
    net.load_state_dict(sd)
    return LoadedModel(model=net, kind=model.kind, config=cfg, norm_mean=model.norm_mean, norm_std=model.norm_std,
                       step=model.step, meta=dict(model.meta or {}))


def bench_reference(model, steps=None, frames: int = 200, warmup: int = 10, seed: int = 0,
                    mirror: bool | None = None, spec=None) -> dict:
    """The default live step against the settings it replaced (``REFERENCE_WINDOW``,
    ``REFERENCE_STEPS``, the shipped file's inpainting: replacement DDIM from the data mean, the
    measured history, whole-chain mirror averaging, whatever the default does: a default that
    answers without averaging is timed against what it replaces), both on the live runtime,
    stepped in turn on the same frames (``interleaved_times``): the ratio holds on any machine, where
    the milliseconds do not."""
    from inference.model.diffusion import parse_steps
    from inference.poser.poser import Poser

    motion, inp = walk_input(frames + warmup, seed)
    ref = reference_model(model, spec)
    posers = {"default": Poser(model, body=motion.body, steps=steps, seed=seed, mirror=mirror, runtime="auto"),
              "reference": Poser(ref, body=motion.body, steps=parse_steps(REFERENCE_STEPS), seed=seed, mirror=True,
                                 mirror_chains=True, noise="mean", inpaint_mode="replace-ddim", history="measured",
                                 runtime="auto", int8=False)}  # the shipped float network
    ms = interleaved_times(posers, inp, frames, warmup)
    out: dict = {"frames": int(frames), "interleaved": True}
    for name, poser in posers.items():
        out[name] = {"p50_ms": round(float(np.percentile(ms[name], 50)), 3),
                     "p99_ms": round(float(np.percentile(ms[name], 99)), 3),
                     "window": poser.window, "steps": list(poser.steps), "passes_per_pose": passes_per_pose(poser),
                     "mirror": poser.mirror, "mirror_chains": bool(poser.chain_mirror), "runtime": poser.runtime,
                     "int8": poser.int8,
                     "size": "{layers}/{d_model}/{ff}".format(**vars(poser.model.config))}
    out["ratio_p50"] = round(out["default"]["p50_ms"] / out["reference"]["p50_ms"], 3)
    out["ratio_p99"] = round(out["default"]["p99_ms"] / out["reference"]["p99_ms"], 3)
    return out
"""The rows of ``bench_variants``: the model call on torch or ONNX Runtime, on 1 intra-op
thread or 2 (``-2t``), and with the linear layers' weights in int8 (``-int8``: ONNX
Runtime's dynamic quantizer, or torch's ``quantize_dynamic``)."""


class _VariantPoser:
    """A live Poser whose model call is one variant's; ``step`` runs with torch on the
    variant's thread count (torch's setting is global, so each step sets it)."""

    def __init__(self, model, variant: str, body, steps, seed: int, mirror: bool | None) -> None:
        import dataclasses

        import torch
        from torch import nn

        from inference.features.layout import N_FEATURES
        from inference.features.mirror import MirrorAveraged
        from inference.model.onnx_runtime import OnnxNet
        from inference.poser.poser import Poser

        self.variant = variant
        self.threads = 2 if variant.endswith("-2t") else 1
        runtime = "onnx" if variant.startswith("onnx") else "torch"
        if variant == "torch-int8":
            q = torch.ao.quantization.quantize_dynamic(model.model, {nn.Linear}, dtype=torch.qint8).eval()
            model = dataclasses.replace(model, model=q)
        torch.set_num_threads(self.threads)
        self.poser = Poser(model, body=body, steps=steps, seed=seed, mirror=mirror, runtime="torch",
                           freeze=variant != "torch-int8")
        if runtime == "onnx":
            p = self.poser
            eager = MirrorAveraged(model.model, model.norm_mean, model.norm_std) if p.mirror else model.model
            p._net = OnnxNet(eager, 1, p.window, N_FEATURES, model.config.mask_input, threads=self.threads,
                             quantize=variant.endswith("int8"))
            p.runtime = "onnx"
        torch.set_num_threads(1)

    def step(self, features, mask):
        import torch

        torch.set_num_threads(self.threads)
        try:
            return self.poser.step(features, mask)
        finally:
            torch.set_num_threads(1)


def rotation_gap_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (deg) between rotation matrices ``a`` and ``b`` (..., 3, 3), elementwise, from
    ``|a - b|_F = 2 sqrt(2) sin(angle / 2)`` (arccos of the trace loses small angles)."""
    d = np.linalg.norm(np.asarray(a, np.float64) - np.asarray(b, np.float64), axis=(-2, -1))
    return np.degrees(2.0 * np.arcsin(np.clip(d / (2.0 * np.sqrt(2.0)), 0.0, 1.0)))


def bench_variants(model, steps=None, frames: int = 200, warmup: int = 10, seed: int = 0,
                   mirror: bool | None = None, variants: tuple[str, ...] = VARIANTS) -> dict:
    """Each variant of the model call (``VARIANTS``) as a live Poser, all stepped in turn on
    the same frames of the generated walk (``interleaved_times``'s order), and what each changes:
    per row p50_ms, p99_ms, ratio_p50 / ratio_p99 to the first row, and its poses against
    the first row's, frame by frame (each poser on its own history, as live): the segments'
    orientation difference, mean and max over frames and segments (``mean_deg``,
    ``max_deg``), and the largest per-frame mean (``frame_max_deg``)."""
    import torch

    motion, inp = walk_input(frames + warmup, seed)
    posers = {v: _VariantPoser(model, v, motion.body, steps, seed, mirror) for v in variants}
    names = list(posers)
    n = inp.features.shape[0]
    ms = {v: np.empty(frames) for v in names}
    rot = {v: np.empty((frames, 24, 3, 3)) for v in names}
    threads_before = torch.get_num_threads()
    for i in range(warmup + frames):
        k = i % n
        r = i % len(names)
        for v in names[r:] + names[:r]:
            t0 = time.perf_counter()
            pf = posers[v].step(inp.features[k], inp.mask[k])
            if i >= warmup:
                ms[v][i - warmup] = (time.perf_counter() - t0) * 1e3
                rot[v][i - warmup] = pf.rot
    torch.set_num_threads(threads_before)
    base = names[0]
    rows = []
    for v in names:
        gap = rotation_gap_deg(rot[v], rot[base])
        p50, p99 = float(np.percentile(ms[v], 50)), float(np.percentile(ms[v], 99))
        rows.append({"variant": v, "runtime": posers[v].poser.runtime, "threads": posers[v].threads,
                     "int8": v.endswith("int8"), "p50_ms": round(p50, 3), "p99_ms": round(p99, 3),
                     "ratio_p50": round(p50 / float(np.percentile(ms[base], 50)), 3),
                     "ratio_p99": round(p99 / float(np.percentile(ms[base], 99)), 3),
                     "mean_deg": round(float(gap.mean()), 4), "max_deg": round(float(gap.max()), 4),
                     "frame_max_deg": round(float(gap.mean(axis=1).max()), 4)})
    first = posers[base].poser
    return {"base": base, "steps": len(first.steps), "mirror": first.mirror, "frames": int(frames),
            "interleaved": True, "rows": rows}


def parse_sizes(text: str) -> list[tuple[int, int, int]]:
    """``"6/128/512,4/192/768"`` -> [(6, 128, 512), (4, 192, 768)]: layers / width / FF."""
    sizes = []
    for part in text.split(","):
        try:
            layers, d, ff = (int(v) for v in part.strip().split("/"))
        except ValueError:
            raise ValueError(f"--sizes: {part.strip()!r} is not LAYERS/WIDTH/FF (e.g. 6/128/512)") from None
        if min(layers, d, ff) < 1 or d % 32:
            raise ValueError(f"--sizes: {part.strip()!r}: all positive, width a multiple of 32 (32-wide heads)")
        sizes.append((layers, d, ff))
    return sizes


def bench_sizes(model, sizes: list[tuple[int, int, int]], steps=None, frames: int = 100, warmup: int = 5,
                seed: int = 0, mirror: bool | None = None, runtime: str = "auto") -> dict:
    """The live loop with ``model``'s settings (steps, mirror averaging, normaliser, meta)
    but randomly initialised denoisers of other sizes, all stepped in turn on the same
    frames with ``model`` itself: which larger model would stay inside the live budget,
    as ratios to the model in use measured in one run. Heads stay 32 wide."""
    import dataclasses

    import torch

    from inference.model.files import build_model
    from inference.poser.poser import Poser

    motion, inp = walk_input(frames + warmup, seed)
    base = _config_label(model).split()[-1]
    models = {base: model}
    for layers, d, ff in sizes:
        cfg = dataclasses.replace(model.config, layers=layers, d_model=d, ff=ff, heads=d // 32, dropout=0.0)
        torch.manual_seed(seed)
        models.setdefault(f"{layers}/{d}/{ff}", dataclasses.replace(
            model, model=build_model(model.kind, cfg).eval(), config=cfg))
    posers = {name: Poser(m, body=motion.body, steps=steps, seed=seed, mirror=mirror, runtime=runtime)
              for name, m in models.items()}
    ms = interleaved_times(posers, inp, frames, warmup)
    p50 = {name: float(np.percentile(v, 50)) for name, v in ms.items()}
    rows = [{"size": name, "parameters": sum(p.numel() for p in models[name].model.parameters()),
             "p50_ms": round(p50[name], 3), "p99_ms": round(float(np.percentile(ms[name], 99)), 3),
             "ratio_p50": round(p50[name] / p50[base], 3)} for name in posers]
    first = posers[base]
    return {"base": base, "runtime": first.runtime, "steps": len(first.steps), "mirror": first.mirror,
            "frames": int(frames), "interleaved": True, "rows": rows}


def paper_model():
    """A randomly initialised paper-size denoiser (8/512/2048, 8 heads)."""
    import torch

    from inference.features.layout import N_FEATURES
    from inference.model.config import ModelConfig
    from inference.model.denoiser import Denoiser
    from inference.model.files import LoadedModel

    cfg = ModelConfig.paper()
    cfg.dropout = 0.0
    torch.manual_seed(0)
    return LoadedModel(model=Denoiser(cfg).eval(), kind="diffusion", config=cfg,
                       norm_mean=np.zeros(N_FEATURES, np.float32), norm_std=np.ones(N_FEATURES, np.float32))


def _config_label(model) -> str:
    if model is None:
        return "floor"
    c = model.config
    return f"{model.kind} {c.layers}/{c.d_model}/{c.ff}"


def run_bench(model_spec: str = DEFAULT_MODEL, steps=None, frames: int = 200, paper_frames: int = 10,
              threads: int = 0, random_weights: bool = False, paper: bool = True, warmup: int = 10,
              mirror: bool | None = None, confidence: bool = True, onnx: bool = True,
              variants: bool = True) -> dict:
    """The `imucap bench` measurement (see the module docstring); returns its JSON object."""
    import torch

    from app.live.model_choice import load_model, set_torch_threads
    from inference.evaluation.runner import SIX
    from inference.features.layout import N_FEATURES
    from inference.model.config import ModelConfig
    from inference.model.diffusion import even_steps, parse_steps
    from inference.model.files import LoadedModel, build_model
    from inference.poser.models import DEFAULT_WEIGHTS, default_weights, model_for_sites

    set_torch_threads(threads)
    weights: str
    if random_weights:
        torch.manual_seed(0)
        model = LoadedModel(model=build_model("diffusion", ModelConfig()).eval(), kind="diffusion",
                            config=ModelConfig(), norm_mean=np.zeros(N_FEATURES, np.float32),
                            norm_std=np.ones(N_FEATURES, np.float32))
        weights = "random (default ModelConfig)"
    else:
        model = load_model(model_spec)[0]
        name = str(model_for_sites(model_spec, SIX))  # the live default at the bench's 6 sites
        weights = str(default_weights(name)) if name in DEFAULT_WEIGHTS else name
    st = parse_steps(steps) if steps is not None else None
    out = bench_poser(model, st, frames, warmup, label=_config_label(model), mirror=mirror)
    out["weights"] = weights
    # the step's stages: the model call and the work around it (docs/latency.md, "Around the model call")
    out["stages"] = bench_stages(model, st, frames, warmup, mirror=mirror)
    from inference.model.onnx_runtime import onnxruntime_available

    if onnx and model is not None and model.kind == "diffusion" and onnxruntime_available():
        # the model call through ONNX Runtime (what live sessions use when it is installed)
        # against torch, frame for frame in turn, so a load change hits both alike
        o = bench_runtimes(model, st, frames, warmup, mirror=mirror)
        out.update(onnx_p50_ms=o["onnx_p50_ms"], onnx_p99_ms=o["onnx_p99_ms"], onnx=o)
    if model is not None and model.kind == "diffusion":
        # the default against the settings it replaced, in turn on the same frames
        out["reference"] = bench_reference(model, st, frames, warmup, mirror=mirror,
                                           spec=None if random_weights else model_spec)
    if variants and onnx and model is not None and model.kind == "diffusion" and onnxruntime_available():
        # threads 1 / 2 and int8 weights, each alone beside the plain call, with what each
        # changes in the poses
        out["variants"] = bench_variants(model, st, frames, warmup, mirror=mirror)
    if out["mirror"]:
        # what the mirror averaging costs, measured in the same run
        out["without_mirror"] = bench_poser(model, st, frames, warmup, label=_config_label(model), mirror=False)
    if confidence and model is not None and model.kind == "diffusion":
        out["confidence"] = bench_poser(model, st, frames, warmup, label=_config_label(model), mirror=mirror,
                                        confidence=True)
    if paper:
        out["paper"] = bench_poser(paper_model(), even_steps(30), paper_frames, min(warmup, 2),
                                   label="diffusion 8/512/2048 (paper, random weights)")
    out["threads"] = torch.get_num_threads()
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("bench", help="per-frame latency of the live poser (default and paper-size model)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--frames", type=int, default=200, help="timed frames of the default model (default 200)")
    p.add_argument("--paper-frames", type=int, default=10,
                   help="timed frames of the paper-size model (default 10; ~1-3 s each on 2 cores)")
    p.add_argument("--threads", type=int, default=1,
                   help="torch threads (default 1, the live loop's setting; 0 = torch's default)")
    p.add_argument("--model", default=DEFAULT_MODEL,
                   help="auto (the live default) | diffusion | fast | regressor | floor | PATH.pt")
    p.add_argument("--steps", default=None, help="diffusion steps (default: the model's own)")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="mirror averaging on/off (default: the model file's own)")
    p.add_argument("--random-weights", action="store_true",
                   help="time a randomly initialised default-size model (no weights needed)")
    p.add_argument("--warmup", type=int, default=10, help="untimed frames before timing (default 10)")
    p.add_argument("--no-paper", action="store_true", help="skip the paper-size model")
    p.add_argument("--no-confidence", action="store_true", help="skip the loop with the per-segment spread on")
    p.add_argument("--no-onnx", action="store_true", help="skip the loop through ONNX Runtime (onnx_p50_ms)")
    p.add_argument("--no-variants", action="store_true",
                   help="skip the model call's variants (threads 1/2, int8 weights; key variants)")
    p.add_argument("--sizes", default=None, metavar="L/D/FF,...",
                   help="instead: the live loop with the model's settings but randomly initialised denoisers "
                        "of these sizes (layers/width/FF), stepped in turn with the model itself, as ratios to it")
    p.add_argument("--end-to-end", action="store_true",
                   help="sensor-to-pose latency of the live path per latency mode instead "
                        "(app/capture/end_to_end_bench.py)")
    p.add_argument("--seconds", type=float, default=10.0, help="--end-to-end: timed seconds per mode and round")
    p.add_argument("--rounds", type=int, default=2, help="--end-to-end: rounds of both modes, alternating")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.end_to_end:
        from app.capture.end_to_end_bench import run_end_to_end

        res = run_end_to_end(args.seconds, args.rounds, args.model, threads=args.threads)
        print(json.dumps(res) if args.json else "\n".join(f"{k}: {v}" for k, v in res.items()))
        sys.stdout.flush()
        return 0
    if args.frames < 1 or args.paper_frames < 1:
        raise ValueError("--frames and --paper-frames must be at least 1")
    if args.sizes is not None:
        return _run_sizes(args)
    res = run_bench(args.model, args.steps, args.frames, args.paper_frames, args.threads, args.random_weights,
                    not args.no_paper, max(0, args.warmup), args.mirror, not args.no_confidence, not args.no_onnx,
                    not args.no_variants)
    if args.json:
        print(json.dumps(res))
    else:
        def line(r: dict) -> str:
            return (f"{r['model']}: {r['steps']} steps{', mirror-averaged' if r['mirror'] else ''}, "
                    f"p50 {r['p50_ms']:.1f} ms, p99 {r['p99_ms']:.1f} ms over {r['frames']} frames, "
                    f"{r['threads']} threads")

        print(line(res))
        if "reference" in res:
            r, d = res["reference"]["reference"], res["reference"]["default"]
            print(f"against the settings it replaced ({r['window']}-frame window, {len(r['steps'])} steps, "
                  f"{r['passes_per_pose']} passes; {r['runtime']}), in turn: "
                  f"p50 {d['p50_ms']:.1f} vs {r['p50_ms']:.1f} ms "
                  f"(x{res['reference']['ratio_p50']:.2f}), p99 {d['p99_ms']:.1f} vs {r['p99_ms']:.1f} ms "
                  f"(x{res['reference']['ratio_p99']:.2f})")
        if "onnx" in res:
            o = res["onnx"]
            print(f"ONNX Runtime vs torch, frame for frame in turn: p50 {o['onnx_p50_ms']:.1f} vs "
                  f"{o['torch_p50_ms']:.1f} ms (x{o['speedup_p50']:.2f}), p99 {o['onnx_p99_ms']:.1f} vs "
                  f"{o['torch_p99_ms']:.1f} ms")
        if "variants" in res:
            print("the model call's variants, stepped in turn (ratio to the first; poses against its):")
            for r in res["variants"]["rows"]:
                print(f"  {r['variant']:>11}  p50 {r['p50_ms']:6.1f} ms  p99 {r['p99_ms']:6.1f} ms  "
                      f"x{r['ratio_p50']:.2f} / x{r['ratio_p99']:.2f}  poses mean {r['mean_deg']:.3f} deg, "
                      f"max {r['max_deg']:.2f} deg")
        for key in ("without_mirror", "confidence", "paper"):
            if key in res:
                print(line(res[key]))
    sys.stdout.flush()
    return 0


def _run_sizes(args: argparse.Namespace) -> int:
    import torch

    from app.live.model_choice import load_model, set_torch_threads
    from inference.model.diffusion import parse_steps

    sizes = parse_sizes(args.sizes)
    set_torch_threads(args.threads)
    # the sizes are the full model's question (what larger denoiser would fit): its file unless named
    model = load_model(args.model if args.model != DEFAULT_MODEL else "diffusion")[0]
    if model is None or model.kind != "diffusion":
        raise ValueError(f"--sizes times denoisers: --model {args.model} is not a diffusion model")
    steps = parse_steps(args.steps) if args.steps is not None else None
    res = bench_sizes(model, sizes, steps, args.frames, max(0, args.warmup), mirror=args.mirror,
                      runtime="torch" if args.no_onnx else "auto")
    res["threads"] = torch.get_num_threads()
    if args.json:
        print(json.dumps(res))
    else:
        print(f"{res['runtime']}, {res['steps']} steps{', mirror-averaged' if res['mirror'] else ''}, "
              f"{res['frames']} frames each, in turn:")
        for r in res["rows"]:
            print(f"  {r['size']:>12}  {r['parameters'] / 1e6:5.2f} M  p50 {r['p50_ms']:6.1f} ms  "
                  f"p99 {r['p99_ms']:6.1f} ms  x{r['ratio_p50']:.2f}")
    sys.stdout.flush()
    return 0


__all__ = ["VARIANTS", "REFERENCE_SIZE", "REFERENCE_STEPS", "REFERENCE_WINDOW", "bench_poser", "bench_reference",
           "passes_per_pose", "reference_model", "bench_sizes", "bench_variants", "rotation_gap_deg", "parse_sizes",
           "paper_model", "run_bench", "register", "run"]
