"""Xsens Xbus wire format (MT Low-Level Communication Protocol), pure functions.

Frame: ``FA BID MID LEN [LENH LENL] DATA CS``. ``LEN = 0xFF`` announces a 2-byte
extended length. The checksum byte makes the sum of every byte after the preamble
(BID .. CS) zero modulo 256. All multi-byte numbers are big-endian.

MTData2 (MID 0x36) carries a list of ``(data id, size, value)`` packets. The low
nibble of a data id selects the number format (bits 0-1: float32, Fp12.20,
Fp16.32, float64) and the coordinate frame (bits 2-3: ENU, NED, NWU); the rest
names the quantity. Fp12.20 is a signed 32-bit integer scaled by 2^-20; Fp16.32
is 6 bytes: the 32-bit fractional part followed by the signed 16-bit integer part.

Everything here is a pure function of bytes so that the simulated MTi (which
encodes) and the driver (which decodes) are tested against each other and
against bytes captured from a real device.
"""

from __future__ import annotations

import operator
import struct
from dataclasses import dataclass, field
from enum import IntEnum

PREAMBLE = 0xFA
BID_MASTER = 0xFF
MAX_EXT_LEN = 2048  # the largest payload an MTi sends; bounds the wait on a corrupted length


class XbusError(ValueError):
    """A frame or payload that does not follow the protocol."""


class MID(IntEnum):
    ReqDID = 0x00
    DeviceID = 0x01
    GoToMeasurement = 0x10
    GoToMeasurementAck = 0x11
    ReqProductCode = 0x1C
    ProductCode = 0x1D
    GoToConfig = 0x30
    GoToConfigAck = 0x31
    MTData2 = 0x36
    WakeUp = 0x3E
    WakeUpAck = 0x3F
    Error = 0x42
    SetOutputConfiguration = 0xC0
    SetOutputConfigurationAck = 0xC1


class XDI(IntEnum):
    """Data identifiers with the format nibble cleared."""

    PacketCounter = 0x1020
    SampleTimeFine = 0x1060
    Quaternion = 0x2010
    Acceleration = 0x4020
    FreeAcceleration = 0x4030
    RateOfTurn = 0x8020
    StatusByte = 0xE010
    StatusWord = 0xE020


class Precision(IntEnum):
    FLOAT32 = 0x0
    FP1220 = 0x1
    FP1632 = 0x2
    FLOAT64 = 0x3


class CoordFrame(IntEnum):
    ENU = 0x0
    NED = 0x4
    NWU = 0x8


_PREC_SIZE = {Precision.FLOAT32: 4, Precision.FP1220: 4, Precision.FP1632: 6, Precision.FLOAT64: 8}
_N_VALUES = {XDI.Quaternion: 4, XDI.Acceleration: 3, XDI.FreeAcceleration: 3, XDI.RateOfTurn: 3}
_INT_FORMATS = {XDI.PacketCounter: ">H", XDI.SampleTimeFine: ">I", XDI.StatusByte: ">B", XDI.StatusWord: ">I"}

SAMPLE_TIME_FINE_HZ = 10_000  # SampleTimeFine ticks per second
SAMPLE_TIME_FINE_MOD = 1 << 32


@dataclass(frozen=True, slots=True)
class XbusMessage:
    mid: int
    data: bytes = b""
    bid: int = BID_MASTER


def checksum(body: bytes) -> int:
    """Checksum byte for ``body`` = BID..DATA (everything after the preamble)."""
    return (-sum(body)) & 0xFF


def encode(mid: int, data: bytes = b"", bid: int = BID_MASTER) -> bytes:
    """One complete Xbus frame."""
    n = len(data)
    if n < 0xFF:
        head = bytes((bid, mid, n))
    elif n <= 0xFFFF:
        head = bytes((bid, mid, 0xFF, n >> 8, n & 0xFF))
    else:
        raise XbusError(f"payload of {n} bytes is too long for Xbus")
    body = head + bytes(data)
    return bytes((PREAMBLE,)) + body + bytes((checksum(body),))


def decode(frame: bytes) -> XbusMessage:
    """Decode exactly one complete frame; raises ``XbusError`` if it is not one."""
    if len(frame) < 5 or frame[0] != PREAMBLE:
        raise XbusError("not an Xbus frame (preamble or size)")
    bid, mid, n = frame[1], frame[2], frame[3]
    start = 4
    if n == 0xFF:
        if len(frame) < 7:
            raise XbusError("truncated extended length")
        n = (frame[4] << 8) | frame[5]
        start = 6
    if len(frame) != start + n + 1:
        raise XbusError(f"length field says {n} bytes, frame holds {len(frame) - start - 1}")
    if sum(frame[1:]) & 0xFF:
        raise XbusError("bad checksum")
    return XbusMessage(mid, bytes(frame[start : start + n]), bid)


class XbusStreamParser:
    """Cuts a byte stream into frames, resynchronising on the preamble.

    A bad checksum drops only the preamble byte and rescans, so a corrupted frame
    costs that frame and nothing after it.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        self.bad_checksum = 0
        self.resyncs = 0
        self.skipped_bytes = 0

    def feed(self, data: bytes) -> list[XbusMessage]:
        buf = self._buf
        buf += data
        out: list[XbusMessage] = []
        while True:
            i = buf.find(PREAMBLE)
            if i < 0:
                if buf:
                    self.resyncs += 1
                    self.skipped_bytes += len(buf)
                    buf.clear()
                return out
            if i > 0:
                self.resyncs += 1
                self.skipped_bytes += i
                del buf[:i]
            if len(buf) < 4:
                return out
            n = buf[3]
            start = 4
            if n == 0xFF:
                if len(buf) < 6:
                    return out
                n = (buf[4] << 8) | buf[5]
                start = 6
                if n > MAX_EXT_LEN:
                    self.bad_checksum += 1
                    del buf[:1]
                    continue
            end = start + n + 1
            if len(buf) < end:
                return out
            if sum(buf[1:end]) & 0xFF:
                self.bad_checksum += 1
                del buf[:1]
                continue
            out.append(XbusMessage(buf[2], bytes(buf[start : end - 1]), buf[1]))
            del buf[:end]


# --- MTData2 -------------------------------------------------------------------------------------------


def _enc_real(v: float, prec: Precision) -> bytes:
    if prec == Precision.FLOAT32:
        return struct.pack(">f", v)
    if prec == Precision.FLOAT64:
        return struct.pack(">d", v)
    if prec == Precision.FP1220:
        i = round(v * (1 << 20))
        i = max(-(1 << 31), min((1 << 31) - 1, i))
        return struct.pack(">i", i)
    i = round(v * (1 << 32))
    i = max(-(1 << 47), min((1 << 47) - 1, i))
    return struct.pack(">Ih", i & 0xFFFFFFFF, i >> 32)


def _dec_reals(b: bytes, count: int, prec: Precision) -> tuple[float, ...]:
    if prec == Precision.FLOAT32:
        return struct.unpack(f">{count}f", b)
    if prec == Precision.FLOAT64:
        return struct.unpack(f">{count}d", b)
    if prec == Precision.FP1220:
        return tuple(i / (1 << 20) for i in struct.unpack(f">{count}i", b))
    vals = struct.unpack(">" + "Ih" * count, b)
    return tuple(vals[2 * k + 1] + vals[2 * k] / 4294967296.0 for k in range(count))


def data_id(xdi: XDI, prec: Precision = Precision.FLOAT32, frame: CoordFrame = CoordFrame.ENU) -> int:
    if xdi in _INT_FORMATS:
        return int(xdi)
    return int(xdi) | int(prec) | int(frame)


@dataclass(slots=True)
class MTData2:
    """Decoded MTData2 payload; quantities absent from the packet are ``None``.

    Values are as transmitted, in ``frame`` (the coordinate frame of the last real
    valued field); ``to_zup`` in the driver maps NED to a Z-up frame.
    """

    packet_counter: int | None = None
    sample_time_fine: int | None = None
    quat: tuple[float, ...] | None = None
    acc: tuple[float, ...] | None = None
    free_acc: tuple[float, ...] | None = None
    gyro: tuple[float, ...] | None = None
    status: int | None = None
    precision: Precision = Precision.FLOAT32
    frame: CoordFrame = CoordFrame.ENU
    unknown: dict[int, bytes] = field(default_factory=dict)


_ATTR = {
    XDI.Quaternion: "quat",
    XDI.Acceleration: "acc",
    XDI.FreeAcceleration: "free_acc",
    XDI.RateOfTurn: "gyro",
}


def encode_mtdata2(d: MTData2) -> bytes:
    """Payload for an MTData2 message, fields in the order an MTi sends them."""
    out = bytearray()

    def put(did: int, payload: bytes) -> None:
        if len(payload) > 255:
            raise XbusError("MTData2 field longer than 255 bytes")
        out.extend(struct.pack(">HB", did, len(payload)))
        out.extend(payload)

    if d.packet_counter is not None:
        put(XDI.PacketCounter, struct.pack(">H", d.packet_counter & 0xFFFF))
    if d.sample_time_fine is not None:
        put(XDI.SampleTimeFine, struct.pack(">I", d.sample_time_fine & 0xFFFFFFFF))
    for xdi in (XDI.Quaternion, XDI.Acceleration, XDI.FreeAcceleration, XDI.RateOfTurn):
        vals = getattr(d, _ATTR[xdi])
        if vals is not None:
            if len(vals) != _N_VALUES[xdi]:
                raise XbusError(f"{xdi.name} needs {_N_VALUES[xdi]} values")
            put(data_id(xdi, d.precision, d.frame), b"".join(_enc_real(float(v), d.precision) for v in vals))
    if d.status is not None:
        put(XDI.StatusWord, struct.pack(">I", d.status & 0xFFFFFFFF))
    return bytes(out)


def decode_mtdata2(payload: bytes) -> MTData2:
    """Parse an MTData2 payload. Unknown data ids are kept raw in ``unknown``;
    a known id with the wrong size, or a truncated field, raises ``XbusError``.

    An MTi sends the same fields in the same order in every packet, so the field
    layout is looked up in a cache of compiled ``struct`` plans and the whole
    payload is unpacked in one call; an unseen or unusual layout (unknown ids,
    Fp16.32, errors) takes the general field-by-field path. Both give identical
    results (tested)."""
    plan = _plan_for(payload)
    if plan is None:
        return _decode_mtdata2_fields(payload)
    return plan(payload)


# layout key (the field headers) -> fast decoder; None = use the general path
_PLANS: dict[bytes, object] = {}
_MAX_PLANS = 64


def _plan_for(payload: bytes):  # type: ignore[no-untyped-def]
    """The cached fast decoder for this payload's field layout, or ``None``."""
    n = len(payload)
    heads = bytearray()
    i = 0
    while i + 3 <= n:
        heads += payload[i : i + 3]
        i += 3 + payload[i + 2]
    if i != n:
        return None  # truncated or overrunning field: the general path raises
    key = bytes(heads)
    plan = _PLANS.get(key)
    if plan is None and key not in _PLANS:
        plan = _compile_plan(key)
        if len(_PLANS) < _MAX_PLANS:
            _PLANS[key] = plan
    return plan


def _compile_plan(key: bytes):  # type: ignore[no-untyped-def]
    """Build the one-``struct`` decoder for a field layout, or ``None`` when the
    layout needs the general path (unknown ids, Fp16.32, inconsistent sizes).
    Field semantics follow ``_decode_mtdata2_fields`` exactly: later fields win,
    except that a StatusByte never overrides an earlier status."""
    fmt = [">"]
    slots: list[tuple[str, int, int, float]] = []  # (attribute, first value index, count (0 = int), scale)
    pos = 0
    have_status = False
    prec, frame = Precision.FLOAT32, CoordFrame.ENU
    for k in range(0, len(key), 3):
        did = (key[k] << 8) | key[k + 1]
        size = key[k + 2]
        base = did & 0xFFF0
        fmt.append("3x")
        if base in _INT_FORMATS and did == base:
            f = _INT_FORMATS[XDI(base)][1:]
            if size != struct.calcsize(">" + f):
                return None
            if base == XDI.PacketCounter:
                attr = "packet_counter"
            elif base == XDI.SampleTimeFine:
                attr = "sample_time_fine"
            elif base == XDI.StatusByte and have_status:
                fmt.append(f"{size}x")
                continue
            else:
                attr, have_status = "status", True
            slots.append((attr, pos, 0, 1.0))
            fmt.append(f)
            pos += 1
        elif base in _N_VALUES:
            p = Precision(did & 0x3)
            if p == Precision.FP1632 or (did & 0xC) == 0xC:
                return None
            count = _N_VALUES[XDI(base)]
            if size != count * _PREC_SIZE[p]:
                return None
            code = {Precision.FLOAT32: "f", Precision.FLOAT64: "d", Precision.FP1220: "i"}[p]
            slots.append((_ATTR[XDI(base)], pos, count, 1.0 / (1 << 20) if p == Precision.FP1220 else 1.0))
            fmt.append(f"{count}{code}")
            pos += count
            prec, frame = p, CoordFrame(did & 0xC)
        else:
            return None
    unpack = struct.Struct("".join(fmt)).unpack
    if all(scale == 1.0 for *_, scale in slots):
        # the common case: one unpack, one itemgetter picks every field (ints by index,
        # vectors by slice, absent fields the trailing None), one constructor call
        final: dict[str, int | slice] = {}
        for attr, i, count, _ in slots:
            final[attr] = i if count == 0 else slice(i, i + count)
        order = ("packet_counter", "sample_time_fine", "quat", "acc", "free_acc", "gyro", "status")
        pick = operator.itemgetter(*(final.get(a, pos) for a in order))

        def fast(payload: bytes) -> MTData2:
            return MTData2(*pick(unpack(payload) + _NONE), prec, frame)

        return fast

    def plan(payload: bytes) -> MTData2:
        v = unpack(payload)
        d = MTData2(precision=prec, frame=frame)
        for attr, i, count, scale in slots:
            if count == 0:
                setattr(d, attr, v[i])
            elif scale != 1.0:
                setattr(d, attr, tuple(x * scale for x in v[i : i + count]))
            else:
                setattr(d, attr, v[i : i + count])
        return d

    return plan


_NONE = (None,)


def _decode_mtdata2_fields(payload: bytes) -> MTData2:
    """The general field-by-field MTData2 parser (the reference the plans are tested against)."""
    d = MTData2()
    i, n = 0, len(payload)
    while i < n:
        if i + 3 > n:
            raise XbusError("truncated MTData2 field header")
        did = (payload[i] << 8) | payload[i + 1]
        size = payload[i + 2]
        i += 3
        if i + size > n:
            raise XbusError(f"MTData2 field 0x{did:04X} runs past the payload")
        b = payload[i : i + size]
        i += size
        base = did & 0xFFF0
        if base in _INT_FORMATS and did == base:
            fmt = _INT_FORMATS[XDI(base)]
            if size != struct.calcsize(fmt):
                raise XbusError(f"field 0x{did:04X} has size {size}")
            (v,) = struct.unpack(fmt, b)
            if base == XDI.PacketCounter:
                d.packet_counter = v
            elif base == XDI.SampleTimeFine:
                d.sample_time_fine = v
            else:
                d.status = v if base == XDI.StatusWord else (d.status if d.status is not None else v)
        elif base in _N_VALUES:
            prec = Precision(did & 0x3)
            fr = did & 0xC
            if fr == 0xC:
                raise XbusError(f"field 0x{did:04X} names no coordinate frame")
            count = _N_VALUES[XDI(base)]
            if size != count * _PREC_SIZE[prec]:
                raise XbusError(f"field 0x{did:04X} has size {size}, expected {count * _PREC_SIZE[prec]}")
            setattr(d, _ATTR[XDI(base)], _dec_reals(b, count, prec))
            d.precision, d.frame = prec, CoordFrame(fr)
        else:
            d.unknown[did] = bytes(b)
    return d


# --- configuration messages ---------------------------------------------------------------------------


def encode_output_configuration(items: list[tuple[int, int]]) -> bytes:
    """SetOutputConfiguration payload: (data id, output rate Hz) pairs."""
    return b"".join(struct.pack(">HH", did, rate) for did, rate in items)


def decode_output_configuration(payload: bytes) -> list[tuple[int, int]]:
    if len(payload) % 4:
        raise XbusError("output configuration payload is not a multiple of 4 bytes")
    return [struct.unpack_from(">HH", payload, k) for k in range(0, len(payload), 4)]


def default_output_configuration(
    rate: int = 100, precision: Precision = Precision.FLOAT32, frame: CoordFrame = CoordFrame.ENU
) -> list[tuple[int, int]]:
    """What our driver asks for: everything the pipeline and calibration use."""
    return [
        (XDI.PacketCounter, 0xFFFF),
        (XDI.SampleTimeFine, 0xFFFF),
        (data_id(XDI.Quaternion, precision, frame), rate),
        (data_id(XDI.Acceleration, precision, frame), rate),
        (data_id(XDI.FreeAcceleration, precision, frame), rate),
        (data_id(XDI.RateOfTurn, precision, frame), rate),
        (XDI.StatusWord, 0xFFFF),
    ]
