"""x-IMU3 data messages, pure functions: what the twin sends and the fuzz target parses.

Format from x-io Technologies' "x-IMU3 User Manual", section "Communication protocol"
(data messages). Every message ends with a newline (0x0A). A message in ASCII mode is
text: an identifier character, then comma-separated fields, then ``\\r\\n``; in binary
mode its first byte is the identifier with bit 7 set, then a uint64 timestamp
(microseconds, the device clock) and float32 fields, little-endian, with 0xDB escaped as
0xDB 0xDD and 0x0A as 0xDB 0xDC so the only newline is the terminator.

==  ==========  ====================================================================
id  message     fields after the timestamp
==  ==========  ====================================================================
I   inertial    gyroscope x, y, z (deg/s); accelerometer x, y, z (g, specific force)
Q   quaternion  w, x, y, z: sensor -> Earth (NWU, Z up)
B   battery     percentage, voltage (V), charging status
==  ==========  ====================================================================

The live driver hands the bytes to x-io's own ``ximu3`` package; this module exists so the
twin speaks the format without it and the format is checked against it (the tests feed
these bytes to ``ximu3`` over loopback UDP).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

INERTIAL, QUATERNION, BATTERY = "I", "Q", "B"
_FIELDS = {INERTIAL: 6, QUATERNION: 4, BATTERY: 3}
_BIN = {k: struct.Struct(f"<Q{n}f") for k, n in _FIELDS.items()}
ESC, ESC_NL, ESC_ESC = 0xDB, 0xDC, 0xDD


class Ximu3Error(ValueError):
    """Bytes that are not an x-IMU3 data message imucap reads."""


@dataclass(frozen=True, slots=True)
class Message:
    kind: str  # "I", "Q" or "B"
    timestamp_us: int
    values: tuple[float, ...]


def _escape(b: bytes) -> bytes:
    return b.replace(b"\xdb", b"\xdb\xdd").replace(b"\n", b"\xdb\xdc")


def _unescape(b: bytes) -> bytes:
    out = bytearray()
    i, n = 0, len(b)
    while i < n:
        c = b[i]
        if c == ESC:
            if i + 1 >= n or b[i + 1] not in (ESC_NL, ESC_ESC):
                raise Ximu3Error("invalid escape sequence")
            out.append(0x0A if b[i + 1] == ESC_NL else ESC)
            i += 2
        else:
            out.append(c)
            i += 1
    return bytes(out)


def encode(m: Message, binary: bool = True) -> bytes:
    """One message with its terminator."""
    n = _FIELDS.get(m.kind)
    if n is None or len(m.values) != n:
        raise Ximu3Error(f"message {m.kind!r} takes {n} values, not {len(m.values)}")
    if binary:
        body = bytes((ord(m.kind) | 0x80,)) + _BIN[m.kind].pack(m.timestamp_us, *m.values)
        return _escape(body) + b"\n"
    fields = ",".join(f"{v:.4f}" for v in m.values)  # four decimals, as the device writes them
    return f"{m.kind},{m.timestamp_us},{fields}\r\n".encode("ascii")


def decode(msg: bytes) -> Message:
    """One message, with or without its terminator (ASCII or binary, told by bit 7 of
    the first byte)."""
    if msg.endswith(b"\n"):
        msg = msg[:-1]
    if not msg:
        raise Ximu3Error("empty message")
    if msg[0] & 0x80:
        kind = chr(msg[0] & 0x7F)
        fmt = _BIN.get(kind)
        if fmt is None:
            raise Ximu3Error(f"binary message {kind!r} is not one imucap reads")
        body = _unescape(msg[1:])
        if len(body) != fmt.size:
            raise Ximu3Error(f"binary {kind!r} message has {len(body)} bytes, expected {fmt.size}")
        v = fmt.unpack(body)
        ts, values = v[0], tuple(v[1:])
    else:
        try:
            text = msg.decode("ascii").rstrip("\r")
        except UnicodeDecodeError:
            raise Ximu3Error("ASCII message with non-ASCII bytes") from None
        parts = text.split(",")
        kind = parts[0]
        n = _FIELDS.get(kind)
        if n is None:
            raise Ximu3Error(f"ASCII message {kind[:8]!r} is not one imucap reads")
        if len(parts) != n + 2:
            raise Ximu3Error(f"ASCII {kind!r} message has {len(parts) - 2} values, expected {n}")
        try:
            ts = int(parts[1])
            values = tuple(float(p) for p in parts[2:])
        except ValueError:
            raise Ximu3Error(f"ASCII {kind!r} message has a field that is not a number") from None
        if ts < 0:
            raise Ximu3Error("negative timestamp")
    if not all(math.isfinite(x) for x in values):
        raise Ximu3Error(f"{kind!r} message has a value that is not finite")
    return Message(kind, ts, values)


def split(stream: bytes) -> tuple[list[bytes], bytes]:
    """Complete messages of a byte stream (TCP, serial) and the unfinished rest."""
    *msgs, rest = stream.split(b"\n")
    return [m + b"\n" for m in msgs if m], rest
