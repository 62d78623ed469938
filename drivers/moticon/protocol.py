"""Moticon OpenGo insole UDP stream, pure functions.

The OpenGo software streams one UDP datagram per sample: ASCII floats separated
by spaces. Which channels it sends is chosen in the software; this module fixes
the layout imucap asks for (``LAYOUT``): time, then for the left and then the
right insole: acceleration (3, g), angular rate (3, deg/s), centre of pressure
(2, insole-normalised, x medial-lateral, y posterior(-)->anterior(+)),
16 pressures (N/cm^2), total force (N).

The contact detector is here too because it is a pure function of that stream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

N_PRESSURE = 16
PER_FOOT = 3 + 3 + 2 + N_PRESSURE + 1
N_FIELDS = 1 + 2 * PER_FOOT
LAYOUT = ("time",) + tuple(
    f"{side}_{name}"
    for side in ("left", "right")
    for name in (
        "acc_x",
        "acc_y",
        "acc_z",
        "gyro_x",
        "gyro_y",
        "gyro_z",
        "cop_x",
        "cop_y",
        *(f"p{k}" for k in range(N_PRESSURE)),
        "total_force",
    )
)


class MoticonError(ValueError):
    pass


@dataclass(slots=True)
class InsoleFrame:
    """Arrays are (2, ...) for (left, right)."""

    time: float
    acc_g: np.ndarray  # (2, 3)
    gyro_dps: np.ndarray  # (2, 3)
    cop: np.ndarray  # (2, 2)
    pressure: np.ndarray  # (2, 16)
    total_force: np.ndarray  # (2,)


def encode(f: InsoleFrame, decimals: int = 4) -> bytes:
    vals = [f.time]
    for k in range(2):
        vals += [*f.acc_g[k], *f.gyro_dps[k], *f.cop[k], *f.pressure[k], f.total_force[k]]
    return " ".join(f"{float(v):.{decimals}f}" for v in vals).encode("ascii")


def decode(datagram: bytes) -> InsoleFrame:
    try:
        text = datagram.decode("ascii")
        vals = [float(x) for x in text.split()]
    except (UnicodeDecodeError, ValueError) as exc:
        raise MoticonError(f"not an ASCII float record: {exc}") from exc
    if len(vals) != N_FIELDS:
        raise MoticonError(f"{len(vals)} fields, layout has {N_FIELDS}")
    if not all(math.isfinite(v) for v in vals):
        raise MoticonError("non-finite value")
    a = np.asarray(vals[1:], dtype=float).reshape(2, PER_FOOT)
    return InsoleFrame(vals[0], a[:, 0:3], a[:, 3:6], a[:, 6:8], a[:, 8 : 8 + N_PRESSURE], a[:, -1])


class ContactDetector:
    """Foot contact from total force: on above ``on_frac`` of body weight, off below
    ``off_frac`` (hysteresis, so noise near the threshold does not chatter), and a
    change only counts once it has lasted ``min_duration`` seconds (a bump is not a
    step). Heel and toe are split by the centre of pressure: a foot in contact has
    its heel loaded when COP y < ``split``, its toe when COP y > -``split``.
    """

    def __init__(
        self,
        body_weight_n: float,
        on_frac: float = 0.05,
        off_frac: float = 0.03,
        min_duration: float = 0.03,
        split: float = 0.15,
    ) -> None:
        self.on_n = on_frac * body_weight_n
        self.off_n = off_frac * body_weight_n
        self.min_duration = min_duration
        self.split = split
        self.state = [False, False]
        self._pending_since: list[float | None] = [None, None]

    def update(self, t: float, force: np.ndarray, cop: np.ndarray) -> np.ndarray:
        """Returns (l_heel, l_toe, r_heel, r_toe) as bools."""
        out = np.zeros(4, dtype=bool)
        for k in range(2):
            f = float(force[k])
            want = f > self.on_n if not self.state[k] else f >= self.off_n
            if want != self.state[k]:
                if self._pending_since[k] is None:
                    self._pending_since[k] = t
                if t - self._pending_since[k] >= self.min_duration:  # type: ignore[operator]
                    self.state[k] = want
                    self._pending_since[k] = None
            else:
                self._pending_since[k] = None
            if self.state[k]:
                y = float(cop[k][1])
                out[2 * k] = y < self.split
                out[2 * k + 1] = y > -self.split
        return out
