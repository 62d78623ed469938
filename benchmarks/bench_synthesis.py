"""Benchmark (not a test): synthesize one hour of 60 Hz motion, all 13 sites + insoles.

Goal (issue 2): <= 10 s on the 2-core development machine. Usage:

    .venv/bin/python benchmarks/bench_synthesis.py [--minutes 60] [--noise] [--json]
"""

from __future__ import annotations

import argparse
import json
import os
import time

from inference.features.codec import features_from_motion
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--noise", action="store_true", help="also apply NoiseModel.typical()")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    t0 = time.perf_counter()
    m = generate("walk", seconds=args.minutes * 60.0, seed=0)
    t_gen = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    sig = synthesize(m, NoiseModel.typical() if args.noise else None, rng=0)
    t_syn, c_syn = time.perf_counter() - t0, time.process_time() - c0
    t0 = time.perf_counter()
    x = features_from_motion(m)
    t_feat = time.perf_counter() - t0
    out = {
        "frames_60hz": len(sig), "motion_minutes": args.minutes, "noise": args.noise,
        "generate_s": round(t_gen, 2), "synthesize_s": round(t_syn, 2),
        "synthesize_cpu_s": round(c_syn, 2), "load_avg_1min": round(os.getloadavg()[0], 1),
        "features_s": round(t_feat, 2),
        "feature_frames_20hz": int(x.shape[0]),
    }
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:22s} {v}")


if __name__ == "__main__":
    main()
