"""Calibration during a live session: collect the two still windows from the stream.

A live stream has no "array of the still window"; the app knows when the user was asked
to lay the sensors down or to hold the T-pose (a button, a voice prompt, or a fixed
schedule as in the simulated demo). ``Calibrator`` collects 60 Hz frames between those
times and runs ``calibrate_world`` / ``calibrate_tpose`` on them, so the same checked
code paths serve offline tests and the live app.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .core import Calibration, CalibrationError, StillnessLimits, calibrate_tpose, calibrate_world


@dataclass
class CalibrationSchedule:
    """When the two windows are, in seconds after the stream's origin (the first frame
    unless given): sensors on the table from ``world_start`` for ``world_seconds``, the
    T-pose from ``tpose_start`` for ``tpose_seconds``."""

    world_start: float
    world_seconds: float
    tpose_start: float
    tpose_seconds: float

    @property
    def end(self) -> float:
        return self.tpose_start + self.tpose_seconds


class Calibrator:
    """Collects frames for the sensor-to-world window, then the T-pose window.

    Phases: ``idle`` -> ``world`` -> ``wait_tpose`` -> ``tpose`` -> ``done`` (or
    ``failed``, with ``error`` holding the message). ``start_world`` /
    ``start_tpose`` begin a window at a time (session clock) or, with a ``schedule``,
    the windows open by themselves. ``push`` takes one hub frame's per-site arrays.
    """

    def __init__(
        self,
        sites: Sequence[str],
        seconds: float = 3.0,
        schedule: CalibrationSchedule | None = None,
        R_known: np.ndarray | None = None,
        limits: StillnessLimits | None = None,
        origin: float | None = None,
    ) -> None:
        self.sites = tuple(sites)
        self.seconds = seconds
        self.schedule = schedule
        self.R_known = R_known
        self.limits = limits or StillnessLimits()
        self.origin = origin
        self.reset(origin)

    def reset(self, origin: float | None = None) -> None:
        """Start over (recalibration); ``origin`` re-anchors a schedule."""
        self.phase = "idle"
        self.origin = origin
        self.error: str | None = None
        self.calibration: Calibration | None = None
        self._win: tuple[float, float] | None = None
        self._rows: list[tuple[np.ndarray, ...]] = []
        self._world: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def start_world(self, t: float, seconds: float | None = None) -> None:
        self.phase, self._win, self._rows = "world", (t, t + (seconds or self.seconds)), []

    def start_tpose(self, t: float, seconds: float | None = None) -> None:
        if self._world is None:
            raise CalibrationError("the T-pose step needs the sensor-to-world step first")
        self.phase, self._win, self._rows = "tpose", (t, t + (seconds or self.seconds)), []

    def status(self) -> str:
        """One line for a user."""
        return {
            "idle": "calibration: waiting",
            "world": "calibration: sensors on the table, do not touch",
            "wait_tpose": "calibration: strap the sensors on, then T-pose",
            "tpose": "calibration: hold the T-pose still",
            "done": "calibrated",
            "failed": f"calibration failed: {self.error}",
        }[self.phase]

    def push(
        self,
        t: float,
        quat: np.ndarray,
        free_acc: np.ndarray | None = None,
        acc: np.ndarray | None = None,
        gyro: np.ndarray | None = None,
        present: np.ndarray | None = None,
    ) -> Calibration | None:
        """Feed one frame (arrays over ``sites``); returns the Calibration when it completes."""
        if self.phase in ("done", "failed"):
            return None
        if self.origin is None:
            self.origin = t
        sch = self.schedule
        if sch is not None:
            rel = t - self.origin
            if self.phase == "idle" and rel >= sch.world_start:
                self.start_world(self.origin + sch.world_start, sch.world_seconds)
            elif self.phase == "wait_tpose" and rel >= sch.tpose_start:
                self.start_tpose(self.origin + sch.tpose_start, sch.tpose_seconds)
        if self._win is None or self.phase not in ("world", "tpose"):
            return None
        S = len(self.sites)
        nan3 = np.full((S, 3), np.nan)
        if t >= self._win[0]:
            self._rows.append((
                np.asarray(quat, float), nan3 if free_acc is None else np.asarray(free_acc, float),
                nan3 if acc is None else np.asarray(acc, float), nan3 if gyro is None else np.asarray(gyro, float),
                np.all(np.isfinite(quat), -1) if present is None else np.asarray(present, bool),
            ))
        if t + 1e-9 < self._win[1]:
            return None
        return self._finish()

    def _finish(self) -> Calibration | None:
        q, fa, a, g, p = (np.stack(c) for c in zip(*self._rows)) if self._rows else (None,) * 5
        self._rows = []
        try:
            if q is None:
                raise CalibrationError(f"{self.phase} window received no frames")
            gyro = g if np.isfinite(g).any() else None
            if self.phase == "world":
                self._world = calibrate_world(self.sites, q, fa, a, gyro, p, R_known=self.R_known, limits=self.limits)
                self.phase = "wait_tpose"
                self._win = None
                return None
            R_WG, off, v1, r1 = self._world  # type: ignore[misc]
            R_SB, v2, r2 = calibrate_tpose(self.sites, q, R_WG, fa, a, gyro, p, limits=self.limits)
        except CalibrationError as exc:
            self.phase, self.error = "failed", str(exc)
            return None
        self.calibration = Calibration(
            sites=self.sites, R_WG=R_WG, R_SB=R_SB, acc_offset=off, valid=v1 & v2,
            R_known=np.eye(3) if self.R_known is None else self.R_known,
            residual_world_deg=r1, residual_tpose_deg=r2,
        )
        self.phase = "done"
        return self.calibration
