"""Sony DualSense as an IMU: calibrated gyro and accelerometer from USB HID report
0x01, orientation fused with imufusion (x-io's Fusion AHRS, a maintained library,
rather than a filter of our own).

The controller has no magnetometer, so its heading is the integral of the gyro's
vertical rate and drifts with whatever bias the factory calibration leaves (a few
tenths of a deg/s on MEMS gyros). Fusion's run-time bias correction learns that bias
whenever the controller is still (every axis under ``STILL_DPS`` for ``STILL_S``), so a
subject who stands, sits or holds a calibration pose stops the drift."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import imufusion
import numpy as np

from .._math import G, quat_normalize
from ..base import Device, DeviceGone, Sample, Unwrapper
from . import protocol as ds
from .hid_seam import HidapiHandle, HidHandle, SocketHidHandle

_RAD2DEG = 180.0 / math.pi
REPORT_HZ = 250.0  # USB input reports a second (the bias filter's time constant is set in samples)
STILL_DPS = 3.0  # Fusion's defaults: a still controller turns slower than this on every axis ...
STILL_S = 3.0  # ... for this long before its gyro readings count as bias


class DualSenseDevice(Device):
    """``dualsense://`` (first controller via hidapi), ``dualsense://?serial=...``,
    or ``dualsense://unix/<socket path>`` for the simulated controller's seam.

    The AHRS runs in the NWU convention (Z up) with a sample period taken from
    the controller's own timestamps, so a USB polling hiccup does not bend the
    integration. ``track_bias`` (URL ``?gyro_bias=off`` to turn it off) removes the
    gyro bias learnt while still from the gyro the AHRS integrates and the samples
    report; ``gyro_offset_dps`` is the current estimate."""

    scheme = "dualsense"
    counter_modulus = 256

    def __init__(
        self, opener: Callable[[], HidHandle], device_id: str = "dualsense", *, gain: float = 0.5,
        track_bias: bool = True, **kw: Any
    ) -> None:
        super().__init__(device_id, **kw)
        self._opener = opener
        self.track_bias = track_bias
        self._bias: imufusion.Bias | None = None
        self._hid: HidHandle | None = None
        self.calibration: ds.DsCalibration | None = None
        self.gain = gain
        self._unwrap = Unwrapper(ds.TIMESTAMP_MOD, 1.0 / ds.TIMESTAMP_HZ)
        self._last_dev_t: float | None = None
        self._ahrs: imufusion.Ahrs | None = None

    @classmethod
    def from_url(cls, netloc: str, path: str, params: dict[str, str], **kw: Any) -> DualSenseDevice:
        track = params.get("gyro_bias", "track")
        if track not in ("track", "off"):
            raise ValueError(f"dualsense gyro_bias={track!r}: track (learn the bias while still) or off")
        kw.setdefault("track_bias", track == "track")
        if netloc == "unix":
            dev_id = kw.pop("device_id", None) or path
            return cls(lambda: SocketHidHandle(path), device_id=dev_id, **kw)
        serial = params.get("serial")
        dev_id = kw.pop("device_id", None) or serial or "dualsense"
        return cls(lambda: HidapiHandle(ds.VENDOR_ID, ds.PRODUCT_IDS, serial), device_id=dev_id, **kw)

    @property
    def gyro_offset_dps(self) -> np.ndarray:
        """The gyro bias learnt so far (deg/s, sensor axes); zero until the controller has been still."""
        return np.zeros(3) if self._bias is None else np.asarray(self._bias.get_offset(), dtype=float)

    def _open(self) -> None:
        self._hid = self._opener()
        raw = self._hid.get_feature_report(ds.CALIBRATION_REPORT_ID, ds.CALIBRATION_REPORT_LEN)
        try:
            self.calibration = ds.decode_calibration(raw)
        except ds.DualSenseError as exc:
            self._close()
            raise DeviceGone(f"bad calibration report: {exc}") from exc
        self._gscale = np.array(self.calibration.gyro_scale())
        self._gbias = np.array(self.calibration.gyro_bias, dtype=float)
        ascale, abias = self.calibration.acc_scale_bias()
        self._ascale, self._abias = np.array(ascale), np.array(abias)
        self._ahrs = imufusion.Ahrs()
        settings = imufusion.AhrsSettings()
        settings.convention = imufusion.CONVENTION_NWU
        settings.gain = self.gain
        settings.gyroscope_range = 2000.0  # deg/s, the controller's full scale (0 would mean "always saturated")
        self._ahrs.set_settings(settings)
        self._ahrs_started = False
        self._bias = None
        if self.track_bias:
            self._bias = imufusion.Bias()
            bias = imufusion.BiasSettings()
            bias.sample_rate = REPORT_HZ
            bias.stationary_threshold = STILL_DPS
            bias.stationary_period = STILL_S
            self._bias.set_settings(bias)
        self._unwrap.reset()
        self._last_dev_t = None

    def _close(self) -> None:
        hid, self._hid = self._hid, None
        if hid is not None:
            hid.close()

    def _read(self, timeout: float | None) -> Sample | None:
        if self._hid is None:
            raise DeviceGone("HID closed")
        data = self._hid.read(ds.INPUT_REPORT_LEN, timeout)
        if not data:
            return None
        try:
            rep = ds.decode_input_report(data)
        except ds.DualSenseError:
            self.stats.bad_frame += 1
            return None
        return self._to_sample(rep)

    def _to_sample(self, rep: ds.DsInput) -> Sample:
        gyro = (np.array(rep.gyro_raw, dtype=float) - self._gbias) * self._gscale
        if self._bias is not None:
            gyro = np.asarray(self._bias.update(gyro * _RAD2DEG), dtype=float) / _RAD2DEG
        acc = (np.array(rep.accel_raw, dtype=float) - self._abias) * self._ascale
        dev_t = self._unwrap.update(rep.timestamp)
        dt = 0.004 if self._last_dev_t is None else dev_t - self._last_dev_t
        self._last_dev_t = dev_t
        ahrs = self._ahrs
        assert ahrs is not None
        if not self._ahrs_started:
            # Fusion's start-up phase pins heading to zero for seconds; start instead from the
            # tilt the first accelerometer reading gives (heading 0) and skip it
            ahrs.set_quaternion(tilt_quaternion(acc))
            ahrs.skip_startup()
            self._ahrs_started = True
        ahrs.set_sample_period(float(min(max(dt, 1e-4), 0.1)))
        ahrs.update_no_magnetometer(gyro * _RAD2DEG, acc / G)
        q = quat_normalize(np.asarray(ahrs.get_quaternion(), dtype=float))
        free = np.asarray(ahrs.get_earth_acceleration(), dtype=float) * G
        return Sample(0.0, dev_t, self.device_id, rep.seq, q, free, acc, gyro, battery=rep.battery_pct)


def tilt_quaternion(acc: np.ndarray) -> np.ndarray:
    """Shortest rotation taking the measured 'up' (specific force, sensor frame) to world +Z."""
    n = float(np.linalg.norm(acc))
    if n < 1e-6:
        return np.array([1.0, 0.0, 0.0, 0.0])
    a = acc / n
    w = 1.0 + a[2]
    if w < 1e-9:  # upside down: 180 deg about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    q = np.array([w, a[1], -a[0], 0.0])  # cross(a, z) = (a_y, -a_x, 0)
    return q / np.linalg.norm(q)
