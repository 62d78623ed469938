"""Gait numbers of the last seconds of a live session, for a view that shows them.

A sink keeps the last ``window_s`` of poses (orientations and contacts only) as they come
from the inference thread; a view asks for the numbers a few times a second from its own
thread (``inference.metrics.gait``). The lock keeps the two from reading a half-appended
window; the work under it is a few hundred small array copies.
"""

from __future__ import annotations

import threading
from collections import deque

import numpy as np

from app.live.pipeline import LivePose, Sink
from inference.metrics.gait import GaitNumbers, gait_numbers
from inference.signals.resample import FPS_MODEL

WINDOW_S = 10.0  # a few strides: steady enough to read, recent enough to follow a change of pace


class GaitSink(Sink):
    def __init__(self, window_s: float = WINDOW_S) -> None:
        n = int(round(window_s * FPS_MODEL)) + 1
        self._t: deque[float] = deque(maxlen=n)
        self._rot: deque[np.ndarray] = deque(maxlen=n)
        self._contacts: deque[np.ndarray] = deque(maxlen=n)
        self._lock = threading.Lock()

    def on_pose(self, pose: LivePose) -> None:
        with self._lock:
            self._t.append(float(pose.t))
            self._rot.append(np.asarray(pose.pose.rot, dtype=np.float32))
            self._contacts.append(np.asarray(pose.pose.contacts, dtype=bool))

    def numbers(self) -> GaitNumbers:
        with self._lock:
            if len(self._t) < 2:
                return GaitNumbers(None, (None, None), None, 0.0)
            t, rot, c = np.array(self._t), np.stack(self._rot), np.stack(self._contacts)
        return gait_numbers(t, rot, c)
