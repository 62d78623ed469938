"""How many frames a headless capture drops: six sensors over three protocols plus insoles,
simulated in their own process at their real rates, captured and recorded by `imucap
capture` in another, for SECONDS after calibration.

    .venv/bin/python benchmarks/capture_drops.py --seconds 60 [--json]

Prints the 60 Hz hub frames and 20 Hz poses expected from the recording's time span, the
ones missing (index gaps), the pipeline's own drop count and the latency. Run on an idle
machine: on two shared cores a test suite next to it is what it measures.

    .venv/bin/python benchmarks/capture_drops.py --seconds 60 --load 3 [--json]

The same beside ``--load`` busy processes (a Python loop of small numpy operations each, at the capture's
priority): per site the share of hub frames after calibration that hold its sample (``present_pct``), and
the least of them; and every garbage collection of the capture process, timed (``--no-freeze``: the
startup heap left unfrozen, as before ``Pipeline.warm_up`` froze it). A collection holds the interpreter
from start to end, and a full one walks every tracked object: the ~210,000 that the model, torch and the
modules leave from the start unless they are frozen. The serial and UDP sensors are read by the hub's one
selector thread, the CAN ones on threads of their own; a stall of the capture's process (its turn on a
core, a collection, a thread holding the interpreter) showed as the selector's sites missing together,
until the hub's poll read them first (``Readers.catch_up``).
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.capture.simulate import read_truth  # noqa: E402
from app.recording import read_recording  # noqa: E402
from sim_devices.devices.can_loopback import loopback_channel  # noqa: E402

CLI = [sys.executable, "-m", "app.cli.main"]
# `imucap capture` with every garbage collection from the model's warm-up on timed (gc.callbacks;
# the collections the program asks for itself, as ``Pipeline.warm_up`` does, left out),
# the pauses written to argv[1] at exit; argv[2] "no-freeze" leaves the startup heap unfrozen
CAPTURE_TIMED = """
import atexit, gc, json, sys, time
out, freeze = sys.argv[1], sys.argv[2] == "freeze"
if not freeze:
    gc.freeze = lambda: None
pauses, started, asked = {0: [], 1: [], 2: []}, [], [False]
real_collect = gc.collect
def collect(*a):
    asked[0] = True
    try:
        return real_collect(*a)
    finally:
        asked[0] = False
gc.collect = collect
live = [False]  # from the model's warm-up on (the devices open after it): import and load left out
def timed(phase, info):
    if asked[0] or not live[0]:
        return
    if phase == "start":
        started.append(time.perf_counter())
    elif started:
        pauses[info["generation"]].append(time.perf_counter() - started.pop())
gc.callbacks.append(timed)
atexit.register(lambda: open(out, "w").write(json.dumps(
    {"frozen": gc.get_freeze_count(), "pauses": {f"gen{g}": p for g, p in pauses.items()}})))
sys.argv = ["imucap", *sys.argv[3:]]
from app.live.pipeline import Pipeline
warm_up = Pipeline.warm_up
def warm_up_then_time(self):
    warm_up(self)
    live[0] = True
Pipeline.warm_up = warm_up_then_time
from app.cli.main import main
raise SystemExit(main())
"""
BUSY = "import numpy as np\na = np.ones(64)\nwhile True:\n    a = np.sin(a) + 1.0\n"


def setup_text(tmp: Path) -> str:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    can_bus = loopback_channel()
    return f"""[subject]
id = "bench"
height = 1.75

[sensors]
pelvis  = "xbus://{tmp}/pelvis?baud=115200"
head    = "bno08x-rvc://{tmp}/head"
l_wrist = "xsens-can://remote/{can_bus}?id_offset=0x100"
r_wrist = "xsens-can://remote/{can_bus}?id_offset=0x200"
l_shank = "bno08x-rvc://{tmp}/l_shank"
r_shank = "xbus://{tmp}/r_shank?baud=115200"

[insoles]
url = "moticon-udp://127.0.0.1:{port}"
"""


def gaps(index: np.ndarray) -> int:
    d = np.diff(np.asarray(index, np.int64))
    return int(np.sum(np.maximum(d - 1, 0)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="capture after calibration")
    ap.add_argument("--load", type=int, default=0, help="busy processes beside the capture")
    ap.add_argument("--no-freeze", action="store_true",
                    help="leave the capture's startup heap unfrozen (gc.freeze in Pipeline.warm_up)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="imucap-drops-"))
    setup = tmp / "setup.toml"
    setup.write_text(setup_text(tmp))
    truth, rec = tmp / "truth.npz", tmp / "rec.h5"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    sim = subprocess.Popen([*CLI, "devices", "simulate", "--setup", str(setup), "--motion", "walk",
                            "--activity-seconds", str(args.seconds + 10), "--truth", str(truth), "--lead-in", "15"],
                           stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env, cwd=REPO)
    load = [subprocess.Popen([sys.executable, "-c", BUSY]) for _ in range(args.load)]
    try:
        for line in sim.stdout:
            if line.startswith("simulating"):
                break
        total = 15 + 7 + 4 + 3.5 + 1 + args.seconds
        gc_log = tmp / "gc.json"
        cap = subprocess.run([sys.executable, "-c", CAPTURE_TIMED, str(gc_log),
                              "no-freeze" if args.no_freeze else "freeze", "capture", "--setup", str(setup),
                              "--headless", "--record", str(rec),
                              "--seconds", f"{total:.0f}", "--json", "--countdown", "1"],
                             stdin=subprocess.DEVNULL, capture_output=True, text=True, env=env, cwd=REPO)
    finally:
        sim.terminate()
        sim.wait(10)
        for p in load:
            p.kill()
            p.wait()
    if cap.returncode != 0:
        print(cap.stderr[-2000:], file=sys.stderr)
        return 1
    res = json.loads(cap.stdout.strip().splitlines()[-1])
    r = read_recording(rec)
    tr = read_truth(truth)
    t_cal = r.calibrations[0][0] if r.calibrations else float("nan")
    raw_t, raw_i = r.raw["t"], r.raw["index"]
    live = raw_t > t_cal
    rec_t, rec_i = r.recon["t"], r.recon["index"]
    span = float(raw_t[live][-1] - raw_t[live][0]) if live.any() else 0.0
    hub_expected = int(raw_i[live][-1] - raw_i[live][0] + 1) if live.any() else 0
    hub_missing = gaps(raw_i[live])
    gc_out = json.loads(gc_log.read_text())
    pauses = {g: {"n": len(p), "max_ms": round(1e3 * max(p, default=0.0), 1), "total_ms": round(1e3 * sum(p), 1)}
              for g, p in gc_out["pauses"].items()}
    present = {site: round(100 * float(np.mean(np.asarray(r.raw[site]["present"])[live])), 2)
               for site in r.sites} if live.any() else {}
    pose_expected = int(round(span * 20)) + 1
    pose_missing = max(pose_expected - len(rec_t), 0)
    out = {
        "seconds_after_calibration": round(span, 1), "calibrated": res["calibrated"],
        "hub_frames_expected": hub_expected, "hub_frames_missing": hub_missing,
        "hub_missing_pct": round(100 * hub_missing / max(hub_expected, 1), 3),
        "poses_expected": pose_expected, "poses_recorded": int(len(rec_t)), "poses_missing": pose_missing,
        "poses_missing_pct": round(100 * pose_missing / max(pose_expected, 1), 3),
        "pose_index_gaps": gaps(rec_i), "pipeline_dropped": res["pipeline"].get("dropped"),
        "latency_p50_ms": res["latency_p50_ms"], "latency_p99_ms": res["latency_p99_ms"],
        "activity_start_s": round(tr.activity_start, 1), "load": args.load,
        "present_pct": present, "least_present_pct": min(present.values(), default=None),
        "gc_frozen_objects": gc_out["frozen"], "gc_pauses": pauses,
    }
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:28s} {v}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
