"""Cadence, knee range and asymmetry from orientations and contacts, on synthesized gait
whose cadence is known from the motion itself."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.skeleton import SEGMENT_INDEX
from inference.metrics.gait import foot_strikes, gait_numbers, knee_flexion_deg
from inference.signals.synthesis import contact_labels
from sim_devices.motions import generate


def truth_of(kind: str, seconds: float = 12.0, seed: int = 1):
    m = generate(kind, seconds=seconds, seed=seed)
    return np.arange(len(m.rot)) / m.fps, m.rot, contact_labels(m.contacts(), m.fps)


@pytest.mark.parametrize("kind, lo, hi", [("walk", 95, 135), ("jog", 140, 185)])
def test_cadence_is_two_steps_per_stride_of_the_motion(kind, lo, hi):
    t, rot, c = truth_of(kind)
    n = gait_numbers(t, rot, c)
    # the stride period read off the left knee's flexion (its spectrum peak), not off the contacts
    knee = knee_flexion_deg(rot)[:, 0]
    spec = np.abs(np.fft.rfft(knee - knee.mean()))
    f = np.fft.rfftfreq(len(knee), d=t[1] - t[0])
    stride_hz = f[np.argmax(spec[1:]) + 1]
    assert n.cadence_spm == pytest.approx(120.0 * stride_hz, rel=0.1)
    assert lo < n.cadence_spm < hi


def test_a_symmetric_walk_has_equal_knee_ranges_and_no_asymmetry():
    t, rot, c = truth_of("walk")
    n = gait_numbers(t, rot, c)
    left, right = n.knee_range_deg
    assert 40 < left < 75 and right == pytest.approx(left, abs=1.0) and n.asymmetry_pct < 2.0


def test_a_stiff_right_knee_shows_as_asymmetry():
    t, rot, c = truth_of("walk")
    stiff = rot.copy()
    stiff[:, SEGMENT_INDEX["r_shank"]] = stiff[:, SEGMENT_INDEX["r_thigh"]]  # the right knee never bends
    n = gait_numbers(t, stiff, c)
    assert n.knee_range_deg[1] < 1.0 and n.asymmetry_pct > 150


def test_standing_still_gives_no_cadence():
    t, rot, c = truth_of("squat")
    assert gait_numbers(t, rot, c).cadence_spm is None
    one = gait_numbers(t[:1], rot[:1], c[:1])
    assert one.cadence_spm is None and one.knee_range_deg == (None, None)


def test_flickering_contact_is_not_a_step():
    t = np.arange(0, 4, 1 / 60)
    c = np.zeros((len(t), 4), bool)
    c[(t > 1.0) & (t < 1.6), 0] = True  # left heel down
    c[(t > 1.63) & (t < 1.66), 0] = True  # off for 30 ms and back: a flicker
    c[(t > 2.5) & (t < 3.1), 2] = True  # right heel down after a real swing
    assert np.allclose(foot_strikes(t, c), [1.0 + 1 / 60, 2.5 + 1 / 60], atol=1 / 60)
