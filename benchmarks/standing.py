"""A walk that ends in a stand: the legs' error once the subject stands still.

    .venv/bin/python benchmarks/standing.py --data @sad --model diffusion [--model runs/x/model.pt] --json

By default only the walks of the given sets (``--match walk``).

Each clip is followed by 4 s of standing (entered over 0.6 s), reconstructed from pelvis +
shanks (``--sensors``) and scored per segment over the stand from 1 s on
(``inference.evaluation.standing``). docs/real_signals.md, "A standing body".
"""

from __future__ import annotations

import argparse
import json
import sys

from inference.evaluation.runner import load_motions, resolve_models
from inference.evaluation.standing import stand_errors, summary
from inference.loaders import find_motion_files
from inference.training.splits import held_out_files


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", nargs="+", default=["@sad"], help="motion files or held-out sets (@sad, @dg, @cmu-val)")
    ap.add_argument("--match", default="walk", help="only clips whose file name holds this ('' for all)")
    ap.add_argument("--model", action="append", default=None)
    ap.add_argument("--sensors", default="pelvis,l_shank,r_shank")
    ap.add_argument("--limit", type=int, default=None, help="first N clips only")
    ap.add_argument("--stand", type=float, default=4.0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    files = [f for d in a.data for f in (held_out_files(d) if d.startswith("@") else find_motion_files([d]))]
    files = [f for f in files if a.match in f.name]
    motions = load_motions(files, limit=a.limit)
    out = {}
    for spec, model in resolve_models(a.model or ["diffusion"]).items():
        res = stand_errors(model, motions, a.sensors.split(","), stand_s=a.stand)
        out[spec] = {"clips": len(res), "mean_deg": summary(res),
                     "per_clip": {r.name: r.deg for r in res}}
        print(f"{spec}: {out[spec]['mean_deg']}", file=sys.stderr)
    if a.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
