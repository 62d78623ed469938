"""Does the window keep up? The demo with its window (under a virtual display) beside the
same demo headless, on an idle machine and beside a load of 2 busy processes, in one run.

    .venv/bin/python benchmarks/window_live.py [--runs 2] [--seconds 40] [--loads 0,2] [--json]

Both front ends run the very same capture session (`app/capture/demo.py`), recorded. Per
run and front end, from the recording: the live poses' latency (p50/p90/p99) and the 20 Hz
frames the live loop had no time to pose (``not_posed``, the recording's ``pose skipped``
events); from the window itself (``--window-stats``): redraws a second, the time to hand a
pose to the view, the GUI thread's CPU share and the view timer's lag. The figures that
matter are ratios within one load: window latency over headless latency, and the frames
the window's session left unposed against the headless one's.

Needs xvfb-run. The load is ``python -c "while True: pass"`` x N at normal priority.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.live import POSE_SKIPPED_EVENT  # noqa: E402
from app.recording import read_recording  # noqa: E402

IMUCAP = [sys.executable, "-m", "app.cli.main"]
CALIBRATION_S = 25.0  # the window demo runs this long before its --seconds of activity (guided walk, start-up)


def figures(path: Path) -> dict:
    """Latency and unposed 20 Hz frames of a recording's live reconstruction, after calibration."""
    r = read_recording(path)
    rec = r.recon
    lat = np.asarray(rec["latency_ms"], float)
    lat = lat[np.isfinite(lat)]
    seen = np.asarray(rec["observed_sites"], bool)

    def pct(q: float) -> float | None:
        return round(float(np.percentile(lat, q)), 1) if len(lat) else None

    return {
        "poses": int(len(rec["t"])), "not_posed": sum(kind == POSE_SKIPPED_EVENT for _, kind, _ in r.events),
        "latency_p50_ms": pct(50), "latency_p90_ms": pct(90), "latency_p99_ms": pct(99),
        "blind_poses": int((~seen.any(axis=1)).sum()) if len(seen) else 0,
    }


def run_window(tmp: Path, k: int, seconds: float) -> dict:
    rec, stats = tmp / f"window{k}.h5", tmp / f"window{k}.json"
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", *IMUCAP, "demo", "--seconds", f"{seconds:g}",
           "--quit-after", f"{seconds + CALIBRATION_S:g}", "--record", str(rec), "--window-stats", str(stats)]
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0 or not rec.exists() or not stats.exists():
        raise RuntimeError(f"the window demo failed (rc {done.returncode}): {done.stderr.strip()[-300:]}")
    window = json.loads(stats.read_text())
    window.pop("pipeline", None)  # the recording's figures stand for the session
    return {**figures(rec), "window": window}


def run_headless(tmp: Path, k: int, seconds: float) -> dict:
    rec = tmp / f"headless{k}.h5"
    done = subprocess.run([*IMUCAP, "demo", "--headless", "--json", "--seconds", f"{seconds:g}", "--record", str(rec)],
                          capture_output=True, text=True)
    if done.returncode != 0 or not rec.exists():
        raise RuntimeError(f"the headless demo failed (rc {done.returncode}): {done.stderr.strip()[-300:]}")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    return {**figures(rec), "fps": out["fps"], "ga_deg": out["ga_deg"], "hub": out["hub"]}


def hub_text(front: dict) -> str:
    hub = front.get("window", {}).get("hub") or front.get("hub") or {}
    return f"hub wait {hub.get('wait_ms')} ms (max {hub.get('wait_max_ms')})" if hub else ""


def busy(n: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(n)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=40.0, help="activity seconds per run, after the calibration")
    ap.add_argument("--loads", default="0,2", help="busy processes beside the demo, one condition each")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for load in (int(x) for x in args.loads.split(",")):
            for k in range(args.runs):
                hogs = busy(load)
                try:
                    # alternate which front end goes first, so a drift in the machine hits both
                    order = ("window", "headless") if k % 2 == 0 else ("headless", "window")
                    res = {}
                    for front in order:
                        fn = run_window if front == "window" else run_headless
                        res[front] = fn(Path(tmp), len(rows) * 2 + (front == "window"), args.seconds)
                finally:
                    for h in hogs:
                        h.kill()
                w, h = res["window"], res["headless"]
                row = {"load": load, "run": k, "window": w, "headless": h,
                       "latency_p50_ratio": (round(w["latency_p50_ms"] / h["latency_p50_ms"], 2)
                                             if w["latency_p50_ms"] and h["latency_p50_ms"] else None),
                       "latency_p99_ratio": (round(w["latency_p99_ms"] / h["latency_p99_ms"], 2)
                                             if w["latency_p99_ms"] and h["latency_p99_ms"] else None)}
                rows.append(row)
                if not args.json:
                    print(f"load {load} run {k}: window p50/p99 {w['latency_p50_ms']}/{w['latency_p99_ms']} ms, "
                          f"not posed {w['not_posed']}/{w['poses'] + w['not_posed']}, "
                          f"{w['window']['draws_per_s']} draws/s, draw p50 {w['window']['draw_p50_ms']} ms, "
                          f"GUI thread {w['window']['gui_thread_cores']} core, {hub_text(w)} | headless p50/p99 "
                          f"{h['latency_p50_ms']}/{h['latency_p99_ms']} ms, not posed {h['not_posed']}/"
                          f"{h['poses'] + h['not_posed']}, {hub_text(h)} | ratio p50 {row['latency_p50_ratio']} "
                          f"p99 {row['latency_p99_ratio']}", flush=True)
    if args.json:
        print(json.dumps({"seconds": args.seconds, "runs": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
