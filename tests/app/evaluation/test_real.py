"""The real-data yardstick's pieces (app/evaluation/real.py): which logs it finds and with
which sensor map, which sets a recording can score, the per-phase and constant / dynamic
split of a held-out error, and the per-segment GA that ``imucap evaluate --json`` reports."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from app.evaluation.real import (
    FRAMES_KEY,
    OPENSENSE_MAP,
    REAL_SETS,
    compare_held_out,
    drop_frame_errors,
    held_out_sets,
    mean_over,
    real_logs,
    split_errors,
)
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import N_SITES, SEGMENT_INDEX, SITE_INDEX
from inference.metrics.errors import evaluate_clip, segment_errors
from inference.training.data import data_root


def _device(folder, name):
    d = folder / name
    d.mkdir(parents=True)
    (d / "Inertial.csv").write_text("")
    (d / "Quaternion.csv").write_text("")


def test_real_logs_finds_ximu3_log_folders_only(tmp_path):
    _device(tmp_path / "ximu3" / "walk_b", "pelvis 1")
    _device(tmp_path / "ximu3" / "walk_a", "l_shank 2")
    (tmp_path / "ximu3" / "notes").mkdir()
    (tmp_path / "ximu3" / "notes" / "readme.txt").write_text("x")
    assert [log.name for log in real_logs(tmp_path)] == ["ximu3/walk_a", "ximu3/walk_b"]
    assert real_logs(tmp_path / "nothing") == []


def test_real_logs_find_the_opensense_trial_with_its_sensor_map(tmp_path):
    _device(tmp_path / "ximu3" / "walk", "pelvis 1")
    trial = tmp_path / "opensense" / "mtw_walk"
    trial.mkdir(parents=True)
    for i in ("00B42279", "00B421ED"):
        (trial / f"MT_012005D6_009-001_{i}.txt").write_text("")
    (tmp_path / "opensense" / "other").mkdir()
    (tmp_path / "opensense" / "other" / "MT_0_00AAAAAA.txt").write_text("")  # ids the map does not know
    logs = real_logs(tmp_path)
    assert [log.name for log in logs] == ["ximu3/walk", "opensense/mtw_walk"]
    assert logs[0].mapping == {} and logs[1].mapping == OPENSENSE_MAP
    assert logs[1].map_args()[:2] == ["--map", "00B42268=torso"]
    # every site once: a map that put two sensors on one site would be refused by the import
    assert len(set(OPENSENSE_MAP.values())) == len(OPENSENSE_MAP) == 8


@pytest.mark.data
def test_real_covers_every_real_log_of_the_data_folder():
    root = data_root()
    if not ((root / "ximu3" / "logged_lower_body").is_dir() and (root / "opensense" / "xsens_mtw_walk").is_dir()):
        pytest.skip("the real logs are not in the data folder")
    names = [log.name for log in real_logs(root)]
    assert {"ximu3/logged_lower_body", "opensense/xsens_mtw_walk"} <= set(names)


def _pose(t, rot, observed):
    pose = SimpleNamespace(rot=rot)
    return SimpleNamespace(t=t, pose=pose, observed_sites=observed)


def test_split_errors_by_phase_and_into_constant_and_dynamic():
    """A left-out thigh 10 deg off (constant) through a walk, and 10 deg more while standing:
    the phase split sees the stand, the constant part the offset."""
    T = 40
    t = np.arange(T) / 20.0
    seg = SEGMENT_INDEX["l_thigh"]
    observed = np.ones(N_SITES, bool)
    truth, pred = [], []
    for k in range(T):
        R = np.tile(np.eye(3), (24, 1, 1))
        R[seg] = matrix_about_axis(np.array([0.0, 1.0, 0.0]), 0.5 * np.sin(k / 3.0))  # the thigh swings
        P = R.copy()
        extra = 20.0 if k >= 30 else 10.0
        P[seg] = R[seg] @ matrix_about_axis(np.array([1.0, 0.0, 0.0]), np.deg2rad(extra))
        truth.append(_pose(t[k], R, observed))
        pred.append(_pose(t[k], P, observed))
    missing = observed.copy()
    missing[SITE_INDEX["r_thigh"]] = False
    truth = [_pose(p.t, p.pose.rot, missing) for p in truth]
    out = split_errors(pred, truth, ["l_thigh", "r_thigh"], lambda tt: np.where(tt >= 1.5, "standing", "walking"))
    ph = out["phases"]
    assert ph["walking"]["seconds"] == 1.5 and ph["standing"]["seconds"] == 0.5 and ph["turning"]["seconds"] == 0
    assert ph["walking"]["deg"]["l_thigh"] == pytest.approx(10.0, abs=0.01)
    assert ph["standing"]["deg"]["l_thigh"] == pytest.approx(20.0, abs=0.01)
    assert ph["turning"]["deg"]["l_thigh"] is None and ph["walking"]["deg"]["r_thigh"] is None
    assert out["constant_deg"]["l_thigh"] == pytest.approx(12.5, abs=0.1)  # the mean offset
    assert out["dynamic_deg"]["l_thigh"] == pytest.approx((30 * 2.5 + 10 * 7.5) / 40, abs=0.1)
    assert out["constant_deg"]["r_thigh"] is None


def test_two_models_on_one_log_differ_by_a_block_bootstrap_over_its_frames():
    """A model 1 deg worse on every frame is settled worse; one whose difference swings with
    the stride (+-3 deg, mean 0.2) is not, though a bootstrap over single frames would call
    it (the frames of a take are not independent); frames only one model scored are left out."""
    t = np.round(np.arange(400) / 20.0, 6)
    base = 8.0 + 2.0 * np.sin(t * 2.0)
    swing = 0.2 + 3.0 * np.sin(2 * np.pi * t / 8.0)

    def held(err, keep=slice(None)):
        return {"log": {"pelvis+shanks": {"deg": {}, FRAMES_KEY: {"l_thigh": {"t": t[keep].tolist(),
                                                                             "deg": err[keep].tolist()}}}}}

    worse = compare_held_out(held(base + 1.0), held(base))["log"]["pelvis+shanks"]["l_thigh"]
    assert worse["difference"] == pytest.approx(1.0) and worse["decided"] and worse["low"] > 0.9
    assert worse["blocks"] == 10 and worse["model_lower"] == 0
    unsure = compare_held_out(held(base + swing), held(base))["log"]["pelvis+shanks"]["l_thigh"]
    assert unsure["low"] < 0 < unsure["high"] and not unsure["decided"]
    from scipy.stats import bootstrap

    per_frame = bootstrap((swing,), np.mean, confidence_level=0.95, rng=np.random.default_rng(0)).confidence_interval
    assert per_frame.low > 0 or unsure["high"] - unsure["low"] > 2 * (per_frame.high - per_frame.low)
    part = compare_held_out(held(base + 1.0, slice(100, None)), held(base))["log"]["pelvis+shanks"]["l_thigh"]
    assert part["blocks"] == 8 and part["difference"] == pytest.approx(1.0)
    assert compare_held_out(held(base), {"other": {}}) == {}
    assert FRAMES_KEY not in drop_frame_errors(held(base))["log"]["pelvis+shanks"]


def test_held_out_sets_need_every_site_and_something_left_over():
    lower = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")
    assert [label for label, _ in held_out_sets(lower)] == [label for label, _ in REAL_SETS]
    assert [label for label, _ in held_out_sets(("pelvis", "l_shank", "r_shank"))] == ["shanks"]
    assert held_out_sets(("l_shank", "r_shank")) == []


def test_mean_over_logs():
    ho = {"a": {"shanks": {"deg": {"l_thigh": 10.0, "r_thigh": None}}},
          "b": {"shanks": {"deg": {"l_thigh": 20.0, "r_thigh": 4.0}}}}
    assert mean_over(ho, "shanks") == {"l_thigh": 15.0, "r_thigh": 4.0}
    assert mean_over(ho, "pelvis+shanks") is None


def test_segment_errors_name_the_segment_that_is_off():
    T = 10
    R_true = np.tile(np.eye(3), (T, 24, 1, 1))
    R_pred = R_true.copy()
    R_pred[:, SEGMENT_INDEX["l_thigh"]] = matrix_about_axis(np.array([0.0, 1.0, 0.0]), np.deg2rad(30.0))
    z = np.zeros((T, 24, 3))
    a = evaluate_clip("a", R_pred, z[:, 0], z, R_true, z[:, 0], z, 20.0)
    b = evaluate_clip("b", R_true, z[:, 0], z, R_true, z[:, 0], z, 20.0)
    seg = segment_errors([a, b])
    assert abs(seg["l_thigh"] - 15.0) < 1e-6  # pooled over both clips' frames
    assert seg["r_thigh"] == 0.0
    assert segment_errors([]) is None
