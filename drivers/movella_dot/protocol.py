"""Movella (Xsens) DOT over Bluetooth LE: GATT identifiers and the measurement
notification payloads, pure functions.

Layout from Movella's "Movella DOT BLE Service Specification" (document XD0506P,
formerly "Xsens DOT BLE Services Specifications"). Every characteristic is
``1517xxxx-4947-11e9-8646-d663bd873d93``; every multi-byte number is little-endian,
floats IEEE-754 single precision.

- Measurement service 0x2000. Control characteristic 0x2001 (read/write, 3 bytes):
  type (1 = measurement), action (1 start, 0 stop), payload mode. The real-time data
  arrive as notifications on the long (0x2002, 63 bytes), medium (0x2003, 40 bytes) or
  short (0x2004, 20 bytes) payload characteristic, padded with zeros to its length.
- Battery service 0x3000, battery characteristic 0x3001 (read/notify, 2 bytes):
  level %, charging status (0 not charging, 1 charging).
- Configuration service 0x1000, device control 0x1002: output rate at bytes 24-25
  (1, 4, 10, 12, 15, 20, 30, 60 or 120 Hz; 60 by default).

Payload modes decoded here (all start with a uint32 timestamp in microseconds of the
sensor's own clock, wrapping every 71.6 min):

====  ===================  ========  ==========================================
mode  name                 char      fields after the timestamp
====  ===================  ========  ==========================================
2     extended quaternion  medium    quat w,x,y,z; free acc x,y,z; status u16;
                                     clip count acc u8; clip count gyr u8 (36 B)
3     complete quaternion  medium    quat w,x,y,z; free acc x,y,z (32 B)
5     orientation quat.    short     quat w,x,y,z (20 B)
6     free acceleration    short     free acc x,y,z (16 B)
====  ===================  ========  ==========================================

Mode 3 is the one the driver streams: the orientation and the free acceleration
together, in one notification per sample, at the sensor's full real-time rate.
Orientation is sensor -> local earth (ENU, Z up); free acceleration is in the local
earth frame with gravity removed, m/s^2: the conventions of DESIGN.md as they are.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

BASE_UUID = "1517{:04x}-4947-11e9-8646-d663bd873d93"


def uuid16(short: int) -> str:
    """The full 128-bit UUID string of a DOT characteristic or service."""
    return BASE_UUID.format(short)


CONFIG_SERVICE = uuid16(0x1000)
DEVICE_INFO = uuid16(0x1001)
DEVICE_CONTROL = uuid16(0x1002)
MEASUREMENT_SERVICE = uuid16(0x2000)
CONTROL = uuid16(0x2001)
LONG_PAYLOAD = uuid16(0x2002)
MEDIUM_PAYLOAD = uuid16(0x2003)
SHORT_PAYLOAD = uuid16(0x2004)
BATTERY_SERVICE = uuid16(0x3000)
BATTERY = uuid16(0x3001)

XSENS_COMPANY_ID = 0x0886  # Bluetooth SIG company identifier in the advertisement
ADVERTISED_NAMES = ("Xsens DOT", "Movella DOT")

MODE_EXTENDED_QUATERNION = 2
MODE_COMPLETE_QUATERNION = 3
MODE_ORIENTATION_QUATERNION = 5
MODE_FREE_ACCELERATION = 6
OUTPUT_RATES = (1, 4, 10, 12, 15, 20, 30, 60, 120)
TIMESTAMP_MOD = 1 << 32  # microseconds

CHAR_LENGTH = {LONG_PAYLOAD: 63, MEDIUM_PAYLOAD: 40, SHORT_PAYLOAD: 20}


@dataclass(frozen=True)
class _Mode:
    char: str
    fmt: struct.Struct
    has_quat: bool
    has_free_acc: bool
    has_status: bool


MODES: dict[int, _Mode] = {
    MODE_EXTENDED_QUATERNION: _Mode(MEDIUM_PAYLOAD, struct.Struct("<I4f3fHBB"), True, True, True),
    MODE_COMPLETE_QUATERNION: _Mode(MEDIUM_PAYLOAD, struct.Struct("<I4f3f"), True, True, False),
    MODE_ORIENTATION_QUATERNION: _Mode(SHORT_PAYLOAD, struct.Struct("<I4f"), True, False, False),
    MODE_FREE_ACCELERATION: _Mode(SHORT_PAYLOAD, struct.Struct("<I3f"), False, True, False),
}


class DotError(ValueError):
    """Bytes that are not a notification of the payload mode asked for."""


@dataclass(frozen=True, slots=True)
class DotMeasurement:
    """One real-time sample. ``quat`` (w, x, y, z) and ``free_acc`` are ``None`` when
    the payload mode does not carry them."""

    timestamp_us: int
    quat: tuple[float, float, float, float] | None = None
    free_acc: tuple[float, float, float] | None = None
    status: int | None = None
    clip_acc: int | None = None
    clip_gyr: int | None = None


@dataclass(frozen=True, slots=True)
class DotControl:
    """The measurement control characteristic (0x2001)."""

    action: int  # 1 start, 0 stop
    payload_mode: int
    type: int = 1  # measurement

    @property
    def streaming(self) -> bool:
        return self.action == 1


@dataclass(frozen=True, slots=True)
class DotBattery:
    level: int  # %
    charging: bool


def characteristic_for(mode: int) -> str:
    """The payload characteristic whose notifications carry ``mode``."""
    try:
        return MODES[mode].char
    except KeyError:
        raise DotError(f"payload mode {mode} is not one imucap decodes ({', '.join(map(str, MODES))})") from None


def encode(m: DotMeasurement, mode: int = MODE_COMPLETE_QUATERNION) -> bytes:
    """The notification a DOT sends for ``m`` in ``mode``, padded to the characteristic's length."""
    spec = MODES.get(mode)
    if spec is None:
        raise DotError(f"payload mode {mode} is not one imucap encodes")
    vals: list[float | int] = [m.timestamp_us % TIMESTAMP_MOD]
    if spec.has_quat:
        if m.quat is None:
            raise DotError(f"payload mode {mode} needs a quaternion")
        vals += list(m.quat)
    if spec.has_free_acc:
        if m.free_acc is None:
            raise DotError(f"payload mode {mode} needs a free acceleration")
        vals += list(m.free_acc)
    if spec.has_status:
        vals += [(m.status or 0) & 0xFFFF, (m.clip_acc or 0) & 0xFF, (m.clip_gyr or 0) & 0xFF]
    body = spec.fmt.pack(*vals)
    return body + bytes(CHAR_LENGTH[spec.char] - len(body))


def decode(data: bytes, mode: int = MODE_COMPLETE_QUATERNION) -> DotMeasurement:
    """One payload notification of ``mode``. Raises ``DotError`` on short data, an
    unknown mode or values no sensor sends (non-finite numbers, a quaternion far from
    unit length)."""
    spec = MODES.get(mode)
    if spec is None:
        raise DotError(f"payload mode {mode} is not one imucap decodes")
    if len(data) < spec.fmt.size:
        raise DotError(f"payload mode {mode} needs {spec.fmt.size} bytes, got {len(data)}")
    v = spec.fmt.unpack_from(data, 0)
    k = 1
    quat = free = None
    if spec.has_quat:
        quat = tuple(v[k : k + 4])
        k += 4
        n2 = sum(x * x for x in quat)
        if not 0.8 < n2 < 1.2:  # also false for NaN
            raise DotError(f"quaternion norm^2 {n2:.3g} is not ~1")
    if spec.has_free_acc:
        free = tuple(v[k : k + 3])
        k += 3
        if not all(abs(x) < 1e4 for x in free):  # also false for NaN and inf
            raise DotError("free acceleration is not finite")
    status = clip_a = clip_g = None
    if spec.has_status:
        status, clip_a, clip_g = v[k : k + 3]
    return DotMeasurement(v[0], quat, free, status, clip_a, clip_g)  # type: ignore[arg-type]


def encode_control(c: DotControl) -> bytes:
    return bytes((c.type & 0xFF, c.action & 0xFF, c.payload_mode & 0xFF))


def decode_control(data: bytes) -> DotControl:
    if len(data) < 3:
        raise DotError(f"control characteristic needs 3 bytes, got {len(data)}")
    return DotControl(action=data[1], payload_mode=data[2], type=data[0])


def encode_battery(b: DotBattery) -> bytes:
    return bytes((max(0, min(100, int(b.level))), 1 if b.charging else 0))


def decode_battery(data: bytes) -> DotBattery:
    if len(data) < 2:
        raise DotError(f"battery characteristic needs 2 bytes, got {len(data)}")
    if data[0] > 100:
        raise DotError(f"battery level {data[0]} % is over 100")
    return DotBattery(data[0], data[1] == 1)


def is_dot_advertisement(name: str | None, manufacturer_ids: tuple[int, ...] = ()) -> bool:
    """Whether a scan result is a DOT: by its advertised name, or by Xsens' company id."""
    return bool(name and any(n in name for n in ADVERTISED_NAMES)) or XSENS_COMPANY_ID in manufacturer_ids
