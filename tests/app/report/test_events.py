"""Gait events and strides from contact signals whose events are known by construction."""

from __future__ import annotations

import numpy as np
import pytest

from app.report.events import (
    MIN_STANCE_S,
    MIN_SWING_S,
    WARMUP_S,
    Stance,
    contact_source,
    coordinate_events,
    debounce,
    foot_events,
    model_contact_values,
)
from app.report.strides import strides_of, summarize, symmetry_index
from inference.body.conventions import rot_z

FPS = 20.0


def square(t: np.ndarray, strikes: list[float], offs: list[float]) -> np.ndarray:
    """A 0/1 contact that ramps linearly over two frames at each event, so the crossing of 0.5 is the event
    and the frames either side of it are on the ramp."""
    v = np.zeros_like(t)
    for a, b in zip(strikes, offs):
        v = np.maximum(v, np.clip(0.5 + (t - a) * FPS / 2, 0, 1) * np.clip(0.5 + (b - t) * FPS / 2, 0, 1))
    return v


def walk_contacts(t, period=1.1, stance=0.62, shift=0.55, t0=0.3):
    """(T, 4) contact values of a walk: left strikes at t0 + k period, right half a cycle later; heel and
    toe down together (the foot's union is what counts)."""
    n = int((t[-1] - t0) / period) + 2
    ls = [t0 + k * period for k in range(n)]
    rs = [t0 + shift + (k - 1) * period for k in range(n + 1)]
    left = square(t, ls, [s + stance * period for s in ls])
    right = square(t, rs, [s + stance * period for s in rs])
    return np.stack([left, left, right, right], axis=1), ls, rs


def test_events_are_found_where_the_contact_crosses_between_frames():
    t = np.arange(0, 8.0, 1 / FPS)
    c, ls, _ = walk_contacts(t, period=1.13)
    ev = foot_events(t, c, "model")
    strikes = ev["l"].strikes
    want = [s for s in ls if t[0] < s - 1 / FPS and s < t[-1] - 1 / FPS]
    assert len(strikes) == len(want)
    assert np.max(np.abs(strikes - want)) < 1e-6  # linear ramps: interpolation is exact
    offs = ev["l"].offs
    assert np.max(np.abs(offs - (strikes[: len(offs)] + 0.62 * 1.13))) < 1e-6


def test_flickers_are_debounced_and_cut_ends_are_not_events():
    stances = [Stance(0.0, 0.5, strike=False), Stance(0.55, 1.0), Stance(1.4, 1.45), Stance(2.0, 2.6, off=False)]
    out = debounce(stances)
    # the 50 ms gap closed (a flicker at heel strike), the 50 ms contact dropped (a brush in swing)
    assert [(s.start, s.end) for s in out] == [(0.0, 1.0), (2.0, 2.6)]
    assert not out[0].strike and out[0].off and out[1].strike and not out[1].off
    assert 0.05 < MIN_SWING_S and 0.05 < MIN_STANCE_S


def test_a_gap_in_the_data_cuts_a_stance_without_inventing_events():
    t = np.arange(0, 6.0, 1 / FPS)
    c, _, _ = walk_contacts(t)
    c[40:50] = np.nan  # half a second lost
    ev = foot_events(t, c, "model")
    for side in ("l", "r"):
        for s in ev[side].stances:
            if s.strike:
                assert not (t[39] < s.start < t[50])
            if s.off:
                assert not (t[39] < s.end < t[50])


def test_the_posers_warm_up_gives_no_event():
    """The poser's first WARMUP_S read its made-up standing history: a strike there is not one, and a
    stance running into the warm-up's end has no strike; the same walk's later events are kept."""
    t = 12.5 + np.arange(0, 6.0, 1 / FPS)  # a reconstruction need not start at t = 0
    c, ls, _ = walk_contacts(t, t0=12.6)  # the first left strike 0.1 s in
    kept = foot_events(t, c, "model")["l"].strikes
    assert kept[0] == pytest.approx(12.6)
    values = model_contact_values(t, c)
    assert np.isnan(values[t < t[0] + WARMUP_S - 1e-9]).all() and np.isfinite(values[t >= t[0] + WARMUP_S]).all()
    ev = foot_events(t, values, "model")
    assert np.array_equal(ev["l"].strikes, kept[1:])
    assert not ev["l"].stances[0].strike  # the stance from 12.6 s runs on past the warm-up, cut there
    # a recording's model contacts come with the warm-up missing; the recording's own array is untouched
    recon = {"t": t, "contact_prob": c.copy()}
    ct, cv, source = contact_source(recon)
    assert source == "model" and np.isnan(cv[0]).all() and np.isfinite(recon["contact_prob"]).all()


def straight(t, speed=1.25):
    root = np.stack([speed * t, np.zeros_like(t), np.full_like(t, 0.95)], axis=1)
    return root, np.broadcast_to(np.eye(3), (len(t), 3, 3)).copy()


def test_strides_of_a_steady_walk():
    t = np.arange(0, 10.0, 1 / FPS)
    c, _, _ = walk_contacts(t, period=1.1, stance=0.62)
    root, R = straight(t)
    s = summarize(strides_of(foot_events(t, c, "model"), t, root, R))
    assert s.count("l") >= 7 and s.count("r") >= 7
    for side in ("l", "r"):
        p = s.per_side[side]
        assert p["time_s"]["mean"] == pytest.approx(1.1, abs=1e-6)
        assert p["stance_pct"]["mean"] == pytest.approx(62.0, abs=1e-4)
        assert p["swing_pct"]["mean"] == pytest.approx(38.0, abs=1e-4)
        # the other foot strikes 0.55 s after: double support 0.62 x 1.1 - 0.55 s at each end of the stance
        assert p["double_support_pct"]["mean"] == pytest.approx(100 * 2 * (0.62 * 1.1 - 0.55) / 1.1, abs=1e-3)
        assert p["length_m"]["mean"] == pytest.approx(1.25 * 1.1, abs=1e-6)
        assert p["speed_mps"]["mean"] == pytest.approx(1.25, abs=1e-6)
    assert s.cadence_spm == pytest.approx(120 / 1.1, abs=1e-6)
    assert s.symmetry["time_s"] == pytest.approx(0.0, abs=1e-9)


def test_turns_and_standing_are_left_out_and_counted():
    t = np.arange(0, 10.0, 1 / FPS)
    c, _, _ = walk_contacts(t)
    root, R = straight(t)
    yaw = np.where(t > 5.0, np.minimum((t - 5.0) * np.deg2rad(60.0), np.pi), 0.0)  # a 180 deg turn from 5 s
    R = rot_z(yaw)
    s = summarize(strides_of(foot_events(t, c, "model"), t, root, R))
    assert s.excluded["turning"] >= 2
    for st in s.strides:  # the turn lasts from 5 to 8 s: a stride inside it turns, one outside walks
        if st.start >= 5.0 and st.end <= 8.0:
            assert st.kind == "turning"
        elif st.end <= 5.0 or st.start >= 8.0:
            assert st.kind == "walking"
    still = np.zeros_like(t)
    s = summarize(strides_of(foot_events(t, c, "model"), t, np.stack([still, still, still + 0.95], 1),
                             np.broadcast_to(np.eye(3), (len(t), 3, 3))))
    assert s.count("l") == s.count("r") == 0 and s.excluded["standing"] > 0  # stepping on the spot
    assert s.cadence_spm is None and s.per_side["l"]["time_s"]["mean"] is None


def test_both_feet_down_throughout_gives_no_stride():
    t = np.arange(0, 5.0, 1 / FPS)
    root, R = straight(t, 0.0)
    s = summarize(strides_of(foot_events(t, np.ones((len(t), 4)), "model"), t, root, R))
    assert s.strides == [] and s.cadence_spm is None


def test_symmetry_index():
    assert symmetry_index(1.1, 1.0) == pytest.approx(100 * 0.1 / 1.05)
    assert symmetry_index(None, 1.0) is None


def test_a_joint_range_between_frames_is_refined_by_a_parabola():
    from app.report.strides import Stride, stride_ranges

    t = np.arange(0, 3.0, 1 / FPS)
    s = Stride("l", 0.31, 0.9, 1.44, 1.13, 60, 40, 10, 1.4, 1.25, 0)
    fine = np.arange(s.start, s.end, 1e-4)
    missed = []
    for phase in np.linspace(0.0, 2 * np.pi, 9)[:-1]:  # peaks at different places between the 20 Hz frames
        knee = 30 + 30 * np.sin(2 * np.pi * 1.4 * t + phase)
        truth = np.ptp(30 * np.sin(2 * np.pi * 1.4 * fine + phase))
        sampled = np.ptp(knee[(t > s.start) & (t < s.end)])
        got = stride_ranges([s], t, knee)[0]
        assert abs(got - truth) < 0.15 and abs(got - truth) <= abs(sampled - truth) + 1e-9
        missed.append(truth - sampled)
    assert max(missed) > 0.5  # the frames alone miss a peak by more than the refined range's error
    # an angle still rising into the next stride: its largest frame is no peak and is not extrapolated
    ramp = 10.0 * t
    assert stride_ranges([s], t, ramp)[0] == pytest.approx(10.0 * (s.end - s.start), abs=1e-9)


def _walk_points(fps: float = 60.0, seconds: float = 6.0, stride: float = 1.1, stance: float = 0.62,
                 speed: float = 1.2, heading_deg: float = 30.0):
    """Heel/toe points of two feet walking along a heading: each foot still through its stance, then
    swinging forward at a constant speed (faster than the pelvis) until it strikes; the right foot half a
    stride after the left. Returns t, points (T, 4, 3), pelvis (T, 3) and each foot's true (strike, off)."""
    t = np.arange(int(seconds * fps)) / fps
    d = np.array([np.cos(np.radians(heading_deg)), np.sin(np.radians(heading_deg)), 0.0])
    pel = np.outer(speed * t, d) + [0.0, 0.0, 0.95]
    step = speed * stride  # a foot moves a stride's length in its swing
    swing = (1.0 - stance) * stride
    pts = np.zeros((len(t), 4, 3))
    truth = {}
    for k, (side, phase) in enumerate((("l", 0.0), ("r", 0.5))):
        strike0 = phase * stride
        n = np.floor((t - strike0) / stride)  # the stride each sample is in
        into = t - strike0 - n * stride
        base = n * step  # where the foot stood in stride n
        along = np.where(into < stance * stride, base, base + step * (into - stance * stride) / swing)
        heel = np.outer(along + speed * strike0 + 0.1, d)  # strikes 10 cm ahead of the pelvis
        pts[:, 2 * k] = heel
        pts[:, 2 * k + 1] = heel + 0.2 * d
        strikes = strike0 + stride * np.arange(-1, 7)
        truth[side] = (strikes, strikes + stance * stride)
    return t, pts, pel, truth


def test_coordinate_events_find_strikes_and_offs_of_a_walk():
    t, pts, pel, truth = _walk_points()
    ev = coordinate_events(t, pts, pel)
    for side in ("l", "r"):
        strikes, offs = truth[side]
        found = ev[side]
        assert len(found.strikes) >= 4 and len(found.offs) >= 4
        for s in found.strikes:
            assert np.min(np.abs(strikes - s)) < 1.0 / 60.0
        for o in found.offs:
            assert np.min(np.abs(offs - o)) < 1.0 / 60.0
        whole = [s for s in found.stances if s.strike and s.off]
        assert np.mean([s.end - s.start for s in whole]) == pytest.approx(0.62 * 1.1, abs=1.0 / 60.0)


def test_coordinate_events_cut_stances_at_the_data_ends_and_refuse_bad_shapes():
    t, pts, pel, _ = _walk_points(seconds=3.0)
    ev = coordinate_events(t[70:], pts[70:], pel[70:])
    first = ev["l"].stances[0]
    # the left foot is in stance at 70 / 60 = 1.17 s (its second stance runs 1.1 to 1.78 s): cut, no strike
    assert not first.strike and first.off and first.start == pytest.approx(t[70])
    with pytest.raises(ValueError, match="pelvis"):
        coordinate_events(t, pts, pel[:, :2])
