"""A long live session, to see what drifts: resident memory, latency, queues, drops.

    .venv/bin/python benchmarks/soak.py --minutes 60 [--slice 5] [--json]

An ``imucap demo`` session (``app.capture.demo``: six simulated sensors and insoles in a
process of their own, over their real transports: ptys, CAN on loopback, UDP) plays a walk
at real rate into the hub, the pipeline and the shipped model, recording on
(the recording is deleted at the end unless --keep). Every --slice minutes one row: the
process's resident memory, latency p50/p99 of that slice's poses, the hub's and the
pipeline's queue depths, the frames dropped and filled in the slice, and the recording's
size. A live demo that lagged further behind the longer it ran (TransPose's issue 55)
shows here as a latency that climbs from slice to slice; a leak as a memory that does.

    .venv/bin/python benchmarks/soak.py --recorder-only --minutes 60 [--json]

The recorder alone, fed the frames of --minutes simulated minutes (six sensors, 60 Hz)
as fast as it takes them: per simulated minute the CPU it spent, glibc's heap in use and
the file's size. Whether writing gets slower or holds more as the file grows, without a
live session's noise around it.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import resource
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.capture.demo import DemoConfig, DemoRun  # noqa: E402
from app.live import Sink  # noqa: E402


def rss_mb() -> float:
    """Current resident set size (not the peak ru_maxrss): what a leak makes grow."""
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * resource.getpagesize() / 2**20


class _Mallinfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]


def malloc_stats() -> dict[str, float]:
    """glibc's heap totals over all arenas (MB): ``in_use`` (allocated and not freed),
    ``free`` (freed but kept by the allocator), ``mmapped`` (large blocks mapped on their
    own). A leak grows ``in_use``; fragmentation grows ``free``."""
    libc = ctypes.CDLL("libc.so.6")
    libc.mallinfo2.restype = _Mallinfo2
    m = libc.mallinfo2()
    return {"in_use": round(m.uordblks / 2**20, 1), "free": round(m.fordblks / 2**20, 1),
            "mmapped": round(m.hblkhd / 2**20, 1)}


def malloc_trim() -> None:
    ctypes.CDLL("libc.so.6").malloc_trim(0)


class SliceLatency(Sink):
    """Latencies of the poses since the last ``take``."""

    def __init__(self) -> None:
        self.lat: list[float] = []

    def on_pose(self, pose) -> None:
        if pose.latency_ms is not None:
            self.lat.append(pose.latency_ms)

    def take(self) -> list[float]:
        out, self.lat = self.lat, []
        return out


def recorder_only(minutes: int, as_json: bool) -> int:
    from app.recording import Recorder
    from drivers.hub import HubFrame

    sites = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
    S = len(sites)
    now = [0.0]
    path = Path(tempfile.mkdtemp(prefix="imucap-soak-")) / "recorder.h5"
    rec = Recorder(path, sites=sites, metadata={"source": "soak --recorder-only"}, clock=lambda: now[0])
    rng = np.random.default_rng(0)
    try:
        for m in range(minutes):
            c0 = time.process_time()
            for k in range(3600):
                i = m * 3600 + k
                now[0] = i / 60
                q = rng.normal(size=(S, 4))
                rec.on_frame(HubFrame(now[0], i, sites, q / np.linalg.norm(q, axis=1, keepdims=True),
                                      rng.normal(size=(S, 3)), rng.normal(size=(S, 3)), rng.normal(size=(S, 3)),
                                      np.ones(S, bool), np.zeros(2), np.zeros(4, bool), True))
            row = {"minute": m + 1, "cpu_s": round(time.process_time() - c0, 3),
                   "heap_in_use_mb": malloc_stats()["in_use"], "file_mb": round(path.stat().st_size / 2**20, 1)}
            print(json.dumps(row) if as_json else "  ".join(f"{k}={v}" for k, v in row.items()), flush=True)
    finally:
        rec.close()
        path.unlink(missing_ok=True)
    return 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--slice", type=float, default=5.0, help="minutes per row")
    ap.add_argument("--keep", action="store_true", help="keep the recording")
    ap.add_argument("--no-record", action="store_true", help="no recording (what the rest costs)")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--model", default="diffusion", help="diffusion | regressor | floor (no network) | PATH.pt")
    ap.add_argument("--protocol", default="mixed", help="the suit's wire protocol(s), as imucap demo --protocol")
    ap.add_argument("--malloc", action="store_true",
                    help="per slice also glibc's heap totals (in use / free / mmapped, MB): a leak or fragmentation")
    ap.add_argument("--trim", action="store_true", help="give freed heap memory back (malloc_trim) after each slice")
    ap.add_argument("--tracemalloc", type=int, default=0, metavar="N",
                    help="trace Python and numpy allocations; per slice the N source lines whose memory grew most "
                         "since the first slice")
    ap.add_argument("--recorder-only", action="store_true",
                    help="only the recorder, fed --minutes simulated minutes of frames as fast as it takes them")
    args = ap.parse_args()
    if args.recorder_only:
        return recorder_only(int(args.minutes), args.json)
    if args.tracemalloc:
        tracemalloc.start(8)
    base_snapshot = None
    rec = Path(tempfile.mkdtemp(prefix="imucap-soak-")) / "soak.h5"
    # a minute's walk that loops, after the guided walk calibration
    cfg = DemoConfig(motion="walk", insoles=True, protocol=args.protocol, seconds=60.0,
                     record=None if args.no_record else str(rec), model=args.model)
    demo = DemoRun(cfg)
    session = demo.session
    lat = SliceLatency()
    session.pipeline.add_sink(lat)
    rows = []
    demo.start()
    if not demo.run_for(0.0):
        demo.stop()
        raise SystemExit(f"soak: the session did not calibrate: {session.guided.status()}")
    t0 = time.monotonic()
    last = session.pipeline.stats.summary()
    try:
        for k in range(int(np.ceil(args.minutes / args.slice))):
            end = t0 + min((k + 1) * args.slice, args.minutes) * 60
            while time.monotonic() < end:
                time.sleep(1.0)
            st = session.pipeline.stats.summary()
            live = session.live.stats() if session.live else {}
            hub_q = max((len(tr.queue) for tr in session.hub.tracks.values()), default=0) if session.hub else 0
            ls = lat.take()
            rows.append({
                "slice": k + 1, "minute": round((time.monotonic() - t0) / 60, 1), "rss_mb": round(rss_mb(), 1),
                "latency_p50_ms": round(float(np.percentile(ls, 50)), 1) if ls else None,
                "latency_p99_ms": round(float(np.percentile(ls, 99)), 1) if ls else None,
                "poses": st["poses"] - last["poses"], "dropped": st["dropped"] - last["dropped"],
                "filled": st["frames_filled"] - last["frames_filled"], "pipeline_queue": live.get("queued"),
                "hub_queue_max": hub_q, "recording_mb": round(rec.stat().st_size / 2**20, 1) if rec.exists() else 0,
            })
            if args.malloc:
                rows[-1]["malloc_mb"] = malloc_stats()
            if args.tracemalloc:
                snap = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(False, tracemalloc.__file__)])
                if base_snapshot is None:
                    base_snapshot = snap
                else:
                    grew = snap.compare_to(base_snapshot, "lineno")[: args.tracemalloc]
                    rows[-1]["grew_kb"] = {f"{st.traceback[0].filename.split('/')[-1]}:{st.traceback[0].lineno}":
                                           round(st.size_diff / 1024) for st in grew}
            if args.trim:
                malloc_trim()
                rows[-1]["rss_after_trim_mb"] = round(rss_mb(), 1)
            last = st
            print(json.dumps(rows[-1]) if args.json else "  ".join(f"{k}={v}" for k, v in rows[-1].items()),
                  flush=True)
    finally:
        demo.stop()
        if not args.keep:
            rec.unlink(missing_ok=True)
    if len(rows) > 2:
        first, end = rows[1], rows[-1]  # the first slice holds the warm-up (model load, calibration)
        summary = {"rss_change_pct": round(100 * (end["rss_mb"] / first["rss_mb"] - 1), 1),
                   "p99_change_pct": (round(100 * (end["latency_p99_ms"] / first["latency_p99_ms"] - 1), 1)
                                      if end["latency_p99_ms"] and first["latency_p99_ms"] else None)}
        print(json.dumps(summary) if args.json else f"last vs second slice: {summary}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
