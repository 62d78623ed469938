"""OpenSim's own IMU inverse kinematics (OpenSense) on imucap's ``_orientations.sto`` of a
recorded walk, its knee flexion against imucap's (``inference.metrics.joint_angles``).

    .venv/bin/python benchmarks/opensense_ik.py [--recording REC.h5] [--out DIR] [--json]

Without ``--recording`` it records one: a synthesized 14 s walk through the live pipeline
(calibrating itself, as ``imucap demo --record`` does) with pelvis, torso, thighs, shanks,
upper arms and wrists measured. Then ``imucap export REC --out walk_orientations.sto``,
OpenSense's ``IMUPlacer`` on Rajagopal's OpenSense model (``tests/data/third_party/
opensim_models``; no sensor-to-OpenSim rotation, since the export already holds each
body's orientation in OpenSim's ground; placed at the recording's first frame, where the
subject stands with straight legs) and its ``IMUInverseKinematicsTool`` over the whole
recording. Printed: per knee the RMS of OpenSim's ``knee_angle`` minus imucap's knee
flexion, the mean difference and both ranges; docs/validation.md quotes the figures.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

MODEL = REPO / "tests" / "data" / "third_party" / "opensim_models" / "Rajagopal2015_opensense.osim"
SITES = ("pelvis", "torso", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_upperarm", "r_upperarm", "l_wrist",
         "r_wrist")


def record_walk(path: Path, seconds: float = 14.0, seed: int = 5) -> Path:
    """A walk recorded as ``imucap demo --record`` records (the floor poser: quick)."""
    from app.capture.offline_session import record_motion
    from sim_devices.motions import generate

    record_motion(path, generate("walk", seconds=seconds, seed=seed), SITES, rng=3, t0=500.0, flush_interval=0.2)
    return path


def opensense_ik(sto: Path, out: Path, model: Path = MODEL) -> tuple[list[str], np.ndarray]:
    """(column labels, values) of OpenSense's IMU inverse kinematics (degrees) on ``sto``:
    the IMUs placed on ``model`` at the file's first frame (IMUPlacer's rule)."""
    import opensim as osim

    osim.Logger.setLevelString("error")
    table = osim.TimeSeriesTableQuaternion(str(sto))
    times = list(table.getIndependentColumn())
    placer = osim.IMUPlacer()
    placer.set_model_file(str(model))
    placer.set_orientation_file_for_calibration(str(sto))
    placer.set_sensor_to_opensim_rotations(osim.Vec3(0, 0, 0))
    placer.run(False)
    calibrated = out / "calibrated_model.osim"
    placer.getCalibratedModel().printToXML(str(calibrated))
    ik = osim.IMUInverseKinematicsTool()
    ik.set_model_file(str(calibrated))
    ik.set_orientations_file(str(sto))
    ik.set_sensor_to_opensim_rotations(osim.Vec3(0, 0, 0))
    ik.set_time_range(0, times[0])
    ik.set_time_range(1, times[-1])
    ik.set_results_directory(str(out))
    ik.run(False)
    mot = out / f"ik_{sto.stem}.mot"
    from app.validate.reference import _parse_storage

    _, labels, data = _parse_storage(mot)
    return labels, data


def compare(rec_path: Path, out: Path) -> dict:
    """Export, OpenSense IK, and the knees against imucap's (module docstring)."""
    from app.cli.main import main
    from app.export.c3d_file import regular_frames
    from app.export.formats import body_for_recording, motion_from_recording
    from app.recording import read_recording
    from inference.metrics.joint_angles import knee_flexion_deg

    sto = out / "walk_orientations.sto"
    assert main(["export", str(rec_path), "--out", str(sto)]) == 0
    labels, data = opensense_ik(sto, out)
    rec = read_recording(rec_path)
    body, _ = body_for_recording(rec.metadata)
    m = motion_from_recording(rec, body)
    k = regular_frames(m)
    t = m.time[0] + np.arange(len(k)) / m.fps
    col = {n: i for i, n in enumerate(labels)}
    res: dict = {"frames": int(len(data)), "seconds": round(float(data[-1, 0] - data[0, 0]), 2)}
    for s in "lr":
        ours = np.interp(data[:, 0], t, knee_flexion_deg(m.rot[k], s))
        theirs = data[:, col[f"knee_angle_{s}"]]
        d = theirs - ours
        res[f"{s}_knee"] = {"rms_deg": round(float(np.sqrt(np.mean(d * d))), 3), "mean_deg": round(float(d.mean()), 3),
                            "max_abs_deg": round(float(np.abs(d).max()), 3),
                            "range_imucap_deg": round(float(np.ptp(ours)), 2),
                            "range_opensim_deg": round(float(np.ptp(theirs)), 2)}
    return res


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recording", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        rec = args.recording or record_walk(out / "walk.h5")
        res = compare(rec, out)
    if args.json:
        print(json.dumps(res))
    else:
        for s in "lr":
            r = res[f"{s}_knee"]
            print(f"{s}_knee: OpenSense minus imucap RMS {r['rms_deg']:.2f} deg, mean {r['mean_deg']:+.2f}, "
                  f"max {r['max_abs_deg']:.2f}; range imucap {r['range_imucap_deg']:.1f}, "
                  f"OpenSense {r['range_opensim_deg']:.1f} ({res['frames']} frames, {res['seconds']} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
