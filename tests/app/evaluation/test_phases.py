"""The yardstick's phase split (app/evaluation/phases.py) on a synthesized recording whose
phases are known: a straight walk, a turn on the spot, a still stand."""

from __future__ import annotations

import numpy as np

from app.evaluation.phases import classify_phases, phase_seconds, world_rates
from inference.body.conventions import heading_of, rot_z
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import SEGMENT_INDEX, SITE_SEGMENT
from sim_devices.motions import generate

FPS = 60.0
LOWER = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")


def _walk_turn_stand(walk_s=6.0, turn_s=3.0, stand_s=4.0):
    """Site orientations (site -> (T, 3, 3)) of a walk, then a 180 deg turn on the spot (the
    standing pose turned about Z, smoothly), then a stand; the frame ranges of each part."""
    walk = generate("walk", seconds=walk_s, seed=1, fps=FPS).rot
    turn = generate("stand", seconds=turn_s, seed=2, fps=FPS).rot
    stand = generate("stand", seconds=stand_s, seed=3, fps=FPS).rot
    u = np.linspace(0.0, 1.0, len(turn))
    yaw = np.pi * (3 * u**2 - 2 * u**3)  # smooth start and stop, 180 deg
    heading = heading_of(walk[-1, 0, :2, 0])
    turn = rot_z(heading + yaw)[:, None] @ turn
    stand = rot_z(np.full(len(stand), heading + np.pi))[:, None] @ stand
    R = np.concatenate([walk, turn, stand])
    nw, nt = len(walk), len(turn)
    parts = {"walking": (0, nw), "turning": (nw, nw + nt), "standing": (nw + nt, len(R))}
    return {s: R[:, SEGMENT_INDEX[SITE_SEGMENT[s]]] for s in LOWER}, parts


def _share(labels, phase, lo, hi, margin):
    inner = labels[lo + margin:hi - margin]
    return float(np.mean(inner == phase))


def test_walk_turn_stand_phases_come_out_where_they_were_made():
    R, parts = _walk_turn_stand()
    labels = classify_phases(R, FPS)
    margin = int(0.8 * FPS)  # the windows blur each boundary by up to a stride
    for phase, (lo, hi) in parts.items():
        assert _share(labels, phase, lo, hi, margin) > 0.95, (phase, np.unique(labels[lo:hi], return_counts=True))
    secs = phase_seconds(labels, FPS)
    assert set(secs) == {"walking", "turning", "standing", "other"}
    assert abs(sum(secs.values()) - len(labels) / FPS) < 0.05


def test_phases_ignore_mounting_and_heading():
    """A sensor turned on its segment and a heading error of its world change nothing:
    angular speeds and the turn rate about Z are the same."""
    R, _ = _walk_turn_stand(walk_s=4.0, turn_s=2.0, stand_s=2.0)
    rng = np.random.default_rng(0)
    turned = {}
    for s, r in R.items():
        axis = rng.normal(size=3)
        mount = matrix_about_axis(axis / np.linalg.norm(axis), rng.uniform(0, np.pi))
        turned[s] = rot_z(rng.uniform(-np.pi, np.pi)) @ r @ mount
    assert np.array_equal(classify_phases(R, FPS), classify_phases(turned, FPS))


def test_without_leg_pairs_there_is_no_walking_and_missing_samples_are_not_motion():
    R, parts = _walk_turn_stand(walk_s=4.0, turn_s=2.0, stand_s=3.0)
    only_trunk = classify_phases({"pelvis": R["pelvis"]}, FPS)
    assert "walking" not in set(only_trunk)
    lo, hi = parts["standing"]
    gappy = {s: r.copy() for s, r in R.items()}
    gappy["l_shank"][lo + 30:lo + 60] = np.nan
    labels = classify_phases(gappy, FPS)
    assert np.mean(labels[lo + 50:hi - 50] == "standing") > 0.95


def test_world_rates_of_a_steady_turn():
    t = np.arange(120) / FPS
    w = world_rates(rot_z(0.7 * t), FPS)
    assert np.allclose(w, [0.0, 0.0, 0.7], atol=1e-9)
