"""Stride timing judged stride by stride: the same strides of two analyses paired (``match_strides``), and
the events the report takes from the shank contact detector against a synthesized walk's truth."""

from __future__ import annotations

import numpy as np
import pytest

from app.report.analysis import analyse
from app.report.events import FootEvents, Stance, foot_events, truth_contact_values
from app.report.strides import match_strides, strides_of
from inference.evaluation.runner import clip_input, evaluation_noise, face_forward
from inference.signals.synthesis import kinematics

from .test_events import FPS, straight, walk_contacts


def test_matched_strides_are_the_same_strides_of_both_analyses():
    t = np.arange(0, 12.0, 1 / FPS)
    c, ls, rs = walk_contacts(t, period=1.1, stance=0.6)
    root, R = straight(t)
    truth = foot_events(t, c, "truth")
    # found: every event moved by a known jitter, the left foot's 4th stance missed (its two strides with it)
    jitter = 0.03
    found = {}
    for side, ev in truth.items():
        st = [Stance(s.start + jitter * (-1) ** k, s.end - jitter * (-1) ** k, s.strike, s.off)
              for k, s in enumerate(ev.stances)]
        if side == "l":
            st = st[:3] + st[4:]
        found[side] = FootEvents(side, st, "model")
    a, b = strides_of(truth, t, root, R), strides_of(found, t, root, R)
    pairs = match_strides(a, b)
    n_l = sum(1 for s in a if s.side == "l")
    assert sum(1 for x, _ in pairs if x.side == "l") == n_l - 2  # the two strides around the missed stance
    assert sum(1 for x, _ in pairs if x.side == "r") == sum(1 for s in a if s.side == "r")
    for x, y in pairs:
        assert x.side == y.side and abs(y.start - x.start) <= jitter + 1e-9 and abs(y.end - x.end) <= jitter + 1e-9
        assert abs(y.time_s - x.time_s) <= 2 * jitter + 1e-9
    # the long found stride across the missed stance pairs with no truth stride
    assert sum(1 for s in b if s.side == "l") == n_l - 1
    assert len({id(y) for _, y in pairs}) == len(pairs)  # a stride is paired once
    # a stride is not paired with one whose strikes lie half a stride or more from its own
    lone = [a[0]]
    far = [a[0].__class__(**{**a[0].__dict__, "start": a[0].start + 0.56, "end": a[0].end + 0.56})]
    assert match_strides(lone, far) == [] and len(match_strides(lone, [a[0]])) == 1


def detector_contacts(motion, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(t, (T, 4) contact values) of the shank contact detector on a motion's synthesized shank sensors
    (calibrated, with the evaluation's sensor noise), as the live poser gives them with both shanks worn
    (on its kept history; none for the first frames, where that history still holds its standing start)."""
    from inference.poser.contact_detector import SHANK_INDEX, DetectorKernel
    from inference.poser.models import resolve_detector

    det = DetectorKernel(resolve_detector("default"))
    f = clip_input(motion, ("l_shank", "r_shank"), False, evaluation_noise(), seed).features[:, SHANK_INDEX]
    f = f.astype(np.float32)
    prob = np.full((len(f), 4), np.nan)
    for i in range(det.context - 1, len(f)):
        prob[i] = det(f[i - det.context + 1: i + 1])
    return np.arange(len(f)) / 20.0, prob


@pytest.mark.data
def test_shank_detector_events_match_motion_capture_walks(shared_data):
    """Bandai's walks of six styles, their events from the shank contact detector (the report's source with
    both shanks worn and no foot sensor or insole) against the truth's heel and toe speed, stride by stride:
    the aims of the gait check (stride time within 20 ms, stance within 3 points) and no lag."""
    from inference.loaders import find_motion_files, load_motion
    from inference.poser.contact_detector import DETECTOR_THRESHOLD

    paths = sorted(p for p in find_motion_files([shared_data / "bandai"]) if "_walk_" in p.name)[:6]
    if not paths:
        pytest.skip("no Bandai walks in the data")
    n_truth, time_d, stance_d, strike_d, off_d = 0, [], [], [], []
    for k, p in enumerate(paths):
        m = face_forward(load_motion(p))
        m = m.slice(0, min(m.n_frames, int(8 * m.fps) + 1))
        kin = kinematics(m, 60.0)
        t = np.arange(len(kin.rot)) / 60.0
        truth = analyse(t, kin.rot, kin.root, t, truth_contact_values(kin.contact_pos, 60.0), "truth", threshold=0.0)
        tc, prob = detector_contacts(m, seed=k)
        found = analyse(t, kin.rot, kin.root, tc, prob, "model", threshold=DETECTOR_THRESHOLD)
        tw = [s for s in truth.summary.walking() if s.start > tc[9]]  # the detector's first frames have no event
        n_truth += len(tw)
        for a, b in match_strides(tw, found.summary.strides):
            if b.kind != "walking":
                continue
            time_d.append(abs(b.time_s - a.time_s))
            stance_d.append(abs(b.stance_pct - a.stance_pct))
            strike_d.append(b.start - a.start)
            off_d.append(b.off - a.off)
    assert n_truth >= 40
    assert len(time_d) >= 0.9 * n_truth  # nearly every stride found where it is
    assert np.mean(time_d) < 0.020 and np.mean(stance_d) < 3.0
    assert abs(np.median(strike_d)) < 0.025 and abs(np.median(off_d)) < 0.025
