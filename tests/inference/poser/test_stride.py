"""The shank stride estimator (inference/poser/stride.py) on a planted gait built here.

The gait is made the way a foot-mounted or shank-mounted IMU study would check a
zero-velocity method: each ankle is exactly still in stance and travels one stride in
swing, the tibia turns about it all the time, and the sensor rides the shank at the
body's site offset. Its acceleration goes through the same centred moving average and
60 -> 20 Hz sampling as the model's input."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.body import Body
from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
from inference.poser.stride import SHANK_SITES, StrideScale, StrideScaleConfig
from inference.signals.resample import downsample

FPS = 60.0


def planted_gait(body: Body, stride: float = 1.1, period: float = 1.1, seconds: float = 12.0,
                 heading_deg: float = 30.0, climb: float = 0.0, stance_share: float = 0.6):
    """60 Hz: shank orientations (T, 2, 3, 3), sensor positions (T, 2, 3), ankles (T, 2, 3)
    and heel/toe contacts (T, 4) of a walk along ``heading_deg``; the legs half a period
    apart, each foot flat on the ground for ``stance_share`` of the period (below 0.5 both
    feet are off the ground in between: a run).
    ``climb``: how far each stride rises (a stair has two steps a stride)."""
    t = np.arange(int(seconds * FPS)) / FPS
    yaw = np.deg2rad(heading_deg)
    fwd = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    Rz = matrix_about_axis(np.array([0.0, 0.0, 1.0]), yaw)
    y_axis = np.array([0.0, 1.0, 0.0])
    R = np.empty((len(t), 2, 3, 3))
    sensor = np.empty((len(t), 2, 3))
    ankle = np.empty((len(t), 2, 3))
    stance = np.empty((len(t), 2), dtype=bool)
    for k, (site, foot) in enumerate(zip(SHANK_SITES, ("l_foot", "r_foot"))):
        lever = body.offsets[SEGMENT_INDEX[foot]] - body.site_offsets[SITE_INDEX[site]]
        phase = (t / period + 0.5 * k) % 1.0
        cycle = np.floor(t / period + 0.5 * k)
        swing = phase >= stance_share
        s = np.clip((phase - stance_share) / (1.0 - stance_share), 0.0, 1.0)
        ramp = 0.5 - 0.5 * np.cos(np.pi * s)  # 0 -> 1 over the swing, still in stance
        along = stride * (cycle + ramp)
        lift = 0.08 * np.sin(np.pi * s)
        up = 0.08 + lift + climb * (cycle + ramp)
        ankle[:, k] = along[:, None] * fwd + up[:, None] * np.array([0.0, 0.0, 1.0])
        # the tibia rolls forward over the planted ankle and swings back in the air
        pitch = 0.5 * np.sin(2 * np.pi * phase + 0.4)
        R[:, k] = Rz @ matrix_about_axis(y_axis, pitch)
        sensor[:, k] = ankle[:, k] - (R[:, k] @ lever)
        stance[:, k] = ~swing
    return R, sensor, ankle, np.repeat(stance, 2, axis=1)  # heel and toe down together


def second_difference(p: np.ndarray) -> np.ndarray:
    a = np.zeros_like(p)
    a[1:-1] = (p[2:] - 2 * p[1:-1] + p[:-2]) * FPS**2
    a[0], a[-1] = a[1], a[-2]
    return a


def run(body, R, acc, contacts, ankle_xy, config=None) -> StrideScale:
    est = StrideScale(body, 20.0, config)
    for i in range(len(R)):
        est.update(R[i], acc[i], contacts[i], ankle_xy[i])
    return est


def gait_at_20hz(body, **kw):
    R, sensor, ankle, contacts = planted_gait(body, **kw)
    acc20, rest = downsample(second_difference(sensor).reshape(len(R), -1), np.arange(len(R)))
    return R[rest], acc20.reshape(-1, 2, 3), contacts[rest], ankle[rest]


@pytest.mark.parametrize("too_long", [1.3, 0.8])
def test_scale_undoes_a_reconstructed_stride_of_the_wrong_length(too_long):
    body = Body.from_height(1.75)
    R, acc, contacts, ankle = gait_at_20hz(body)
    est = run(body, R, acc, contacts, too_long * ankle[..., :2])
    assert len(est.strides) >= 12
    # each stride's own length, from the shank alone (the first one per leg starts at the
    # clip's edge, where the centred moving average has no past to average)
    inertial = np.array([a for a, _ in est.strides[2:]])
    assert np.allclose(inertial, 1.1, rtol=0.01), inertial
    assert est.scale == pytest.approx(1.0 / too_long, rel=0.02)


def test_a_constant_accelerometer_bias_cancels_exactly():
    body = Body.from_height(1.6)
    R, acc, contacts, ankle = gait_at_20hz(body, stride=0.7, period=1.3)
    clean = run(body, R, acc, contacts, ankle[..., :2])
    biased = run(body, R, acc + np.array([[0.3, -0.2, 0.5], [-0.4, 0.1, 0.2]]), contacts, ankle[..., :2])
    assert len(clean.strides) >= 8
    assert np.allclose(np.array(biased.strides), np.array(clean.strides), atol=1e-9)
    assert clean.scale == pytest.approx(1.0, abs=0.03)


def test_the_tibia_rolling_over_the_ankle_is_not_taken_for_ankle_motion():
    """Pinning the *sensor* still in stance (a foot-sensor ZUPT) would be wrong on the shank:
    it moves with the tibia's roll. Without the lever the strides come out off."""
    body = Body.from_height(1.75)
    R, acc, contacts, ankle = gait_at_20hz(body)
    right = run(body, R, acc, contacts, ankle[..., :2])
    wrong = StrideScale(body, 20.0)
    wrong._lever[:] = 0.0
    for i in range(len(R)):
        wrong.update(R[i], acc[i], contacts[i], ankle[i, :, :2])
    err = lambda e: np.abs(np.array([a for a, _ in e.strides[2:]]) - 1.1).mean()  # noqa: E731
    assert err(right) < 0.03 < err(wrong)


def test_standing_still_and_shuffling_leave_the_scale_alone():
    body = Body.from_height(1.75)
    R, acc, contacts, ankle = gait_at_20hz(body, stride=0.1)  # shuffling: 10 cm strides
    est = run(body, R, acc, contacts, 1.5 * ankle[..., :2])
    assert est.strides == [] and est.scale == 1.0
    T = 100
    still = run(body, np.broadcast_to(np.eye(3), (T, 2, 3, 3)), np.zeros((T, 2, 3)), np.ones((T, 4), bool),
                np.zeros((T, 2, 2)))
    assert still.strides == [] and still.scale == 1.0


def test_a_dropped_shank_loses_its_pending_stride_only():
    body = Body.from_height(1.75)
    R, acc, contacts, ankle = gait_at_20hz(body)
    est = StrideScale(body, 20.0)
    half = len(R) // 2
    for i in range(half):
        est.update(R[i], acc[i], contacts[i], 1.25 * ankle[i, :, :2])
    before = len(est.strides)
    est.drop()
    for i in range(half, len(R)):
        est.update(R[i], acc[i], contacts[i], 1.25 * ankle[i, :, :2])
    assert before >= 4 and len(est.strides) > before
    assert est.scale == pytest.approx(0.8, rel=0.02)
    est.reset()
    assert est.scale == 1.0 and est.strides == []


def test_an_implausible_ratio_is_a_detection_error_not_a_stride():
    body = Body.from_height(1.75)
    R, acc, contacts, ankle = gait_at_20hz(body)
    est = run(body, R, acc, contacts, 3.0 * ankle[..., :2], StrideScaleConfig(limits=(0.6, 1.6)))
    assert est.strides == [] and est.scale == 1.0


def test_a_stride_that_does_not_end_at_its_starting_height_is_not_trusted():
    """Both anchors of a level stride stand on the same floor, so an inertial stride that
    rises was anchored on a moving ankle or climbs stairs; either way its length is not the
    scale's business. The same gait on level ground is scaled."""
    body = Body.from_height(1.75)
    R, acc, contacts, ankle = gait_at_20hz(body, stride=0.6)
    level = run(body, R, acc, contacts, 1.3 * ankle[..., :2])
    assert level.scale == pytest.approx(1 / 1.3, rel=0.03)
    R, acc, contacts, ankle = gait_at_20hz(body, stride=0.6, climb=0.34)
    stairs = run(body, R, acc, contacts, 1.3 * ankle[..., :2])
    assert stairs.strides == [] and stairs.scale == 1.0
    lenient = run(body, R, acc, contacts, 1.3 * ankle[..., :2], StrideScaleConfig(max_rise_m=0.5))
    assert lenient.scale == pytest.approx(1 / 1.3, rel=0.03)


def test_a_run_returns_the_scale_to_one():
    """Running has a flight phase and a foot-flat too short at 20 Hz to anchor on; the scale
    learnt while walking says nothing about the model's running stride, so it goes back to 1
    and stays there while the run lasts."""
    body = Body.from_height(1.75)
    est = StrideScale(body, 20.0)
    R, acc, contacts, ankle = gait_at_20hz(body, seconds=8.0)
    for i in range(len(R)):
        est.update(R[i], acc[i], contacts[i], 1.3 * ankle[i, :, :2])
    walked = len(est.strides)
    assert walked >= 8 and est.scale == pytest.approx(1 / 1.3, rel=0.03)
    R, acc, contacts, ankle = gait_at_20hz(body, seconds=8.0, stride=1.6, period=0.7, stance_share=0.3)
    assert (~contacts.any(axis=1)).mean() > 0.2  # both feet up a fifth of the time
    for i in range(len(R)):
        est.update(R[i], acc[i], contacts[i], 1.3 * ankle[i, :, :2])
    assert len(est.strides) <= walked + 1 and est.scale == 1.0  # one stride may bridge the change
    # a forefoot runner never puts a heel down, so no stride completes; the flight still tells
    R0, acc0, contacts0, ankle0 = gait_at_20hz(body, seconds=8.0)
    est = run(body, R0, acc0, contacts0, 1.3 * ankle0[..., :2])
    assert est.scale == pytest.approx(1 / 1.3, rel=0.03)
    contacts[:, [0, 2]] = False
    for i in range(30):
        est.update(R[i], acc[i], contacts[i], 1.3 * ankle[i, :, :2])
    assert est.scale == 1.0

