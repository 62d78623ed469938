"""Offline replay of a recording (app/replay/run.py): all sensors reproduce the live
reconstruction; a subset keeps the chosen sensors' segments and inpaints the rest;
wrong sites, missing insoles or calibrations are clear errors."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.recording import read_recording
from app.replay import compare_to_recorded, replay_recording, resolve_insoles, resolve_sensors
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
from inference.poser.poser import make_poser


def _rot(poses):
    return np.stack([lp.pose.rot for lp in poses])


def test_all_sensors_reproduce_the_live_reconstruction(recorded):
    rec = read_recording(recorded.path)
    res = replay_recording(rec, make_poser("floor", body=recorded.body))
    assert res.sensors == recorded.sites and res.insoles is True and res.calibrations_used == 1
    assert res.hub_frames == rec.n_frames
    assert len(res.poses) == len(recorded.live) == len(rec.recon["t"])
    assert np.allclose([lp.t for lp in res.poses], rec.recon["t"])
    assert np.allclose(_rot(res.poses), _rot(recorded.live), atol=1e-6)
    assert np.array_equal(np.stack([lp.pose.contacts for lp in res.poses]), rec.recon["contacts"])
    cmp = compare_to_recorded(rec, res.poses)
    assert cmp["vs_recorded_frames"] == len(res.poses) and cmp["vs_recorded_ga_deg"] < 1e-3


def test_a_sensor_subset_keeps_its_segments_and_inpaints_the_others(recorded):
    rec = read_recording(recorded.path)
    res = replay_recording(rec, make_poser("floor", body=recorded.body), sensors="r_shank,pelvis,l_shank")
    assert res.sensors == ("pelvis", "l_shank", "r_shank")  # the recording's order
    observed = np.stack([lp.observed_sites for lp in res.poses])
    assert observed[:, [SITE_INDEX[s] for s in ("pelvis", "l_shank", "r_shank")]].all()
    assert not observed[:, [SITE_INDEX[s] for s in ("head", "l_wrist", "r_wrist")]].any()
    R, R_live = _rot(res.poses), rec.recon["R"]
    kept = np.rad2deg(matrix_angle_between(R[:, SEGMENT_INDEX["l_shank"]], R_live[:, SEGMENT_INDEX["l_shank"]]))
    dropped = np.rad2deg(matrix_angle_between(R[:, SEGMENT_INDEX["r_forearm"]], R_live[:, SEGMENT_INDEX["r_forearm"]]))
    assert kept.max() < 0.01  # measured segments are the measurement
    assert dropped.mean() > 3.0  # the floor holds an unmeasured forearm standing; live it was measured
    assert compare_to_recorded(rec, res.poses)["vs_recorded_ga_deg"] > 1.0


def test_site_errors_list_what_the_recording_has(recorded):
    rec = read_recording(recorded.path)
    with pytest.raises(ValueError, match="elbow") as e1:
        resolve_sensors(rec, "pelvis,elbow")
    with pytest.raises(ValueError, match="torso") as e2:
        resolve_sensors(rec, ["torso"])
    for e in (e1, e2):
        assert "pelvis, head, l_wrist, r_wrist, l_shank, r_shank" in str(e.value)
    assert resolve_sensors(rec, None) == recorded.sites


def test_insoles_default_to_the_session_and_cannot_be_invented(recorded):
    rec = read_recording(recorded.path)
    assert resolve_insoles(rec, None) is True and resolve_insoles(rec, False) is False
    raw = dict(rec.raw)
    raw["insoles"] = {**rec.raw["insoles"], "present": np.zeros_like(rec.raw["insoles"]["present"])}
    bare = replace(rec, raw=raw)
    assert resolve_insoles(bare, None) is False
    with pytest.raises(ValueError, match="no insole data"):
        resolve_insoles(bare, True)


def test_every_recorded_calibration_takes_effect_and_none_is_an_error(recorded):
    rec = read_recording(recorded.path)
    t_cal, cal = rec.calibrations[0]
    once = replay_recording(rec, make_poser("floor", body=recorded.body))
    t_mid = float(rec.raw["t"][(np.searchsorted(rec.raw["t"], t_cal) + rec.n_frames) // 2])
    twice = replay_recording(replace(rec, calibrations=[(t_cal, cal), (t_mid, cal)]),
                             make_poser("floor", body=recorded.body))
    assert twice.calibrations_used == 2
    assert len(once.poses) - 4 <= len(twice.poses) < len(once.poses)  # the resampler restarts at t_mid
    assert not any(abs(lp.t - t_mid) < 1e-9 for lp in twice.poses)  # that frame was the calibrating one
    with pytest.raises(ValueError, match="no calibration"):
        replay_recording(replace(rec, calibrations=[]), make_poser("floor", body=recorded.body))
    # an explicit calibration replaces the recorded ones from the first frame
    own = replay_recording(replace(rec, calibrations=[]), make_poser("floor", body=recorded.body), calibration=cal)
    assert own.calibrations_used == 1 and len(own.poses) > len(once.poses)


def test_a_recalibration_pauses_the_replay_where_it_paused_live(tmp_path):
    """The clip is played twice and the pipeline recalibrates at the second start, as the
    demo does at every loop: live, nothing is posed from the first frame that went back to
    the calibrator until the new calibration; the replay must pose the very same frames."""
    import itertools

    from app.live import RECALIBRATION_EVENT, Pipeline, frames_from_signals
    from app.recording import Recorder
    from calibration import Calibrator, synthesize_session
    from inference.signals.synthesis import NoiseModel
    from sim_devices.motions import generate
    from tests.app.conftest import REC_PROTO, REC_SITES

    act = generate("walk", seconds=2.0, seed=7)
    sig, truth = synthesize_session(act, REC_PROTO, noise=NoiseModel.typical(), rng=3, sites=REC_SITES)
    first = frames_from_signals(sig, t0=100.0)
    span = first[-1].t - first[0].t + 1 / 60
    second = [replace(f, index=f.index + len(first)) for f in frames_from_signals(sig, t0=100.0 + span)]
    ticks = itertools.count(0.0, 0.01)
    path = tmp_path / "twice.h5"
    rec = Recorder(path, REC_SITES, metadata={"model": "floor"}, flush_interval=0.2, clock=lambda: next(ticks))
    cal = Calibrator(REC_SITES, schedule=REC_PROTO.schedule())
    pipe = Pipeline(make_poser("floor", body=truth.body), REC_SITES, calibrator=cal, sinks=[rec])
    live = []
    for f in first:
        live += pipe.push(f)
    assert pipe.calibration is not None
    pipe.recalibrate(second[0].t)
    for f in second:
        live += pipe.push(f)
    pipe.close()

    r = read_recording(path)
    assert len(r.calibrations) == 2
    recal = [t for t, kind, _ in r.events if kind == RECALIBRATION_EVENT]
    assert recal == [pytest.approx(second[0].t)]
    # live posed nothing between the recalibration's start and the second calibration
    t_cal2 = r.calibrations[1][0]
    assert not any(recal[0] <= lp.t <= t_cal2 for lp in live)
    again = replay_recording(r, make_poser("floor", body=truth.body))
    assert again.calibrations_used == 2
    assert len(again.poses) == len(live)
    assert np.allclose([lp.t for lp in again.poses], [lp.t for lp in live])
    assert np.allclose(_rot(again.poses), _rot(live), atol=1e-4)
    # a recording from before the event (none in it): the old way, the stretch posed with the first calibration
    old = replay_recording(replace(r, events=[]), make_poser("floor", body=truth.body))
    assert sum(recal[0] <= lp.t <= t_cal2 for lp in old.poses) > 10


def test_frames_live_had_no_time_for_are_left_out_again_so_the_replay_gives_back_live(tmp_path):
    """Live, a loop that falls behind passes frames over (``Pipeline.pass_over``): their
    20 Hz frames are never posed, and the autoregressive poser goes on from the frames it
    did see. The recording keeps each skipped frame's time; a replay with no options leaves
    out the same frames and gives back live exactly, ``every_frame`` poses them all."""
    import itertools

    from app.live import POSE_SKIPPED_EVENT, Pipeline, frames_from_signals
    from app.recording import Recorder
    from calibration import Calibrator, synthesize_session
    from inference.signals.synthesis import NoiseModel
    from sim_devices.motions import generate
    from tests.app.conftest import REC_PROTO, REC_SITES

    act = generate("walk", seconds=3.0, seed=2)
    sig, truth = synthesize_session(act, REC_PROTO, noise=NoiseModel.typical(), rng=5, sites=REC_SITES)
    frames = frames_from_signals(sig, t0=300.0)
    ticks = itertools.count(0.0, 0.01)
    path = tmp_path / "behind.h5"
    rec = Recorder(path, REC_SITES, metadata={"model": "diffusion"}, flush_interval=0.2, clock=lambda: next(ticks))

    def poser():
        return make_poser("diffusion", body=truth.body, steps=[1], seed=0)

    pipe = Pipeline(poser(), REC_SITES, calibrator=Calibrator(REC_SITES, schedule=REC_PROTO.schedule()), sinks=[rec])
    live = []
    for k, f in enumerate(frames):
        if pipe.calibration is not None and k % 30 >= 24:  # behind for 0.1 s of every 0.5 s
            pipe.pass_over(f)
        else:
            live += pipe.push(f)
    pipe.close()
    skipped = pipe.stats.poses_skipped
    assert skipped > 5 and len(live) > 20

    r = read_recording(path)
    assert sum(kind == POSE_SKIPPED_EVENT for _, kind, _ in r.events) == skipped
    again = replay_recording(r, poser())
    assert again.stats["poses_skipped"] == skipped
    assert np.allclose([lp.t for lp in again.poses], [lp.t for lp in live])
    assert np.allclose(_rot(again.poses), _rot(live), atol=1e-5)
    every = replay_recording(r, poser(), every_frame=True)
    assert len(every.poses) == len(live) + skipped and every.stats["poses_skipped"] == 0
    # the poser remembers: posing the skipped frames changes the frames after them
    cmp = compare_to_recorded(r, every.poses)
    assert cmp["vs_recorded_frames"] == len(live) and cmp["vs_recorded_ga_deg"] > 1e-3, cmp


def test_a_replay_keeps_the_knee_twist_the_recording_was_posed_with(recorded):
    """A recording says the knees' twist share its poses were made with; one posed before the share
    existed (a step list, no share) ran the strict hinge and replays so; a log never posed takes the
    model file's; asking overrides all three."""
    from app.replay import ReplaySettings, build_replay_poser, poser_metadata
    from inference.poser.knee_twist import KNEE_TWIST

    rec = read_recording(recorded.path)
    # what a live session or an import writes of its poser
    assert poser_metadata(make_poser("diffusion", body=recorded.body), "centred")["knee_twist"] == KNEE_TWIST

    def twist(meta, asked=None):
        return build_replay_poser(replace(rec, metadata=meta), ReplaySettings(knee_twist=asked),
                                  recorded.body).poser.knee_twist

    base = {k: v for k, v in rec.metadata.items() if k not in ("knee_twist", "step_list")}
    assert twist({**base, "knee_twist": 0.25}) == 0.25
    assert twist({**base, "step_list": [1000, 400, 0]}) == 0.0
    assert twist(base) == KNEE_TWIST
    assert twist({**base, "knee_twist": 0.25}, asked=0.0) == 0.0


def test_a_replay_with_no_model_named_poses_with_the_recorded_one(recorded):
    """The recording names the spec it was posed with; one recorded before that is read from
    its label (a shipped file's name), and one that says neither was the full model's, the
    default then. The live default ("auto") chooses by the sensors the replay wears."""
    from app.replay import ReplaySettings, recorded_model, replay_model
    from inference.poser.models import DEFAULT_WEIGHTS

    assert recorded_model({"model_spec": "fast", "model": "diffusion 4/128/512 (diffusionposer.pt)"}) == "fast"
    assert recorded_model({"model": f"diffusion 4/128/512 ({DEFAULT_WEIGHTS['fast'].name})"}) == "fast"
    assert recorded_model({"model": f"diffusion 4/128/512 ({DEFAULT_WEIGHTS['diffusion'].name})"}) == "diffusion"
    assert recorded_model({"model": "floor (fallback: weights missing)"}) == "floor"
    assert recorded_model({"model": "diffusion 4/128/512 (mine.pt)"}) == recorded_model({}) == "diffusion"
    rec = read_recording(recorded.path)
    assert rec.metadata["model"] == "floor" and replay_model(rec, ReplaySettings(model=None)) == "floor"
    assert replay_model(rec, ReplaySettings()) == "floor"
    assert replay_model(rec, ReplaySettings(model="diffusion")) == "diffusion"  # what an import and a report pose with
    assert replay_model(rec, ReplaySettings(model="auto")) == "fast"
    thighs = replace(rec, metadata={**rec.metadata, "model_spec": "auto"})
    assert replay_model(thighs, ReplaySettings(model=None), ("pelvis", "l_thigh", "r_thigh")) == "diffusion"


def test_another_model_than_the_recorded_one_runs_its_own_files_settings(recorded):
    """A live capture of the 21-frame file (no mirror pair) replayed with the full model runs the full model's
    mirror chains, as an import or a report's second posing must; the recorded model keeps what it ran."""
    from app.replay import ReplaySettings, build_replay_poser
    from inference.poser.models import DEFAULT_WEIGHTS

    if not (DEFAULT_WEIGHTS["fast"].exists() and DEFAULT_WEIGHTS["diffusion"].exists()):
        pytest.skip("shipped weights not installed")
    rec = read_recording(recorded.path)
    live = replace(rec, metadata={**rec.metadata, "model": f"diffusion 4/128/512 ({DEFAULT_WEIGHTS['fast'].name})",
                                  "model_spec": "fast", "mirror": False, "step_list": [1000, 0]})
    again = build_replay_poser(live, ReplaySettings(), recorded.body)
    full = build_replay_poser(live, ReplaySettings(model="diffusion"), recorded.body)
    assert again.spec == "fast" and not again.poser.mirror and again.poser.steps == [1000, 0]
    assert full.spec == "diffusion" and full.poser.mirror and full.poser.chain_mirror
    assert full.poser.steps == [1000, 400, 0]  # the full file's own steps, not the recorded model's
