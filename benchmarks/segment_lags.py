"""Each segment's error of a recording's live poses against a simulator's truth, at the
truth's own clock (lag 0) and at the segment's own best lag, beside the one lag
``imucap replay --truth`` fits for the whole body.

Why: replay's lag is the one that minimises the whole body's GA, which the unobserved
segments (pelvis, thighs: 5-10 deg, preferring lags at the search's edge) dominate; a
stream that trails the others (a VR rig's tracking latency) can pull it off zero, and
then an observed segment of another stream (a shank) is scored at the wrong instant
(docs/vr_input.md, "End to end").

    .venv/bin/python benchmarks/segment_lags.py REC.h5 TRUTH.npz [--segments head,l_forearm,...]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.capture.simulate import read_truth  # noqa: E402
from app.recording import read_recording  # noqa: E402
from inference.body.rotations import matrix_angle_between  # noqa: E402
from inference.body.skeleton import SEGMENT_INDEX  # noqa: E402

DEFAULT = "head,l_forearm,r_forearm,l_shank,r_shank,pelvis"
MAX_LAG_S = 0.2


def segment_lags(rec_path: Path, truth_path: Path, segments: list[str]) -> dict[str, dict[str, float]]:
    r = read_recording(rec_path)
    truth = read_truth(truth_path)
    t, R = r.recon["t"], r.recon["R"]
    keep = (t >= truth.t0 + truth.activity_start) & ((t - truth.t0) * truth.fps < len(truth.rot) - 0.5)
    t, R = t[keep], R[keep]
    lags = np.arange(-MAX_LAG_S, MAX_LAG_S + 1e-9, 1.0 / truth.fps)
    out = {}
    for s in segments:
        k = SEGMENT_INDEX[s]
        err = [float(np.rad2deg(matrix_angle_between(R[:, k], truth.rot[truth.frame_at(t - lag), k])).mean())
               for lag in lags]
        best = int(np.argmin(err))
        zero = int(np.argmin(np.abs(lags)))
        out[s] = {"at_zero_deg": round(err[zero], 2), "best_deg": round(err[best], 2),
                  "best_lag_s": round(float(lags[best]), 4)}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("--segments", default=DEFAULT)
    a = ap.parse_args()
    print(json.dumps(segment_lags(a.recording, a.truth, [s for s in a.segments.split(",") if s])))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
