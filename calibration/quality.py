"""How good a calibration is, per sensor, with warnings a person can act on.

A calibration that completes is not necessarily right: a strap that slipped a little
during the still pose, a left sensor on the right leg, a thigh sensor on the shank all
give a calibration, and a body on screen that is subtly wrong. The walk of the table-free
protocol is a few seconds of known motion, and gait is regular enough to check against:

- **moved during a still phase**: the rotation spread of the still window above half the
  hard limit (the hard limit fails the step);
- **heading spread**: the heading from each third of the walk differs from the whole by
  more than 10 deg (a curved walk, or a sensor whose heading drifts);
- **probably on another segment**: the segment's swing in the sagittal plane during the
  walk is outside what that segment does in gait: on synthesized walks trunk 2-3 deg,
  thigh 40-41, shank 74-82, foot ~85; on six Bandai walks (styles active, angry, childish) pelvis
  8-12, head 13-25, thigh 33-56, shank 55-79, foot 59-106. The limits below hold all of
  these; the arms are not checked (their swing is personal: 32-154 deg);
- **probably on the wrong side**: in gait the pelvis turns toward the leg that swings
  forward, so a left leg segment's extension goes with the pelvis turning left and the
  arms swing opposite to the legs. The correlation of each limb sensor's sagittal angle
  with the pelvis heading (pelvis worn) has a known sign per side; a sensor whose sign
  is the other side's is flagged, and a flagged left/right pair is reported as swapped.
  On Bandai walks of the active and angry styles thighs score 0.61-0.77, shanks 0.43-0.82,
  feet 0.12-0.66 and the arms 0.45-0.90 on their own side;
  a stylised "childish" walk scores near zero (no flag: below the thresholds) except
  for its flailing arms, hence the arms' stricter threshold.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np

from inference.body.rotations import matrix_angle_between, quat_to_matrix, so3_log

from .core import Calibration, StillnessLimits, mean_rotation

# sagittal swing (deg) during a walk that fits each segment: (low, high); outside it the
# sensor is probably elsewhere
SWING_RANGE = {
    "pelvis": (0.0, 25.0), "torso": (0.0, 25.0), "head": (0.0, 35.0),
    "l_thigh": (25.0, 62.0), "r_thigh": (25.0, 62.0), "l_shank": (50.0, 110.0), "r_shank": (50.0, 110.0),
    "l_foot": (52.0, 140.0), "r_foot": (52.0, 140.0),
}
TYPICAL_SWING = {"trunk": 3.0, "arm": 33.0, "thigh": 43.0, "shank": 76.0, "foot": 85.0}
LEG = ("thigh", "shank", "foot")
ARM = ("upperarm", "wrist")
# |corr| below these says nothing about the side. Arms need more: arm swing differs
# between people and walking styles far more than the legs' pattern does
SIDE_CORRELATION = {"leg": 0.4, "arm": 0.7}
HEADING_SPREAD_DEG = 10.0


@dataclass
class SensorQuality:
    site: str
    still_rotation_deg: float | None = None
    heading_spread_deg: float | None = None
    walk_path_m: float | None = None
    swing_deg: float | None = None
    side_score: float | None = None  # > 0: moves like its own side, < 0: like the other
    warnings: list[str] = field(default_factory=list)


@dataclass
class QualityReport:
    protocol: str
    sensors: dict[str, SensorQuality]
    warnings: list[str] = field(default_factory=list)
    redo: list[str] = field(default_factory=list)  # steps worth repeating

    @property
    def ok(self) -> bool:
        return not self.warnings and not any(q.warnings for q in self.sensors.values())

    def all_warnings(self) -> list[str]:
        return self.warnings + [w for q in self.sensors.values() for w in q.warnings]

    def to_dict(self) -> dict:
        return {"protocol": self.protocol, "warnings": self.warnings, "redo": self.redo,
                "sensors": {k: asdict(v) for k, v in self.sensors.items()}}

    @classmethod
    def from_dict(cls, d: dict) -> QualityReport:
        return cls(d.get("protocol", ""), {k: SensorQuality(**v) for k, v in d.get("sensors", {}).items()},
                   list(d.get("warnings", [])), list(d.get("redo", [])))

    def lines(self) -> list[str]:
        """The report as a terminal shows it: one line per sensor, then the warnings."""
        out = []
        for s, q in self.sensors.items():
            parts = [f"{s:>10}"]
            if q.still_rotation_deg is not None:
                parts.append(f"still {q.still_rotation_deg:4.1f} deg")
            if q.heading_spread_deg is not None:
                parts.append(f"heading +-{q.heading_spread_deg:4.1f} deg")
            if q.swing_deg is not None:
                parts.append(f"swing {q.swing_deg:3.0f} deg")
            parts.append("ok" if not q.warnings else "CHECK")
            out.append("  ".join(parts))
        out += [f"warning: {w}" for w in self.all_warnings()]
        if self.redo:
            out.append("redo: " + ", ".join(self.redo))
        return out


def _part(site: str) -> tuple[str | None, str]:
    side, _, part = site.partition("_")
    return (side, part) if part else (None, site)


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 0 else 0.0


def _detrend(x: np.ndarray) -> np.ndarray:
    t = np.arange(len(x))
    return x - np.polyval(np.polyfit(t, x, 1), t) if len(x) > 2 else x - x.mean()


def walk_angles(cal: Calibration, quat: np.ndarray, fps: float) -> np.ndarray:
    """(T, S, 3) cumulative world rotation of each calibrated segment over a walk window:
    x roll, y sagittal pitch (+ = segment turning its lower end backward), z heading."""
    ok = np.all(np.isfinite(quat), -1)
    R_GS = quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0]))
    R = cal.R_WG[None] @ R_GS @ cal.R_SB[None]
    dR = R[1:] @ np.swapaxes(R[:-1], -1, -2)
    om = np.where(ok[1:, :, None] & ok[:-1, :, None], so3_log(dR), 0.0)
    return np.concatenate([np.zeros((1,) + om.shape[1:]), np.cumsum(om, axis=0)])


def side_scores(sites: Sequence[str], angles: np.ndarray) -> dict[str, float]:
    """Per limb sensor, the correlation of its sagittal angle with the pelvis heading,
    signed so that > 0 is what its own side does (needs the pelvis among ``sites``)."""
    if "pelvis" not in sites:
        return {}
    yaw = _detrend(angles[:, list(sites).index("pelvis"), 2])
    out = {}
    for k, s in enumerate(sites):
        side, part = _part(s)
        if side is None or part not in LEG + ARM:
            continue
        sign = (1.0 if side == "l" else -1.0) * (1.0 if part in LEG else -1.0)
        out[s] = sign * _corr(_detrend(angles[:, k, 1]), yaw)
    return out


def _swing_warning(site: str, swing: float) -> str | None:
    if site not in SWING_RANGE:  # arms: how much they swing is personal, not a placement check
        return None
    lo, hi = SWING_RANGE[site]
    if lo <= swing <= hi:
        return None
    _, part = _part(site)
    guess = min(TYPICAL_SWING, key=lambda k: abs(TYPICAL_SWING[k] - swing))
    return (f"{site}: swings {swing:.0f} deg in the walk, a {part} {lo:.0f}-{hi:.0f}: "
            f"probably not on the {part} (moves like a {guess}); check where it is strapped")


def assess(cal: Calibration, protocol: str, still: dict[str, np.ndarray] | None = None,
           walk: dict | None = None, limits: StillnessLimits | None = None) -> QualityReport:
    """The quality report of ``cal``. ``still``: per still step name, the rotation spread
    (deg, over ``cal.sites``) of its window. ``walk``: ``quat`` (T,S,4) of the walk
    window, ``fps``, and the ``WalkResult``'s ``spread_deg`` and ``path_m``."""
    limits = limits or StillnessLimits()
    sites = cal.sites
    report = QualityReport(protocol, {s: SensorQuality(s) for s in sites})
    for step, rot in (still or {}).items():
        for k, s in enumerate(sites):
            q = report.sensors[s]
            v = float(rot[k]) if np.isfinite(rot[k]) else None
            if v is None:
                continue
            q.still_rotation_deg = max(q.still_rotation_deg or 0.0, v)
            if v > 0.5 * limits.max_rotation_deg:
                q.warnings.append(f"{s}: moved {v:.1f} deg during the {step} (limit {limits.max_rotation_deg:g}); "
                                  f"redo '{step}' holding still")
                if step not in report.redo:
                    report.redo.append(step)
    if walk is not None:
        _assess_walk(cal, report, walk)
    for k, s in enumerate(sites):
        if not cal.valid[k]:
            report.sensors[s].warnings.append(f"{s}: not calibrated (no data during a step); check it streams")
    return report


def _assess_walk(cal: Calibration, report: QualityReport, walk: dict) -> None:
    sites = cal.sites
    angles = walk_angles(cal, np.asarray(walk["quat"], float), float(walk.get("fps", 60.0)))
    lo, hi = np.percentile(angles[..., 1], 5, axis=0), np.percentile(angles[..., 1], 95, axis=0)
    swing = np.rad2deg(hi - lo)
    spread = np.asarray(walk.get("spread_deg", np.full(len(sites), np.nan)), float)
    path = np.asarray(walk.get("path_m", np.full(len(sites), np.nan)), float)
    scores = side_scores(sites, angles)
    for k, s in enumerate(sites):
        if not cal.valid[k]:
            continue
        q = report.sensors[s]
        q.swing_deg = float(swing[k])
        q.heading_spread_deg = float(spread[k]) if np.isfinite(spread[k]) else None
        q.walk_path_m = float(path[k]) if np.isfinite(path[k]) else None
        if q.heading_spread_deg is not None and q.heading_spread_deg > HEADING_SPREAD_DEG:
            q.warnings.append(f"{s}: heading uncertain (+-{q.heading_spread_deg:.0f} deg over the walk); "
                              "walk straight and redo 'walk'")
            if "walk" not in report.redo:
                report.redo.append("walk")
        w = _swing_warning(s, q.swing_deg)
        if w:
            q.warnings.append(w)
        if s in scores:
            q.side_score = round(scores[s], 3)
    wrong = {s for s, v in scores.items() if v < -SIDE_CORRELATION["leg" if _part(s)[1] in LEG else "arm"]}
    for s in sorted(wrong):
        side, part = _part(s)
        other = f"{'r' if side == 'l' else 'l'}_{part}"
        if other in wrong:
            if side == "l":
                report.warnings.append(f"{s} and {other} are probably swapped (left/right): "
                                       f"exchange the two sensors or their sites in the setup")
        else:
            report.sensors[s].warnings.append(f"{s}: probably on the {'right' if side == 'l' else 'left'} side "
                                              f"(moves like {other} in the walk); check the setup")
    if not scores and any(_part(s)[1] in LEG + ARM for s in sites):
        report.warnings.append("left/right not checked: it needs the pelvis sensor")


def max_rotation(quat: np.ndarray) -> np.ndarray:
    """(S,) largest angle (deg) of a still window's samples from their mean orientation."""
    ok = np.all(np.isfinite(quat), -1)
    R = np.where(ok[..., None, None], quat_to_matrix(np.where(ok[..., None], quat, [1.0, 0, 0, 0])), np.nan)
    Rm = mean_rotation(R)
    ang = np.rad2deg(matrix_angle_between(np.nan_to_num(R), Rm[None]))
    ang[~ok] = 0.0
    return ang.max(axis=0) if len(ang) else np.zeros(quat.shape[1])


__all__ = ["QualityReport", "SensorQuality", "assess", "max_rotation", "side_scores", "walk_angles", "SWING_RANGE"]

