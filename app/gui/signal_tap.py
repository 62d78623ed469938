"""The last seconds of each sensor's signals, kept for the live plots.

Why a sink with its own ring buffer: the hub frames exist only on the pipeline's thread;
copying the few numbers a plot needs into a preallocated array there, under a lock held
for microseconds, lets the GUI thread draw them whenever it likes without ever touching
the pipeline.
"""

from __future__ import annotations

import threading

import numpy as np

from app.live import Sink
from drivers.hub import HubFrame

QUANTITIES = {
    "|free acceleration| (m/s²)": ("free_acc", "norm"),
    "|angular rate| (°/s)": ("gyro", "norm"),
    "free acceleration x, y, z (m/s²)": ("free_acc", "xyz"),
    "angular rate x, y, z (°/s)": ("gyro", "xyz"),
}


class SignalTap(Sink):
    def __init__(self, sites: tuple[str, ...], seconds: float = 10.0, rate: float = 60.0) -> None:
        self.sites = tuple(sites)
        n = int(seconds * rate)
        self.t = np.full(n, np.nan)
        self.free_acc = np.full((n, len(self.sites), 3), np.nan, dtype=np.float32)
        self.gyro = np.full((n, len(self.sites), 3), np.nan, dtype=np.float32)
        self.i = 0
        self.count = 0
        self._lock = threading.Lock()

    def on_frame(self, frame: HubFrame) -> None:
        with self._lock:
            k = self.i
            self.t[k] = frame.t
            self.free_acc[k] = frame.free_acc
            g = frame.gyro
            self.gyro[k] = np.degrees(g) if g is not None else np.nan
            self.i = (k + 1) % len(self.t)
            self.count += 1

    def series(self, site: str, quantity: str) -> tuple[np.ndarray, np.ndarray]:
        """(t relative to now, values (N,) or (N, 3)) in time order."""
        kind, shape = QUANTITIES[quantity]
        s = self.sites.index(site)
        with self._lock:
            order = np.r_[self.i:len(self.t), 0:self.i]
            t = self.t[order].copy()
            v = (self.free_acc if kind == "free_acc" else self.gyro)[order, s].astype(float)
        ok = np.isfinite(t)
        t, v = t[ok], v[ok]
        if len(t):
            t = t - t[-1]
        return t, (np.linalg.norm(v, axis=-1) if shape == "norm" else v)
