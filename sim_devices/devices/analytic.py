"""Signals of simple analytic motion, exact by construction.

Each site spins at a constant rate about a fixed world axis while standing in
place: orientation, angular rate and specific force are known in closed form,
which makes these the reference input for testing that bytes -> numbers is
right without depending on the motion synthesis.
"""

from __future__ import annotations

import numpy as np

from inference.body.rotations import quat_about_axis, quat_conjugate, quat_rotate
from inference.signals.site_signals import SiteSignals

G = 9.80665


def spinning_signals(
    sites: tuple[str, ...] | list[str],
    seconds: float = 10.0,
    fps: float = 60.0,
    rate_dps: float = 45.0,
    body_weight_n: float = 735.0,
) -> SiteSignals:
    """Site k spins about z (k even) or a tilted axis (k odd) at ``rate_dps * (1 + k/10)``.

    Feet alternate contact every second, so insoles have something to detect."""
    n = int(round(seconds * fps))
    t = np.arange(n) / fps
    S = len(sites)
    quat = np.zeros((n, S, 4))
    gyro = np.zeros((n, S, 3))
    sf = np.zeros((n, S, 3))
    for k in range(S):
        axis = np.array([0.0, 0.0, 1.0]) if k % 2 == 0 else np.array([0.3, 0.2, 1.0])
        axis = axis / np.linalg.norm(axis)
        w = np.radians(rate_dps) * (1 + k / 10)
        q = quat_about_axis(axis, w * t)
        quat[:, k] = q
        gyro[:, k] = axis * w  # constant rotation about a fixed axis: same axis in the sensor frame
        sf[:, k] = quat_rotate(quat_conjugate(q), [0.0, 0.0, G])  # the world's up in the sensor frame
    phase = (t % 2.0) < 1.0
    contacts = np.stack([phase, phase, ~phase, ~phase], axis=1)
    force = np.stack([phase, ~phase], axis=1) * body_weight_n
    return SiteSignals(
        fps=fps,
        sites=tuple(sites),
        t=t,
        quat=quat,
        free_acc=np.zeros((n, S, 3)),
        specific_force=sf,
        gyro=gyro,
        contacts=contacts,
        insole_force=force.astype(float),
        meta={"name": "spinning"},
    )
