"""Replaying a recording to the streams at the pace it was captured (or a multiple).

A receiver (an avatar, a recorder) expects the body to move in real time; a replay
otherwise goes as fast as the poser runs. ``Pacer`` holds each frame back until its
time, measured from the first frame, has come on the wall clock (divided by ``speed``;
0 = no waiting), and maps recording times to ``time.monotonic()`` accordingly, so the
LSL stamps of a paced replay are when the samples go out and those of an unpaced one
keep the recording's own spacing.
"""

from __future__ import annotations

import time
from collections.abc import Callable


class Pacer:
    def __init__(self, speed: float = 1.0, clock: Callable[[], float] = time.monotonic,
                 sleep: Callable[[float], None] = time.sleep) -> None:
        if not speed >= 0:
            raise ValueError(f"--stream-speed must be >= 0 (0 = as fast as it goes), not {speed}")
        self.speed = float(speed)
        self._clock, self._sleep = clock, sleep
        self._t0: float | None = None
        self._wall0 = 0.0

    def _start(self, t: float) -> None:
        if self._t0 is None:
            self._t0, self._wall0 = float(t), self._clock()

    def to_monotonic(self, t: float) -> float:
        """When the frame of recording time ``t`` is (or was) released, on time.monotonic()."""
        self._start(t)
        return self._wall0 + (t - self._t0) / (self.speed or 1.0)  # type: ignore[operator]

    def __call__(self, t: float) -> None:
        """Wait until the frame of recording time ``t`` is due."""
        due = self.to_monotonic(t)
        if self.speed > 0:
            wait = due - self._clock()
            if wait > 0:
                self._sleep(wait)
