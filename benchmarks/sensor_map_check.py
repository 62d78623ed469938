"""Which sensor is on which leg: the checks docs/real_signals.md ("The OpenSense sensor map")
reports, from the signals alone.

    .venv/bin/python benchmarks/sensor_map_check.py [LOG] [--map ID=SITE ...] [--json]

LOG defaults to $IMUCAP_DATA/opensense/xsens_mtw_walk with ``OPENSENSE_MAP``
(app/evaluation/real.py); an x-IMU3 folder, whose device names say their sites, is the
control. The log is imported as ``imucap import`` does with the map under test, then:

- pairing: correlation of the angular speeds of every two leg sensors over the moving frames,
  at the best lag within 0.3 s: a thigh and a foot go with their own leg's shank;
- alternation: the two shanks, best lag and correlation at lag 0 (anti-phase);
- landings: each foot's landings (start of a still foot) against the last swing peak of
  each shank: its own shank's comes a few tenths of a second before, the other's a step earlier;
- trunk: yaw rate (world Z, mounting-free) of torso against pelvis;
- pelvis rotation: the pelvis' yaw rate about its stride mean while one leg swings faster
  than the other: it turns forward on the side of the swinging leg (positive, to the left,
  while the right leg swings);
- forward: the direction the knees bend (the shank's lower end behind the thigh's at peak
  flexion), in the sensors' shared Earth frame, against the pelvis sensor's axes (Xsens MTw:
  one frame for all; not meaningful for the x-IMU3, whose headings are each its own);
- mounting: each sensor's axes in its bone's frame after the import's calibration (X
  forward, Y left, Z up): which side of its segment the sensor's z axis points to.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import find_peaks

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

FPS = 60.0


def _corr_at(a, b, m, lag):
    head, tail = slice(max(0, lag), len(a) + min(0, lag)), slice(max(0, -lag), len(b) + min(0, -lag))
    x, y, mm = a[head], b[tail], m[head]
    return float(np.corrcoef(x[mm], y[mm])[0, 1])


def best_lag(a, b, moving, max_s):
    """(best correlation, lag in s by which b follows a) within +-max_s, and the correlation at 0."""
    lags = range(-int(max_s * FPS), int(max_s * FPS) + 1)
    c = {L: _corr_at(a, b, moving, L) for L in lags}
    L = max(c, key=c.get)
    return round(c[L], 2), round(-L / FPS, 3), round(c[0], 2)


def check(rec) -> dict:
    from app.evaluation.phases import classify_phases, quat_matrices, world_rates

    sites = rec.sites
    R = {s: quat_matrices(rec.raw[s]["quat"]) for s in sites}
    lab = classify_phases(R, FPS)
    moving, walking = lab != "standing", lab == "walking"
    w = {s: world_rates(R[s], FPS) for s in sites}
    speed = {s: uniform_filter1d(np.nan_to_num(np.linalg.norm(w[s], axis=-1)), 6) for s in sites}
    legs = [s for s in sites if s[2:] in ("thigh", "shank", "foot")]
    out: dict = {"phases_s": {p: round(float(np.mean(lab == p)) * len(lab) / FPS, 1) for p in np.unique(lab)}}
    out["pairing"] = {a: {b: best_lag(speed[a], speed[b], moving, 0.3)[::2] for b in ("l_shank", "r_shank")}
                      for a in legs if not a.endswith("shank")}
    out["thigh_to_shank_lag_s"] = {side: best_lag(speed[f"{side}_thigh"], speed[f"{side}_shank"], moving, 0.3)[1]
                                   for side in "lr"}
    c0 = round(_corr_at(speed["l_shank"], speed["r_shank"], moving, 0), 2)
    lag2 = max(range(int(0.2 * FPS), int(1.0 * FPS)),
               key=lambda L: _corr_at(speed["l_shank"], speed["r_shank"], moving, L))
    out["shanks"] = {"corr_at_0": c0, "best_positive_lag_s": round(lag2 / FPS, 3),
                     "corr_there": round(_corr_at(speed["l_shank"], speed["r_shank"], moving, lag2), 2)}
    land = {}
    for side in "lr":
        still = speed[f"{side}_foot"] < 1.0
        on = np.flatnonzero(still[1:] & ~still[:-1]) + 1
        on = np.array([p for p in on if still[p:p + 9].all() and moving[p]], dtype=int)
        land[f"{side}_foot"] = {"landings": int(len(on))}
        for sh in ("l_shank", "r_shank"):
            pk, _ = find_peaks(speed[sh], height=1.5, distance=int(0.6 * FPS))
            d = [(p - pk[pk < p].max()) / FPS for p in on if (pk < p).any()]
            land[f"{side}_foot"][f"after_{sh}_s"] = round(float(np.median(d)), 2) if d else None
    out["landings"] = land
    if "torso" in sites and "pelvis" in sites:
        a, b = (uniform_filter1d(np.nan_to_num(w[s][:, 2]), 12) for s in ("torso", "pelvis"))
        out["trunk"] = {"yaw_rate_corr": round(float(np.corrcoef(a, b)[0, 1]), 3),
                        "turn_deg": {"torso": round(float(np.degrees(a.sum() / FPS))),
                                     "pelvis": round(float(np.degrees(b.sum() / FPS)))}}
    yaw = np.nan_to_num(w["pelvis"][:, 2])
    hp = yaw - uniform_filter1d(yaw, int(1.2 * FPS))
    diff = speed["r_shank"] - speed["l_shank"]
    out["pelvis_yaw_deg_s"] = {"r_swings": round(float(np.degrees(hp[walking & (diff > 1)].mean())), 1),
                               "l_swings": round(float(np.degrees(hp[walking & (diff < -1)].mean())), 1),
                               "corr": round(float(np.corrcoef(hp[walking], diff[walking])[0, 1]), 2)}
    fwd = []
    for side in "lr":
        up_t, up_s = R[f"{side}_thigh"], R[f"{side}_shank"]
        k = int(np.argmax([np.abs(np.nanmedian(up_t[moving][:, 2, i])) for i in range(3)]))  # the long axis
        sgn = np.sign(np.nanmedian(up_t[~moving][:, 2, k])) if (~moving).any() else 1.0
        th, sh = -sgn * up_t[:, :, k], -sgn * up_s[:, :, k]  # pointing down the leg
        knee = np.degrees(np.arccos(np.clip(np.sum(th * sh, -1), -1, 1)))
        for p in find_peaks(np.nan_to_num(knee), height=35, distance=int(0.6 * FPS))[0]:
            v = -(sh[p] - th[p])
            z = R["pelvis"][p][:, 2]
            fwd.append(np.degrees(np.arctan2(v[0] * z[1] - v[1] * z[0], v[0] * z[0] + v[1] * z[1])))
    out["knee_forward_vs_pelvis_z_deg"] = {"n": len(fwd), "median": round(float(np.median(fwd)), 1),
                                           "p10_p90": [round(float(x), 1) for x in np.percentile(fwd, [10, 90])]}
    _, cal = rec.calibrations[-1]
    out["sensor_z_in_bone"] = {s: [round(float(x), 2) for x in cal.R_SB[cal.sites.index(s)].T[:, 2]] for s in sites}
    return out


def main() -> int:
    from app.cli.importing import import_paths
    from app.evaluation.real import OPENSENSE_MAP
    from app.recording import read_recording
    from inference.training.data import data_root

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("log", nargs="?")
    ap.add_argument("--map", action="append", default=[], metavar="ID=SITE")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    log = Path(args.log) if args.log else data_root() / "opensense" / "xsens_mtw_walk"
    mapping = dict(m.split("=", 1) for m in args.map) if args.map else (OPENSENSE_MAP if not args.log else {})
    with tempfile.TemporaryDirectory() as tmp:
        import_paths([log], Path(tmp) / "s.h5", mapping=mapping, reconstruct=False)
        res = check(read_recording(Path(tmp) / "s.h5"))
    print(json.dumps(res) if args.json else json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
