"""The stand prior straightens a measured-shank knee only on a still, upright stand."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.rotations import matrix_about_axis_np, matrix_angle_between
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.poser.joint_constraints import KNEE_AXIS
from inference.poser.stand_prior import StandPrior

PELVIS, LT, LS, RT, RS = (SEGMENT_INDEX[s] for s in ("pelvis", "l_thigh", "l_shank", "r_thigh", "r_shank"))
AXIS = np.asarray(KNEE_AXIS)


def frame(flexion_deg: float = 10.0, shank_lean_deg: float = 0.0, turn_deg: float = 0.0) -> tuple[np.ndarray, ...]:
    """Pelvis and shanks measured; each thigh the shank turned back about the knee."""
    R = np.tile(np.eye(3), (N_SEGMENTS, 1, 1))
    shank = matrix_about_axis_np(AXIS, np.radians(shank_lean_deg)) @ matrix_about_axis_np(
        np.array([0.0, 0.0, 1.0]), np.radians(turn_deg))
    for t, s in ((LT, LS), (RT, RS)):
        R[s] = shank
        R[t] = shank @ matrix_about_axis_np(AXIS, np.radians(flexion_deg)).T
    measured = np.zeros(N_SEGMENTS, dtype=bool)
    measured[[PELVIS, LS, RS]] = True
    return R, measured


def bend(R: np.ndarray, t: int, s: int) -> float:
    return float(np.degrees(matrix_angle_between(R[t], R[s])))


def test_a_still_upright_stand_settles_straight_within_a_second():
    prior = StandPrior()
    R, m = frame(10.0)
    out = [prior(R, m) for _ in range(30)]
    assert bend(out[0], LT, LS) == pytest.approx(10.0, abs=1e-6)  # moving or just stopped: the model's
    assert bend(out[4], LT, LS) == pytest.approx(10.0, abs=1e-6)  # still for less than 0.25 s: not yet
    assert 0.5 < bend(out[10], LT, LS) < 9.5  # on the way
    assert bend(out[20], LT, LS) < 1e-6 and bend(out[20], RT, RS) < 1e-6  # settled a second after it stopped
    assert np.array_equal(out[20][[PELVIS, LS, RS]], R[[PELVIS, LS, RS]])  # measured ones untouched


@pytest.mark.parametrize("case", ["leaning shank", "sitting", "thigh measured"])
def test_no_straightening_where_a_stand_is_not_what_the_sensors_say(case):
    prior = StandPrior()
    R, m = frame(70.0 if case == "sitting" else 10.0, shank_lean_deg=15.0 if case == "leaning shank" else 0.0)
    if case == "thigh measured":
        m[[LT, RT]] = True
    for _ in range(40):
        out = prior(R, m)
    assert np.array_equal(out, R)


def test_motion_gives_the_flexion_back_at_once():
    prior = StandPrior()
    R, m = frame(10.0)
    for _ in range(30):
        prior(R, m)
    turned, _ = frame(10.0, turn_deg=5.0)  # a shank turning 100 deg/s
    out = prior(turned, m)
    assert bend(out, LT, LS) == pytest.approx(10.0, abs=1e-6) and prior.weight() == 0.0


LF, RF = SEGMENT_INDEX["l_foot"], SEGMENT_INDEX["r_foot"]


def thighs_frame(flexion_deg: float = 10.0, thigh_lean_deg: float = 0.0,
                 foot_pitch_deg: float = 8.0, foot_heading_deg: float = 15.0) -> tuple[np.ndarray, ...]:
    """Pelvis and thighs measured; each shank the thigh turned about the knee (as the hinge
    rebuilds it), each foot pitched and turned."""
    R = np.tile(np.eye(3), (N_SEGMENTS, 1, 1))
    thigh = matrix_about_axis_np(AXIS, np.radians(thigh_lean_deg))
    foot = matrix_about_axis_np(np.array([0.0, 0.0, 1.0]), np.radians(foot_heading_deg)) @ matrix_about_axis_np(
        AXIS, np.radians(foot_pitch_deg))
    for t, s, f in ((LT, LS, LF), (RT, RS, RF)):
        R[t] = thigh
        R[s] = thigh @ matrix_about_axis_np(AXIS, np.radians(flexion_deg))
        R[f] = foot
    measured = np.zeros(N_SEGMENTS, dtype=bool)
    measured[[PELVIS, LT, RT]] = True
    return R, measured


def test_a_worn_upright_thigh_straightens_its_shank_and_levels_the_foot():
    prior = StandPrior()
    R, m = thighs_frame(12.0)
    out = [prior(R, m) for _ in range(30)]
    assert bend(out[4], LT, LS) == pytest.approx(12.0, abs=1e-6)  # not yet still long enough
    assert bend(out[20], LT, LS) < 1e-6 and bend(out[20], RT, RS) < 1e-6
    assert np.array_equal(out[20][[PELVIS, LT, RT]], R[[PELVIS, LT, RT]])  # measured ones untouched
    for f in (LF, RF):
        assert out[20][f][2, 2] == pytest.approx(1.0, abs=1e-9)  # flat
        fwd = out[20][f] @ np.array([1.0, 0.0, 0.0])
        assert np.degrees(np.arctan2(fwd[1], fwd[0])) == pytest.approx(15.0, abs=1e-6)  # heading kept
    half = out[10][LF]  # on the way: part of the tilt gone
    assert 0.0 < np.degrees(np.arccos(half[2, 2])) < 8.0


@pytest.mark.parametrize("case", ["sitting thigh", "kneeling", "on the toes"])
def test_a_worn_thigh_leaves_what_is_no_stand(case):
    prior = StandPrior()
    R, m = thighs_frame(90.0 if case == "kneeling" else 12.0,
                        thigh_lean_deg=-80.0 if case == "sitting thigh" else 0.0,
                        foot_pitch_deg=35.0 if case == "on the toes" else 8.0)
    for _ in range(40):
        out = prior(R, m)
    if case == "on the toes":  # the knee straightens, the foot the model tilts far is left
        assert bend(out, LT, LS) < 1e-6
        assert np.array_equal(out[[LF, RF]], R[[LF, RF]])
    else:
        assert np.array_equal(out, R)


TRUNK = [SEGMENT_INDEX[s] for s in ("spine1", "spine2", "spine3", "neck")]


def lean(R: np.ndarray, deg: float, heading_deg: float = 30.0) -> np.ndarray:
    """``R`` with the unworn spine and neck turned ``heading_deg`` and leaning forward ``deg``."""
    R = R.copy()
    turn = matrix_about_axis_np(np.array([0.0, 0.0, 1.0]), np.radians(heading_deg))
    for k in TRUNK:
        R[k] = turn @ matrix_about_axis_np(np.array([0.0, 1.0, 0.0]), np.radians(deg))
    return R


def tilt_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(R[2, 2], -1.0, 1.0))))


def test_a_standing_body_over_an_upright_pelvis_stands_its_trunk_upright():
    """The 21-frame model leaned a real stand's torso 7-21 deg forward over a still, upright
    pelvis and straight legs; settled, the unworn trunk loses its tilt and keeps its heading."""
    prior = StandPrior()
    R, m = frame(10.0)
    R = lean(R, 18.0)
    out = [prior(R, m) for _ in range(30)]
    assert all(tilt_deg(out[0][k]) == pytest.approx(18.0, abs=1e-6) for k in TRUNK)  # just stopped: the model's
    for k in TRUNK:
        assert tilt_deg(out[20][k]) < 1e-4
        heading = np.degrees(np.arctan2(out[20][k][1, 0], out[20][k][0, 0]))
        assert heading == pytest.approx(30.0, abs=1e-4)


@pytest.mark.parametrize("case", ["stoop", "pelvis leaning", "trunk worn", "no standing leg"])
def test_the_trunk_is_left_where_the_sensors_do_not_say_upright_stand(case):
    prior = StandPrior()
    R, m = frame(10.0, shank_lean_deg=15.0 if case == "no standing leg" else 0.0)
    R = lean(R, 40.0 if case == "stoop" else 18.0)
    if case == "pelvis leaning":
        R[PELVIS] = matrix_about_axis_np(np.array([0.0, 1.0, 0.0]), np.radians(20.0))
    if case == "trunk worn":
        m[TRUNK] = True
    for _ in range(40):
        out = prior(R, m)
    assert np.array_equal(out[TRUNK], R[TRUNK])
