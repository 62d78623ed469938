"""CPU share of a 6-sensor capture with the outdoor view, at the default model setting and
the lighter one (fewer diffusion steps, for a laptop on battery), in one run.

    xvfb-run -a .venv/bin/python benchmarks/outdoor_cpu.py [--seconds 40] [--repeat 2] [--json]

Each round starts the simulated suit in its own process (`imucap devices simulate
--setup`), then `imucap capture --setup --view outdoor` with the window (under Xvfb here:
software GL, so drawing costs more than on a laptop's GPU) for ``--seconds``; the capture
process's CPU time (all its threads: devices, hub, model, drawing) over its wall time is
its share of one core. The two settings are taken in turn, ``--repeat`` times each, and
the medians reported with their ratio.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from app.capture.setup_file import save_setup
from app.capture.simulator_process import SimulatorProcess
from app.capture.twins import simulated_setup

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
SETTINGS = {"default": None, "light": "1"}  # the [model] steps of the setup file
CLI = [sys.executable, "-m", "app.cli.main"]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def one_round(steps: str | None, seconds: float) -> float:
    folder = Path(tempfile.mkdtemp(prefix="imucap-outdoor-"))
    setup = simulated_setup(SIX, "xbus", folder=folder, steps=steps)
    path = folder / "setup.toml"
    save_setup(setup, path)
    with SimulatorProcess(path, "walk", seconds=seconds + 60.0, lead_in=2.0):
        c0, t0 = _children_cpu(), time.perf_counter()
        subprocess.run([*CLI, "capture", "--setup", str(path), "--view", "outdoor", "--countdown", "1",
                        "--quit-after", f"{seconds:g}"], check=True, capture_output=True, timeout=seconds + 180)
        cpu, wall = _children_cpu() - c0, time.perf_counter() - t0  # the simulator is not reaped yet: not counted
    return cpu / wall


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    shares: dict[str, list[float]] = {k: [] for k in SETTINGS}
    for _ in range(args.repeat):
        for name, steps in SETTINGS.items():
            shares[name].append(round(one_round(steps, args.seconds), 3))
    med = {k: float(np.median(v)) for k, v in shares.items()}
    res = {"seconds": args.seconds, "runs": shares,
           **{f"{k}_share_of_one_core": round(v, 3) for k, v in med.items()},
           "light_over_default": round(med["light"] / med["default"], 2), "light_steps": SETTINGS["light"]}
    print(json.dumps(res) if args.json else "\n".join(f"{k}: {v}" for k, v in res.items()))


if __name__ == "__main__":
    main()
