"""`imucap evaluate --points`: tracked VR points read as the live vmc-in chain reads them
(app/evaluation/tracked_points.py), scored beside IMU sites."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
from scipy.ndimage import uniform_filter1d

from app.cli.main import main
from app.evaluation.tracked_points import tracked_signals
from app.export.bvh import write_motion_bvh
from drivers.vmc.implied_imu import WINDOW_S
from inference.body.rotations import quat_to_matrix
from inference.body.skeleton import SEGMENT_INDEX
from inference.evaluation.runner import face_forward
from inference.signals.synthesis import FPS_SIGNAL, synthesize
from sim_devices.devices.vr_rig import TrackingNoise
from sim_devices.motions import generate


@pytest.fixture(scope="module")
def walk():
    return face_forward(generate("walk", seconds=8.0, seed=1))


def test_points_read_like_the_live_chain(walk):
    sig = tracked_signals(["head", "l_hand", "r_hand"])(walk, 3)
    assert set(sig) == {"head", "l_wrist", "r_wrist"}  # a controller stands for the wrist sensor
    imu = synthesize(walk, None, sites=("head", "l_wrist", "r_wrist"))
    T = walk.resample(FPS_SIGNAL).n_frames
    for k, site in enumerate(("head", "l_wrist", "r_wrist")):
        quat, free = sig[site]
        assert quat.shape == (T, 4) and free.shape == (T, 3)
        # the headset's orientation is the head's, to the tracking jitter (0.3 deg per axis)
        if site == "head":
            R = quat_to_matrix(quat)
            Rt = walk.resample(FPS_SIGNAL).rot[:, SEGMENT_INDEX["head"]]
            cos = (np.trace(np.swapaxes(R, 1, 2) @ Rt, axis1=1, axis2=2) - 1) / 2
            assert np.degrees(np.arccos(np.clip(cos, -1, 1))).mean() < 2.0
        # the implied acceleration is the site's, late by the rig's latency and the fit's half
        # window, once an 11-frame average has taken the jitter out
        expected = round((TrackingNoise().latency_s + WINDOW_S / 2) * FPS_SIGNAL)

        def corr(got_acc: np.ndarray, want_acc: np.ndarray, lag: int) -> float:
            got = uniform_filter1d(got_acc[60 + lag:], 11)
            want = uniform_filter1d(want_acc[60:len(want_acc) - lag], 11)
            return float(np.corrcoef(got, want)[0, 1])

        for axis in range(3):
            pair = (free[:, axis], imu.free_acc[:T, k, axis])
            best = max(range(10), key=lambda lag, p=pair: corr(*p, lag))
            assert abs(best - expected) <= 1, (site, axis, best, expected)
            assert corr(*pair, best) > 0.85, (site, axis)


def test_the_same_seed_gives_the_same_signals(walk):
    a = tracked_signals(["head"])(walk, 7)["head"][1]
    b = tracked_signals(["head"])(walk, 7)["head"][1]
    c = tracked_signals(["head"])(walk, 8)["head"][1]
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def _run(capsys, *argv):
    code = main(["evaluate", *argv, "--threads", "1", "--no-progress"])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    """``imucap evaluate --json`` of one 8 s walk, each sensor/point set run once for the module
    (the points alone are both tests' reference)."""
    d = tmp_path_factory.mktemp("data")
    write_motion_bvh(d / "walk.bvh", generate("walk", seconds=8.0, seed=2))
    runs: dict[tuple[str, ...], dict] = {}

    def run(*argv: str) -> dict:
        if argv not in runs:
            out, err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                code = main(["evaluate", "--data", str(d), *argv, "--json", "--threads", "1", "--no-progress"])
            assert code == 0, err.getvalue()
            runs[argv] = json.loads(out.getvalue())
        return runs[argv]

    return run


def test_points_and_shanks_against_each_alone(evaluated):
    runs = {}
    for label, sensors, points in (("both", "l_shank,r_shank", "head,l_hand,r_hand"),
                                   ("points", "none", "head,l_hand,r_hand"),
                                   ("shanks", "l_shank,r_shank", "")):
        runs[label] = evaluated("--sensors", sensors, "--points", points)
    assert runs["both"]["points"] == ["head", "l_hand", "r_hand"]
    assert runs["both"]["sensors"] == ["l_shank", "r_shank"] and runs["points"]["sensors"] == []
    # the points observe the head and both forearms: the whole body's error falls with them
    assert runs["both"]["ga_deg"] < runs["shanks"]["ga_deg"] - 2.0
    # and the shanks observe the legs, which three points on the upper body leave open
    assert runs["both"]["lower_pe_cm"] < runs["points"]["lower_pe_cm"]


def test_the_arms_reach_puts_the_hands_on_their_controllers(evaluated):
    runs = {}
    for label, extra in (("model", ()), ("reach", ("--reach",))):
        runs[label] = evaluated("--sensors", "none", "--points", "head,l_hand,r_hand", *extra)
    assert runs["reach"]["reach"] and not runs["model"]["reach"]
    # the controller's few millimetres of tracking error and the hand's grip, not the model's guess
    assert runs["reach"]["hand_pe_cm"] < 3.0 < runs["model"]["hand_pe_cm"]
    assert runs["reach"]["upper_pe_cm"] < runs["model"]["upper_pe_cm"]
    assert runs["reach"]["lower_pe_cm"] == pytest.approx(runs["model"]["lower_pe_cm"], abs=1e-6)


@pytest.mark.parametrize(("argv", "says"), [
    (["--sensors", "head", "--points", "head"], "both give head"),
    (["--reach"], "needs --points"),
    (["--sensors", "none", "--points", "l_hand,r_hand", "--reach"], "needs the headset"),
    (["--points", "l_foot"], "unknown tracked point"),
    (["--sensors", "none"], "needs --points"),
    (["--points", "head,head"], "named twice"),
])
def test_bad_point_sets_get_one_line(capsys, tmp_path, argv, says):
    write_motion_bvh(tmp_path / "w.bvh", generate("walk", seconds=2.0, seed=2))
    code, _, err = _run(capsys, "--data", str(tmp_path), *argv)
    assert code != 0
    assert says in err and len(err.strip().splitlines()) == 1
