"""Sensor-to-world and sensor-to-bone calibration, as the live demos of TransPose, PIP
and TIP do it (papers/diffusionposer.md, "Calibration").

Frames (DESIGN.md): W is our world (Z up, X = the subject's forward at calibration
time); G is one sensor's own reference frame (Z up by gravity, heading arbitrary: magnetic
north for a 9-axis sensor, wherever it started for a 6-axis one); S is the sensor's body
frame; B the bone (segment) frame. A device reports R_GS (its quaternion) and its free
acceleration a_G in G (gravity removed), or only the specific force f_S in S.

1. Sensor-to-world: every sensor lies in one known orientation R_WS = R_known (on a
   table, x forward, y left, z up) and still for ~3 s. Then R_WG = R_known R_GS^T per
   sensor, and the mean world acceleration over that window is an offset (bias, gravity
   leak) subtracted from then on.
2. Sensor-to-bone: strapped on, the subject holds the T-pose, where every bone has its
   rest orientation R_WB_rest (identity: ``inference.body.tpose``); R_SB = (R_WG R_GS)^T
   R_WB_rest, from the mean sensor orientation over the still window.
3. Live: R_WB = R_WG R_GS R_SB and a_W = R_WG a_G - offset.

Why two steps: one known pose gives only the product R_WG R_GS R_SB; the heading of a
sensor's reference frame and the yaw of its strap cannot be told apart, and both must be
known because accelerations need R_WG alone.

Stillness is checked on every window (spread of the orientation about its mean, spread
of the acceleration, gyro rate when the device reports it): a subject who moved gets a
``CalibrationError`` naming the sites and by how much, not a silently skewed body.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from inference.body.body import tpose
from inference.body.rotations import matrix_angle_between, matrix_to_quat, quat_to_matrix
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX, parse_sites

GRAVITY = np.array([0.0, 0.0, -9.81])
FORMAT = "imucap-calibration"
VERSION = 1


class CalibrationError(ValueError):
    """Calibration could not be done from the data given (the subject moved, a sensor sent
    nothing); the message says which sites and what to do."""


@dataclass
class StillnessLimits:
    """What counts as still. Defaults sit well above a good sensor's noise (orientation
    noise ~0.3 deg, acceleration noise ~0.05 m/s^2, gyro ~0.6 deg/s) and well below a
    fidget: a 5 deg wobble of a wrist is already a visibly wrong calibration.

    max_rotation_deg: largest angle of any sample from the window's mean orientation.
    max_acc_std: RMS (over axes) standard deviation of the acceleration, m/s^2.
    max_gyro_deg_s: RMS angular rate about the window's mean rate (the mean removes the
        gyro bias), deg/s; only checked when the device reports its gyro.
    min_fraction: fraction of the window's frames a site must be present in.
    """

    max_rotation_deg: float = 5.0
    max_acc_std: float = 0.6
    max_gyro_deg_s: float = 15.0
    min_fraction: float = 0.5


@dataclass
class Stillness:
    """Per-site measures of one window (arrays over the sites)."""

    sites: tuple[str, ...]
    rotation_deg: np.ndarray
    acc_std: np.ndarray
    gyro_deg_s: np.ndarray
    present: np.ndarray  # fraction of frames present
    still: np.ndarray

    def problems(self, limits: StillnessLimits) -> list[str]:
        out = []
        for k, s in enumerate(self.sites):
            if self.present[k] < limits.min_fraction:
                out.append(f"{s}: present in only {100 * self.present[k]:.0f}% of the window")
                continue
            why = []
            if self.rotation_deg[k] > limits.max_rotation_deg:
                why.append(f"rotated {self.rotation_deg[k]:.1f} deg (limit {limits.max_rotation_deg:g})")
            if self.acc_std[k] > limits.max_acc_std:
                why.append(f"acceleration std {self.acc_std[k]:.2f} m/s^2 (limit {limits.max_acc_std:g})")
            if self.gyro_deg_s[k] > limits.max_gyro_deg_s:
                why.append(f"gyro {self.gyro_deg_s[k]:.1f} deg/s (limit {limits.max_gyro_deg_s:g})")
            if why:
                out.append(f"{s}: " + ", ".join(why))
        return out


def mean_rotation(R: np.ndarray, axis: int = 0) -> np.ndarray:
    """Chordal L2 mean of rotation matrices along ``axis`` (NaN entries ignored): the
    rotation nearest (Frobenius) to the arithmetic mean, by SVD. Equal to the geodesic
    mean to second order for the small spreads of a still window."""
    R = np.moveaxis(np.asarray(R, dtype=np.float64), axis, 0)
    ok = np.all(np.isfinite(R), axis=(-1, -2))
    M = np.where(ok[..., None, None], R, 0.0).sum(0)
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[..., :, -1] *= d[..., None]
    out = U @ Vt
    out[~ok.any(0)] = np.nan
    return out


def _free_acc_G(quat: np.ndarray, free_acc: np.ndarray | None, acc: np.ndarray | None) -> np.ndarray:
    """Free acceleration in the sensor's reference frame G: the device's own where it
    reports one, else from the specific force, R_GS f_S + g."""
    shape = quat.shape[:-1] + (3,)
    out = np.full(shape, np.nan) if free_acc is None else np.array(free_acc, dtype=np.float64, copy=True)
    if acc is not None:
        need = ~np.all(np.isfinite(out), axis=-1)
        if need.any():
            R = quat_to_matrix(np.where(np.isfinite(quat), quat, [1.0, 0, 0, 0]))
            f = np.asarray(acc, dtype=np.float64)
            derived = (R @ f[..., None])[..., 0] + GRAVITY
            out[need] = derived[need]
    return out


def stillness(
    sites: Sequence[str],
    quat: np.ndarray,
    free_acc: np.ndarray | None = None,
    acc: np.ndarray | None = None,
    gyro: np.ndarray | None = None,
    present: np.ndarray | None = None,
    limits: StillnessLimits | None = None,
) -> Stillness:
    """How still each site was over a window: quat (T,S,4), free_acc/acc/gyro (T,S,3),
    present (T,S) bool (default: finite quaternion)."""
    limits = limits or StillnessLimits()
    quat = np.asarray(quat, dtype=np.float64)
    T, S = quat.shape[:2]
    ok = np.all(np.isfinite(quat), axis=-1)
    if present is not None:
        ok &= np.asarray(present, bool)
    R = quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0]))
    R = np.where(ok[..., None, None], R, np.nan)
    Rm = mean_rotation(R)
    rot = np.zeros(S)
    acc_std = np.zeros(S)
    gyro_rate = np.zeros(S)
    a = _free_acc_G(quat, free_acc, acc)
    for k in range(S):
        m = ok[:, k]
        if not m.any():
            continue
        rot[k] = float(np.rad2deg(matrix_angle_between(R[m, k], Rm[k][None])).max())
        ak = a[m, k]
        ak = ak[np.all(np.isfinite(ak), axis=-1)]
        if len(ak) > 1:
            acc_std[k] = float(np.sqrt(np.mean(np.var(ak, axis=0))))
        if gyro is not None:
            g = np.asarray(gyro, dtype=np.float64)[m, k]
            g = g[np.all(np.isfinite(g), axis=-1)]
            if len(g) > 1:
                gyro_rate[k] = float(np.rad2deg(np.sqrt(np.mean(np.sum((g - g.mean(0)) ** 2, -1)))))
    frac = ok.mean(axis=0) if T else np.zeros(S)
    still = (
        (frac >= limits.min_fraction)
        & (rot <= limits.max_rotation_deg)
        & (acc_std <= limits.max_acc_std)
        & (gyro_rate <= limits.max_gyro_deg_s)
    )
    return Stillness(tuple(sites), rot, acc_std, gyro_rate, frac, still)


@dataclass
class Calibration:
    """Per-site calibration. Arrays are over ``sites``.

    R_WG (S,3,3): sensor reference frame -> world. R_SB (S,3,3): bone -> sensor (so
    R_WB = R_WG R_GS R_SB). acc_offset (S,3): world-frame acceleration subtracted after
    rotation. valid (S,): the site was calibrated (a site that sent nothing during a
    window is not, and stays unobserved). residual_world_deg / residual_tpose_deg (S,):
    RMS angle of the window's samples about their mean, i.e. how still the sensor was;
    the number a user can judge a calibration by.
    """

    sites: tuple[str, ...]
    R_WG: np.ndarray
    R_SB: np.ndarray
    acc_offset: np.ndarray
    valid: np.ndarray
    R_known: np.ndarray = field(default_factory=lambda: np.eye(3))
    residual_world_deg: np.ndarray | None = None
    residual_tpose_deg: np.ndarray | None = None
    created: float = field(default_factory=time.time)
    meta: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.sites = tuple(self.sites)
        S = len(self.sites)
        self.R_WG = np.asarray(self.R_WG, dtype=np.float64).reshape(S, 3, 3)
        self.R_SB = np.asarray(self.R_SB, dtype=np.float64).reshape(S, 3, 3)
        self.acc_offset = np.asarray(self.acc_offset, dtype=np.float64).reshape(S, 3)
        self.valid = np.asarray(self.valid, dtype=bool).reshape(S)
        self.R_known = np.asarray(self.R_known, dtype=np.float64).reshape(3, 3)

    @property
    def residual_deg(self) -> float | None:
        """Mean of the world and T-pose residuals over the valid sites (deg)."""
        vals = [r[self.valid] for r in (self.residual_world_deg, self.residual_tpose_deg) if r is not None]
        vals = [v for v in vals if v.size]
        return float(np.mean(np.concatenate(vals))) if vals else None

    def index(self, sites: Sequence[str]) -> np.ndarray:
        return np.array([self.sites.index(s) for s in sites], dtype=int)

    def apply(
        self,
        quat: np.ndarray,
        free_acc: np.ndarray | None = None,
        acc: np.ndarray | None = None,
        sites: Sequence[str] | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Raw device quaternions (..., S, 4) (R_GS) and free acceleration in G (..., S, 3)
        (or specific force ``acc`` in S) -> bone orientations R_WB (..., S, 3, 3) and world
        accelerations a_W (..., S, 3). ``sites`` gives the order of the S axis when it
        differs from the calibration's. Uncalibrated sites and missing samples give NaN."""
        idx = self.index(sites) if sites is not None else np.arange(len(self.sites))
        quat = np.asarray(quat, dtype=np.float64)
        fin = np.all(np.isfinite(quat), axis=-1)
        R_GS = quat_to_matrix(np.where(fin[..., None], quat, [1.0, 0, 0, 0]))
        R_WB = self.R_WG[idx] @ R_GS @ self.R_SB[idx]
        a_G = _free_acc_G(quat, free_acc, acc)
        a_W = (self.R_WG[idx] @ a_G[..., None])[..., 0] - self.acc_offset[idx]
        bad = ~fin | ~self.valid[idx]
        R_WB[bad] = np.nan
        a_W[bad] = np.nan
        return R_WB, a_W

    # ------------------------------------------------------------------ persistence
    def to_dict(self) -> dict[str, Any]:
        def arr(a: np.ndarray | None) -> Any:
            return None if a is None else np.asarray(a).tolist()

        return {
            "format": FORMAT, "version": VERSION, "sites": list(self.sites),
            "R_WG": arr(self.R_WG), "R_SB": arr(self.R_SB), "acc_offset": arr(self.acc_offset),
            "valid": arr(self.valid), "R_known": arr(self.R_known),
            "residual_world_deg": arr(self.residual_world_deg), "residual_tpose_deg": arr(self.residual_tpose_deg),
            "created": self.created, "meta": self.meta,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Calibration:
        if d.get("format") != FORMAT:
            raise ValueError(f"not an imucap calibration (format {d.get('format')!r})")
        if int(d.get("version", 0)) > VERSION:
            raise ValueError(f"calibration version {d['version']} is newer than this program ({VERSION})")

        def opt(k: str) -> np.ndarray | None:
            return None if d.get(k) is None else np.asarray(d[k], dtype=np.float64)

        return cls(
            sites=tuple(d["sites"]), R_WG=np.asarray(d["R_WG"]), R_SB=np.asarray(d["R_SB"]),
            acc_offset=np.asarray(d["acc_offset"]), valid=np.asarray(d["valid"], bool),
            R_known=np.asarray(d.get("R_known", np.eye(3))), residual_world_deg=opt("residual_world_deg"),
            residual_tpose_deg=opt("residual_tpose_deg"), created=float(d.get("created", 0.0)),
            meta=dict(d.get("meta") or {}),
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_json(cls, text: str) -> Calibration:
        return cls.from_dict(json.loads(text))

    def save(self, path: str | os.PathLike) -> None:
        """Write JSON atomically (a crash never leaves half a calibration behind)."""
        p = Path(path)
        tmp = p.with_name(p.name + ".tmp")
        tmp.write_text(json.dumps(self.to_dict(), indent=1))
        os.replace(tmp, p)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Calibration:
        return cls.from_dict(json.loads(Path(path).read_text()))


def _rms_about(R: np.ndarray, Rm: np.ndarray) -> np.ndarray:
    """(S,) RMS geodesic angle (deg) of R (T,S,3,3) about Rm (S,3,3), NaN frames skipped."""
    ang = np.rad2deg(matrix_angle_between(np.nan_to_num(R), Rm[None]))
    ok = np.all(np.isfinite(R), axis=(-1, -2))
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.where(ok, ang**2, 0.0).sum(0) / np.maximum(ok.sum(0), 1))


def _check(kind: str, st: Stillness, limits: StillnessLimits, strict: bool, hint: str) -> np.ndarray:
    """Raise on movement; sites that sent (almost) nothing are only left uncalibrated
    unless ``strict``. Returns the sites usable."""
    moved = [p for p in st.problems(limits) if "present in only" not in p]
    missing = [s for k, s in enumerate(st.sites) if st.present[k] < limits.min_fraction]
    if moved:
        raise CalibrationError(f"{kind}: not still: " + "; ".join(moved) + f". {hint}")
    usable = st.present >= limits.min_fraction
    if not usable.any() or (strict and missing):
        raise CalibrationError(f"{kind}: no data from {', '.join(missing)}; check that these sensors stream")
    return usable


def calibrate_world(
    sites: Sequence[str],
    quat: np.ndarray,
    free_acc: np.ndarray | None = None,
    acc: np.ndarray | None = None,
    gyro: np.ndarray | None = None,
    present: np.ndarray | None = None,
    R_known: np.ndarray | None = None,
    limits: StillnessLimits | None = None,
    strict: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sensor-to-world from a still window with every sensor in orientation ``R_known``
    (default identity: x forward, y left, z up). Returns R_WG (S,3,3), acc_offset (S,3),
    valid (S,), residual_deg (S,). Raises CalibrationError if a sensor moved."""
    sites = tuple(parse_sites(list(sites)))
    limits = limits or StillnessLimits()
    Rk = np.eye(3) if R_known is None else np.asarray(R_known, dtype=np.float64)
    quat = np.asarray(quat, dtype=np.float64)
    st = stillness(sites, quat, free_acc, acc, gyro, present, limits)
    valid = _check("sensor-to-world", st, limits, strict,
                   "Lay the sensors in the reference orientation, do not touch them, and calibrate again.")
    ok = np.all(np.isfinite(quat), axis=-1) & (True if present is None else np.asarray(present, bool))
    R_GS = np.where(ok[..., None, None], quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0])), np.nan)
    Rm = mean_rotation(R_GS)
    S = len(sites)
    R_WG = np.tile(np.eye(3), (S, 1, 1))
    R_WG[valid] = Rk @ np.swapaxes(Rm[valid], -1, -2)
    a_G = _free_acc_G(quat, free_acc, acc)
    a_W = (R_WG[None] @ a_G[..., None])[..., 0]
    a_W[~ok] = np.nan
    # mean over the finite samples; a site with none (unplugged all along) gets 0, without nanmean's warning
    fin = np.isfinite(a_W)
    n = fin.sum(axis=0)
    offset = np.where(n > 0, np.where(fin, a_W, 0.0).sum(axis=0) / np.maximum(n, 1), 0.0).reshape(S, 3)
    offset[~valid] = 0.0
    resid = _rms_about(R_GS, Rm)
    resid[~valid] = np.nan
    return R_WG, offset, valid, resid


def calibrate_tpose(
    sites: Sequence[str],
    quat: np.ndarray,
    R_WG: np.ndarray,
    free_acc: np.ndarray | None = None,
    acc: np.ndarray | None = None,
    gyro: np.ndarray | None = None,
    present: np.ndarray | None = None,
    R_WB_rest: np.ndarray | None = None,
    limits: StillnessLimits | None = None,
    strict: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sensor-to-bone from a still T-pose window. ``R_WB_rest`` (24,3,3) is the pose's
    bone orientations (default ``inference.body.tpose``: identity). Returns R_SB (S,3,3),
    valid (S,), residual_deg (S,). Raises CalibrationError if the subject moved."""
    sites = tuple(parse_sites(list(sites)))
    limits = limits or StillnessLimits()
    rest = tpose(1)[0] if R_WB_rest is None else np.asarray(R_WB_rest, dtype=np.float64)
    quat = np.asarray(quat, dtype=np.float64)
    st = stillness(sites, quat, free_acc, acc, gyro, present, limits)
    valid = _check("T-pose", st, limits, strict, "Hold the T-pose still (arms level, palms down) and calibrate again.")
    ok = np.all(np.isfinite(quat), axis=-1) & (True if present is None else np.asarray(present, bool))
    R_GS = np.where(ok[..., None, None], quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0])), np.nan)
    Rm = mean_rotation(R_GS)
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[s]] for s in sites]
    S = len(sites)
    R_SB = np.tile(np.eye(3), (S, 1, 1))
    R_WS = np.asarray(R_WG) @ Rm
    R_SB[valid] = np.swapaxes(R_WS[valid], -1, -2) @ rest[seg][valid]
    resid = _rms_about(R_GS, Rm)
    resid[~valid] = np.nan
    return R_SB, valid, resid


def calibrate(
    sites: Sequence[str],
    world: dict[str, np.ndarray],
    tpose_window: dict[str, np.ndarray],
    R_known: np.ndarray | None = None,
    limits: StillnessLimits | None = None,
    strict: bool = False,
) -> Calibration:
    """Both steps. ``world`` and ``tpose_window`` are dicts with ``quat`` (T,S,4) and any of
    ``free_acc``, ``acc``, ``gyro`` (T,S,3), ``present`` (T,S)."""
    sites = tuple(parse_sites(list(sites)))
    keys = ("free_acc", "acc", "gyro", "present")
    R_WG, off, v1, r1 = calibrate_world(sites, world["quat"], **{k: world.get(k) for k in keys},
                                        R_known=R_known, limits=limits, strict=strict)
    R_SB, v2, r2 = calibrate_tpose(sites, tpose_window["quat"], R_WG, **{k: tpose_window.get(k) for k in keys},
                                   limits=limits, strict=strict)
    return Calibration(sites=sites, R_WG=R_WG, R_SB=R_SB, acc_offset=off, valid=v1 & v2,
                       R_known=np.eye(3) if R_known is None else R_known, residual_world_deg=r1,
                       residual_tpose_deg=r2)


def identity_calibration(sites: Sequence[str]) -> Calibration:
    """No-op calibration (sensors already report bone orientation in our world frame),
    e.g. for replaying synthesized signals without mounting or heading errors."""
    S = len(sites)
    return Calibration(sites=tuple(sites), R_WG=np.tile(np.eye(3), (S, 1, 1)), R_SB=np.tile(np.eye(3), (S, 1, 1)),
                       acc_offset=np.zeros((S, 3)), valid=np.ones(S, bool))


def quat_of(R: np.ndarray) -> np.ndarray:
    """Rotation matrices -> (w, x, y, z) quaternions (NaN stays NaN); recordings store
    orientations this way."""
    R = np.asarray(R, dtype=np.float64)
    ok = np.all(np.isfinite(R), axis=(-1, -2))
    q = matrix_to_quat(np.where(ok[..., None, None], R, np.eye(3)))
    q[~ok] = np.nan
    return q
