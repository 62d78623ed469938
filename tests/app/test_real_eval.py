"""The real-data yardstick's pieces: which logs it finds, which sets a recording can score,
and the per-segment GA that ``imucap evaluate --json`` reports."""

from __future__ import annotations

import numpy as np

from app.real_eval import REAL_SETS, held_out_sets, mean_over, real_logs
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import SEGMENT_INDEX
from inference.metrics.errors import evaluate_clip, segment_errors


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
