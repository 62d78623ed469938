"""Xsens MTi-600 on CAN, through any python-can interface named in the URL."""

from __future__ import annotations

import time
from typing import Any

import can
import numpy as np

from .._math import quat_normalize
from ..base import Device, DeviceGone, Sample, Unwrapper
from . import protocol as xcan
from .shared_bus import BUSES, Tap


class XsensCanDevice(Device):
    """``xsens-can://<interface>/<channel>?id_offset=0x100&bitrate=1000000``.

    Frames of other nodes on a shared bus are ignored; malformed frames of ours
    and CAN error frames count as bad frames.

    Every device on one interface/channel in this process shares one python-can
    bus (``shared_bus``), which hands each device only the frames of its own
    identifier block: N sensors on a channel cost one receive per frame, not N
    receives and N decode attempts.
    """

    scheme = "xsens-can"
    counter_modulus = 1 << 16

    def __init__(
        self,
        interface: str,
        channel: str,
        *,
        id_offset: int = 0,
        bitrate: int | None = None,
        bus_kwargs: dict[str, Any] | None = None,
        **kw: Any,
    ) -> None:
        super().__init__(kw.pop("device_id", None) or f"{interface}/{channel}+0x{id_offset:X}", **kw)
        self.interface = interface
        self.channel = channel
        self.id_offset = id_offset
        self.bitrate = bitrate
        self.bus_kwargs = dict(bus_kwargs or {})
        # a Tap on the shared bus: the part of python-can's BusABC we use (recv, shutdown)
        self._bus: Tap | can.BusABC | None = None
        self._dropped_before = 0  # frames dropped by taps of earlier connections
        self._asm = xcan.GroupAssembler()
        self._unwrap = Unwrapper(1 << 32, 1e-6)

    def describe(self) -> str:
        return f"xsens-can://{self.interface}/{self.channel}?id_offset=0x{self.id_offset:X}"

    def _open(self) -> None:
        kwargs = dict(self.bus_kwargs)
        if self.bitrate:
            kwargs["bitrate"] = self.bitrate
        try:
            self._bus = BUSES.attach(self.interface, self.channel, kwargs, owned_ids(self.id_offset))
        except Exception as exc:  # interfaces raise their own types (refused, no such channel)
            raise DeviceGone(f"cannot open CAN {self.interface}/{self.channel}: {exc or type(exc).__name__}") from exc
        self._asm = xcan.GroupAssembler()
        self._unwrap.reset()

    def _close(self) -> None:
        bus, self._bus = self._bus, None
        if isinstance(bus, Tap):
            self._dropped_before += bus.dropped
        if bus is not None:
            bus.shutdown()

    @property
    def frames_dropped(self) -> int:
        """Frames of ours the shared bus dropped because this device's reader fell
        more than a queue behind (they show up as lost packets too)."""
        bus = self._bus
        return self._dropped_before + (bus.dropped if isinstance(bus, Tap) else 0)

    def _read(self, timeout: float | None) -> Sample | None:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            if self._bus is None:
                raise DeviceGone("bus closed")
            remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                msg = self._bus.recv(remaining)
            except can.CanError as exc:
                raise DeviceGone(str(exc)) from exc
            if msg is None:
                return None
            if msg.is_error_frame:
                self.stats.bad_frame += 1
                continue
            try:
                r = xcan.decode(msg.arbitration_id, msg.data, self.id_offset)
            except xcan.CanDecodeError:
                self.stats.bad_frame += 1
                continue
            if r is None:
                continue
            g = self._asm.push(*r)
            if g is not None:
                return group_to_sample(g, self.device_id, self._unwrap)
            if deadline is not None and time.monotonic() >= deadline:
                return None


def owned_ids(id_offset: int) -> frozenset[int]:
    """The identifiers an MTi moved to ``id_offset`` sends: those the shared bus
    routes to its device (an id is ours when ``id - id_offset`` is in the DBC)."""
    return frozenset(m.frame_id + id_offset for m in xcan.database().messages)


def group_to_sample(g: xcan.CanGroup, device_id: str, unwrap: Unwrapper | None = None) -> Sample:
    q = quat_normalize(np.array(g.quat)) if g.quat is not None else None
    dev_t = None
    if g.sample_time_us is not None:
        dev_t = unwrap.update(g.sample_time_us) if unwrap else g.sample_time_us * 1e-6

    def arr(v):
        return None if v is None else np.array(v, dtype=float)

    return Sample(0.0, dev_t, device_id, g.counter, q, arr(g.free_acc), arr(g.acc), arr(g.gyro), status=g.status)
