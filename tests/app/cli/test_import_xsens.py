"""`imucap import` of Xsens exports -> a session recording that replay reconstructs.

A session synthesized here (a still stand, then a walk; sensors strapped at random
angles, the subject facing 70 deg from the sensors' Earth X) is written by
``sim_devices.xsens_export`` as MT Manager exports (six sensors with Acc, Gyr and
quaternions, named by device id) and as DOT app exports (the paper's six sites, Quat +
FreeAcc only, named by their tags), imported, and replayed; the truth is the motion it
was synthesized from, turned to the subject's forward."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli.importing import gyro_from_orientation, site_for
from app.cli.main import main
from app.export.hdf5_file import read_hdf5
from app.recording import read_recording
from inference.body.motion import Motion
from inference.body.rotations import axis_angle_to_quat, matrix_about_axis, matrix_angle_between, quat_multiply
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from inference.metrics.errors import global_angle_error
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate
from sim_devices.xsens_export import write_dot_exports, write_mtmanager_exports, write_mvnx

HEADING = 70.0
NOISE = NoiseModel(mounting_deg=40.0, ori_white_deg=0.3, acc_white=0.05, gyro_white=0.01)
MT_IDS = {"pelvis": "00B421E6", "l_thigh": "00B421E7", "r_thigh": "00B421E8", "l_shank": "00B421E9",
          "r_shank": "00B421EA", "head": "00B421EB"}
DOT_TAGS = {"pelvis": "Pelvis", "head": "Head", "l_wrist": "LWrist", "r_wrist": "RWrist", "l_shank": "LTibia",
            "r_shank": "RTibia"}
TO_FORWARD = matrix_about_axis(np.array([0.0, 0.0, 1.0]), np.deg2rad(-HEADING))


@pytest.fixture(scope="module")
def motion():
    stand = generate("npose", seconds=1.5, heading_deg=HEADING)
    walk = generate("walk", seconds=6.0, heading_deg=HEADING)
    root = walk.root - walk.root[0] + stand.root[-1] * [1, 1, 0] + [0, 0, walk.root[0, 2]]
    return Motion(rot=np.concatenate([stand.rot, walk.rot]), root=np.concatenate([stand.root, root]), fps=60.0,
                  body=stand.body)


@pytest.fixture(scope="module")
def mt_folder(motion, tmp_path_factory):
    sig = synthesize(motion, NOISE, rng=5, sites=tuple(MT_IDS))
    folder = tmp_path_factory.mktemp("mt")
    write_mtmanager_exports(sig, folder, MT_IDS, drop=[200, 201, 300], blank=[(50, "Acc_Z"), (120, "Quat_q1")])
    (folder / "notes.txt").write_text("subject 7, trial 2\n")
    return folder


@pytest.fixture(scope="module")
def dot_folder(motion, tmp_path_factory):
    sig = synthesize(motion, NOISE, rng=6, sites=tuple(DOT_TAGS))
    folder = tmp_path_factory.mktemp("dot")
    write_dot_exports(sig, folder, DOT_TAGS, drop=[200, 201, 300])
    return folder


def _import(capsys, *args):
    assert main(["import", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def _mt_maps():
    return [a for s, i in MT_IDS.items() for a in ("--map", f"{i}={s}")]


def _heading_deg(out):
    return np.degrees(np.arctan2(out["forward_G"][1], out["forward_G"][0]))


def _bone_error_deg(path, motion):
    """Median angle of the sensors' bones, from the raw stream and the calibration, to the
    truth turned to the subject's forward."""
    rec = read_recording(path)
    cal = rec.calibrations[0][1]
    quat = np.stack([rec.raw[s]["quat"] for s in rec.sites], axis=1).astype(np.float64)
    R_WB, _ = cal.apply(quat, acc=np.stack([rec.raw[s]["acc"] for s in rec.sites], axis=1).astype(np.float64))
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[s]] for s in rec.sites]
    n = min(len(R_WB), len(motion.rot))
    ok = np.all(np.isfinite(R_WB[:n]), axis=(-1, -2))
    err = matrix_angle_between(np.where(ok[..., None, None], R_WB[:n], np.eye(3)), TO_FORWARD @ motion.rot[:n, seg])
    return float(np.median(np.degrees(err)[ok]))


def _replay(capsys, path, tmp_path, motion):
    """The replay's summary, its GA to the truth (deg) and its mean angle on the worn segments."""
    poses = tmp_path / "poses.h5"
    assert main(["replay", str(path), "--json", "--no-progress", "--steps", "1", "--out", str(poses)]) == 0
    rep = json.loads(capsys.readouterr().out)
    data, _ = read_hdf5(poses)
    idx = np.clip(np.rint(data["time"] * motion.fps).astype(int), 0, len(motion.rot) - 1)
    truth = TO_FORWARD @ motion.rot[idx]
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[s]] for s in rep["sensors"]]
    worn = np.degrees(matrix_angle_between(data["rot"][:, seg], truth[:, seg])).mean()
    return rep, float(global_angle_error(data["rot"], truth).mean()), float(worn)


def test_an_mtmanager_session_imports_by_device_id_and_replays(mt_folder, motion, tmp_path, capsys):
    out = _import(capsys, mt_folder, "--out", tmp_path / "mt.h5", "--height", "1.75", "--calibration", "standing",
                  *_mt_maps())
    assert out["format"] == "mtmanager" and out["clock"] == "shared"
    assert out["sites"] == ["pelvis", "head", "l_thigh", "r_thigh", "l_shank", "r_shank"]
    assert out["ignored"] == [str(mt_folder / "notes.txt")]
    assert out["still_start_s"] == pytest.approx(1.5, abs=0.2) and out["duration_s"] == pytest.approx(7.5, abs=0.1)
    assert out["forward_from"] == "knees" and _heading_deg(out) == pytest.approx(HEADING, abs=4.0)
    dev = out["devices"]["l_shank"]
    assert dev["id"] == "00B421E9" and dev["rate_hz"] == pytest.approx(60.0, abs=0.5)
    assert dev["skipped"]["no_orientation"] == 1 and dev["skipped"]["filled"] == 1  # the blanked cells
    rec = read_recording(tmp_path / "mt.h5")
    assert rec.metadata["source"] == "MT Manager export" and rec.metadata["body_height_m"] == 1.75
    assert rec.raw["l_shank"]["present"].mean() > 0.97  # lost packets are short gaps, filled
    assert _bone_error_deg(tmp_path / "mt.h5", motion) < 4.0
    rep, ga, worn = _replay(capsys, tmp_path / "mt.h5", tmp_path, motion)
    assert rep["frames"] > 100 and rep["sensors"] == out["sites"]
    assert worn < 5.0 and ga < 20.0  # the arms are not worn: the model's guess


def test_a_dot_session_maps_by_tag_and_calibrates_without_gyro(dot_folder, motion, tmp_path, capsys):
    """The DOT app's Quat + FreeAcc: no gyro, and no thigh to show the knee's plane, so
    the forward comes from the shanks' swing, on a rate taken from orientation."""
    files = sorted(dot_folder.iterdir())
    out = _import(capsys, *files, "--out", tmp_path / "dot.h5")  # the files themselves, not the folder
    assert out["format"] == "dot" and set(out["sites"]) == set(DOT_TAGS)
    assert out["forward_from"] == "shank swing" and _heading_deg(out) == pytest.approx(HEADING, abs=5.0)
    assert out["still_start_s"] == pytest.approx(1.5, abs=0.2)
    assert out["devices"]["r_shank"]["acc_from"] == "FreeAcc" and out["devices"]["r_shank"]["id"] == "D4CA6EF17205"
    rec = read_recording(tmp_path / "dot.h5")
    assert np.isnan(rec.raw["pelvis"]["gyro"]).all()  # recorded as logged: the export had none
    assert _bone_error_deg(tmp_path / "dot.h5", motion) < 4.0
    rep, ga, worn = _replay(capsys, tmp_path / "dot.h5", tmp_path, motion)
    assert rep["frames"] > 100 and worn < 6.0 and ga < 20.0


MVN_LABELS = {"pelvis": "Pelvis", "torso": "T8", "head": "Head", "l_wrist": "LeftForeArm", "r_wrist": "RightForeArm",
              "l_thigh": "LeftUpperLeg", "r_thigh": "RightUpperLeg", "l_shank": "LeftLowerLeg",
              "r_shank": "RightLowerLeg"}


@pytest.fixture(scope="module")
def mvnx_file(motion, tmp_path_factory):
    sig = synthesize(motion, NOISE, rng=7, sites=tuple(MVN_LABELS))
    return write_mvnx(sig, tmp_path_factory.mktemp("mvn") / "take-007.mvnx", MVN_LABELS,
                      extra={"RightHand": "r_wrist", "LeftShoulder": "torso"}, drop=[200, 201], motion=motion)


def test_an_mvn_take_imports_its_sensors_at_their_sites_and_replays(mvnx_file, motion, tmp_path, capsys):
    """One MVNX file for the whole suit: the sensors at imucap's sites by their MVN labels,
    the hand and shoulder listed as not used; calibrated from the standing start on the
    rate from orientation (MVNX holds none), and re-run with three of its nine sensors."""
    out = _import(capsys, mvnx_file, "--out", tmp_path / "mvn.h5")
    assert out["format"] == "mvnx" and out["sites"] == list(MVN_LABELS)
    assert [u.split()[0] for u in out["ignored"]] == ["RightHand", "LeftShoulder"]
    assert out["still_start_s"] == pytest.approx(1.5, abs=0.2) and out["forward_from"] == "knees"
    assert _heading_deg(out) == pytest.approx(HEADING, abs=4.0)
    dev = out["devices"]["r_shank"]
    assert dev["name"] == "RightLowerLeg" and dev["rate_hz"] == pytest.approx(60.0, abs=0.5)
    assert dev["acc_from"] == "sensorFreeAcceleration" and "from orientation" in dev["gyro_from"]
    rec = read_recording(tmp_path / "mvn.h5")
    assert rec.metadata["source"] == "Xsens MVN export (MVNX)" and np.isnan(rec.raw["pelvis"]["gyro"]).all()
    assert _bone_error_deg(tmp_path / "mvn.h5", motion) < 4.0
    rep, ga, worn = _replay(capsys, tmp_path / "mvn.h5", tmp_path, motion)
    assert rep["frames"] > 100 and worn < 5.0 and ga < 20.0
    # the hand's sensor instead of the forearm's, by --map: the forearm is then not used
    out = _import(capsys, mvnx_file, "--out", tmp_path / "hand.h5", "--map", "RightHand=r_wrist")
    assert out["devices"]["r_wrist"]["name"] == "RightHand"
    assert any(u.startswith("RightForeArm (r_wrist is RightHand") for u in out["ignored"])
    assert main(["import", str(mvnx_file), "--out", str(tmp_path / "x.h5"), "--map", "RightPinky=r_wrist"]) != 0
    assert "no sensor 'RightPinky'" in capsys.readouterr().err


def test_an_mvn_takes_own_solution_is_the_truth_for_a_sparse_rerun(mvnx_file, mt_folder, motion, tmp_path, capsys):
    """``--truth``: MVN's 23 segments, turned into the recording's world and clock, score a
    re-run with three of the take's sensors; the file's body gives the height."""
    from app.capture.simulate import read_truth

    out = _import(capsys, mvnx_file, "--out", tmp_path / "mvn.h5", "--truth", tmp_path / "truth.npz")
    assert out["truth"] == str(tmp_path / "truth.npz")
    assert read_recording(tmp_path / "mvn.h5").metadata["body_height_m"] == pytest.approx(1.75, abs=0.05)
    truth = read_truth(tmp_path / "truth.npz")
    t = np.arange(0.0, 7.0, 0.5)  # recording seconds: MVN's frame k is at k / 60 s of the take
    played = TO_FORWARD @ motion.rot[np.rint(t * 60).astype(int)]
    apart = np.degrees(matrix_angle_between(truth.rot[truth.frame_at(t)], played))
    assert apart.max() < 4.0  # the standing start's forward, within the calibration's error
    assert truth.activity_start + truth.t0 == pytest.approx(out["still_start_s"])
    reps = {}
    for sensors in ("pelvis,l_wrist,r_wrist", ",".join(MVN_LABELS)):
        assert main(["replay", str(tmp_path / "mvn.h5"), "--truth", str(tmp_path / "truth.npz"), "--sensors", sensors,
                     "--json", "--no-progress", "--steps", "1"]) == 0
        reps[sensors] = json.loads(capsys.readouterr().out)
    three, nine = reps.values()
    assert three["truth_frames"] > 100 and abs(three["truth_lag_s"]) < 0.1
    assert nine["ga_deg"] < three["ga_deg"] < 25.0 and nine["ga_deg"] < 10.0
    assert main(["import", str(mt_folder), "--out", str(tmp_path / "x.h5"), "--truth", str(tmp_path / "t.npz"),
                 *_mt_maps()]) != 0
    assert "only an MVN take" in capsys.readouterr().err


def test_sensors_without_a_site_are_skipped_or_refused_with_the_way_out(mt_folder, dot_folder, tmp_path, capsys):
    """One sensor without a site is skipped with a warning (a folder holds sensors the
    study did not use); when none has a site, the import is refused in one line."""
    assert main(["import", str(mt_folder), "--out", str(tmp_path / "x.h5")]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--map" in err and all(i in err for i in MT_IDS.values())
    tibia = next(dot_folder.glob("LTibia_*.csv"))
    renamed = tibia.with_name(tibia.name.replace("LTibia", "bei"))
    renamed.write_text(tibia.read_text().replace("DeviceTag:,LTibia", "DeviceTag:,bei"))
    tibia.unlink()
    try:
        # the mapping is what is checked here, not the body: no reconstruction
        assert main(["import", str(dot_folder), "--out", str(tmp_path / "y.h5"), "--json", "--no-reconstruct"]) == 0
        cap = capsys.readouterr()
        out = json.loads(cap.out)
        assert "l_shank" not in out["sites"] and len(out["sites"]) == 5
        assert [w for w in out["warnings"] if w.startswith("bei")] == [
            f"bei ({renamed.name}): no site, skipped (--map 'bei=SITE' to use it)"]
        assert "no site, skipped" in cap.err
        for way in ("bei=l_shank", "D4:CA:6E:F1:72:04=l_shank", f"{renamed.stem}=l_shank"):  # tag, address, stem
            assert "l_shank" in _import(capsys, dot_folder, "--out", tmp_path / "z.h5", "--map", way,
                                        "--no-reconstruct")["sites"]
    finally:
        tibia.write_text(renamed.read_text().replace("DeviceTag:,bei", "DeviceTag:,LTibia"))
        renamed.unlink()


def test_one_session_is_one_layout(mt_folder, dot_folder, tmp_path, capsys):
    files = [next(mt_folder.glob("*.txt")), next(dot_folder.glob("*.csv"))]
    assert main(["import", *map(str, files), "--out", str(tmp_path / "x.h5")]) != 0
    assert "both MT Manager and DOT exports" in capsys.readouterr().err


def test_bone_style_names_map_to_sites():
    assert site_for("LFemur", {}) == "l_thigh" and site_for("tibia_r_imu", {}) == "r_shank"
    assert site_for("calcn_l", {}) == "l_foot" and site_for("RightHand", {}) == "r_wrist"
    assert site_for("torso_imu", {}) == "torso" and site_for("bei", {}) is None


def test_the_rate_from_orientation_is_the_turn_rate_and_jitter_does_not_read_as_motion():
    t = np.arange(240) / 60.0
    turning = axis_angle_to_quat(np.outer(t, [0.0, 0.0, 1.5]))  # 1.5 rad/s about the sensor's z
    np.testing.assert_allclose(gyro_from_orientation(t, turning), np.tile([0.0, 0.0, 1.5], (240, 1)), atol=1e-9)
    jitter = axis_angle_to_quat(np.random.default_rng(0).normal(scale=np.deg2rad(0.3), size=(240, 3)))
    still = quat_multiply(axis_angle_to_quat(np.array([0.3, -1.0, 0.2])), jitter)
    assert np.degrees(np.linalg.norm(gyro_from_orientation(t, still), axis=1)).max() < 10.0  # still_start's limit
