"""Motion features played backwards, to teach the pelvis odometry walking backwards
(``OdometryTraining.reverse_walks``: the backward net of ``pelvis_odometry.TwoWayOdometry``).

Why: a pelvis sensor tells a forward walk from a backward one only by the order of events
within a stride (accelerations are the same played either way), and the training data has
few backward walks (one take per Bandai style, against hundreds of forward walks). Trained
without a style, the odometry walked that style's backward walk in place (proud: 0.26 of
6.52 m; docs/model.md, "Pelvis odometry").

Backward walking is close to forward walking played backwards: the joint-angle patterns of
the leg in backward gait are roughly the time reversal of those of forward gait (Thorstensson
1986; Winter, Pluck and Yang 1989). Played backwards, a forward walk is a plausible backward
walk with its path traced the other way, and the training split holds hundreds of them.
Features of a clip played backwards are exact: orientations, contacts and height are per
frame; the synthesized accelerations (a second difference, then a centred moving average) are
the same numbers for the reversed positions; only the root step changes sign and moves by one
frame. Runs, hops and everything else stay as they are: played backwards a flight phase
takes off where it landed, and reversing every clip scored worse on clips held out of the
training split than reversing the walks alone.

What it buys and costs (docs/model.md, "Pelvis odometry"): a held-out style's backward walk goes
backward (proud: 5.1 of 6.5 m instead of 0.3), and clips held out of the training split
score RE5 0.14 instead of 0.25 m; but forward walks come out ~10 % less accurate (the sad
walks' RE10 0.75 -> 0.89 m over four seeds) and on the real x-IMU3 log in-place knee raises
drift backwards. So a net trained this way answers only while it says the subject walks
backwards, and a net trained without it answers otherwise (``TwoWayOdometry``).
"""

from __future__ import annotations

import numpy as np

from inference.features.layout import SL_CONTACT, SL_DP
from inference.signals.resample import FPS_MODEL


def reverse_features(x: np.ndarray) -> np.ndarray:
    """(T, 190) features -> the same motion played backwards: every per-frame feature in
    reverse order; the root step of frame i is minus the true step into frame T - i (the
    first frame steps 0, as a clip's first frame does)."""
    x = np.asarray(x)
    r = x[::-1].copy()
    dp = np.zeros_like(x[:, SL_DP])
    dp[1:] = -x[:0:-1, SL_DP]
    r[:, SL_DP] = dp
    return r


def is_forward_walk(x: np.ndarray, heading_steps: np.ndarray, min_forward: float = 0.9,
                    speed_m_s: tuple[float, float] = (0.5, 1.8), max_flight: float = 0.05,
                    fps: float = FPS_MODEL) -> bool:
    """Whether a clip walks forward: at least ``min_forward`` of its path in the direction
    the pelvis faces (``heading_steps``: (T, 2) root steps in the frame facing the pelvis),
    at a walking pace, with no more than ``max_flight`` of its frames off the ground (runs
    and hops have a flight phase; walks do not)."""
    path = float(np.linalg.norm(heading_steps, axis=1).sum())
    speed = path / (len(heading_steps) / fps)
    flight = float((np.asarray(x)[:, SL_CONTACT] < 0.5).all(axis=1).mean())
    return (path > 0 and float(heading_steps[:, 0].sum()) >= min_forward * path
            and speed_m_s[0] <= speed <= speed_m_s[1] and flight <= max_flight)
