"""How far a recording started in the middle of a session replays from the live poses: the
same recording replayed whole and from SECONDS after its calibration, compared on the same
frames. The gap is the poser's state (its history, stride scale, root odometry) that a
recording started late does not hold (NOTES.md, "Export and replay").

    .venv/bin/python benchmarks/replay_cut.py REC.h5 [--after 20]

REC.h5: any recording from a session's start, e.g.
``imucap demo --headless --seconds 40 --record REC.h5``.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.export.formats import body_for_recording  # noqa: E402
from app.recording import Recording, read_recording  # noqa: E402
from app.replay import ReplaySettings, build_replay_poser, match_times, replay_recording  # noqa: E402
from inference.metrics.errors import global_angle_error  # noqa: E402


def _cut(rec: Recording, i0: int) -> Recording:
    def cut(v):
        if isinstance(v, dict):
            return {k: cut(x) for k, x in v.items()}
        return v[i0:] if isinstance(v, np.ndarray) and len(v) == rec.n_frames else v

    return dataclasses.replace(rec, raw=cut(rec.raw))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("recording", type=Path)
    ap.add_argument("--after", type=float, default=20.0, help="seconds after the calibration to cut at")
    args = ap.parse_args()
    rec = read_recording(args.recording)
    body, _ = body_for_recording(rec.metadata)

    def run(r: Recording):
        built = build_replay_poser(r, ReplaySettings(), body)
        poses = replay_recording(r, built.poser, causal=built.causal).poses
        return np.array([p.t for p in poses]), np.stack([p.pose.rot for p in poses])

    t_full, R_full = run(rec)
    i0 = int(np.searchsorted(rec.raw["t"], rec.calibrations[0][0] + args.after))
    t_cut, R_cut = run(_cut(rec, i0))
    j = match_times(t_cut, t_full)
    ga = global_angle_error(R_cut[j >= 0], R_full[j[j >= 0]])
    for s in (0, 1, 2, 5, 10, 20):
        k = int(s * 20)
        if k < len(ga):
            print(f"{s:3d} s after the cut: GA {ga[k]:.3f} deg, mean over the next second {ga[k:k + 20].mean():.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
