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
- The three-point papers' metrics (AGRoL, HAD): MPJRE, MPJPE, MPJVE, jitter, hand, upper,
  lower and root PE, head-anchored on SMPL's 22 body joints; definitions in ``vr``.
- RE at 2/5/10 s: || (r_true[t+h] - r_true[t]) - (r_pred[t+h] - r_pred[t]) || on the
  horizontal (x, y) root path, averaged over every start point t with t+h inside the clip.

A whole evaluation pools frames (and RE start points, and jitter samples) over all clips,
so a long clip weighs by its length, not as one vote; a metric no clip is long enough
for is ``None`` -- never a made-up number.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.body.body import local_from_global
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import METRIC_EXCLUDED, N_SEGMENTS, SEGMENT_INDEX
from inference.metrics import vr
from inference.metrics.plausibility import implausible_frames

EVAL_SEGMENTS: tuple[int, ...] = tuple(
    i for i in range(N_SEGMENTS) if i not in {SEGMENT_INDEX[s] for s in METRIC_EXCLUDED}
)
RE_SECONDS: tuple[int, ...] = (2, 5, 10)
# the three-point papers' figures: key (with the papers' unit) -> (ClipMetrics sum
# attribute, scale from the sum's SI unit, ClipMetrics count attribute)
VR_METRICS: dict[str, tuple[str, float, str]] = {
    "mpjre_deg": ("mpjre_sum", 1.0, "pos_n"), "mpjpe_cm": ("mpjpe_sum", 100.0, "pos_n"),
    "mpjve_cms": ("mpjve_sum", 100.0, "vel_n"), "jitter_1e2m_s3": ("jerk_pred_sum", 0.01, "jerk_n"),
    "hand_pe_cm": ("hand_pe_sum", 100.0, "pos_n"), "upper_pe_cm": ("upper_pe_sum", 100.0, "pos_n"),
    "lower_pe_cm": ("lower_pe_sum", 100.0, "pos_n"), "root_pe_cm": ("root_pe_sum", 100.0, "pos_n"),
}


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
    # frames whose truth no body makes (``plausibility``) and their share of ga_sum
    implausible: int = 0
    ga_implausible_sum: float = 0.0
    # (24,) per segment, the sum over frames of its global angle error (deg): which segment
    # carries the error (``segment_errors``)
    seg_sum: np.ndarray | None = None
    # the three-point papers' metrics (``vr``, head-anchored): per-frame sums over pos_n
    # frames (deg; metres), MPJVE over vel_n frame pairs (m/s), jerk over jerk_n samples
    # (m/s^3). Zero counts (clips scored before these existed) give None, not 0.
    pos_n: int = 0
    mpjre_sum: float = 0.0
    mpjpe_sum: float = 0.0
    hand_pe_sum: float = 0.0
    upper_pe_sum: float = 0.0
    lower_pe_sum: float = 0.0
    root_pe_sum: float = 0.0
    vel_n: int = 0
    mpjve_sum: float = 0.0
    jerk_n: int = 0
    jerk_pred_sum: float = 0.0
    jerk_true_sum: float = 0.0

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
    seg = np.rad2deg(matrix_angle_between(np.asarray(R_pred, np.float64), np.asarray(R_true, np.float64)))
    ga = seg[:, list(EVAL_SEGMENTS)].mean(axis=1)
    bad = implausible_frames(R_true)
    cm = ClipMetrics(
        name=name, frames=T, ga_sum=float(ga.sum()), implausible=int(bad.sum()), seg_sum=seg.sum(axis=0),
        ga_implausible_sum=float(ga[bad].sum()),
        la_sum=float(local_angle_error(R_pred, R_true).sum()),
        jpe_sum=float(joint_position_error(j_pred, j_true).sum()),
        jitter_pred_sum=float(jp.sum()), jitter_true_sum=float(jt.sum()), jitter_n=int(jp.shape[0]),
    )
    _add_vr(cm, R_pred, j_pred, R_true, j_true, fps)
    for s in re_seconds:
        e = root_error(root_pred, root_true, s, fps)
        if e is not None:
            cm.re_sum[s] = float(e.sum())
            cm.re_n[s] = int(e.shape[0])
    return cm


def _add_vr(cm: ClipMetrics, R_pred: np.ndarray, j_pred: np.ndarray, R_true: np.ndarray, j_true: np.ndarray,
            fps: float) -> None:
    """The three-point papers' sums of one clip, head-anchored as the papers place the body."""
    dist = vr.joint_distances(j_pred, j_true, "head")  # (T, 22) m
    cm.pos_n = int(dist.shape[0])
    cm.mpjre_sum = float(vr.mpjre(R_pred, R_true).sum())
    cm.mpjpe_sum = float(dist.mean(axis=1).sum())
    for attr, joints in (("hand_pe_sum", vr.HAND_JOINTS), ("upper_pe_sum", vr.UPPER_JOINTS),
                         ("lower_pe_sum", vr.LOWER_JOINTS), ("root_pe_sum", (vr.ROOT_JOINT,))):
        setattr(cm, attr, float(dist[:, list(joints)].mean(axis=1).sum()))
    ve = vr.mpjve(j_pred, j_true, fps, "head")
    cm.vel_n, cm.mpjve_sum = int(ve.shape[0]), float(ve.sum())
    jk_p = vr.mean_jerk(vr.head_anchored(j_pred, j_true), fps)
    cm.jerk_n, cm.jerk_pred_sum = int(jk_p.shape[0]), float(jk_p.sum())
    cm.jerk_true_sum = float(vr.mean_jerk(j_true, fps).sum())


def summarize(clips: list[ClipMetrics], re_seconds: tuple[int, ...] = RE_SECONDS) -> dict:
    """Pooled figures: clips, frames, ga_deg, la_deg, jpe_cm, jitter_ratio, re<s>_m, and the
    three-point papers' mpjre_deg, mpjpe_cm, mpjve_cms, jitter_1e2m_s3 (the prediction's;
    jitter_true_1e2m_s3 the truth's), hand_pe_cm, upper_pe_cm, lower_pe_cm, root_pe_cm.
    Any figure without data (no frames, no clip long enough, a truth with no jitter) is
    None."""
    frames = sum(c.frames for c in clips)
    out: dict = {"clips": len(clips), "frames": frames}

    def mean(total: float, n: int, scale: float = 1.0) -> float | None:
        return total / n * scale if n > 0 else None

    out["ga_deg"] = mean(sum(c.ga_sum for c in clips), frames)
    # the truth of some motion capture frames is a solver failure (HDM05: flipped feet);
    # GA over the other frames says how much of the error sits in them
    bad = sum(c.implausible for c in clips)
    out["implausible_truth_share"] = bad / frames if frames > 0 else None
    out["ga_deg_plausible_truth"] = mean(sum(c.ga_sum - c.ga_implausible_sum for c in clips), frames - bad)
    out["la_deg"] = mean(sum(c.la_sum for c in clips), frames)
    out["jpe_cm"] = mean(sum(c.jpe_sum for c in clips), frames, 100.0)
    jt = sum(c.jitter_true_sum for c in clips)
    jn = sum(c.jitter_n for c in clips)
    out["jitter_ratio"] = sum(c.jitter_pred_sum for c in clips) / jt if jn > 0 and jt > 0 else None
    for s in re_seconds:
        n = sum(c.re_n.get(s, 0) for c in clips)
        out[f"re{s}_m"] = mean(sum(c.re_sum.get(s, 0.0) for c in clips), n)
    for key, (attr, scale, count) in VR_METRICS.items():
        out[key] = mean(sum(getattr(c, attr) for c in clips), sum(getattr(c, count) for c in clips), scale)
    out["jitter_true_1e2m_s3"] = mean(sum(c.jerk_true_sum for c in clips), sum(c.jerk_n for c in clips), 0.01)
    return out


def segment_errors(clips: list[ClipMetrics]) -> dict[str, float] | None:
    """Segment name -> its global angle error (deg) pooled over the clips' frames, for
    every segment (GA averages only the evaluated ones): a held-out thigh's error is read
    here, not guessed from the mean. None without frames."""
    from inference.body.skeleton import SEGMENTS

    have = [c for c in clips if c.seg_sum is not None and c.frames > 0]
    frames = sum(c.frames for c in have)
    if not frames:
        return None
    total = np.sum([c.seg_sum for c in have], axis=0) / frames
    return {name: round(float(v), 2) for name, v in zip(SEGMENTS, total)}


# per-sample metrics a paired comparison can pool: key -> (ClipMetrics sum attribute, scale,
# ClipMetrics count attribute the sum is over)
_FRAME_METRICS: dict[str, tuple[str, float, str]] = {
    "ga_deg": ("ga_sum", 1.0, "frames"), "la_deg": ("la_sum", 1.0, "frames"), "jpe_cm": ("jpe_sum", 100.0, "frames"),
    **VR_METRICS,
}


@dataclass(frozen=True)
class PairedDifference:
    """Pooled metric of model A minus model B over the same clips, with a bootstrap interval.

    With ~60 short validation clips, one model's lead of a degree can be the luck of which
    clips were held out; resampling the *clips* (both models together, pooled by frames as
    ``summarize`` does) says how much of a lead the clip sample supports."""

    metric: str
    difference: float  # A - B, pooled over all clips
    low: float  # confidence interval of the difference
    high: float
    confidence: float
    clips: int
    a_lower: int  # clips on which A's own figure is lower than B's

    @property
    def decided(self) -> bool:
        """The interval excludes zero: the clip sample supports a difference of this sign."""
        return self.low > 0.0 or self.high < 0.0

    def as_dict(self) -> dict:
        """The JSON form the evaluation output uses (``model_lower`` = ``a_lower``)."""
        return {"difference": self.difference, "low": self.low, "high": self.high, "confidence": self.confidence,
                "clips": self.clips, "model_lower": self.a_lower, "decided": self.decided}


def paired_difference(a: list[ClipMetrics], b: list[ClipMetrics], metric: str = "ga_deg",
                      confidence: float = 0.95, n_resamples: int = 4000, seed: int = 0) -> PairedDifference:
    """A - B on a frame-pooled metric (ga_deg, la_deg, jpe_cm, or one of ``VR_METRICS``,
    pooled over its own samples: MPJVE's frame pairs, jitter's), with a percentile bootstrap
    interval over clips (scipy.stats.bootstrap, paired: a resample draws whole clips for both
    models at once). A and B must be the same clips in the same order."""
    from scipy.stats import bootstrap

    if metric not in _FRAME_METRICS:
        raise ValueError(f"paired_difference pools per-frame metrics only ({', '.join(_FRAME_METRICS)}), "
                         f"not {metric!r}")
    if [c.name for c in a] != [c.name for c in b] or [c.frames for c in a] != [c.frames for c in b]:
        raise ValueError("paired_difference needs the same clips (names and frames) in the same order")
    attr, scale, count = _FRAME_METRICS[metric]
    if [getattr(c, count) for c in a] != [getattr(c, count) for c in b]:
        raise ValueError(f"paired_difference: {metric} was scored on different samples of the same clips")
    if not a or sum(getattr(c, count) for c in a) == 0:
        raise ValueError(f"paired_difference needs at least one clip with {metric} samples")
    sa = np.array([getattr(c, attr) for c in a], np.float64) * scale
    sb = np.array([getattr(c, attr) for c in b], np.float64) * scale
    fr = np.array([getattr(c, count) for c in a], np.float64)

    def pooled(xa, xb, f, axis=-1):
        n = f.sum(axis=axis)
        return (xa.sum(axis=axis) - xb.sum(axis=axis)) / n

    diff = float(pooled(sa, sb, fr))
    ma, mb = sa / np.maximum(fr, 1), sb / np.maximum(fr, 1)  # each clip's own figure
    if len(a) > 1 and np.ptp(ma - mb) > 0:
        res = bootstrap((sa, sb, fr), pooled, paired=True, vectorized=True, confidence_level=confidence,
                        n_resamples=n_resamples, method="percentile", rng=np.random.default_rng(seed))
        low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    else:  # one clip, or the same difference on every clip: nothing to resample
        low = high = diff
    return PairedDifference(metric, diff, low, high, confidence, len(a), int(np.sum(ma < mb)))


def paired_block_difference(a: np.ndarray, b: np.ndarray, block: int, confidence: float = 0.95,
                            n_resamples: int = 4000, seed: int = 0) -> PairedDifference:
    """mean(a) - mean(b) of two per-frame error series of one recording, paired frame by
    frame, with a percentile bootstrap interval over contiguous blocks of ``block`` frames.

    Why blocks: one real log is one take, and its frames' errors are correlated over a
    stride or a turn; resampling frames would call a 1-deg difference on a 17 s walk settled
    when it is not. Blocks of about two strides stand in for the clips ``paired_difference``
    resamples (a trailing part block is its own, smaller block). ``a_lower`` counts the
    blocks on which A's mean is lower."""
    from scipy.stats import bootstrap

    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    if a.shape != b.shape or a.ndim != 1 or not len(a):
        raise ValueError("paired_block_difference needs two per-frame series of the same, non-zero length")
    if block < 1:
        raise ValueError(f"block {block}: at least one frame")
    edges = np.arange(0, len(a), block)
    sa, sb = np.add.reduceat(a, edges), np.add.reduceat(b, edges)
    fr = np.diff(np.append(edges, len(a))).astype(np.float64)

    def pooled(xa, xb, f, axis=-1):
        return (xa.sum(axis=axis) - xb.sum(axis=axis)) / f.sum(axis=axis)

    diff = float(pooled(sa, sb, fr))
    per = sa / fr - sb / fr
    if len(fr) > 1 and np.ptp(per) > 0:
        res = bootstrap((sa, sb, fr), pooled, paired=True, vectorized=True, confidence_level=confidence,
                        n_resamples=n_resamples, method="percentile", rng=np.random.default_rng(seed))
        low, high = float(res.confidence_interval.low), float(res.confidence_interval.high)
    else:
        low = high = diff
    return PairedDifference("deg", diff, low, high, confidence, len(fr), int(np.sum(per < 0)))


__all__ = [
    "EVAL_SEGMENTS", "RE_SECONDS", "VR_METRICS", "global_angle_error", "local_angle_error", "joint_position_error",
    "jitter", "root_error", "ClipMetrics", "evaluate_clip", "summarize", "segment_errors", "PairedDifference",
    "paired_difference", "paired_block_difference",
]
