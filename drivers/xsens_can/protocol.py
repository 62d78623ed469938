"""Xsens MTi-600 CAN output, described by our own DBC (``mti600.dbc``), via cantools.

An MTi on CAN sends one small frame per quantity per sample (a *group*): sample
time, group counter, status word, quaternion, rate of turn, acceleration, free
acceleration. Several MTis share a bus by moving their identifiers as a block,
which the ``id_offset`` here models. ``GroupAssembler`` turns the frames back
into one measurement per sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources

import cantools

SCALE_Q = 1.0 / 32767.0
DBC_NAME = "mti600.dbc"

# message name -> (signal names, our field name)
FIELDS: dict[str, tuple[tuple[str, ...], str]] = {
    "SampleTime": (("SampleTimeUs",), "sample_time_us"),
    "GroupCounter": (("Counter",), "counter"),
    "StatusWord": (("Status",), "status"),
    "Quaternion": (("Q0", "Q1", "Q2", "Q3"), "quat"),
    "RateOfTurn": (("GyrX", "GyrY", "GyrZ"), "gyro"),
    "Acceleration": (("AccX", "AccY", "AccZ"), "acc"),
    "FreeAcceleration": (("FreeAccX", "FreeAccY", "FreeAccZ"), "free_acc"),
}
GROUP_START = ("SampleTime", "GroupCounter")


class CanDecodeError(ValueError):
    pass


@lru_cache(maxsize=1)
def database() -> cantools.database.can.Database:
    """The DBC shipped with the package (parsed once)."""
    text = resources.files(__package__).joinpath(DBC_NAME).read_text()
    return cantools.database.load_string(text, database_format="dbc")


@dataclass(slots=True)
class CanGroup:
    """One sample's worth of MTi CAN output; absent quantities are ``None``."""

    sample_time_us: int | None = None
    counter: int | None = None
    status: int | None = None
    quat: tuple[float, ...] | None = None
    gyro: tuple[float, ...] | None = None
    acc: tuple[float, ...] | None = None
    free_acc: tuple[float, ...] | None = None
    names: list[str] = field(default_factory=list)


def _clip(v: float, scale: float) -> float:
    return max(-32768, min(32767, round(v / scale))) * scale


def encode(group: CanGroup, id_offset: int = 0) -> list[tuple[int, bytes]]:
    """(arbitration id, payload) for each quantity present, in MTi order."""
    db = database()
    out: list[tuple[int, bytes]] = []
    for name, (signals, attr) in FIELDS.items():
        v = getattr(group, attr)
        if v is None:
            continue
        msg = db.get_message_by_name(name)
        if isinstance(v, tuple | list):
            scale = msg.signals[0].scale
            values = {s: _clip(float(x), scale) for s, x in zip(signals, v, strict=True)}
        else:
            values = {signals[0]: int(v) & ((1 << msg.signals[0].length) - 1)}
        out.append((msg.frame_id + id_offset, bytes(msg.encode(values, scaling=True, strict=False))))
    return out


def decode(arbitration_id: int, data: bytes, id_offset: int = 0) -> tuple[str, object] | None:
    """Decode one frame into (message name, value). ``None`` if the id is not an MTi
    output of this sensor (other traffic on a shared bus is normal, not an error);
    ``CanDecodeError`` if it is ours but malformed."""
    db = database()
    try:
        msg = db.get_message_by_frame_id(arbitration_id - id_offset)
    except KeyError:
        return None
    if len(data) != msg.length:
        raise CanDecodeError(f"{msg.name}: {len(data)} bytes, expected {msg.length}")
    try:
        values = msg.decode(bytes(data), decode_choices=False, scaling=True)
    except Exception as exc:  # cantools raises several types for bad payloads
        raise CanDecodeError(f"{msg.name}: {exc}") from exc
    signals, _ = FIELDS[msg.name]
    if len(signals) == 1:
        return msg.name, int(values[signals[0]])
    return msg.name, tuple(float(values[s]) for s in signals)


class GroupAssembler:
    """Collects per-quantity frames into ``CanGroup``s.

    A group is complete when every quantity seen in the previous complete group
    has arrived (no extra latency in steady state), or when a quantity repeats or
    a group-start message arrives (a frame of the old group was lost).
    """

    def __init__(self) -> None:
        self._cur = CanGroup()
        self._expected: set[str] | None = None
        self.incomplete = 0

    def push(self, name: str, value: object) -> CanGroup | None:
        done: CanGroup | None = None
        cur = self._cur
        if cur.names and (name in cur.names or (name in GROUP_START and not set(cur.names) <= set(GROUP_START))):
            done = self._flush(complete=False)
            cur = self._cur
        setattr(cur, FIELDS[name][1], value)
        cur.names.append(name)
        if self._expected is not None and self._expected <= set(cur.names):
            return self._flush(complete=True)
        return done

    def _flush(self, complete: bool) -> CanGroup:
        g = self._cur
        self._cur = CanGroup()
        names = set(g.names)
        if self._expected is None or names >= self._expected:
            self._expected = names  # learn (or widen) the group layout
        elif not complete:
            self.incomplete += 1
        return g
