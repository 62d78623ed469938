"""Stride length from the shank sensors' own accelerations, to scale the root path.

Why: the paper's root correction walks the pelvis by the planted foot's displacement
relative to it, so the stride it produces is whatever the *reconstructed* leg says. The
thigh is never measured by the sensor sets we ship (the knee hinge fixes only its axis),
and its flexion amplitude is the model's prior: with the shanks alone a short-step walker
gets the typical stride (docs/model.md, "Stride scaling": 8-17 % too long on the held-out "sad"
walks; with 6 sites 0-13 % too short).

A shank sensor measures what the root correction lacks. Between two stance phases the
ankle's displacement is the sensor's displacement (strapdown integration of its free
acceleration) plus the change of the sensor-to-ankle lever. In mid-stance the ankle
is still, which fixes the sensor's velocity there (``-omega x lever``: the tibia rolls
over the planted ankle). Pinning the integrated velocity to those values at both ends of
a stride removes any constant acceleration bias exactly (a linear velocity drift). This is
the zero-velocity-update method of foot- and shank-mounted gait analysis, run per stride.

Each completed stride gives the ratio of the inertial stride length to the same ankle's
displacement on the *unscaled* reconstructed path; a running (log-domain) mean of that
ratio (by default just the last stride's) scales the root displacement of the frames
that follow. A stride whose two ends are not at the same height was badly anchored and
is skipped; one with a flight phase is a run, which a 20 Hz stance cannot anchor, and
returns the scale to 1. It is causal: a stride is
known when its second stance ends, so the first stride of a walk is unscaled.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from inference.body.body import Body
from inference.body.rotations import so3_log_np
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX

SHANK_SITES = ("l_shank", "r_shank")
FOOT_SEGMENTS = ("l_foot", "r_foot")
FLIGHT_WINDOW = 20  # frames (1 s at 20 Hz) in which more than max_flight_frames of flight mean running


@dataclass(frozen=True)
class StrideScaleConfig:
    """min_stride_m: strides shorter than this (on either path) say nothing about scale
    (shuffling, turning on the spot). gain: weight of a new stride in the running mean
    (log domain), so ~1/gain strides of memory; 1 = the last stride alone, which did best
    on the training walks: the reconstruction's stride error changes from stride to stride,
    and memory only makes the scale lag it (docs/model.md, "Stride scaling"). limits: a stride ratio
    outside this range is a detection error, not a stride, and is skipped. anchor_at: where
    in a stance run (0 = its first frame, 1 = its last) the zero-velocity anchor sits; stance
    is foot-flat (heel and toe down, ``foot_flat``), and the ankle of a rolling foot is
    stillest in its first half. max_stride_frames: a longer gap between
    anchors (a dropout, standing still on one leg) is not integrated: drift grows with its
    square. max_rise_m: both ends of a stride stand on the ground, so on level ground its
    inertial displacement has no vertical part; one that rises or sinks by more than this
    was anchored where the ankle was not still (a sidestep's roll, a heel already lifting),
    and its length is off too. Stairs fail this test as well: they keep the last scale.
    max_flight_frames: a stride with more frames than this where neither foot touches the
    ground is a run. Its stance is too short to hold the ankle still at 20 Hz (the
    inertial strides of the training runs came out 10-30 % short), and the walking scale
    says nothing about the model's running stride, so the scale returns to 1."""

    min_stride_m: float = 0.2
    gain: float = 1.0
    limits: tuple[float, float] = (0.6, 1.6)
    anchor_at: float = 0.35
    max_stride_frames: int = 60
    max_rise_m: float = 0.05
    max_flight_frames: int = 2


class _Leg:
    """One shank's integration state and a bounded buffer of its recent frames."""

    def __init__(self, maxlen: int) -> None:
        # (velocity integral, R, lever in the world, ankle on the path, neither foot down)
        self.frames: deque[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]] = deque(maxlen=maxlen)
        self.count = 0          # frames pushed since the leg's buffer was (re)started
        self.vint = np.zeros(3)  # running integral of the free acceleration
        self.prev_acc: np.ndarray | None = None
        self.stance_start: int | None = None  # frame count where the current stance began
        self.anchor: int | None = None  # frame count of the pending stride's start

    def restart(self) -> None:
        self.frames.clear()
        self.count = 0
        self.vint = np.zeros(3)
        self.prev_acc = None
        self.stance_start = None
        self.anchor = None


class StrideScale:
    """Running ratio of the shanks' inertial strides to the reconstructed ones.

    ``update`` once per 20 Hz frame with both shanks' orientation and free acceleration
    (world frame, m/s^2, the model's smoothed input), the four heel/toe contacts, and
    each ankle's horizontal position on the unscaled root path. ``scale`` is the factor
    for the root displacement of the next frame.
    """

    def __init__(self, body: Body, fps: float = 20.0, config: StrideScaleConfig | None = None) -> None:
        self.config = config or StrideScaleConfig()
        self.dt = 1.0 / float(fps)
        # lever from each shank sensor to its ankle (the foot segment's origin), shank frame
        self._lever = np.stack([
            np.asarray(body.offsets[SEGMENT_INDEX[f]], dtype=np.float64)
            - np.asarray(body.site_offsets[SITE_INDEX[s]], dtype=np.float64)
            for s, f in zip(SHANK_SITES, FOOT_SEGMENTS)])
        self.reset()

    def reset(self) -> None:
        self.log_scale = 0.0
        self.strides: list[tuple[float, float]] = []  # (inertial, reconstructed) lengths, m
        self._legs = [_Leg(self.config.max_stride_frames + 4) for _ in SHANK_SITES]
        self._flight: deque[bool] = deque(maxlen=FLIGHT_WINDOW)

    @property
    def scale(self) -> float:
        return math.exp(self.log_scale)

    def drop(self, leg: int | None = None) -> None:
        """A shank stopped delivering: its pending stride cannot be integrated."""
        for k in range(len(self._legs)) if leg is None else (leg,):
            self._legs[k].restart()

    def update(self, R: np.ndarray, acc: np.ndarray, contacts: np.ndarray, ankle_xy: np.ndarray) -> float:
        """R: (2, 3, 3) shank orientations R_WB; acc: (2, 3) free acceleration at the
        sensors; contacts: (4,) bool, ``skeleton.CONTACTS`` order (detector, insoles or
        model); ankle_xy: (2, 2) ankles on the unscaled path."""
        contacts = np.asarray(contacts, dtype=bool)
        stance, flight = foot_flat(contacts), not bool(contacts.any())
        # a run with no foot-flat at all (a forefoot runner) completes no stride to test
        self._flight.append(flight)
        if sum(self._flight) > self.config.max_flight_frames:
            self.log_scale = 0.0
        for k, leg in enumerate(self._legs):
            self._push(k, leg, np.asarray(R[k], dtype=np.float64), np.asarray(acc[k], dtype=np.float64),
                       bool(stance[k]), np.asarray(ankle_xy[k], dtype=np.float64), flight)
        return self.scale

    # ------------------------------------------------------------------ internals
    def _push(self, k: int, leg: _Leg, R: np.ndarray, acc: np.ndarray, stance: bool, ankle: np.ndarray,
              flight: bool) -> None:
        if leg.prev_acc is not None:
            leg.vint = leg.vint + 0.5 * (acc + leg.prev_acc) * self.dt
        leg.prev_acc = acc
        leg.frames.append((leg.vint.copy(), R, R @ self._lever[k], ankle, flight))
        n = leg.count
        leg.count += 1
        if stance and leg.stance_start is None:
            leg.stance_start = n
        elif not stance and leg.stance_start is not None:
            self._stance_ended(leg, leg.stance_start, n - 1)
            leg.stance_start = None

    def _stance_ended(self, leg: _Leg, first: int, last: int) -> None:
        """A stance run [first, last] closed: its anchor ends the pending stride and starts
        the next one."""
        anchor = first + int(round(self.config.anchor_at * (last - first)))
        if leg.anchor is not None:
            self._stride(leg, leg.anchor, anchor)
        leg.anchor = anchor

    def _frame(self, leg: _Leg, n: int):
        """Buffered frame with count ``n`` (None if it fell out of the buffer)."""
        i = n - (leg.count - len(leg.frames))
        return leg.frames[i] if 0 <= i < len(leg.frames) else None

    def _still_velocity(self, leg: _Leg, n: int) -> np.ndarray | None:
        """The sensor's velocity when its ankle is still: the tibia turning about it."""
        before, here, after = self._frame(leg, n - 1), self._frame(leg, n), self._frame(leg, n + 1)
        if before is None or here is None or after is None:
            return None
        w = _world_rate(before[1], after[1], 2.0 * self.dt)
        return -np.cross(w, here[2])

    def _stride(self, leg: _Leg, a0: int, a1: int) -> None:
        c = self.config
        if not 0 < a1 - a0 <= c.max_stride_frames:
            return
        v0, v1 = self._still_velocity(leg, a0), self._still_velocity(leg, a1)
        if v0 is None or v1 is None:
            return
        seg = [self._frame(leg, n) for n in range(a0, a1 + 1)]
        if sum(f[4] for f in seg) > c.max_flight_frames:
            self.log_scale = 0.0
            return
        vint = np.stack([f[0] for f in seg])
        # integrated velocity, pinned to the still-ankle values at both ends
        v = vint - vint[0] + v0
        frac = np.linspace(0.0, 1.0, len(seg))[:, None]
        v = v + frac * (v1 - v[-1])
        sensor = 0.5 * (v[1:] + v[:-1]).sum(axis=0) * self.dt
        inertial = sensor + seg[-1][2] - seg[0][2]
        if abs(inertial[2]) > c.max_rise_m:
            return
        L_in = float(np.hypot(inertial[0], inertial[1]))
        L_rec = float(np.hypot(*(seg[-1][3] - seg[0][3])))
        if min(L_in, L_rec) < c.min_stride_m:
            return
        lo, hi = c.limits
        ratio = L_in / L_rec
        if not lo <= ratio <= hi:
            return
        self.strides.append((L_in, L_rec))
        self.log_scale += c.gain * (math.log(ratio) - self.log_scale)


def foot_flat(contacts: np.ndarray) -> np.ndarray:
    """(..., 2) stance per foot, where the strides are anchored, from (..., 4) heel/toe
    contacts (``skeleton.CONTACTS`` order): heel and toe down. Contact runs from heel strike to toe
    off, and the ankle is still only while the foot is flat; anchoring in a union of the
    two put some strides on a rolling foot (docs/model.md, "Stride scaling")."""
    c = np.asarray(contacts, dtype=bool)
    return np.stack([c[..., 0] & c[..., 1], c[..., 2] & c[..., 3]], axis=-1)


def _world_rate(R_before: np.ndarray, R_after: np.ndarray, dt: float) -> np.ndarray:
    """World-frame angular velocity from two orientations ``dt`` apart."""
    return so3_log_np((R_after @ R_before.T)[None])[0] / dt


__all__ = ["StrideScale", "StrideScaleConfig", "SHANK_SITES", "foot_flat"]
