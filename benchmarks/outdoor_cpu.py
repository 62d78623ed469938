"""CPU share of a 6-sensor capture with the outdoor view, at the default model setting and
the lighter one (fewer diffusion steps, for a laptop on battery), in one run.

    xvfb-run -a .venv/bin/python benchmarks/outdoor_cpu.py [--seconds 40] [--repeat 2] [--json]

Each round starts the simulated suit in its own process (`imucap devices simulate
--setup`), then `imucap capture --setup --view outdoor --record` with the window (under
Xvfb here: software GL, so drawing costs more than on a laptop's GPU) for ``--seconds``.
The capture process's CPU time (all its threads: devices, hub, model, drawing, recording)
per second of poses it made (poses / 20 Hz; its start-up and calibration included) is its
share of one core at the full 20 Hz: a busy machine that starves it makes fewer poses and
less CPU alike, so the figure holds better beside other work than CPU over wall time; a
round that did not calibrate in time gives no figure. The two settings are taken in turn,
``--repeat`` times each, and the medians reported with their ratio.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from app.capture.setup_file import save_setup
from app.capture.simulator_process import SimulatorProcess
from app.capture.twins import simulated_setup
from app.recording import read_recording
from inference.signals.resample import FPS_MODEL

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
SETTINGS = {"default": None, "light": "1"}  # the [model] steps of the setup file
CLI = [sys.executable, "-m", "app.cli.main"]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def one_round(steps: str | None, seconds: float) -> float | None:
    folder = Path(tempfile.mkdtemp(prefix="imucap-outdoor-"))
    setup = simulated_setup(SIX, "xbus", folder=folder, steps=steps)
    path = folder / "setup.toml"
    save_setup(setup, path)
    rec = folder / "rec.h5"
    # a lead-in long enough for the window and the model to be up before the N-pose ends, on a busy machine too
    with SimulatorProcess(path, "walk", seconds=seconds + 60.0, lead_in=15.0):
        c0 = _children_cpu()
        subprocess.run([*CLI, "capture", "--setup", str(path), "--view", "outdoor", "--countdown", "1",
                        "--record", str(rec), "--quit-after", f"{seconds:g}"], check=True, capture_output=True,
                       timeout=seconds + 180)
        cpu = _children_cpu() - c0  # the simulator is not reaped yet: not counted
    poses = len(read_recording(rec).recon["t"])
    return cpu / (poses / FPS_MODEL) if poses >= 10 * FPS_MODEL else None  # not calibrated in time: no figure


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    shares: dict[str, list[float | None]] = {k: [] for k in SETTINGS}
    for _ in range(args.repeat):
        for name, steps in SETTINGS.items():
            share = one_round(steps, args.seconds)
            shares[name].append(None if share is None else round(share, 3))
    med = {k: float(np.median([x for x in v if x is not None])) if any(x is not None for x in v) else None
           for k, v in shares.items()}
    ratio = round(med["light"] / med["default"], 2) if med["light"] and med["default"] else None
    res = {"seconds": args.seconds, "runs": shares,
           **{f"{k}_share_of_one_core": None if v is None else round(v, 3) for k, v in med.items()},
           "light_over_default": ratio, "light_steps": SETTINGS["light"]}
    print(json.dumps(res) if args.json else "\n".join(f"{k}: {v}" for k, v in res.items()))


if __name__ == "__main__":
    main()
