"""Calibration as a sequence of guided steps, driven by the stream itself.

A person calibrating a patient cannot watch a clock: each step says what to do, counts
down, and then waits for the body to be still (or to move, for the walk), with a timeout
and a message that names the sensor that kept moving. The same state machine is fed
frames by the terminal capture, the window and the tests, so all three see one
behaviour; it keeps the ``Calibrator`` interface (``push`` returns the Calibration when
the last step completes), so the pipeline takes either.

Protocols:
- ``walk`` (no table; sensors need not share a heading reference): ``npose`` still,
  ``walk`` a few steps forward until still again, ``stand`` still (``calibration.walk``).
- ``table`` (sensors that share one heading reference, or a table to lay them on):
  ``table`` still with every sensor in the reference orientation, ``strap`` (waits for the
  sensors to be picked up), ``tpose`` still (``calibration.core``).

Stillness live: each sensor's angular speed from consecutive orientations, smoothed over
~0.2 s; a still step starts holding when every sensor is below ``still_dps`` and restarts
when one exceeds ``moved_dps``. The window found is then checked by the same stillness
measures as offline calibration.

A still step holds on data, not on the clock: it starts holding only once every sensor
streams (none silent for more than ``gap_s``, 0.5 s), counts only frames that carry data
(a reader or a whole process stalled on a busy machine leaves frames with none), and ends
once it has held ``seconds`` with every sensor in enough of those frames for the calibration
(``StillnessLimits.min_fraction``: a flaky wireless link holds longer; after twice the
step's time the calibration's own check decides). A hold that counted the clock took frames
without samples, and a sensor silent for half the N-pose came out uncalibrated, or every
sensor, with "no data". A sensor never heard from is waited for ``wait_all_s`` at the first
still step and then left out, as before (the quality report names it).

A walk also shows in the acceleration: a trunk sensor turns at 20-40 deg/s in a normal walk,
under ``move_dps``, but its free acceleration swings by ~2 m/s^2 (spread over the last 0.5 s).
A move step starts, and goes on, when either measure says walking (``move_acc``), so a setup
of the pelvis alone, or the pelvis and the head, is walked through like any other.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from inference.body.rotations import matrix_angle_between, quat_to_matrix

from .core import Calibration, CalibrationError, StillnessLimits, calibrate_tpose, calibrate_world
from .quality import QualityReport, assess, max_rotation
from .walk import WalkWindows, calibrate_walk


@dataclass(frozen=True)
class Step:
    name: str
    kind: str  # "still": hold still for `seconds`; "move": wait for motion, then stillness
    prompt: str
    seconds: float  # still: how long to hold; move: how long the stillness that ends it lasts
    pose: str  # picture the window shows: npose, tpose, table, walk, strap


PROTOCOLS: dict[str, tuple[Step, ...]] = {
    "walk": (
        Step("npose", "still", "Stand upright, arms relaxed by the side, look ahead; hold still", 3.0, "npose"),
        Step("walk", "move", "Walk 4-6 steps straight ahead at a normal pace, then stop and stand still", 1.0,
             "walk"),
        Step("stand", "still", "Stand still, arms by the side", 1.5, "npose"),
    ),
    "table": (
        Step("table", "still", "Lay every sensor on the table: x forward, y left, z up; do not touch", 3.0,
             "table"),
        Step("strap", "move", "Strap the sensors on, then stand in the T-pose and hold it", 1.0, "strap"),
        Step("tpose", "still", "Hold the T-pose: arms level, palms down; hold still", 3.0, "tpose"),
    ),
}
PROTOCOL_NAMES = tuple(PROTOCOLS)


@dataclass
class GuidedFeedback:
    """What a screen shows now: the step, its prompt, the countdown or hold progress, and
    each sensor's angular speed (deg/s) with the ones that move too much."""

    step: str
    step_index: int
    steps: int
    phase: str
    prompt: str
    countdown: float | None = None
    held: float = 0.0
    need: float = 0.0
    speeds: dict[str, float] = field(default_factory=dict)
    moving: list[str] = field(default_factory=list)
    message: str = ""


class GuidedCalibration:
    """The state machine. Phases: ``countdown`` -> (still step) ``waiting_still`` ->
    ``holding`` -> next step, or (move step) ``waiting_move`` -> ``moving`` ->
    ``settling`` -> next step; at the end ``done`` (``report`` holds the quality report)
    or ``failed`` (``error`` says why and what to do; ``redo`` starts a step again)."""

    def __init__(self, sites: Sequence[str], protocol: str = "walk", countdown: float = 3.0, timeout: float = 20.0,
                 still_dps: float = 20.0, moved_dps: float = 35.0, move_dps: float = 45.0, move_acc: float = 1.0,
                 limits: StillnessLimits | None = None, fps: float = 60.0, origin: float | None = None,
                 gap_s: float = 0.5, wait_all_s: float = 3.0) -> None:
        if protocol not in PROTOCOLS:
            raise ValueError(f"unknown calibration protocol {protocol!r}; choose {' or '.join(PROTOCOLS)}")
        self.sites = tuple(sites)
        self.protocol = protocol
        self.steps = PROTOCOLS[protocol]
        self.countdown_s = countdown
        self.timeout = timeout
        self.still_dps, self.moved_dps, self.move_dps = still_dps, moved_dps, move_dps
        self.move_acc = move_acc  # m/s^2: free-acceleration spread (0.5 s) that reads as walking
        self.limits = limits or StillnessLimits()
        self.fps = fps
        self.gap_s = gap_s  # s of silence from a sensor that streamed before a still hold may start
        self.wait_all_s = wait_all_s  # s the first still step waits for a sensor never heard from
        self.reset(origin)

    # ------------------------------------------------------------------ state
    def reset(self, origin: float | None = None) -> None:
        self.origin = origin
        self.calibration: Calibration | None = None
        self.report: QualityReport | None = None
        self.error: str | None = None
        self.message = ""
        self._frames: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []
        self._data: dict[str, tuple[np.ndarray, ...]] = {}  # per completed step: quat, free_acc, acc, gyro, present
        self._t_last: float | None = origin
        self._recent: list[tuple[float, np.ndarray]] = []
        self._acc_recent: list[tuple[float, np.ndarray]] = []
        self._acc_spread = np.full(len(self.sites), np.nan)
        self._speed = np.zeros(len(self.sites))
        self._last_seen = np.full(len(self.sites), -np.inf)  # stream time each sensor last sent
        self._waited_from: float | None = None  # when the first still step began waiting for data
        self._enter(0, origin)

    def _enter(self, index: int, t: float | None, countdown: bool = True) -> None:
        """Begin step ``index``. Only the first step (and a redone one) counts down: the
        steps after it follow on, as the subject is already in place and a move step must
        not miss the first stride."""
        self.index = index
        self._frames = []  # a step keeps only its own frames: memory stays bounded on a long wait
        self.phase = "countdown" if countdown and self.countdown_s > 0 else self._first_phase()
        self._phase_t = t
        self._step_t = t
        self._begin_hold(None, t)
        self._move_from: int | None = None
        self._restarts = 0
        self._unsteady = np.zeros(len(self.sites))  # frames each sensor was above still_dps in this step

    def _begin_hold(self, index: int | None, t: float | None) -> None:
        """A still hold from frame ``index`` (None: none yet): the time it has held with data
        and, over its frames with data, in how many each sensor is present."""
        self._hold_from = index
        self._held, self._held_t = 0.0, t
        self._hold_frames, self._hold_present = 0, np.zeros(len(self.sites))

    def _first_phase(self) -> str:
        return "waiting_still" if self.step.kind == "still" else "waiting_move"

    @property
    def step(self) -> Step:
        return self.steps[min(self.index, len(self.steps) - 1)]

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def redo(self, step: str, t: float | None = None) -> None:
        """Start again at ``step`` (the steps before it keep what they measured; a later
        step that depends on this one is redone too)."""
        names = [s.name for s in self.steps]
        if step not in names:
            raise ValueError(f"no step {step!r} in the {self.protocol} protocol ({', '.join(names)})")
        k = names.index(step)
        for s in names[k:]:
            self._data.pop(s, None)
        self.calibration, self.report, self.error = None, None, None
        self._enter(k, t if t is not None else self._t_last)

    def status(self) -> str:
        """One line for a terminal."""
        if self.phase == "done":
            return "calibrated"
        if self.phase == "failed":
            return f"calibration failed: {self.error}"
        f = self.feedback()
        head = f"calibration {f.step_index + 1}/{f.steps} {f.step}: {f.prompt}"
        if f.phase == "countdown" and f.countdown is not None:
            return f"{head} -- starting in {f.countdown:.0f} s"
        if f.phase == "holding":
            return f"{head} -- holding {f.held:.1f}/{f.need:.1f} s"
        if f.moving:
            return f"{head} -- moving: {', '.join(f.moving)}"
        return f"{head} -- {f.phase.replace('_', ' ')}"

    def feedback(self) -> GuidedFeedback:
        t = self._t_last
        cd = None
        if self.phase == "countdown" and t is not None and self._phase_t is not None:
            cd = max(self.countdown_s - (t - self._phase_t), 0.0)
        held = 0.0
        if self.phase == "holding":
            held = self._held
        elif self.phase == "settling" and self._hold_from is not None and self._frames:
            held = self._frames[-1][0] - self._frames[self._hold_from][0]
        speeds = {s: round(float(v), 1) for s, v in zip(self.sites, self._speed)}
        moving = [s for s, v in speeds.items() if v > self.moved_dps]
        return GuidedFeedback(self.step.name, self.index, len(self.steps), self.phase, self.step.prompt, cd, held,
                              self.step.seconds, speeds, moving, self.message)

    # ------------------------------------------------------------------ frames
    def push(self, t: float, quat: np.ndarray, free_acc: np.ndarray | None = None, acc: np.ndarray | None = None,
             gyro: np.ndarray | None = None, present: np.ndarray | None = None) -> Calibration | None:
        """One 60 Hz frame (arrays over ``sites``); returns the Calibration when the last
        step completes."""
        if self.phase in ("done", "failed"):
            return None
        S = len(self.sites)
        quat = np.asarray(quat, float)
        nan3 = np.full((S, 3), np.nan)
        ok = np.all(np.isfinite(quat), -1) if present is None else np.asarray(present, bool) & np.all(
            np.isfinite(quat), -1)
        self._frames.append((t, quat, nan3 if free_acc is None else np.asarray(free_acc, float),
                             nan3 if acc is None else np.asarray(acc, float),
                             nan3 if gyro is None else np.asarray(gyro, float), ok))
        self._last_seen[ok] = t
        self._update_speed(t, quat, ok)
        self._update_acc_spread(t, self._frames[-1][2], ok)
        self._t_last = t
        if self._phase_t is None:
            self._phase_t = self._step_t = t
        return self._advance(t)

    def _update_speed(self, t: float, quat: np.ndarray, ok: np.ndarray) -> None:
        """Angular speed over the last ~0.2 s, from the orientation then and now, over the
        time that really passed (a busy hub skips frames): frame to frame, an orientation
        noise of 0.3 deg alone reads as ~25 deg/s at 60 Hz."""
        self._recent.append((t, np.where(ok[:, None], quat, np.nan)))
        while len(self._recent) > 2 and t - self._recent[1][0] >= 0.2:
            self._recent.pop(0)
        t_old, old = self._recent[0]
        both = np.all(np.isfinite(old), -1) & np.all(np.isfinite(self._recent[-1][1]), -1)
        dt = t - t_old
        if dt <= 0 or not both.any():
            return
        ang = np.rad2deg(matrix_angle_between(quat_to_matrix(self._recent[-1][1][both]), quat_to_matrix(old[both])))
        self._speed[both] = ang / dt

    def _update_acc_spread(self, t: float, free_acc: np.ndarray, ok: np.ndarray) -> None:
        """Per sensor, the spread of the free acceleration over the last 0.5 s (root of the
        summed per-axis variances; NaN for a sensor that gives none): a bias does not count,
        a gait's swing does."""
        self._acc_recent.append((t, np.where(ok[:, None], free_acc, np.nan)))
        while len(self._acc_recent) > 2 and t - self._acc_recent[0][0] > 0.5:
            self._acc_recent.pop(0)
        if len(self._acc_recent) < 5:
            return
        a = np.stack([x for _, x in self._acc_recent])  # (n, S, 3)
        seen = np.isfinite(a).all(-1).sum(0) >= 5
        with np.errstate(invalid="ignore"):
            spread = np.sqrt(np.nansum(np.nanvar(a[:, seen], axis=0), axis=-1)) if seen.any() else np.zeros(0)
        self._acc_spread[:] = np.nan
        self._acc_spread[seen] = spread

    def _walking(self) -> np.ndarray:
        """(S,) sensors whose acceleration says the body is walking."""
        with np.errstate(invalid="ignore"):
            return np.nan_to_num(self._acc_spread, nan=0.0) > self.move_acc

    def _advance(self, t: float) -> Calibration | None:
        step = self.step
        i = len(self._frames) - 1
        if self.phase == "countdown":
            if t - self._phase_t >= self.countdown_s:
                self.phase, self._phase_t, self._step_t = self._first_phase(), t, t
            return None
        if t - self._step_t > self.timeout and self.phase in ("waiting_still", "waiting_move", "holding", "moving"):
            return self._fail(self._timeout_message(step))
        fast = self._speed > self.moved_dps
        silent = self._silent(t) if step.kind == "still" else np.zeros(len(self.sites), bool)
        if self.phase in ("waiting_still", "holding"):
            self._unsteady += self._speed >= self.still_dps
        if self.phase == "waiting_still":
            if silent.any():
                self.message = f"waiting for data from {', '.join(np.array(self.sites)[silent])}"
            elif np.all(self._speed < self.still_dps):
                self.phase = "holding"
                self._begin_hold(i, t)
                if self.message.startswith("waiting for data"):
                    self.message = ""
        elif self.phase == "holding":
            if fast.any():
                self._restarts += 1
                self.message = f"{', '.join(np.array(self.sites)[fast])} moved: hold still"
                self.phase, self._hold_from = "waiting_still", None
                return None
            ok = self._frames[-1][5]
            if ok.any():  # a frame with data: it counts; one with none (every sensor silent) does not
                self._held += min(t - self._held_t, 0.1)
                self._hold_frames += 1
                self._hold_present += ok
            self._held_t = t
            heard = np.isfinite(self._last_seen)
            short = heard & (self._hold_present < self.limits.min_fraction * max(self._hold_frames, 1))
            self.message = (f"waiting for data from {', '.join(np.array(self.sites)[short | silent])}"
                            if (short | silent).any() else "")
            elapsed = t - self._frames[self._hold_from][0]
            # held long enough with data, and every sensor in enough of it; a sensor that stays short is
            # left to the calibration's own check after twice the step (used if in half, else left out)
            if self._held >= step.seconds and (not short.any() or elapsed >= 2 * step.seconds):
                self._data[step.name] = self._arrays(self._hold_from, i + 1, drop_empty=True)
                self.message = ""
                return self._next(t)
        elif self.phase == "waiting_move":
            if np.median(self._speed) > self.move_dps or self._walking().any():
                # the window starts half a second before: still, so the velocity starts at zero
                self.phase, self._move_from = "moving", max(i - int(0.5 * self.fps), 0)
        elif self.phase == "moving":
            if np.all(self._speed < self.still_dps) and not self._walking().any():
                self.phase, self._hold_from = "settling", i
        elif self.phase == "settling":
            if fast.any() or self._walking().any():
                self.phase, self._hold_from = "moving", None
            elif t - self._frames[self._hold_from][0] >= step.seconds:
                self._data[step.name] = self._arrays(self._move_from, i + 1)
                return self._next(t)
        return None

    def _silent(self, t: float) -> np.ndarray:
        """(S,) the sensors a still step waits for: one that streamed and has sent nothing for
        ``gap_s``, and, for ``wait_all_s`` from the first still step's start, one not heard
        from yet (after that it is left out, in every step). With no sensor heard from at
        all, every one."""
        if self._waited_from is None:
            self._waited_from = t
        heard = np.isfinite(self._last_seen)
        if not heard.any():
            return np.ones(len(self.sites), bool)
        quiet = heard & (t - self._last_seen > self.gap_s)
        if t - self._waited_from < self.wait_all_s:
            quiet |= ~heard
        return quiet

    def _timeout_message(self, step: Step) -> str:
        if step.kind == "move" and self.phase == "waiting_move":
            return (f"{step.name}: no movement in {self.timeout:.0f} s; {step.prompt.lower()} "
                    f"(redo '{step.name}')")
        if step.kind == "move":
            return f"{step.name}: the subject did not stand still again within {self.timeout:.0f} s"
        silent = self._silent(self._t_last if self._t_last is not None else 0.0)
        if silent.any():
            who = ", ".join(np.array(self.sites)[silent])
            return (f"{step.name}: no data from {who} for more than {self.gap_s:g} s at a time; check that it is "
                    f"switched on and in range, and redo '{step.name}'")
        # the sensors that kept the step from holding: most often above the still limit
        share = self._unsteady / max(self._unsteady.max(), 1.0)
        worst = [k for k in np.argsort(-self._unsteady)[:3] if self._unsteady[k] > 0 and share[k] > 0.5]
        who = ", ".join(f"{self.sites[k]} {self._speed[k]:.0f} deg/s" for k in worst) or "small movements"
        return (f"{step.name}: never still for {step.seconds:g} s in {self.timeout:.0f} s (moving: {who}); "
                f"hold still, or check that strap, and redo '{step.name}'")

    def _fail(self, message: str) -> None:
        self.phase, self.error = "failed", message
        return None

    def _next(self, t: float) -> Calibration | None:
        if self.index + 1 < len(self.steps):
            self._enter(self.index + 1, t, countdown=False)
            return None
        try:
            cal = self._calibrate()
        except CalibrationError as exc:
            return self._fail(str(exc))
        self.phase, self.calibration = "done", cal
        return cal

    # ------------------------------------------------------------------ the maths
    def _arrays(self, a: int, b: int, drop_empty: bool = False) -> tuple[np.ndarray, ...]:
        """The frames a..b of the step; ``drop_empty``: without the frames in which no
        sensor sent (a still window's gaps, which carry nothing and would count against
        every sensor's share of the window)."""
        rows = self._frames[a:b]
        if drop_empty:
            rows = [r for r in rows if r[5].any()] or rows
        return tuple(np.stack([r[k] for r in rows]) for k in range(1, 6))

    def _calibrate(self) -> Calibration:
        def opt(x: np.ndarray) -> np.ndarray | None:
            return x if np.isfinite(x).any() else None

        def seen(q: np.ndarray, p: np.ndarray) -> np.ndarray:
            return np.where(p[..., None], q, np.nan)

        if self.protocol == "walk":
            parts = [self._data[k] for k in ("npose", "walk", "stand")]
            n = [len(x[0]) for x in parts]
            q, fa, ac, g, p = (np.concatenate([x[k] for x in parts]) for k in range(5))
            win = WalkWindows((0, n[0]), (n[0], n[0] + n[1]), (n[0] + n[1], sum(n)))
            cal, res = calibrate_walk(self.sites, q, win, opt(fa), opt(ac), opt(g), p, self.fps, self.limits)
            still = {"N-pose": max_rotation(seen(parts[0][0], parts[0][4])),
                     "stand": max_rotation(seen(parts[2][0], parts[2][4]))}
            walk = {"quat": seen(parts[1][0], parts[1][4]), "fps": self.fps, "spread_deg": res.spread_deg,
                    "path_m": res.path_m}
            report = assess(cal, "walk", still, walk, self.limits)
        else:
            q, fa, ac, g, p = self._data["table"]
            R_WG, off, v1, r1 = calibrate_world(self.sites, q, opt(fa), opt(ac), opt(g), p, limits=self.limits)
            q2, fa2, ac2, g2, p2 = self._data["tpose"]
            R_SB, v2, r2 = calibrate_tpose(self.sites, q2, R_WG, opt(fa2), opt(ac2), opt(g2), p2, limits=self.limits)
            cal = Calibration(sites=self.sites, R_WG=R_WG, R_SB=R_SB, acc_offset=off, valid=v1 & v2,
                              residual_world_deg=r1, residual_tpose_deg=r2)
            report = assess(cal, "table", {"table": max_rotation(seen(q, p)), "T-pose": max_rotation(seen(q2, p2))},
                            None, self.limits)
        cal.meta["protocol"] = self.protocol
        cal.meta["quality"] = report.to_dict()
        self.report = report
        return cal
