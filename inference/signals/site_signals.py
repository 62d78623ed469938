"""The signals a body-worn sensor suit would measure, as arrays on one 60 Hz clock.

This is the hand-off between synthesis (inference) and the simulated devices
(sim_devices): a device replays one site's rows through its own wire format.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class SiteSignals:
    """Per-site sensor signals, time-major.

    quat: (T, S, 4) sensor orientation, (w, x, y, z), sensor frame -> world frame.
    free_acc: (T, S, 3) world-frame acceleration without gravity, m/s^2 (after the
        11-frame moving average the model was trained with).
    specific_force: (T, S, 3) what an accelerometer reads, sensor frame, gravity
        included (a still sensor reads +9.81 along world up), m/s^2, unsmoothed.
    gyro: (T, S, 3) angular rate in the sensor frame, rad/s.
    contacts: (T, 4) bool, (l_heel, l_toe, r_heel, r_toe).
    insole_force: (T, 2) total vertical force under (left, right) foot, N.
    """

    fps: float
    sites: tuple[str, ...]
    t: np.ndarray
    quat: np.ndarray
    free_acc: np.ndarray
    specific_force: np.ndarray
    gyro: np.ndarray
    contacts: np.ndarray
    insole_force: np.ndarray
    meta: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def site(self, name: str) -> dict[str, np.ndarray]:
        """One site's streams, as a simulated device wants them."""
        k = self.sites.index(name)
        return {
            "t": self.t,
            "quat": self.quat[:, k],
            "free_acc": self.free_acc[:, k],
            "specific_force": self.specific_force[:, k],
            "gyro": self.gyro[:, k],
        }
