"""Each device's clock mapped onto the session clock (``ClockModel``).

Arrival times are jittered by the OS and the transport; device clocks are smooth but offset
and drifting. A running linear fit of arrival time against device time, taken through the
lower envelope of the arrivals (transport delay is never negative), gives jitter-free
session times.
"""

from __future__ import annotations

from collections import deque

import numpy as np


class ClockModel:
    """session_time ~= offset + slope * device_time, refitted every ``refit`` samples
    over the last ``window`` pairs.

    Reset (the pairs forgotten, the fitted rate kept: a reboot moves a clock's zero, not
    its oscillator) when the device clock jumps: backwards at all (a restart from zero
    after a brown-out or reconnect), forwards by more than ``ahead`` (a sample cannot
    arrive before it was sent, so an arrival that much earlier than predicted means the
    device time leapt), or by more than ``jump`` either way. Without the forward check a
    leap of 50 ms .. 1 s was absorbed by the lower envelope and then bent the next fit,
    whose window straddled it: streams stayed ~50 ms apart for the whole window."""

    def __init__(self, window: int = 2048, refit: int = 32, jump: float = 1.0, ahead: float = 0.005,
                 max_rate_error: float = 0.05) -> None:
        self.window = window
        self.refit = refit
        self.jump = jump
        self.ahead = ahead
        self.max_rate_error = max_rate_error
        self._dev: deque[float] = deque(maxlen=window)
        self._arr: deque[float] = deque(maxlen=window)
        self.slope = 1.0
        self.offset: float | None = None
        self._since = 0
        self._floor_d: float | None = None  # device time of the last sample on the envelope
        self.resets = 0

    def update(self, device_t: float, arrival_t: float) -> float:
        if self.offset is not None:
            resid = arrival_t - (self.offset + self.slope * device_t)
            # a slope that is off lets the prediction run ahead of the arrivals by up to
            # max_rate_error per second since a sample last sat on the envelope: not a jump
            early = self.ahead + self.max_rate_error * (device_t - (self._floor_d or device_t))
            if resid < -early or abs(resid) > self.jump or (self._dev and device_t < self._dev[-1]):
                self.reset()
            elif resid <= self.ahead:
                self._floor_d = device_t
        self._dev.append(device_t)
        self._arr.append(arrival_t)
        self._since += 1
        if self.offset is None:
            self.offset = arrival_t - self.slope * device_t
            self._floor_d = device_t
        elif self._since >= (self.refit if len(self._dev) < 256 else 4 * self.refit):
            # once the window holds seconds of data the slope hardly moves between fits;
            # fitting 4x less often saves most of the hub's numpy time at 13 x 100 Hz
            self._fit()
        else:
            # keep the lower envelope current between fits
            self.offset = min(self.offset, arrival_t - self.slope * device_t)
        return self.map(device_t)

    def _fit(self) -> None:
        """Line through the per-chunk minima of (arrival - device time): those are the
        samples that met the least transport delay, so their scatter is small and
        their slope is the clock rate ratio."""
        self._since = 0
        d = np.fromiter(self._dev, float)
        a = np.fromiter(self._arr, float)
        # half a second of pairs already pins a clock that is off by percents far better
        # than the nominal rate does (a 3 % slow clock drifts 15 ms in that time)
        if d.size >= 32 and d[-1] - d[0] > 0.5:
            chunk = max(8, d.size // 32)
            n = d.size // chunk * chunk
            r = (a[-n:] - d[-n:]).reshape(-1, chunk)
            j = np.argmin(r, axis=1) + np.arange(r.shape[0]) * chunk + (d.size - n)
            dm, am = d[j], a[j]
            dc = dm - dm.mean()
            den = float(np.dot(dc, dc))
            if den > 0:
                slope = float(np.dot(dc, am - am.mean()) / den)
                # a device clock can be off by percents (a BNO08x's time is its counter over a
                # nominal 100 Hz its oscillator does not quite keep); beyond a few it is a broken fit
                if abs(slope - 1.0) < self.max_rate_error:
                    self.slope = slope
        self.offset = float(np.min(a - self.slope * d))

    def map(self, device_t: float) -> float:
        return (self.offset or 0.0) + self.slope * device_t

    def reset(self) -> None:
        """Forget the pairs and the offset; keep the fitted rate (same oscillator)."""
        self._dev.clear()
        self._arr.clear()
        self.offset = None
        self._floor_d = None
        self._since = 0
        self.resets += 1
