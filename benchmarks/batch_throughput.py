"""How fast a study is re-processed: hours of motion per hour of wall time, in one run.

    .venv/bin/python benchmarks/batch_throughput.py [--recordings 6] [--seconds 30] [--json]

Three ways over the same simulated recordings (6 sites, walking, written offline by
``app.capture.offline_session``), each taken in turn so the machine's load falls on all:
- ``replay_each``: one ``imucap replay REC --json`` process per recording, as a study was
  re-run before ``imucap batch`` (start-up paid per recording);
- ``batch_1``: ``imucap batch --workers 1`` (one worker process, the model loaded once);
- ``batch_pool``: ``imucap batch`` with its default pool (one worker per core).
Replay speed per core is motion seconds over CPU seconds of the replaying processes.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from app.capture.offline_session import write_session

CLI = [sys.executable, "-m", "app.cli.main"]


def _cpu_children() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def run(recordings: int, seconds: float) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="imucap-batch-bench-"))
    try:
        study = tmp / "study"
        study.mkdir()
        for k in range(recordings):
            write_session(study / f"r{k:02d}.h5", seconds=seconds, seed=k)
        motion = recordings * seconds
        out: dict = {"recordings": recordings, "seconds_each": seconds}

        c0, t0 = _cpu_children(), time.perf_counter()
        for p in sorted(study.glob("*.h5")):
            subprocess.run([*CLI, "replay", str(p), "--json", "--no-progress"], check=True, capture_output=True)
        out["replay_each"] = {"wall_s": round(time.perf_counter() - t0, 2), "cpu_s": round(_cpu_children() - c0, 2)}
        for name, extra in (("batch_1", ["--workers", "1"]), ("batch_pool", [])):
            c0, t0 = _cpu_children(), time.perf_counter()
            subprocess.run([*CLI, "batch", str(study), "--out", str(tmp / name), "--json", "--no-progress", *extra],
                           check=True, capture_output=True)
            out[name] = {"wall_s": round(time.perf_counter() - t0, 2), "cpu_s": round(_cpu_children() - c0, 2)}
        for v in (out["replay_each"], out["batch_1"], out["batch_pool"]):
            v["motion_hours_per_hour"] = round(motion / v["wall_s"], 2)
            v["real_time_per_core"] = round(motion / v["cpu_s"], 2)
        out["pool_over_one_process"] = round(out["batch_pool"]["motion_hours_per_hour"]
                                             / out["batch_1"]["motion_hours_per_hour"], 2)
        out["batch_1_over_replay_each"] = round(out["batch_1"]["motion_hours_per_hour"]
                                                / out["replay_each"]["motion_hours_per_hour"], 2)
        return out
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--recordings", type=int, default=6)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    res = run(args.recordings, args.seconds)
    print(json.dumps(res) if args.json else "\n".join(f"{k}: {v}" for k, v in res.items()))


if __name__ == "__main__":
    main()
