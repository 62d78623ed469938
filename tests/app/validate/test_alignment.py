"""The offset search: FFT-based, and honest about what it cannot tell apart.

Unit level, on angle curves made here: the FFT correlation over each lag's overlap is
the direct one; a periodic curve shifted by one period has two candidates and a warning
naming both; an unrelated reference gets a low-correlation warning; a lab's trial (standing, then
walking with turns and a change of pace: ``walk_trial``) has one clear offset where the
steady walk has a rival every stride. End to end: a steady
walk whose reference is shifted by one more stride (its period read off the knee angle's
spectrum, not from the gait generator): validate warns, names both offsets, and
``--offset`` settles it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.capture.simulate import save_truth
from app.cli.main import main
from app.validate.align import correlation_at, correlation_curve, search_time_offset
from inference.metrics.joint_angles import elbow_flexion_deg, hip_angles_deg, knee_flexion_deg
from sim_devices.motions import generate
from tests.app.validate.conftest import T0


def curves(t: np.ndarray, period: float, seed: int, jitter: float = 0.0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    phase = 2 * np.pi * t / period + jitter * np.cumsum(rng.normal(size=len(t))) * np.sqrt(t[1] - t[0])
    return {"l_knee": 30 + 25 * np.sin(phase) + 8 * np.sin(2 * phase + 1.0),
            "r_knee": 30 + 25 * np.sin(phase + np.pi) + 8 * np.sin(2 * phase + 1.0 + 2 * np.pi)}


def test_the_fft_curve_is_the_direct_correlation():
    t_rec = np.arange(0, 30, 0.05)
    t_ref = np.arange(0, 20, 1 / 120)
    rec = curves(t_rec, 1.13, 1, jitter=0.3)
    ref = {j: np.interp(t_ref + 4.2, t_rec, v) for j, v in rec.items()}
    ref["l_knee"][300:340] = np.nan  # a gap in the reference
    lags, score = correlation_curve(t_rec, rec, t_ref, ref, 5.0)
    for lag in (-4.2, -3.0, 0.5, 3.7):
        k = int(np.argmin(np.abs(lags - lag)))
        assert score[k] == pytest.approx(correlation_at(lags[k], t_rec, rec, t_ref, ref, 5.0), abs=0.01)
    lag, corr, _, cands, warns = search_time_offset(t_rec, rec, t_ref, ref)
    assert lag == pytest.approx(-4.2, abs=0.005) and corr > 0.99


def test_a_periodic_walk_one_period_off_has_two_candidates_and_a_warning():
    t_rec = np.arange(0, 20, 0.05)
    t_ref = np.arange(0, 12, 0.01)
    rec = curves(t_rec, 1.1, 2, jitter=0.05)  # a little stride-to-stride variability: the true lag is best
    ref = {j: np.interp(t_ref + 3.0, t_rec, v) for j, v in rec.items()}
    lag, corr, _, cands, warns = search_time_offset(t_rec, rec, t_ref, ref)
    assert lag == pytest.approx(-3.0, abs=0.005) and cands[0][0] == lag
    assert any(abs(abs(o + 3.0) - 1.1) < 0.05 for o, _ in cands[1:])
    assert len(warns) == 1 and "rival" in warns[0] and "--offset" in warns[0]


def test_an_unrelated_reference_is_called_low():
    t = np.arange(0, 20, 0.05)
    rng = np.random.default_rng(3)
    rec = curves(t, 1.1, 4)
    ref = {j: rng.normal(size=len(t)) for j in rec}
    *_, warns = search_time_offset(t, rec, t, ref)
    assert any("low correlation" in w for w in warns)


def flexion(R: np.ndarray) -> dict[str, np.ndarray]:
    out = {}
    for s in "lr":
        out[f"{s}_knee"], out[f"{s}_hip"] = knee_flexion_deg(R, s), hip_angles_deg(R, s)[0]
        out[f"{s}_elbow"] = elbow_flexion_deg(R, s)
    return out


@pytest.mark.parametrize("kind", ["walk", "walk_trial"])
def test_a_trial_that_stands_then_walks_with_turns_has_one_offset_a_steady_walk_has_many(kind):
    """The motion as a reference (60 Hz, from its first frame) and as a recording (20 Hz,
    2 deg of noise, starting 7 s earlier with the subject standing as at the clip's
    start): a steady walk's offset has rivals a stride apart, the trial's is alone."""
    m = generate(kind, seconds=30.0, seed=21)
    t_ref, ref = np.arange(m.n_frames) / m.fps, flexion(m.rot)
    lead = 140  # 7 s at 20 Hz
    rng = np.random.default_rng(0)
    rec = {j: np.concatenate([np.full(lead, v[0]), v]) for j, v in flexion(m.rot[::3]).items()}
    rec = {j: v + rng.normal(0.0, 2.0, len(v)) for j, v in rec.items()}
    t_rec = np.arange(len(rec["l_knee"])) / 20.0
    lag, corr, _, cands, warns = search_time_offset(t_rec, rec, t_ref, ref)
    assert corr > 0.8
    if kind == "walk":  # the true offset is one of several that score alike
        assert any(abs(o + 7.0) < 1 / 60 for o, _ in cands)
        assert len(warns) == 1 and "rival" in warns[0]
    else:
        assert lag == pytest.approx(-7.0, abs=1 / 60)
        assert warns == [] and all(c < corr - 0.15 for _, c in cands[1:])


def test_a_steady_walk_shifted_by_one_stride_is_warned_and_settled_by_offset(walk, tmp_path, capsys):
    m = walk.truth
    start = m.meta["activity_start_frame"] + int(2 * m.fps)  # well into the walk, past the calibration poses
    hip = hip_angles_deg(m.rot, "l")[0][start:]
    f = np.fft.rfftfreq(len(hip), 1 / m.fps)
    spec = np.abs(np.fft.rfft(hip - hip.mean()))
    band = (f > 0.4) & (f < 2.0)
    stride = 1.0 / f[band][np.argmax(spec[band])]  # the hip swings once per stride
    shift = start + int(round(stride * m.fps))  # one stride later than a reference starting at `start`
    n = int(6.0 * m.fps)  # 6 s of steady walking, as a treadmill trial would give
    ref = walk.reference_motion(shift=shift, heading_deg=0.0)
    path = save_truth(tmp_path / "tread.npz", ref.rot[:n], ref.root[:n], m.fps, T0, 0.0,
                      m.body.height, m.body.offsets, ["pelvis"], "treadmill")
    assert main(["validate", str(walk.path), "--reference", str(path), "--model", "floor", "--json"]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    true = walk.expected_offset(shift)
    offs = [c["time_offset_s"] for c in out["time_offset_candidates"]]
    assert any(abs(o - true) < 1.5 / m.fps for o in offs)  # the true offset is a candidate ...
    assert any(abs(abs(o - true) - stride) < 0.1 for o in offs)  # ... and so is one a stride away
    assert any("rival" in w for w in out["warnings"])
    warned = [ln for ln in cap.err.splitlines() if ln.startswith("validate: warning:")]
    assert len(warned) == 1 and warned[0].count(" s (correlation") >= 2
    # --offset settles it: no search, no warning, the true offset used
    assert main(["validate", str(walk.path), "--reference", str(path), "--model", "floor", "--json",
                 "--offset", f"{true}"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["time_offset_given"] and out["warnings"] == [] and out["time_offset_s"] == pytest.approx(true)
