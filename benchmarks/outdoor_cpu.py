"""CPU share of a 6-sensor capture with the outdoor view, at the default model setting and
the model it replaced (the file shipped before the one-step student: a 61-frame window, 3
steps), in one run.

    xvfb-run -a .venv/bin/python benchmarks/outdoor_cpu.py [--seconds 40] [--repeat 2] [--json]
        [--previous FILE]

The previous file is read from git (``PREVIOUS``, the last commit that shipped it) unless
``--previous`` names one.

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
PREVIOUS = "ecfd154:inference/weights/diffusionposer.pt"  # the 3-step file, before the one-step student
CLI = [sys.executable, "-m", "app.cli.main"]


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def previous_file(path: str | None) -> Path:
    """The file the default replaced: ``path``, or ``PREVIOUS`` taken out of git."""
    if path is not None:
        return Path(path)
    out = Path(tempfile.mkdtemp(prefix="imucap-previous-")) / "diffusionposer_previous.pt"
    root = Path(__file__).resolve().parents[1]
    out.write_bytes(subprocess.run(["git", "show", PREVIOUS], cwd=root, check=True, capture_output=True).stdout)
    return out


def one_round(model: str, seconds: float) -> float | None:
    folder = Path(tempfile.mkdtemp(prefix="imucap-outdoor-"))
    setup = simulated_setup(SIX, "xbus", folder=folder, model=model)
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
    ap.add_argument("--previous", default=None, help="the replaced model file (default: from git, PREVIOUS)")
    args = ap.parse_args()
    settings = {"default": "diffusion", "previous": str(previous_file(args.previous))}
    shares: dict[str, list[float | None]] = {k: [] for k in settings}
    for _ in range(args.repeat):
        for name, model in settings.items():
            share = one_round(model, args.seconds)
            shares[name].append(None if share is None else round(share, 3))
    med = {k: float(np.median([x for x in v if x is not None])) if any(x is not None for x in v) else None
           for k, v in shares.items()}
    ratio = round(med["default"] / med["previous"], 2) if med["default"] and med["previous"] else None
    res = {"seconds": args.seconds, "runs": shares,
           **{f"{k}_share_of_one_core": None if v is None else round(v, 3) for k, v in med.items()},
           "default_over_previous": ratio}
    print(json.dumps(res) if args.json else "\n".join(f"{k}: {v}" for k, v in res.items()))


if __name__ == "__main__":
    main()
