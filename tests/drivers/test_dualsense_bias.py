"""The DualSense driver's gyro bias correction: the controller has no magnetometer, so a
bias the factory calibration leaves turns its heading for as long as it runs; learnt while
the controller is still, it stops the drift, and a turning controller teaches it nothing.

The reports are the protocol's own bytes (``protocol.encode_input_report``) at 250 Hz,
read through the HID seam's interface from a list, so a minute of device time takes a
fraction of a second."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivers._math import G
from drivers.dualsense import protocol as ds
from drivers.dualsense.driver import REPORT_HZ, DualSenseDevice

CAL = ds.DsCalibration(gyro_bias=(2, -3, 1))
BIAS_DPS = np.array([0.15, -0.2, 0.45])  # left by the factory calibration, as on a real controller


class ReplayHid:
    """HidHandle over prepared input reports (one per read), then silence."""

    def __init__(self, reports: list[bytes]) -> None:
        self.reports = reports
        self.i = 0

    def read(self, size: int, timeout: float | None) -> bytes:
        if self.i >= len(self.reports):
            return b""
        self.i += 1
        return self.reports[self.i - 1][:size]

    def get_feature_report(self, report_id: int, size: int) -> bytes:
        assert report_id == ds.CALIBRATION_REPORT_ID
        return ds.encode_calibration(CAL)[:size]

    def close(self) -> None:
        pass


def _reports(seconds: float, yaw_rate_dps, noise_dps: float = 0.1, seed: int = 0) -> list[bytes]:
    """A controller lying flat, turning about the vertical at ``yaw_rate_dps(t)``, its gyro
    reading BIAS_DPS too, with white noise."""
    rng = np.random.default_rng(seed)
    gscale = np.degrees(np.array(CAL.gyro_scale()))  # deg/s per count
    ascale, abias = (np.array(v) for v in CAL.acc_scale_bias())
    acc_raw = tuple(int(round(v)) for v in np.array([0.0, 0.0, G]) / ascale + abias)
    out = []
    for k in range(int(seconds * REPORT_HZ)):
        t = k / REPORT_HZ
        w = np.array([0.0, 0.0, yaw_rate_dps(t)]) + BIAS_DPS + rng.normal(0.0, noise_dps, 3)
        raw = tuple(int(round(v)) for v in w / gscale + np.array(CAL.gyro_bias))
        ts = int(t * ds.TIMESTAMP_HZ) % ds.TIMESTAMP_MOD
        out.append(ds.encode_input_report(ds.DsInput(k & 0xFF, raw, acc_raw, ts, 85.0, False)))
    return out


def _run(reports: list[bytes], url_params: dict[str, str]) -> tuple[DualSenseDevice, np.ndarray, np.ndarray]:
    """The device over the reports: (device, device times, unwrapped yaw in degrees)."""
    hid = ReplayHid(reports)
    dev = DualSenseDevice.from_url("unix", "/replay", url_params, device_id="l_shank")
    dev._opener = lambda: hid
    t, yaw = [], []
    with dev:
        while hid.i < len(reports):
            s = dev.read(0.0)
            if s is not None:
                t.append(s.device_time)
                yaw.append(2 * math.atan2(s.quat[3], s.quat[0]))
    return dev, np.array(t), np.degrees(np.unwrap(np.array(yaw) * 2) / 2)


def _drift(t: np.ndarray, yaw: np.ndarray, after: float) -> float:
    """Heading change per second over the samples after ``after`` s (deg/s)."""
    keep = t - t[0] >= after
    return float(np.polyfit(t[keep], yaw[keep], 1)[0])


def test_a_still_controller_stops_drifting_once_its_bias_is_learnt():
    reports = _reports(60.0, lambda t: 0.0)
    off, t0, yaw0 = _run(reports, {"gyro_bias": "off"})
    on, t1, yaw1 = _run(reports, {})
    # without the correction the heading turns at the bias's vertical part for the whole minute
    assert _drift(t0, yaw0, 30.0) == pytest.approx(BIAS_DPS[2], abs=0.05)
    assert np.allclose(off.gyro_offset_dps, 0.0)
    # with it: learnt within a few tenths of the truth, the last half-minute nearly still
    assert np.allclose(on.gyro_offset_dps, BIAS_DPS, atol=0.06), on.gyro_offset_dps
    assert abs(_drift(t1, yaw1, 30.0)) < 0.1 * BIAS_DPS[2]
    assert abs(yaw1[-1] - yaw1[0]) < 0.5 * abs(yaw0[-1] - yaw0[0])


def test_a_turning_controller_teaches_the_bias_nothing_and_keeps_its_rate():
    def sway(t: float) -> float:  # never still: a slow sway plus a steady turn
        return 20.0 + 15.0 * math.sin(2 * math.pi * 0.5 * t)

    reports = _reports(30.0, sway)
    on, t, yaw = _run(reports, {})
    assert np.allclose(on.gyro_offset_dps, 0.0, atol=1e-6)
    assert _drift(t, yaw, 2.0) == pytest.approx(20.0 + BIAS_DPS[2], abs=0.3)


def test_still_then_turning_keeps_the_learnt_bias_and_turns_by_the_truth():
    """Twenty seconds still (a calibration pose, standing) then 45 deg/s: the turn reads
    45 deg/s, not 45 plus the bias."""
    reports = _reports(40.0, lambda t: 0.0 if t < 20.0 else 45.0)
    on, t, yaw = _run(reports, {})
    off, t0, yaw0 = _run(reports, {"gyro_bias": "off"})
    rate_on, rate_off = _drift(t, yaw, 22.0), _drift(t0, yaw0, 22.0)
    assert rate_off == pytest.approx(45.0 + BIAS_DPS[2], abs=0.05)
    assert abs(rate_on - 45.0) < 0.5 * abs(rate_off - 45.0), (rate_on, rate_off)


def test_a_bad_setting_is_refused_in_one_line():
    with pytest.raises(ValueError, match="gyro_bias='sometimes'"):
        DualSenseDevice.from_url("unix", "/x", {"gyro_bias": "sometimes"})
