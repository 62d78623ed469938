"""Foot sensors as the gait events' source: their angular rate's events against the walk's truth, on
procedural walks (recordings the real Recorder wrote, read back by the report) and on motion-capture
walks synthesized into foot-sensor signals."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli.main import main
from app.recording import read_recording
from app.report.analysis import analyse_recording, figures
from app.report.events import foot_events, truth_contact_values
from app.report.feet import foot_sensor_events, sagittal_rate, sensor_events
from inference.evaluation.runner import face_forward
from inference.signals.synthesis import NoiseModel, kinematics, synthesize
from sim_devices.motions import generate

from .walks import truth_recording

LOWER = ("pelvis", "l_shank", "r_shank", "l_foot", "r_foot")


@pytest.fixture(scope="module")
def walks(tmp_path_factory):
    d = tmp_path_factory.mktemp("feet")
    walk = generate("walk", speed=1.2, seconds=10.0, seed=1)
    return {"feet": truth_recording(d / "feet.h5", walk, sites=LOWER, raw=True, seed=1),
            "no_feet": truth_recording(d / "no_feet.h5", walk, sites=LOWER[:3], raw=True, seed=1),
            "lost_foot": truth_recording(d / "lost.h5", walk, sites=LOWER, raw=True, seed=1, drop=("l_foot",)),
            "dir": d}


def test_the_report_takes_its_events_from_the_foot_sensors_when_worn(walks, capsys):
    out = walks["dir"] / "feet.html"
    assert main(["report", str(walks["feet"]), "--out", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["events_from"] == "foot sensors"
    # the reconstruction here is the motion itself, its contacts the truth's: the same walk's figures
    truth = figures(analyse_recording(read_recording(walks["feet"]), "model"))
    assert truth["events_from"] == "model"
    for side in ("l", "r"):
        assert s["strides"][side] >= 6
        assert s["stride_time_s"][side]["mean"] == pytest.approx(truth["stride_time_s"][side]["mean"], abs=0.02)
        assert s["stance_pct"][side] == pytest.approx(truth["stance_pct"][side], abs=6.0)
    html = out.read_text()
    assert "the foot sensors&#x27; angular rate" in html and "Rampp" in html


def test_without_both_foot_sensors_the_events_come_from_the_model(walks):
    for key in ("no_feet", "lost_foot"):
        rec = read_recording(walks[key])
        assert foot_sensor_events(rec) is None
        assert analyse_recording(rec).source == "model"
        with pytest.raises(ValueError, match="foot sensors"):
            analyse_recording(rec, "foot sensors")


def test_a_gap_in_a_foot_sensor_makes_no_event_inside_it():
    m = generate("walk", speed=1.3, seconds=8.0, seed=0)
    sig = synthesize(m, NoiseModel.typical(), rng=0, sites=("l_foot",))
    present = np.ones(len(sig.t), bool)
    present[200:260] = False  # one second lost
    ev = sensor_events(sig.t, sig.gyro[:, 0], sig.meta["R_SB"][0], present, acc=sig.specific_force[:, 0])
    lo, hi = sig.t[199], sig.t[260]
    assert not any(lo < x < hi for x in np.concatenate([ev.strikes, ev.offs]))
    assert len(ev.strikes) >= 4  # the walk either side still has its events
    whole = sensor_events(sig.t, sig.gyro[:, 0], sig.meta["R_SB"][0], acc=sig.specific_force[:, 0])
    assert len(whole.strikes) > len(ev.strikes)


def test_the_sagittal_rate_is_the_bones_and_plantarflexion_is_positive():
    m = generate("walk", speed=1.3, seconds=6.0, seed=0)
    sig = synthesize(m, NoiseModel.typical(), rng=0, sites=("l_foot",))
    w = sagittal_rate(sig.gyro[:, 0], sig.meta["R_SB"][0])
    clean = synthesize(m, None, sites=("l_foot",))  # no mounting rotation: the gyro is the bone's rate
    assert np.corrcoef(w, clean.gyro[:, 0, 1])[0, 1] > 0.99
    # mid-swing (the largest magnitude) turns the foot toes-up: negative; the stance rolls it toes-down
    assert w.min() < -np.radians(250) and abs(w.min()) > 0.5 * w.max() > 0
    wrong = sagittal_rate(sig.gyro[:, 0], np.eye(3)) if not np.allclose(sig.meta["R_SB"][0], np.eye(3)) else None
    assert wrong is None or not np.allclose(wrong, w)


@pytest.mark.data
def test_foot_sensor_events_match_motion_capture_walks(shared_data):
    """Bandai's walks of six styles (motion capture, their truth's heel and toe speed giving the events):
    the foot sensors' strikes and offs lie near the truth's, stride by stride."""
    from inference.loaders import find_motion_files, load_motion

    paths = sorted(p for p in find_motion_files([shared_data / "bandai"]) if "_walk_" in p.name)[:6]
    if not paths:
        pytest.skip("no Bandai walks in the data")
    strike, off, stride = [], [], []
    for p in paths:
        m = face_forward(load_motion(p))
        m = m.slice(0, min(m.n_frames, int(8 * m.fps) + 1))
        kin = kinematics(m, 60.0)
        t = np.arange(len(kin.rot)) / 60.0
        truth = foot_events(t, truth_contact_values(kin.contact_pos, 60.0), "truth", threshold=0.0)
        sig = synthesize(m, NoiseModel.typical(), rng=1, sites=("l_foot", "r_foot"))
        for k, side in enumerate(("l", "r")):
            ev = sensor_events(sig.t, sig.gyro[:, k], sig.meta["R_SB"][k], side=side, acc=sig.specific_force[:, k])
            ts, fs = truth[side].strikes, ev.strikes
            assert abs(len(fs) - len(ts)) <= 1  # a strike at the clip's very end may be missed
            for x in ts:
                d = fs - x
                if len(d) and abs(d).min() < 0.3:
                    strike.append(d[np.argmin(abs(d))])
            for x in truth[side].offs:
                d = ev.offs - x
                if len(d) and abs(d).min() < 0.3:
                    off.append(d[np.argmin(abs(d))])
            pairs = [(a, b) for a, b in zip(ts[:-1], ts[1:])]
            for a, b in pairs:
                i = np.argmin(abs(fs - a)) if len(fs) else None
                if i is not None and i + 1 < len(fs) and abs(fs[i] - a) < 0.3:
                    stride.append((fs[i + 1] - fs[i]) - (b - a))
    assert len(strike) >= 40 and len(off) >= 40
    # the foot flattening after the heel lands comes ~30 ms before the heel's speed-threshold contact, the
    # roll over the toes within a few ms of the toe's lift (docs/report.md)
    assert abs(np.median(strike)) < 0.06 and abs(np.median(off)) < 0.06
    assert np.mean(np.abs(stride)) < 0.03


def test_true_runs_split_at_gaps_in_time():
    from app.report.feet import true_runs

    mask = np.array([0, 1, 1, 1, 0, 1, 1, 0, 1], bool)
    assert true_runs(mask) == [(1, 3), (5, 6), (8, 8)]
    starts = np.zeros(len(mask), bool)
    starts[2] = True  # a gap in time before sample 2
    assert true_runs(mask, starts) == [(1, 1), (2, 3), (5, 6), (8, 8)]
    assert true_runs(np.zeros(3, bool)) == []
