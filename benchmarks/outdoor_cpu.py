"""CPU share of a 6-sensor capture with the outdoor view while it poses, its skeleton drawn
flat (the default) or in GL, beside the same capture without a window, in one run.

    xvfb-run -a .venv/bin/python benchmarks/outdoor_cpu.py [--seconds 50] [--repeat 2]
        [--variants "3d full","2d full",2d,headless,3d,"headless full","2d light"] [--json]

Each round starts the simulated suit in its own process (`imucap devices simulate
--setup`), then `imucap capture --setup --record` for ``--seconds``: with the window on
the outdoor view (``--view outdoor --outdoor-skeleton 2d|3d``; under Xvfb here, so GL is
software GL, llvmpipe, on threads of the capture process), or ``--headless``. Plain names run
the live default (``[model] name = "auto"``: at these 6 sites the 21-frame int8 file, under a
third of the full model's compute); "full" the full model (``name = "diffusion"``, the default
before); "light" the full model's lighter setting (one diffusion step). The
capture process's CPU time, all its threads (devices, hub, model, drawing, recording),
is read from /proc twice a second; its share of one core is taken over the last 15 s
before it stops, when it has posed for a while (the start-up's imports and the
calibration are not the view's cost). A round that did not calibrate in time gives no
figure. The variants are taken in turn, ``--repeat`` times each, and the medians reported
with their ratio to the first variant; ``window_share`` is a window variant's share less
the headless one's (what drawing and the window's own work add).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from app.capture.setup_file import save_setup
from app.capture.simulator_process import SimulatorProcess
from app.capture.twins import simulated_setup
from app.recording import read_recording
from inference.signals.resample import FPS_MODEL

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
# name -> (the setup's [model] name and steps, the outdoor skeleton or None for no window)
# ("auto": the live default, at 6 sites the 21-frame int8 file; "full": the full model, the default
# before it, with which the "default setting" was measured as the GL skeleton)
VARIANTS = {"3d full": ("diffusion", None, "3d"), "2d full": ("diffusion", None, "2d"),
            "headless full": ("diffusion", None, None), "2d light": ("diffusion", "1", "2d"),
            "3d": ("auto", None, "3d"), "2d": ("auto", None, "2d"), "headless": ("auto", None, None)}
LIVE_S = 15.0  # seconds of posing over which the share is taken
CLI = [sys.executable, "-m", "app.cli.main"]


def _process_cpu(pid: int) -> float | None:
    """All threads of ``pid`` (llvmpipe's rasterisers too), user + system, in seconds."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def one_round(steps: str | None, seconds: float, skeleton: str | None = "2d", model: str = "diffusion") -> dict:
    """One capture of ``seconds`` after its start-up: its CPU share while it poses, and what
    its window said it took itself."""
    folder = Path(tempfile.mkdtemp(prefix="imucap-outdoor-"))
    setup = simulated_setup(SIX, "xbus", folder=folder, model=model, steps=steps)
    path = folder / "setup.toml"
    save_setup(setup, path)
    rec = folder / "rec.h5"
    stats = folder / "window.json"
    window = skeleton is not None
    view = (["--view", "outdoor", "--outdoor-skeleton", skeleton, "--quit-after", f"{seconds:g}",
             "--window-stats", str(stats)] if window else ["--headless", "--seconds", f"{seconds:g}"])
    samples: list[tuple[float, float]] = []  # (wall, CPU) of the capture process, twice a second
    # a lead-in long enough for the window and the model to be up before the N-pose ends, on a busy machine too
    with SimulatorProcess(path, "walk", seconds=seconds + 60.0, lead_in=15.0):
        proc = subprocess.Popen([*CLI, "capture", "--setup", str(path), "--countdown", "1", "--record", str(rec),
                                 *view], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + seconds + 180
        while proc.poll() is None and time.monotonic() < deadline:
            cpu = _process_cpu(proc.pid)
            if cpu is not None:
                samples.append((time.monotonic(), cpu))
            time.sleep(0.5)
        if proc.poll() is None:
            proc.kill()
        err = proc.communicate()[1].decode(errors="replace")
        if proc.returncode:
            raise RuntimeError(f"capture failed ({proc.returncode}): {err.strip().splitlines()[-1:]}")
    poses = len(read_recording(rec).recon["t"])
    gui = json.loads(stats.read_text()) if window and stats.exists() else {}
    out: dict = {"poses": poses, "window": gui}
    # the share while posing: the last LIVE_S seconds before the shutdown (the model, the devices, the hub,
    # the recording and the drawing, without the start-up's imports and the calibration)
    if poses >= (LIVE_S + 5.0) * FPS_MODEL and samples:
        end = samples[-1][0] - 2.0
        part = [s for s in samples if end - LIVE_S <= s[0] <= end]
        if len(part) >= 2:
            out["live_share"] = round((part[-1][1] - part[0][1]) / (part[-1][0] - part[0][0]), 3)
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=50.0)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--variants", default="3d full,2d full,2d,headless",
                    help=f"comma-separated, of: {', '.join(VARIANTS)}")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    names = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown:
        ap.error(f"unknown variant(s) {unknown}: choose from {list(VARIANTS)}")
    runs: dict[str, list[dict]] = {n: [] for n in names}
    for _ in range(args.repeat):
        for name in names:
            model, steps, skeleton = VARIANTS[name]
            runs[name].append(one_round(steps, args.seconds, skeleton, model))
    shares = {n: [r.get("live_share") for r in rs] for n, rs in runs.items()}
    med = {n: float(np.median([x for x in v if x is not None])) if any(x is not None for x in v) else None
           for n, v in shares.items()}
    base = med[names[0]]
    res: dict = {"seconds": args.seconds, "live_s": LIVE_S, "shares": shares,
                 "share_of_one_core": {n: None if v is None else round(v, 3) for n, v in med.items()},
                 f"ratio_to_{names[0]}": {n: None if v is None or not base else round(v / base, 3)
                                          for n, v in med.items()}}
    # a window variant less the headless capture of the same model
    bare = {n: next((h for h, (m, st, sk) in VARIANTS.items() if sk is None and m == VARIANTS[n][0]), None)
            for n in med}
    shares_less = {n: round(v - med[bare[n]], 3) for n, v in med.items()
                   if v is not None and VARIANTS[n][2] is not None and med.get(bare[n]) is not None}
    if shares_less:
        res["window_share"] = shares_less
    res["windows"] = {n: [{k: r["window"].get(k) for k in ("gui_thread_cores", "draws_per_s", "draw_p50_ms",
                                                           "outdoor")} for r in rs]
                      for n, rs in runs.items() if VARIANTS[n][2] is not None}
    print(json.dumps(res) if args.json else "\n".join(f"{k}: {v}" for k, v in res.items()))


if __name__ == "__main__":
    main()
