"""How far behind the window's live loop runs: the window demo under a virtual display,
recorded, RUNS times for SECONDS each; per run, the live poses' latency and the 20 Hz frames
the loop did not pose, read back from the recording.

    .venv/bin/python benchmarks/window_live.py --runs 3 --seconds 40 [--json]

Needs xvfb-run. Run on an idle machine: the headless demo (`imucap demo --headless --json`)
is the reference without the window.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from app.recording import read_recording


def figures(path: Path) -> dict:
    """Latency and unposed 20 Hz frames of a recording's live reconstruction."""
    rec = read_recording(path).recon
    idx = np.asarray(rec["index"])
    lat = np.asarray(rec["latency_ms"], float)
    seen = np.asarray(rec["observed_sites"], bool)
    span = int(idx.max() - idx.min() + 1) if len(idx) else 0
    return {
        "poses": int(len(idx)), "not_posed": span - int(len(idx)),
        "latency_p50_ms": round(float(np.median(lat)), 1) if len(lat) else None,
        "latency_p90_ms": round(float(np.percentile(lat, 90)), 1) if len(lat) else None,
        "blind_poses": int((~seen.any(axis=1)).sum()),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    imucap = str(Path(sys.executable).with_name("imucap"))
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.runs):
            rec = Path(tmp) / f"run{k}.h5"
            cmd = ["xvfb-run", "-a", "-s", "-screen 0 1600x1000x24", imucap, "demo",
                   "--quit-after", f"{args.seconds:g}", "--record", str(rec)]
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0 or not rec.exists():
                print(f"run {k}: the demo failed (rc {done.returncode}): {done.stderr.strip()[-300:]}", file=sys.stderr)
                return 1
            out.append(figures(rec))
            if not args.json:
                print(f"run {k}: {out[-1]}")
    if args.json:
        print(json.dumps({"seconds": args.seconds, "runs": out}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
