"""The live chain without threads (Pipeline.push), then on its threads (LivePipeline)."""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.live import CallbackSink, ListSource, LivePipeline, Pipeline, frames_from_signals, stride_text
from calibration import Calibrator, Protocol, synthesize_session
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from inference.features.layout import SL_ACC
from inference.metrics.errors import global_angle_error
from inference.poser.poser import make_poser
from inference.signals.resample import moving_average
from inference.signals.synthesis import NoiseModel, kinematics
from sim_devices.devices import SignalSource
from sim_devices.devices.base import LOOP_BLEND_S
from sim_devices.motions import generate

SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
PROTO = Protocol(table=1.2, strap=0.6, tpose=1.2, blend=0.4, margin=0.15)
T0 = 1000.0


@pytest.fixture(scope="module")
def session():
    act = generate("walk", seconds=3.0, seed=4)
    sig, truth = synthesize_session(act, PROTO, noise=NoiseModel.typical(), rng=11, sites=SITES)
    return sig, truth


def _pipeline(truth, **kw):
    cal = Calibrator(SITES, schedule=PROTO.schedule())
    return Pipeline(make_poser("floor", body=truth.body), SITES, calibrator=cal, **kw)


def _run(pipe, frames):
    out = []
    for f in frames:
        out += pipe.push(f)
    return out


def _truth_index(poses):
    return np.array([int(round((lp.t - T0) * 60)) for lp in poses])


def test_chain_calibrates_and_reconstructs_observed_segments(session):
    sig, truth = session
    pipe = _pipeline(truth)
    frames = frames_from_signals(sig, t0=T0)
    poses = _run(pipe, frames)
    assert pipe.calibration is not None and pipe.calibration.valid.all()
    n_cal = pipe.stats.frames_calibrating
    assert abs(n_cal - PROTO.calibrated_at * 60) <= 2
    # one 20 Hz pose per 3 frames after calibration, minus the resampler's 5-sample look-ahead
    assert len(poses) == (len(frames) - n_cal - 5 + 2) // 3
    assert all(lp.observed_sites[[SITE_INDEX[s] for s in SITES]].all() for lp in poses)
    i = _truth_index(poses)
    R = np.stack([lp.pose.rot for lp in poses])
    for s in SITES:
        seg = SITE_SEGMENT_INDEX[SITE_INDEX[s]]
        err = np.rad2deg(matrix_angle_between(R[:, seg], truth.rot[i, seg]))
        assert err.mean() < 1.5, (s, err.mean())
    # world accelerations reach the model smoothed once (raw replayed, resampler smooths)
    acc_true = moving_average(kinematics(truth).site_acc_raw)
    a_in = np.stack([lp.pose.features[SL_ACC].reshape(13, 3) for lp in poses])
    k = [SITE_INDEX[s] for s in SITES]
    assert np.linalg.norm(a_in[:, k] - acc_true[i][:, k], axis=-1).mean() < 0.25
    assert global_angle_error(R, truth.rot[i]).mean() < 15.0  # floor: unobserved segments held standing


def test_simulated_devices_replay_raw_free_acceleration(session):
    """The contract the pipeline relies on (docs/motion_data.md, synthesis): devices stream the unsmoothed
    free acceleration, so the moving average is applied exactly once, in the resampler."""
    sig, _ = session
    src = SignalSource(sig, "l_shank")
    k = sig.sites.index("l_shank")
    body = slice(0, src.n - int(round(LOOP_BLEND_S * src.fps)) - 1)  # the loop's closing turn apart
    assert np.array_equal(src.free_acc[body], sig.meta["free_acc_raw"][body, k])
    assert not np.allclose(src.free_acc[body], sig.free_acc[body, k])


def test_missing_sensor_is_unobserved_then_rejoins(session):
    sig, truth = session
    act0 = sig.meta["activity_start"]
    frames = frames_from_signals(sig, t0=T0, drop={"l_wrist": [(act0, act0 + 0.8)]})
    pipe = _pipeline(truth)
    poses = _run(pipe, frames)
    k = SITE_INDEX["l_wrist"]
    obs = np.array([lp.observed_sites[k] for lp in poses])
    t = np.array([lp.t - T0 for lp in poses])
    assert not obs[(t > act0 + 0.1) & (t < act0 + 0.7)].any()
    assert obs[t > act0 + 1.0].all() and obs[t < act0 - 0.1].all()
    assert all(np.isfinite(lp.pose.rot).all() for lp in poses)
    # the poser's mask follows the data: the wrist's acceleration features unobserved while it is gone
    acc_obs = np.array([lp.pose.observed[SL_ACC][3 * k] for lp in poses])
    assert np.array_equal(acc_obs, obs)


def test_active_sites_and_insoles(session):
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0, insoles=True)
    pipe = _pipeline(truth, active_sites=("pelvis", "head"), insoles=True)
    poses = _run(pipe, frames)
    obs = np.array([lp.observed_sites for lp in poses])
    assert obs[:, [SITE_INDEX["pelvis"], SITE_INDEX["head"]]].all()
    assert not obs[:, SITE_INDEX["l_shank"]].any()
    assert all(lp.insoles for lp in poses) and poses[-1].pose.observed[-4:].all()
    with pytest.raises(ValueError, match="not in this suit"):
        pipe.set_active_sites(["l_foot"])


def test_gaps_are_filled_or_restart_the_resampler(session):
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0)
    n_cal = int(PROTO.calibrated_at * 60) + 30
    short = frames[: n_cal] + frames[n_cal + 4:]  # 4 frames lost: filled as unobserved
    pipe = _pipeline(truth)
    _run(pipe, short)
    assert pipe.stats.frames_filled == 4 and pipe.stats.resampler_restarts == 0
    long = frames[: n_cal] + frames[n_cal + 30:]  # half a second lost: start the resampler afresh
    pipe = _pipeline(truth)
    poses = _run(pipe, long)
    assert pipe.stats.resampler_restarts == 1 and poses


def test_sink_errors_do_not_stop_the_chain(session):
    sig, truth = session

    def broken(_):
        raise RuntimeError("sink bug")

    pipe = _pipeline(truth, sinks=[CallbackSink(on_pose=broken)])
    poses = _run(pipe, frames_from_signals(sig, t0=T0)[:400])
    assert poses and pipe.stats.sink_errors == len(poses)


def test_threaded_runner_matches_the_synchronous_chain(session):
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0)
    ref = _run(_pipeline(truth), frames)
    got = []
    pipe = _pipeline(truth, sinks=[CallbackSink(on_pose=got.append)], clock=time.monotonic)
    with LivePipeline(pipe, ListSource(frames), queue_size=10_000, max_lag=None) as live:
        assert live.wait_for(lambda: len(got) >= len(ref), 60)
        assert live.latest() is got[-1]
    assert len(got) == len(ref)
    assert np.allclose(np.stack([p.pose.rot for p in got]), np.stack([p.pose.rot for p in ref]))
    st = live.stats()
    assert st["poses"] == len(ref) and st["dropped"] == 0 and st["latency_p50_ms"] is not None


def test_threaded_runner_drops_oldest_when_inference_lags(session):
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0)
    slow = _pipeline(truth)
    orig = slow.push

    def slow_push(f):
        time.sleep(0.002)
        return orig(f)

    slow.push = slow_push
    with LivePipeline(slow, ListSource(frames), queue_size=20) as live:
        # the whole clip arrives at once; a 20-frame queue must shed the backlog, oldest first
        assert live.wait_for(lambda: slow.stats.frames_in + slow.stats.dropped >= len(frames), 60)
    assert slow.stats.dropped > 0
    assert slow.stats.frames_in + slow.stats.dropped == len(frames)
    # and commands run on the inference thread
    ran = []
    with LivePipeline(_pipeline(truth), ListSource([])) as live:
        live.call(lambda p: ran.append(p.status))
        assert live.wait_for(lambda: bool(ran), 10)
    assert ran == ["calibration: waiting"]


def test_stride_status_says_whether_the_distance_comes_from_the_shanks(session):
    sig, truth = session
    pipe = Pipeline(make_poser("diffusion", body=truth.body, steps=[0]), SITES,
                    calibrator=Calibrator(SITES, schedule=PROTO.schedule()))
    st = pipe.stride_status()
    assert st == {"enabled": True, "shanks": True, "scale": None, "strides": 0, "odometry": True}
    assert stride_text(st) == "waiting for the first strides"
    pipe.set_active_sites(("pelvis", "head", "l_wrist", "r_wrist", "l_shank"))
    assert stride_text(pipe.stride_status()) == "needs both shanks (walk from the pelvis sensor)"
    pipe.set_active_sites(("head", "l_wrist", "r_wrist", "l_shank"))
    assert stride_text(pipe.stride_status()) == "needs both shanks"
    assert stride_text(_pipeline(truth).stride_status()) == "off"  # the floor has no root to scale
    assert stride_text({"enabled": True, "shanks": True, "scale": 0.934, "strides": 12}) == "x0.93 from 12 strides"



def test_frames_passed_over_still_reach_the_sinks_and_the_calibration(session):
    """A live loop that falls behind passes frames over instead of reconstructing them: a
    recorder still gets every raw frame, and a calibration in progress still sees them."""
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0)
    raw = []
    pipe = _pipeline(truth, sinks=[CallbackSink(on_frame=raw.append)])
    poses = []
    for k, f in enumerate(frames):
        if k % 12 >= 8:  # a third of the frames passed over, in runs of four, during calibration too
            pipe.pass_over(f)
        else:
            poses += pipe.push(f)
    assert len(raw) == len(frames) and [f.index for f in raw] == [f.index for f in frames]
    assert pipe.calibration is not None and poses
    # frames passed over are not lost packets: no pose is made blind, none for them at all
    assert pipe.stats.frames_filled == 0 and pipe.stats.resampler_restarts == 0
    assert all(lp.observed_sites.sum() == len(SITES) for lp in poses), [int(lp.observed_sites.sum()) for lp in poses]
    calibrated = len(frames) - pipe.stats.frames_calibrating  # pushed or passed over, after calibration
    twenty_hz = len(poses) + pipe.stats.poses_skipped
    assert pipe.stats.poses_skipped > 0 and abs(twenty_hz - calibrated / 3) <= 3, (twenty_hz, calibrated)
    assert np.all(np.diff([lp.index for lp in poses]) > 0)


def test_warm_up_freezes_the_heap_it_starts_from(session):
    """What the model, torch and the modules left is frozen out of the collector's full
    passes (``gc.freeze``), once: a full collection holds the interpreter, so every reader
    thread, for as long as it walks them (96-116 ms in a capture, docs/testing.md)."""
    import gc

    _, truth = session
    gc.unfreeze()
    pipe = _pipeline(truth)
    pipe.warm_up()
    frozen = gc.get_freeze_count()
    assert frozen > 10_000
    # a second warm-up freezes nothing more: not these 20,000 objects made since (the count may
    # drop a little meanwhile, as frozen objects another thread held are freed)
    since = [[] for _ in range(20_000)]  # tracked by the collector, as empty dicts are not
    pipe.warm_up()  # once per pipeline
    assert gc.get_freeze_count() < frozen + len(since) // 2
