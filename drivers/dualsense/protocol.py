"""Sony DualSense (PS5 controller) USB HID reports, pure functions.

Layout as the Linux ``hid-playstation`` driver reads it (USB, report id 0x01,
64 bytes including the id byte):

=======  ===========================================================
0        report id 0x01
1-6      sticks and triggers, 7 sequence number
8-11     buttons, 12-15 reserved
16-21    gyro pitch, yaw, roll: int16 LE (raw counts)
22-27    accel x, y, z: int16 LE (raw counts)
28-31    sensor timestamp: uint32 LE, units of 1/3 microsecond
33-40    touch points, 53 status (battery: low nibble 0..10, high nibble
         charging state)
=======  ===========================================================

Calibration comes from feature report 0x05 (41 bytes): gyro biases, the raw
readings at +/- a reference rate, the reference rate itself, and the raw
accelerometer readings at +/- 1 g per axis. Sensitivities follow from those the
same way the kernel driver derives them (value = (raw - bias) * numer / denom).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

from .._math import G

VENDOR_ID = 0x054C
PRODUCT_IDS = (0x0CE6, 0x0DF2)  # DualSense, DualSense Edge
INPUT_REPORT_ID = 0x01
INPUT_REPORT_LEN = 64
CALIBRATION_REPORT_ID = 0x05
CALIBRATION_REPORT_LEN = 41
TIMESTAMP_HZ = 3_000_000
TIMESTAMP_MOD = 1 << 32

_IMU = struct.Struct("<3h3hI")  # at offset 16
_CAL = struct.Struct("<B17h")  # id + 17 int16 (bytes 1..34); rest reserved


class DualSenseError(ValueError):
    pass


@dataclass(frozen=True, slots=True)
class DsInput:
    seq: int
    gyro_raw: tuple[int, int, int]
    accel_raw: tuple[int, int, int]
    timestamp: int
    battery_pct: float | None
    charging: bool


@dataclass(frozen=True, slots=True)
class DsCalibration:
    """The raw numbers of feature report 0x05 (field names as the kernel calls them)."""

    gyro_bias: tuple[int, int, int] = (0, 0, 0)
    gyro_plus: tuple[int, int, int] = (8192, 8192, 8192)
    gyro_minus: tuple[int, int, int] = (-8192, -8192, -8192)
    gyro_speed_plus: int = 540  # deg/s at which gyro_plus was read
    gyro_speed_minus: int = 540
    acc_plus: tuple[int, int, int] = (8192, 8192, 8192)
    acc_minus: tuple[int, int, int] = (-8192, -8192, -8192)

    def valid(self) -> bool:
        g = all(abs(p - b) + abs(m - b) > 0 for p, m, b in zip(self.gyro_plus, self.gyro_minus, self.gyro_bias))
        a = all(p - m != 0 for p, m in zip(self.acc_plus, self.acc_minus))
        return g and a and (self.gyro_speed_plus + self.gyro_speed_minus) > 0

    def gyro_scale(self) -> tuple[float, float, float]:
        """rad/s per raw count, per axis."""
        speed_2x = self.gyro_speed_plus + self.gyro_speed_minus
        return tuple(  # type: ignore[return-value]
            math.radians(speed_2x / (abs(p - b) + abs(m - b)))
            for p, m, b in zip(self.gyro_plus, self.gyro_minus, self.gyro_bias)
        )

    def acc_scale_bias(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """(m/s^2 per count, bias counts) per axis: +/-1 g readings span 2 g."""
        scale = tuple(2 * G / (p - m) for p, m in zip(self.acc_plus, self.acc_minus))
        bias = tuple(p - (p - m) / 2 for p, m in zip(self.acc_plus, self.acc_minus))
        return scale, bias  # type: ignore[return-value]


def encode_input_report(d: DsInput) -> bytes:
    buf = bytearray(INPUT_REPORT_LEN)
    buf[0] = INPUT_REPORT_ID
    buf[1:5] = b"\x80\x80\x80\x80"  # sticks centred
    buf[7] = d.seq & 0xFF
    buf[8] = 0x08  # d-pad "none"
    _IMU.pack_into(buf, 16, *(_c16(v) for v in d.gyro_raw), *(_c16(v) for v in d.accel_raw), d.timestamp & 0xFFFFFFFF)
    if d.battery_pct is not None:
        level = max(0, min(10, round((d.battery_pct - 5) / 10)))
        buf[53] = level | ((1 if d.charging else 0) << 4)
    return bytes(buf)


def decode_input_report(data: bytes) -> DsInput:
    if len(data) < INPUT_REPORT_LEN or data[0] != INPUT_REPORT_ID:
        raise DualSenseError(f"not a USB input report 0x01 ({len(data)} bytes)")
    gx, gy, gz, ax, ay, az, ts = _IMU.unpack_from(data, 16)
    status = data[53]
    level, charge = status & 0x0F, status >> 4
    battery = None if level > 10 else min(100.0, level * 10 + 5.0)
    return DsInput(data[7], (gx, gy, gz), (ax, ay, az), ts, battery, charge == 1)


def encode_calibration(c: DsCalibration) -> bytes:
    vals = (
        *c.gyro_bias,
        c.gyro_plus[0],
        c.gyro_minus[0],
        c.gyro_plus[1],
        c.gyro_minus[1],
        c.gyro_plus[2],
        c.gyro_minus[2],
        c.gyro_speed_plus,
        c.gyro_speed_minus,
        c.acc_plus[0],
        c.acc_minus[0],
        c.acc_plus[1],
        c.acc_minus[1],
        c.acc_plus[2],
        c.acc_minus[2],
    )
    buf = bytearray(CALIBRATION_REPORT_LEN)
    _CAL.pack_into(buf, 0, CALIBRATION_REPORT_ID, *(_c16(v) for v in vals))
    return bytes(buf)


def decode_calibration(data: bytes) -> DsCalibration:
    if len(data) < _CAL.size or data[0] != CALIBRATION_REPORT_ID:
        raise DualSenseError("not a calibration feature report 0x05")
    v = _CAL.unpack_from(data, 0)[1:]
    cal = DsCalibration(
        gyro_bias=(v[0], v[1], v[2]),
        gyro_plus=(v[3], v[5], v[7]),
        gyro_minus=(v[4], v[6], v[8]),
        gyro_speed_plus=v[9],
        gyro_speed_minus=v[10],
        acc_plus=(v[11], v[13], v[15]),
        acc_minus=(v[12], v[14], v[16]),
    )
    if not cal.valid():
        raise DualSenseError("calibration report has zero ranges")
    return cal


def _c16(v: float) -> int:
    return max(-32768, min(32767, round(v)))
