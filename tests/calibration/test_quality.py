"""The calibration quality report's warnings, each caused on purpose in a synthesized walk
calibration: a swapped left/right pair, a sensor that moved in the still pose, a sensor on
another segment; and none on a correct setup."""

from __future__ import annotations

import numpy as np
import pytest

from calibration.protocol import WalkProtocol, synthesize_walk_session
from calibration.quality import QualityReport, assess, max_rotation
from calibration.walk import WalkWindows, calibrate_walk
from inference.body.rotations import matrix_about_axis, matrix_to_quat, quat_to_matrix
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_thigh", "r_thigh", "l_shank", "r_shank")


@pytest.fixture(scope="module", params=[0, 1])
def session(request):
    seed = request.param
    act = generate("walk", seconds=3, seed=seed + 1)
    walk = generate("walk", seconds=6, seed=seed, speed=1.1 + 0.2 * seed)
    sig, _ = synthesize_walk_session(act, walk, WalkProtocol(), noise=NoiseModel.typical(), rng=seed, sites=SITES)
    (n0, n1), _, (s0, s1) = sig.meta["walk_windows"]
    return sig, WalkWindows((n0 + 12, n1 - 12), (n1 - 12, s0 + 12), (s0 + 12, s1 - 12))


def report_for(sig, win, quat=None, free_acc=None, sites=SITES) -> QualityReport:
    q = sig.quat if quat is None else quat
    fa = sig.free_acc if free_acc is None else free_acc
    cal, res = calibrate_walk(sites, q, win, free_acc=fa, fps=sig.fps)
    return assess(cal, "walk", {"N-pose": max_rotation(q[slice(*win.npose)])},
                  {"quat": q[slice(*win.walk)], "fps": sig.fps, "spread_deg": res.spread_deg, "path_m": res.path_m})


def swapped(sig, a: str, b: str):
    i, j = SITES.index(a), SITES.index(b)
    q, fa = sig.quat.copy(), sig.free_acc.copy()
    q[:, [i, j]] = q[:, [j, i]]
    fa[:, [i, j]] = fa[:, [j, i]]
    return q, fa


def test_a_correct_setup_has_no_warnings(session):
    sig, win = session
    rep = report_for(sig, win)
    assert rep.ok, rep.all_warnings()
    assert all(q.side_score > 0.4 for q in rep.sensors.values() if q.side_score is not None)


@pytest.mark.parametrize("pair", [("l_thigh", "r_thigh"), ("l_wrist", "r_wrist"), ("l_shank", "r_shank")])
def test_a_swapped_pair_is_named(session, pair):
    sig, win = session
    rep = report_for(sig, win, *swapped(sig, *pair))
    assert rep.warnings == [f"{pair[0]} and {pair[1]} are probably swapped (left/right): "
                            "exchange the two sensors or their sites in the setup"]


def test_one_sensor_on_the_other_side(session):
    sig, win = session
    sites = tuple(s for s in SITES if s != "r_thigh")
    keep = [SITES.index(s) for s in sites]
    q, fa = swapped(sig, "l_thigh", "r_thigh")  # the l_thigh column now holds the right thigh
    rep = report_for(sig, win, q[:, keep], fa[:, keep], sites)
    assert any("l_thigh: probably on the right side" in w for w in rep.all_warnings())


def test_a_sensor_on_another_segment(session):
    sig, win = session
    rep = report_for(sig, win, *swapped(sig, "l_thigh", "l_shank"))
    w = rep.all_warnings()
    assert any(x.startswith("l_thigh: swings") and "probably not on the thigh" in x for x in w), w
    assert any(x.startswith("l_shank: swings") and "moves like a thigh" in x for x in w), w


def test_moved_during_the_still_pose(session):
    sig, win = session
    q = sig.quat.copy()
    k = SITES.index("head")
    n0, n1 = win.npose
    # a 3.5 deg nod in the middle of the N-pose: under the 5 deg that fails the step
    ang = np.deg2rad(3.5) * np.sin(np.linspace(0, np.pi, n1 - n0))
    nod = matrix_about_axis(np.broadcast_to([0.0, 1.0, 0.0], (n1 - n0, 3)), ang)
    q[n0:n1, k] = matrix_to_quat(quat_to_matrix(q[n0:n1, k]) @ nod)
    rep = report_for(sig, win, q)
    assert rep.sensors["head"].warnings and rep.sensors["head"].warnings[0].startswith("head: moved 2.")
    assert "redo 'N-pose' holding still" in rep.sensors["head"].warnings[0]
    assert rep.redo == ["N-pose"]
    assert not any(rep.sensors[s].warnings for s in SITES if s != "head")


def test_without_a_pelvis_left_right_is_not_checked(session):
    sig, win = session
    sites = SITES[1:]
    rep = report_for(sig, win, sig.quat[:, 1:], sig.free_acc[:, 1:], sites)
    assert rep.warnings == ["left/right not checked: it needs the pelvis sensor"]


def test_report_round_trips_through_json(session):
    import json

    sig, win = session
    rep = report_for(sig, win, *swapped(sig, "l_thigh", "r_thigh"))
    back = QualityReport.from_dict(json.loads(json.dumps(rep.to_dict())))
    assert back.all_warnings() == rep.all_warnings() and back.lines() == rep.lines()
