"""Where the real logs' thigh error sits, stage by stage (pelvis + shanks, thighs held out).

    .venv/bin/python benchmarks/real_thigh_stages.py [--model diffusion] [--lags 6] [--json out.json]

For every real log under ``$IMUCAP_DATA`` (``imucap evaluate --data @real``'s logs), the
thighs with pelvis + shanks worn, against their own sensors (the replay with every sensor):

- ``output``: the poses as a replay gives them, then with the output stage's parts taken
  out in turn (the 1-Euro smoothing of unmeasured segments, the knee hinge);
- ``window``: the model's own answer before the output stage, for the newest frame and for
  the frames k = 1.. back in the same window (what a replay that waits k frames could show);
- ``sagittal``: the thigh's forward swing (long axis in the pelvis's heading frame) against
  the sensor's: the model's range, the best-correlating lag (frames of 50 ms) and r;
- ``constant``: the constant part of the error (``app.evaluation.offset``) split into its
  rotation vector in the thigh's frame (x forward, y left, z along the bone).

Errors from the second second on (the standing start is the calibration's). Why this exists:
docs/real_signals.md, "The thighs stage by stage".
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from inference.body.conventions import rot_z, yaw_of
from inference.body.rotations import matrix_angle_between, rot6d_to_matrix
from inference.body.skeleton import SEGMENT_INDEX
from inference.features.layout import SL_ROT
from inference.poser.poser import reconstruct_offline

SENSORS = ("pelvis", "l_shank", "r_shank")
THIGHS = ("l_thigh", "r_thigh")
SKIP = 20  # frames: the calibration's standing start


def deg_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.asarray(matrix_angle_between(a, b)))


def forward_swing_deg(seg: np.ndarray, pelvis: np.ndarray) -> np.ndarray:
    """(T,) the long axis's lean forward in the pelvis's heading frame (sagittal swing)."""
    turn = rot_z(yaw_of(pelvis))
    z = np.einsum("nji,nj->ni", turn, seg[:, :, 2])
    return np.degrees(np.arctan2(z[:, 0], z[:, 2]))


def best_lag(model: np.ndarray, sensor: np.ndarray, most: int = 8) -> tuple[int, float]:
    """Frames by which ``model`` trails ``sensor`` at the best correlation, and that r."""
    lags = range(-most, most + 1)
    r = [np.corrcoef(np.roll(model, -k)[most:-most], sensor[most:-most])[0, 1] for k in lags]
    k = int(np.argmax(r))
    return list(lags)[k], float(r[k])


def features_and_truth(rec, built):
    """What the poser gets with pelvis + shanks (features, masks) and the all-sensor replay."""
    from app.replay.run import replay_recording

    full = replay_recording(rec, built.fresh(), sensors=rec.sites, causal=built.causal).poses
    poser = built.fresh()
    feats, masks = [], []
    step = poser.step

    def record(f, m, points=None):
        feats.append(np.array(f, dtype=np.float64))
        masks.append(np.array(m, dtype=bool))
        return step(f, m, points)

    poser.step = record
    poses = replay_recording(rec, poser, sensors=list(SENSORS), causal=built.causal).poses
    return (np.array(feats), np.array(masks), np.array([p.pose.rot for p in full]),
            np.array([p.pose.rot for p in poses]), np.array([p.t for p in full]))


def stages(rec, built, lags: int) -> dict:
    from app.evaluation.offset import constant_and_dynamic, mean_rotation
    from app.evaluation.real import phase_at, recording_phases

    F, M, truth, as_replayed, t = features_and_truth(rec, built)
    T = len(truth)
    out: dict = {"frames": T, "output": {}, "window": {}, "sagittal": {}, "constant": {}, "last_stand": None}

    def score(rot: np.ndarray) -> dict[str, float]:
        return {s: round(float(deg_between(rot[SKIP:T, SEGMENT_INDEX[s]], truth[SKIP:, SEGMENT_INDEX[s]]).mean()), 2)
                for s in THIGHS}

    out["output"]["as replayed"] = score(as_replayed)
    K = lags + 1
    window: list[np.ndarray] = []
    for label, hinge, smooth in (("no smoothing", True, False), ("no knee hinge", False, True),
                                 ("neither", False, False)):
        poser = built.fresh()
        poser.knee_hinge = poser.knee_hinge and hinge
        if not smooth:
            poser._filters = None
        if label == "neither":
            predict = poser._predict

            def keep(win, mask, predict=predict, poser=poser):
                o = predict(win, mask)
                y = o[0, -K:].numpy() * poser._std.numpy() + poser._mean.numpy()
                window.append(y[:, SL_ROT].reshape(K, -1, 6)[:, [SEGMENT_INDEX[s] for s in THIGHS]])
                return o

            poser._predict = keep
        out["output"][label] = score(reconstruct_offline(poser, F, M).rot)
    w = np.array(window)  # (T, K, 2, 6): row K-1 is the newest frame
    for k in range(K):
        est = rot6d_to_matrix(w[k:, K - 1 - k])  # step t's answer for frame t - k
        out["window"][f"{k} back"] = {
            s: round(float(deg_between(est[SKIP:, j], truth[SKIP:T - k, SEGMENT_INDEX[s]]).mean()), 2)
            for j, s in enumerate(THIGHS)}
    pelvis = truth[:, SEGMENT_INDEX["pelvis"]]
    for s in THIGHS:
        i = SEGMENT_INDEX[s]
        pm, ps = forward_swing_deg(as_replayed[:, i], pelvis), forward_swing_deg(truth[:, i], pelvis)
        lag, r = best_lag(pm, ps)
        out["sagittal"][s] = {"range_model": round(float(np.ptp(np.percentile(pm, [5, 95]))), 1),
                              "range_sensor": round(float(np.ptp(np.percentile(ps, [5, 95]))), 1),
                              "lag_frames": lag, "r": round(r, 2)}
        mean = mean_rotation(np.einsum("nji,njk->nik", truth[SKIP:, i], as_replayed[SKIP:T, i]))
        c, d = constant_and_dynamic(as_replayed[SKIP:T, i], truth[SKIP:, i])
        out["constant"][s] = {"deg": round(c, 1), "dynamic_deg": round(d, 1),
                              "rotvec_deg": np.round(Rotation.from_matrix(mean).as_rotvec(degrees=True), 1).tolist()}
    labels = phase_at(*recording_phases(rec), t)
    if labels[-1] == "standing":  # the log ends standing: each segment's heading and lean there
        n = len(labels) - int(np.flatnonzero(labels != "standing")[-1]) - 1
        stand = {"seconds": round(n / 20.0, 2)}

        def yaw_pitch(R: np.ndarray) -> np.ndarray:
            return np.round(Rotation.from_matrix(R[-n:]).as_euler("ZYX", degrees=True).mean(0)[:2], 1)

        for s in SENSORS + THIGHS:
            i = SEGMENT_INDEX[s]
            stand[s] = {"sensor_yaw_pitch": yaw_pitch(truth[:, i]).tolist(),
                        "model_yaw_pitch": yaw_pitch(as_replayed[:, i]).tolist(),
                        "deg": round(float(deg_between(as_replayed[-n:, i], truth[-n:, i]).mean()), 1)}
        out["last_stand"] = stand
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="diffusion")
    ap.add_argument("--lags", type=int, default=6, help="frames back in the window to score (default 6)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    import torch

    # one thread, as the CLI's replays: torch's default threads crawl beside any other job
    torch.set_num_threads(1)
    from app.cli.importing import import_paths
    from app.evaluation.real import real_logs
    from app.export.formats import body_for_recording
    from app.recording.reader import read_recording
    from app.replay.run import ReplaySettings, build_replay_poser
    from inference.training.data import data_root

    logs = real_logs(data_root())
    if not logs:
        raise SystemExit(f"no real log under {data_root()}")
    result = {}
    with tempfile.TemporaryDirectory(prefix="imucap-stages-") as tmp:
        for k, log in enumerate(logs):
            h5 = Path(tmp) / f"log{k}.h5"
            import_paths([log.path], h5, mapping=dict(log.mapping), reconstruct=False)
            rec = read_recording(h5)
            body, _ = body_for_recording(rec.metadata)
            result[log.name] = stages(rec, build_replay_poser(rec, ReplaySettings(model=a.model), body), a.lags)
            print(json.dumps({log.name: result[log.name]}), flush=True)
    if a.json is not None:
        a.json.write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
