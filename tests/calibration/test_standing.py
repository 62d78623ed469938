"""Calibration from a standing start (calibration/standing.py) on a session synthesized
here: a still N-pose, then a walk, sensors strapped on at random angles, every sensor's
reference frame the same Earth frame whose X is *not* the subject's forward."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import CalibrationError
from calibration.standing import calibrate_standing, forward_from_knees, forward_from_shanks, still_stand
from inference.body.conventions import rot_z
from inference.body.motion import Motion
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate

SITES = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")
FPS = 60.0


def stand_then(kind: str, heading_deg: float, stand_s: float = 1.5, seconds: float = 6.0,
               back_s: float = 0.0) -> Motion:
    """A still N-pose, then ``kind`` facing ``heading_deg``, then (``back_s`` > 0) the same
    facing the other way, as after a turn."""
    parts = [generate("npose", seconds=stand_s, heading_deg=heading_deg),
             generate(kind, seconds=seconds, heading_deg=heading_deg)]
    if back_s > 0:
        parts.append(generate(kind, seconds=back_s, heading_deg=heading_deg + 180.0, seed=1))
    roots = [parts[0].root]
    for m in parts[1:]:
        roots.append(m.root - m.root[0] + roots[-1][-1] * [1, 1, 0] + [0, 0, m.root[0, 2]])
    return Motion(rot=np.concatenate([m.rot for m in parts]), root=np.concatenate(roots), fps=FPS, body=parts[0].body)


def session(kind="walk", heading_deg=70.0, seed=3, back_s=0.0):
    motion = stand_then(kind, heading_deg, back_s=back_s)
    noise = NoiseModel(mounting_deg=40.0, heading_deg=0.0, ori_white_deg=0.3, acc_white=0.05, gyro_white=0.01)
    sig = synthesize(motion, noise, rng=seed, sites=SITES)
    return motion, sig


def test_forward_comes_from_the_knees_and_the_bones_come_out_right():
    motion, sig = session(heading_deg=70.0)
    present = np.ones(sig.quat.shape[:2], bool)
    still = still_stand(sig.gyro, present, FPS)
    assert 1.2 * FPS <= still.stop <= 1.6 * FPS
    f = forward_from_knees(SITES, sig.quat, present, still)
    assert np.degrees(np.arctan2(f[1], f[0])) == pytest.approx(70.0, abs=4.0)
    cal = calibrate_standing(SITES, sig.quat, acc=sig.specific_force, gyro=sig.gyro, present=present, rate=FPS)
    assert cal.valid.all()
    R_WB, a_W = cal.apply(sig.quat, acc=sig.specific_force)
    # our world is the subject's: the truth turned by -70 deg about Z
    Rz = rot_z(np.deg2rad(-70.0))
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[x]] for x in SITES]
    err = np.degrees(matrix_angle_between(R_WB, Rz @ motion.rot[:, seg]))
    assert np.median(err) < 4.0, np.median(err, axis=0)
    still_acc = a_W[: still.stop]
    assert np.abs(still_acc.mean(axis=0)).max() < 0.05  # gravity leak removed


def test_a_walk_back_after_a_turn_still_votes_for_the_forward_at_calibration():
    """Out for 3 s, turn, back for 6 s: in G the knees bend the other way for twice as
    long, so summing the votes as they fall would point the subject backward."""
    _, sig = session(heading_deg=-40.0, back_s=6.0)
    sig_out = synthesize(stand_then("walk", -40.0, seconds=3.0, back_s=6.0), NoiseModel(mounting_deg=40.0), rng=4,
                         sites=SITES)
    for s in (sig, sig_out):
        present = np.ones(s.quat.shape[:2], bool)
        f = forward_from_knees(SITES, s.quat, present, still_stand(s.gyro, present, FPS))
        assert np.degrees(np.arctan2(f[1], f[0])) == pytest.approx(-40.0, abs=5.0)


def test_without_thighs_the_forward_comes_from_the_shanks_swing():
    """The paper's six wear no thigh: the shanks' fastest turn (the swing) says which way
    is forward, through a turn too."""
    lower = ("pelvis", "l_shank", "r_shank")
    for back_s, heading in ((0.0, 70.0), (6.0, -40.0)):
        sig = synthesize(stand_then("walk", heading, seconds=3.0, back_s=back_s), NoiseModel(mounting_deg=40.0),
                         rng=6, sites=lower)
        present = np.ones(sig.quat.shape[:2], bool)
        if back_s:  # the walk back is joined on with a half turn in one sample: no body turns so, left out
            joint = int((1.5 + 3.0) * FPS)
            present[joint - 3: joint + 3] = False
        f = forward_from_shanks(lower, sig.quat, sig.gyro, present, still_stand(sig.gyro, present, FPS))
        assert np.degrees(np.arctan2(f[1], f[0])) == pytest.approx(heading, abs=8.0)
        cal = calibrate_standing(lower, sig.quat, acc=sig.specific_force, gyro=sig.gyro, present=present, rate=FPS)
        assert cal.meta["forward_from"] == "shank swing"


def test_a_session_that_never_bends_a_knee_or_never_stands_still_is_refused():
    motion, sig = session(kind="arm_raises")
    present = np.ones(sig.quat.shape[:2], bool)
    with pytest.raises(CalibrationError, match="knees never bent|forward"):
        calibrate_standing(SITES, sig.quat, acc=sig.specific_force, gyro=sig.gyro, present=present, rate=FPS)
    walk = synthesize(generate("walk", seconds=4.0), NoiseModel(), rng=1, sites=SITES)
    with pytest.raises(CalibrationError, match="no still stand of 1 s found in 0-4.0 s of the log"):
        calibrate_standing(SITES, walk.quat, acc=walk.specific_force, gyro=walk.gyro, rate=FPS)
    with pytest.raises(CalibrationError, match="thigh and a shank"):
        forward_from_knees(("pelvis", "l_foot"), sig.quat[:, [0, 5]], present[:, [0, 5]], slice(0, 60))


def test_a_still_stand_anywhere_serves_and_the_refusal_says_where_it_looked():
    """A trial recorded as people record them starts walking; its stand may come later."""
    gyro = np.full((600, 2, 3), np.deg2rad(40.0))
    gyro[300:400] = 0.0  # 1.67 s still at 5 s
    present = np.ones((600, 2), bool)
    assert still_stand(gyro, present, 60.0) == slice(300, 400)
    gyro[350:355] = np.deg2rad(40.0)  # broken into 0.83 s and 0.75 s
    with pytest.raises(CalibrationError, match=r"^no still stand of 1 s found in 0-10.0 s of walk_003 \(longest "
                                               r"still: 0.83 s at 5.0 s"):
        still_stand(gyro, present, 60.0, name="walk_003")
