"""One device's logged samples, as the readers of other systems' logs return them.

Why here, below the readers: an x-IMU3 GUI log (``drivers.ximu3``) and an Xsens export
(``drivers.xsens_export``) are different files that end as the same thing, and
``imucap import`` treats every one of them alike from there on.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class DeviceLog:
    """One device's samples in time order. t: (N,) s on the device's (or the log's shared)
    clock; quat: (N, 4) (w, x, y, z) sensor -> Earth, Earth Z up; acc: (N, 3) specific
    force (m/s^2, sensor frame); gyro: (N, 3) rad/s. A channel the log does not carry at
    all is NaN throughout, so a reader never has to invent one. skipped: rows dropped for
    being malformed, non-finite, incomplete or duplicated, by reason, and rows kept with a
    missing cell filled ("filled"); counted, not fatal. info: what the log's header says
    about the device (settings, firmware, clock), for the import's summary."""

    name: str
    serial: str
    t: np.ndarray
    quat: np.ndarray
    acc: np.ndarray
    gyro: np.ndarray
    skipped: dict[str, int] = field(default_factory=dict)
    info: dict[str, str] = field(default_factory=dict)

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t))) if len(self.t) > 1 else float("nan")


__all__ = ["DeviceLog"]
