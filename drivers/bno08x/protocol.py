"""CEVA BNO08x UART-RVC ("robot vacuum cleaner") wire format, pure functions.

In RVC mode the chip streams 19-byte frames at 100 Hz, 115200 baud, with no
commands at all:

====  =====================================================================
0-1   header ``AA AA``
2     index (8-bit counter)
3-8   yaw, pitch, roll: int16 little-endian, 0.01 deg
9-14  x, y, z acceleration: int16 little-endian, mg, gravity included
15    motion intent, 16 motion request, 17 reserved
18    checksum: sum of bytes 2..17 modulo 256
====  =====================================================================

Orientation is reported as Tait-Bryan angles applied yaw, then pitch, then roll.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

HEADER = b"\xaa\xaa"
FRAME_LEN = 19
_BODY = struct.Struct("<B3h3hBBB")


class RvcError(ValueError):
    pass


@dataclass(frozen=True, slots=True)
class RvcFrame:
    index: int
    yaw_deg: float
    pitch_deg: float
    roll_deg: float
    acc_mg: tuple[float, float, float]
    motion_intent: int = 0
    motion_request: int = 0


def _clip16(x: float) -> int:
    return max(-32768, min(32767, round(x)))


def encode(f: RvcFrame) -> bytes:
    """One 19-byte frame. Angles are wrapped to (-180, 180]; values are clipped to int16."""

    def wrap(a: float) -> float:
        a = (a + 180.0) % 360.0 - 180.0
        return 180.0 if a == -180.0 else a

    body = _BODY.pack(
        f.index & 0xFF,
        _clip16(wrap(f.yaw_deg) * 100),
        _clip16(f.pitch_deg * 100),
        _clip16(wrap(f.roll_deg) * 100),
        *(_clip16(a) for a in f.acc_mg),
        f.motion_intent & 0xFF,
        f.motion_request & 0xFF,
        0,
    )
    return HEADER + body + bytes((sum(body) & 0xFF,))


def decode(frame: bytes) -> RvcFrame:
    """Decode exactly one frame; raises ``RvcError`` if it is not a valid one."""
    if len(frame) != FRAME_LEN or frame[:2] != HEADER:
        raise RvcError("not an RVC frame")
    if sum(frame[2:18]) & 0xFF != frame[18]:
        raise RvcError("bad checksum")
    idx, yaw, pitch, roll, ax, ay, az, mi, mr, _ = _BODY.unpack_from(frame, 2)
    return RvcFrame(idx, yaw / 100.0, pitch / 100.0, roll / 100.0, (float(ax), float(ay), float(az)), mi, mr)


class RvcStreamParser:
    """Finds frames in a byte stream; resynchronises on the header after any damage."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.bad_checksum = 0
        self.resyncs = 0
        self.skipped_bytes = 0

    def feed(self, data: bytes) -> list[RvcFrame]:
        buf = self._buf
        buf += data
        out: list[RvcFrame] = []
        while True:
            i = buf.find(HEADER)
            if i < 0:
                # keep a trailing 0xAA: it may be half of the next header
                keep = 1 if buf[-1:] == b"\xaa" else 0
                drop = len(buf) - keep
                if drop:
                    self.resyncs += 1
                    self.skipped_bytes += drop
                    del buf[:drop]
                return out
            if i > 0:
                self.resyncs += 1
                self.skipped_bytes += i
                del buf[:i]
            if len(buf) < FRAME_LEN:
                return out
            if sum(buf[2:18]) & 0xFF != buf[18]:
                self.bad_checksum += 1
                del buf[:1]
                continue
            out.append(decode(bytes(buf[:FRAME_LEN])))
            del buf[:FRAME_LEN]
