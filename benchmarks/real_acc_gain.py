"""The real logs scored with their free accelerations scaled or shifted in time, to ask whether the model
reads real accelerations as it reads synthesized ones.

    .venv/bin/python benchmarks/real_acc_gain.py [--gains 1.0 1.6] [--shifts 0] [--json out.json]

Each variant rewrites every imported sensor's specific force so that its free acceleration (gravity
removed in the sensor's own earth frame) is ``gain`` times the measured one, ``shift`` 60 Hz samples
earlier (negative: later), then runs ``imucap evaluate --data @real`` on it: the held-out segments' mean
errors (deg) per log and set. Nothing here changes what an import or a replay does (docs/real_signals.md,
"What differs": the gain).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json

import numpy as np

import app.evaluation.real as real
from app.cli.main import main as imucap
from app.recording import read_recording
from calibration.core import GRAVITY
from inference.body.rotations import quat_to_matrix_np


def altered(gain: float, shift: int):
    """``read_recording`` whose sensors' free accelerations are scaled by ``gain`` and moved ``shift``
    samples earlier."""
    def read(path, *args, **kwargs):
        rec = read_recording(path, *args, **kwargs)
        for site in rec.sites:
            d = rec.raw[site]
            R = quat_to_matrix_np(np.nan_to_num(np.asarray(d["quat"], dtype=np.float64), nan=1.0))
            free = np.einsum("nij,nj->ni", R, np.asarray(d["acc"], dtype=np.float64)) + GRAVITY
            if shift > 0:
                free[:-shift] = free[shift:]
            elif shift < 0:
                free[-shift:] = free[:shift].copy()
            d["acc"] = np.einsum("nji,nj->ni", R, gain * free - GRAVITY)
        return rec
    return read


def held_out(gain: float, shift: int) -> dict:
    real.read_recording = altered(gain, shift)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        imucap(["evaluate", "--data", "@real", "--json"])
    res = json.loads(out.getvalue())
    res = res.get("held_out", res)
    return {log: {label: r["deg"] for label, r in sets.items()} for log, sets in res.items()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gains", type=float, nargs="+", default=[1.0, 1.6])
    ap.add_argument("--shifts", type=int, nargs="+", default=[0], help="60 Hz samples earlier (negative: later)")
    ap.add_argument("--json", help="write the results here")
    a = ap.parse_args(argv)
    results = {}
    for shift in a.shifts:
        for gain in a.gains:
            key = f"gain {gain:g}, shift {shift}"
            results[key] = held_out(gain, shift)
            for log, sets in results[key].items():
                for label, deg in sets.items():
                    print(f"{key} | {log} | {label} | " + ", ".join(f"{s} {v:.2f}" for s, v in deg.items()), flush=True)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
