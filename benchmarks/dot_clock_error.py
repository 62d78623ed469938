"""How far apart the hub puts several Movella DOTs without the DOT's own synchronisation.

Each DOT stamps its samples with its own crystal (offset and drift of its own); over BLE a
notification leaves at the link's next connection event, so it arrives 0..one connection
interval after it was sampled, the phase set by when that link was made. The hub's clock
model (``drivers.hub.ClockModel``: a line through the lower envelope of arrival - device
time) maps each DOT onto the host clock; what it cannot see is a delivery delay that never
gets small. This plays that model: per DOT a random offset, drift within +-50 ppm and a
random connection-event phase, samples at 60 Hz, arrivals at the next connection event plus
0-2 ms of host scheduling, and reports the error of the mapped time of a sample (the
inter-DOT clock error is the spread of those errors).

    python benchmarks/dot_clock_error.py [--seconds 120] [--dots 6] [--trials 20] [--json]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.hub import ClockModel  # noqa: E402

RATE = 60.0


def one_dot(rng: np.random.Generator, seconds: float, interval_ms: float) -> float:
    """Mean error (s) of the mapped time of this DOT's samples over the run's last half."""
    n = int(seconds * RATE)
    true_t = np.arange(n) / RATE + rng.uniform(0, 1 / RATE)  # host time each sample was taken
    drift = rng.uniform(-50e-6, 50e-6)
    device_t = rng.uniform(0, 3000) + true_t * (1 + drift)
    iv = interval_ms * 1e-3
    phase = rng.uniform(0, iv)
    events = np.ceil((true_t - phase) / iv) * iv + phase  # next connection event after each sample
    arrival = events + rng.uniform(0, 0.002, n)
    model = ClockModel()
    err = []
    for k in range(n):
        model.update(float(device_t[k]), float(arrival[k]))
        if k > n // 2 and model.offset is not None:
            err.append(model.map(float(device_t[k])) - true_t[k])
    return float(np.mean(err))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--dots", type=int, default=6)
    ap.add_argument("--trials", type=int, default=20)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    out = {}
    for interval in (7.5, 15.0, 16.25, 30.0, 45.0, 50.0):  # 50 ms = 3 sample periods: the phase hardly slides
        spreads, worst = [], 0.0
        for _ in range(args.trials):
            e = np.array([one_dot(rng, args.seconds, interval) for _ in range(args.dots)])
            spreads.append(float(e.max() - e.min()))
            worst = max(worst, float(np.abs(e).max()))
        out[f"{interval:g}ms"] = {"median_spread_ms": round(1e3 * float(np.median(spreads)), 2),
                                  "p95_spread_ms": round(1e3 * float(np.percentile(spreads, 95)), 2),
                                  "worst_abs_error_ms": round(1e3 * worst, 2)}
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"connection interval {k}: spread between {args.dots} DOTs median {v['median_spread_ms']} ms, "
                  f"95th percentile {v['p95_spread_ms']} ms; worst single DOT {v['worst_abs_error_ms']} ms")


if __name__ == "__main__":
    main()
