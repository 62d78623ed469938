"""The live step's work around the model call, stage by stage: ``Poser.observe``,
``Poser.enter`` and ``Poser.finish`` (cleaning, knee hinge, contact detector, FK, contact
points, root correction, stride scale, output filters, the PoseFrame), timed beside the
same stages as written in torch (tests/inference/poser/reference_poser.py), the two
posers stepped in turn on the same frames, the order turning each frame (the machine is
shared: only ratios from one run compare). The model call is timed too, apart (``model``).

    .venv/bin/python benchmarks/poser_stages.py [--frames 300] [--threads 1] [--sites SITE,...] [--json]

The input is ``imucap bench``'s generated walk at the paper's 6 sites, or at ``--sites``
(e.g. ``pelvis,l_wrist,r_wrist``: the pelvis odometry's root instead of the shanks' contacts).

Prints per stage and poser the median wall and thread-CPU time (ms), their sum outside the
model call, and the ratio of the torch sum to the numpy one (docs/latency.md, "Around the
model call").
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

STAGES = ("observe", "enter", "finish")  # the model call (between enter and finish) is reported apart


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--runtime", default="auto", help="the model call's runtime (untimed): auto, torch, onnx")
    ap.add_argument("--sites", default="", help="comma-separated sensor sites (default: the paper's 6)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)

    import torch

    from app.cli.bench_loop import stage_times, walk_input
    from app.live.model_choice import load_model
    from inference.poser.poser import Poser
    from tests.inference.poser.reference_poser import ReferencePoser

    torch.set_num_threads(args.threads)
    model, label, _ = load_model("diffusion")
    motion, inp = walk_input(args.frames + 10, 0)
    if args.sites:
        from inference.evaluation.runner import clip_input

        inp = clip_input(motion, args.sites.split(","))
    posers = {"numpy": Poser(model, body=motion.body, runtime=args.runtime),
              "torch": ReferencePoser(model, body=motion.body, runtime=args.runtime)}
    times = stage_times(posers, inp, args.frames)
    res: dict = {"model": label, "frames": args.frames, "threads": args.threads, "sites": args.sites or "6 (paper)",
                 "runtime": posers["numpy"].runtime}
    for name, t in times.items():
        res[name] = {k: round(float(np.median(v)), 4) for k, v in t.items()}
        res[name]["sum_wall"] = round(sum(res[name][f"{s}_wall"] for s in STAGES), 4)
        res[name]["sum_cpu"] = round(sum(res[name][f"{s}_cpu"] for s in STAGES), 4)
    res["ratio_wall"] = round(res["torch"]["sum_wall"] / res["numpy"]["sum_wall"], 2)
    res["ratio_cpu"] = round(res["torch"]["sum_cpu"] / res["numpy"]["sum_cpu"], 2)
    if args.json:
        print(json.dumps(res))
        return 0
    print(f"{label}, {args.frames} frames, {args.threads} thread(s); median ms per frame (wall / thread CPU)")
    for s in (*STAGES, "sum", "model"):
        row = "  ".join(f"{name} {res[name][f'{s}_wall']:.3f} / {res[name][f'{s}_cpu']:.3f}" for name in times)
        print(f"{s:8s} {row}")
    print(f"torch / numpy: wall {res['ratio_wall']}x, cpu {res['ratio_cpu']}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
