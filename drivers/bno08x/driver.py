"""CEVA BNO08x in UART-RVC mode: a receive-only 100 Hz stream on a serial port."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._math import G, quat_from_euler_zyx, quat_rotate
from ..base import Sample, Unwrapper
from ..serial_base import SerialDevice
from . import protocol as rvc

RVC_RATE_HZ = 100.0


class Bno08xRvcDevice(SerialDevice):
    """Orientation from the chip's yaw/pitch/roll, free acceleration by removing
    gravity with that orientation. The chip has no clock field, but it emits at a
    fixed 100 Hz from its own oscillator, so the unwrapped frame index / 100 Hz is
    a device clock the hub can fit drift against."""

    scheme = "bno08x-rvc"
    counter_modulus = 256

    def __init__(self, port: str, baud: int = 115200, **kw: Any) -> None:
        super().__init__(port, baud, **kw)
        self._parser = rvc.RvcStreamParser()
        self._unwrap = Unwrapper(256, 1.0 / RVC_RATE_HZ)

    def _open(self) -> None:
        self._open_port()
        self._unwrap.reset()

    def _reset_parser(self) -> None:
        self._parser = rvc.RvcStreamParser()
        self._seen = {"bad_checksum": 0, "resyncs": 0}

    def _feed(self, data: bytes) -> list[rvc.RvcFrame]:
        frames = self._parser.feed(data)
        self._account(self._parser)
        return frames

    def _convert(self, f: rvc.RvcFrame) -> Sample:
        return rvc_to_sample(f, self.device_id, self._unwrap)


_GRAVITY = np.array([0.0, 0.0, G])


def rvc_to_sample(f: rvc.RvcFrame, device_id: str, unwrap: Unwrapper | None = None) -> Sample:
    q = quat_from_euler_zyx(math.radians(f.yaw_deg), math.radians(f.pitch_deg), math.radians(f.roll_deg))
    acc = np.array(f.acc_mg) * (G / 1000.0)
    free = quat_rotate(q, acc) - _GRAVITY
    dev_t = unwrap.update(f.index) if unwrap else None
    return Sample(0.0, dev_t, device_id, f.index, q, free, acc, None)
