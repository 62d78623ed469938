"""Reconstruction metrics as DiffusionPoser reports them (papers/diffusionposer.md,
"Metrics"; the paper follows the TransPose/PIP/TIP evaluators).

- GA: mean geodesic angle between predicted and true *global* segment orientations, deg.
- LA: the same for *local* (parent-relative) joint rotations, deg.
  Both leave out the segments in ``skeleton.METRIC_EXCLUDED`` (toes, hands, fingers:
  no sensor set constrains them, and the paper excludes them).
- JPE: joint positions relative to the root joint (translation removed, global
  orientation kept), mean Euclidean distance over the 23 non-root joints, cm.
- Jitter ratio: mean norm of the third finite difference of *global* joint positions
  times fps^3 (m/s^3) of the prediction, divided by the same of the ground truth.
- RE at 2/5/10 s: || (r_true[t+h] - r_true[t]) - (r_pred[t+h] - r_pred[t]) || on the
  horizontal (x, y) root path, averaged over every start point t with t+h inside the clip.

A whole evaluation pools frames (and RE start points, and jitter samples) over all clips,
so a long clip weighs by its length, not as one vote; a metric no clip is long enough
for is ``None`` -- never a made-up number.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .body import local_from_global
from .rotations import matrix_angle_between
from .skeleton import METRIC_EXCLUDED, N_SEGMENTS, SEGMENT_INDEX

EVAL_SEGMENTS: tuple[int, ...] = tuple(
    i for i in range(N_SEGMENTS) if i not in {SEGMENT_INDEX[s] for s in METRIC_EXCLUDED}
)
RE_SECONDS: tuple[int, ...] = (2, 5, 10)


def global_angle_error(R_pred: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """(T,) per-frame mean geodesic angle (deg) over the evaluated segments of global
    orientations (T, 24, 3, 3)."""
    ang = matrix_angle_between(np.asarray(R_pred, np.float64), np.asarray(R_true, np.float64))
    return np.rad2deg(ang[:, list(EVAL_SEGMENTS)]).mean(axis=1)


def local_angle_error(R_pred: np.ndarray, R_true: np.ndarray) -> np.ndarray:
    """(T,) per-frame mean geodesic angle (deg) of parent-relative joint rotations over
    the evaluated segments (the root's "local" rotation is its global one)."""
    Lp = local_from_global(np.asarray(R_pred, np.float64))
    Lt = local_from_global(np.asarray(R_true, np.float64))
    return global_angle_error(Lp, Lt)


def joint_position_error(j_pred: np.ndarray, j_true: np.ndarray) -> np.ndarray:
    """(T,) per-frame mean distance (m) of the non-root joints after moving both roots to
    the origin. Inputs (T, 24, 3) world joint positions."""
    jp = np.asarray(j_pred, np.float64)
    jt = np.asarray(j_true, np.float64)
    rp = jp[:, 1:] - jp[:, :1]
    rt = jt[:, 1:] - jt[:, :1]
    return np.linalg.norm(rp - rt, axis=-1).mean(axis=1)


def jitter(joints: np.ndarray, fps: float) -> np.ndarray:
    """(T-3,) per-sample mean over joints of ||third finite difference|| * fps^3 (m/s^3)
    of global joint positions (T, J, 3); empty for T < 4."""
    j = np.asarray(joints, np.float64)
    if j.shape[0] < 4:
        return np.zeros(0)
    d3 = j[3:] - 3 * j[2:-1] + 3 * j[1:-2] - j[:-3]
    return np.linalg.norm(d3, axis=-1).mean(axis=1) * fps**3


def root_error(root_pred: np.ndarray, root_true: np.ndarray, seconds: float, fps: float) -> np.ndarray | None:
    """Errors (m) of the horizontal root displacement over `seconds`, one per start point
    (T - h of them, h = round(seconds * fps)); None if the clip has no such pair."""
    h = int(round(seconds * fps))
    rp = np.asarray(root_pred, np.float64)[:, :2]
    rt = np.asarray(root_true, np.float64)[:, :2]
    if h < 1 or rp.shape[0] <= h:
        return None
    d = (rt[h:] - rt[:-h]) - (rp[h:] - rp[:-h])
    return np.linalg.norm(d, axis=-1)


@dataclass
class ClipMetrics:
    """Sums and counts of one clip, so clips pool by frames (see module docstring)."""

    name: str
    frames: int
    ga_sum: float
    la_sum: float
    jpe_sum: float  # metres
    jitter_pred_sum: float
    jitter_true_sum: float
    jitter_n: int
    re_sum: dict[int, float] = field(default_factory=dict)
    re_n: dict[int, int] = field(default_factory=dict)

    def summary(self) -> dict:
        """This clip's own figures (same keys as ``summarize``)."""
        return summarize([self])


def evaluate_clip(name: str, R_pred: np.ndarray, root_pred: np.ndarray, j_pred: np.ndarray,
                  R_true: np.ndarray, root_true: np.ndarray, j_true: np.ndarray, fps: float,
                  re_seconds: tuple[int, ...] = RE_SECONDS) -> ClipMetrics:
    """All metrics of one clip; predictions and truth frame-aligned at `fps`."""
    T = int(R_true.shape[0])
    if R_pred.shape[0] != T or j_pred.shape[0] != T or root_pred.shape[0] != T:
        raise ValueError(f"clip {name}: prediction has {R_pred.shape[0]} frames, truth {T}")
    jp, jt = jitter(j_pred, fps), jitter(j_true, fps)
    cm = ClipMetrics(
        name=name, frames=T, ga_sum=float(global_angle_error(R_pred, R_true).sum()),
        la_sum=float(local_angle_error(R_pred, R_true).sum()),
        jpe_sum=float(joint_position_error(j_pred, j_true).sum()),
        jitter_pred_sum=float(jp.sum()), jitter_true_sum=float(jt.sum()), jitter_n=int(jp.shape[0]),
    )
    for s in re_seconds:
        e = root_error(root_pred, root_true, s, fps)
        if e is not None:
            cm.re_sum[s] = float(e.sum())
            cm.re_n[s] = int(e.shape[0])
    return cm


def summarize(clips: list[ClipMetrics], re_seconds: tuple[int, ...] = RE_SECONDS) -> dict:
    """Pooled figures: clips, frames, ga_deg, la_deg, jpe_cm, jitter_ratio, re<s>_m.
    Any figure without data (no frames, no clip long enough, a truth with no jitter) is
    None."""
    frames = sum(c.frames for c in clips)
    out: dict = {"clips": len(clips), "frames": frames}

    def mean(total: float, n: int, scale: float = 1.0) -> float | None:
        return total / n * scale if n > 0 else None

    out["ga_deg"] = mean(sum(c.ga_sum for c in clips), frames)
    out["la_deg"] = mean(sum(c.la_sum for c in clips), frames)
    out["jpe_cm"] = mean(sum(c.jpe_sum for c in clips), frames, 100.0)
    jt = sum(c.jitter_true_sum for c in clips)
    jn = sum(c.jitter_n for c in clips)
    out["jitter_ratio"] = sum(c.jitter_pred_sum for c in clips) / jt if jn > 0 and jt > 0 else None
    for s in re_seconds:
        n = sum(c.re_n.get(s, 0) for c in clips)
        out[f"re{s}_m"] = mean(sum(c.re_sum.get(s, 0.0) for c in clips), n)
    return out


__all__ = [
    "EVAL_SEGMENTS", "RE_SECONDS", "global_angle_error", "local_angle_error", "joint_position_error", "jitter",
    "root_error", "ClipMetrics", "evaluate_clip", "summarize",
]
