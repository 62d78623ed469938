"""The low-latency mode waits for no future sample: not in the resampler (causal filter),
not in the hub (latest sample held, never the one after the grid time), and a pose is
unchanged by anything that arrives after it. No wall-clock assertions."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.live import Pipeline, frames_from_signals, latency
from calibration import Calibrator, Protocol, synthesize_session
from drivers.base import Sample
from drivers.hub import Hub
from inference.poser.poser import make_poser
from inference.signals.synthesis import NoiseModel
from sim_devices.motions import generate

SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
PROTO = Protocol(table=1.2, strap=0.6, tpose=1.2, blend=0.4, margin=0.15)
T0 = 1000.0


@pytest.fixture(scope="module")
def session():
    act = generate("walk", seconds=3.0, seed=4)
    return synthesize_session(act, PROTO, noise=NoiseModel.typical(), rng=11, sites=SITES)


def _pipeline(truth, causal):
    return Pipeline(make_poser("floor", body=truth.body), SITES,
                    calibrator=Calibrator(SITES, schedule=PROTO.schedule()),
                    causal=causal)


def _fed(pipe, frames):
    """(pose times, the 190 features the poser was given for each)."""
    seen = []
    step = pipe.poser.step

    def spy(x, mask, points=None):
        seen.append(np.array(x, copy=True))
        return step(x, mask, points)

    pipe.poser.step = spy
    _, poses = _emitted_at(pipe, frames)
    return [lp.t for lp in poses], seen


def _emitted_at(pipe, frames):
    """(index of the frame whose push emitted each pose, the poses)."""
    at, poses = [], []
    for i, f in enumerate(frames):
        for lp in pipe.push(f):
            at.append(i)
            poses.append(lp)
    return at, poses


def test_causal_pipeline_emits_each_pose_with_its_own_frame(session):
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0)
    at, poses = _emitted_at(_pipeline(truth, causal=True), frames)
    assert poses and all(frames[i].t == lp.t == lp.t_newest for i, lp in zip(at, poses, strict=True))
    at_c, poses_c = _emitted_at(_pipeline(truth, causal=False), frames)
    # the centred filter emits the frame of time t when the frame 5 samples later is in
    assert all(frames[i].t == lp.t_newest and round((lp.t_newest - lp.t) * 60) == 5
               for i, lp in zip(at_c, poses_c, strict=True))


def test_causal_pose_is_unchanged_by_later_samples(session):
    sig, truth = session
    frames = frames_from_signals(sig, t0=T0)
    _, ref = _emitted_at(_pipeline(truth, causal=True), frames)
    k = len(frames) - 40  # change everything from here on
    rng = np.random.default_rng(0)
    changed = frames[:k] + [replace(f, free_acc=f.free_acc + rng.normal(size=f.free_acc.shape) * 50,
                                    quat=np.roll(f.quat, 1, axis=-1)) for f in frames[k:]]
    _, got = _emitted_at(_pipeline(truth, causal=True), changed)
    before = [lp for lp in ref if lp.t < frames[k].t]
    assert before and len(got) >= len(before)
    for a, b in zip(before, got, strict=False):
        assert a.t == b.t
        np.testing.assert_array_equal(a.pose.rot, b.pose.rot)
        np.testing.assert_array_equal(a.pose.root, b.pose.root)
    # what the poser was fed (accelerations included): identical before the change with the
    # trailing filter; the centred one reads 5 samples ahead, so its last frames before move
    for causal in (True, False):
        t_ref, x_ref = _fed(_pipeline(truth, causal), frames)
        t_got, x_got = _fed(_pipeline(truth, causal), changed)
        n = sum(t < frames[k].t for t in t_ref)
        assert t_ref[:n] == t_got[:n]
        same = [np.array_equal(a, b) for a, b in zip(x_ref[:n], x_got[:n], strict=True)]
        assert all(same) if causal else (all(same[:-2]) and not same[-1])


def test_pipeline_follows_the_model_filter_unless_told():
    poser = make_poser("floor", body=1.75)
    assert Pipeline(poser, SITES).causal is False
    poser.acc_filter = "causal"  # what a model file trained causally says (Poser reads its meta)
    assert Pipeline(poser, SITES).causal is True
    assert Pipeline(poser, SITES, causal=False).causal is False


class _FakeDevice:
    kind = "imu"
    is_open = True
    connected = True
    events: list = []
    counter_modulus = 1 << 16

    def fileno(self):
        return None


def _hub(interpolate: bool) -> Hub:
    mode = "centred" if interpolate else "low"
    return Hub({"pelvis": _FakeDevice()}, clock=lambda: 0.0, **latency.hub_options(mode))


def _feed(hub: Hub, times: np.ndarray) -> None:
    for i, t in enumerate(times):
        hub.push("pelvis", Sample(t=float(t), device_time=None, device_id="p", counter=i,
                                  quat=np.array([1.0, 0, 0, 0]), free_acc=np.array([float(i), 0, 0]),
                                  acc=np.zeros(3), gyro=np.zeros(3)))


def test_low_mode_hub_holds_the_latest_sample_at_or_before_the_grid_time():
    times = 10.0 + np.arange(0, 0.5, 0.01) + 0.003  # 100 Hz, off the 60 Hz grid
    hub = _hub(interpolate=False)
    assert hub.latency == latency.LOW_HUB_WAIT and hub.interpolation is None
    _feed(hub, times)
    hub.poll(now=10.1)
    frames = hub.poll(now=10.45)
    assert frames
    for f in frames:
        assert f.present[0]
        assert f.sample_t[0] <= f.t  # never a sample from after the grid time
        assert f.t - f.sample_t[0] < 0.01 + 1e-9  # the latest one before it
        k = int(f.sample_counter[0])
        assert times[k] == f.sample_t[0] and f.free_acc[0, 0] == k


def test_centred_mode_hub_reports_the_sample_after_the_grid_time_it_waited_for():
    times = 10.0 + np.arange(0, 0.5, 0.01) + 0.003
    hub = _hub(interpolate=True)
    assert hub.latency == latency.CENTRED_HUB_WAIT and hub.interpolation is not None
    _feed(hub, times)
    hub.poll(now=10.1)
    frames = hub.poll(now=10.45)
    assert frames
    for f in frames:
        assert f.sample_t[0] > f.t and f.sample_t[0] - f.t < 0.01 + 1e-9
        assert times[int(f.sample_counter[0])] == f.sample_t[0]


def test_latency_settings_and_model_choice(tmp_path, monkeypatch):
    low, centred = latency.latency_settings("low"), latency.latency_settings("centred")
    assert low.causal and not low.interpolate and low.hub_wait < centred.hub_wait
    assert centred.interpolate and not centred.causal
    with pytest.raises(ValueError):
        latency.latency_settings("fast")

    class M:
        def __init__(self, meta):
            self.meta = meta

    assert latency.resolve_filter("centred", M({})) == (False, None)
    causal, warning = latency.resolve_filter("low", M({}))
    assert causal and "untuned" in warning  # a centred-trained model in the low mode says so
    assert latency.resolve_filter("low", M({"acc_filter": "causal"})) == (True, None)
    assert latency.resolve_filter("centred", M({"acc_filter": "causal"})) == (True, None)  # its own filter
    monkeypatch.setattr(latency, "causal_weights", lambda: tmp_path / "causal.pt")
    assert latency.model_spec_for("low", "diffusion") == "diffusion"  # not installed: the shipped one
    (tmp_path / "causal.pt").write_bytes(b"")
    assert latency.model_spec_for("low", "diffusion") == str(tmp_path / "causal.pt")
    assert latency.model_spec_for("centred", "diffusion") == "diffusion"
    assert latency.model_spec_for("low", "regressor") == "regressor"
