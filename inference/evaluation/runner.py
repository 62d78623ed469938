"""Evaluation harness behind `imucap evaluate`: motion file -> synthesized sensor signals
(with the sensor noise model) -> 60->20 Hz features -> the live poser frame by frame ->
metrics against the truth.

Why this path and not the training features: the point is to measure what a user gets.
Signals are synthesized the way a device reports them (``synthesis.synthesize`` with
white noise, bias and orientation error; the mounting and heading rotations are left
out because sensor-to-world and sensor-to-bone calibration remove them), the free
acceleration goes through the same moving average + decimation as live
(``resample.downsample``), and the poser runs one frame at a time with no look-ahead.
The truth is the motion at the same 20 Hz frames (60 Hz sample 3k, as the resampler
keeps them).

Every model (diffusion, regressor, floor) goes through the same harness on the same
signals (same seed per clip), so the report compares methods, not data.
"""

from __future__ import annotations

import os
import sys
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from inference.body.body import Body, global_from_local, npose_rotations
from inference.body.conventions import heading_of, heading_vector, rot_z
from inference.body.motion import Motion
from inference.body.reach import reach_hands
from inference.body.rotations import matrix_about_axis, matrix_to_rot6d, quat_to_matrix
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX, SITE_SEGMENT, parse_sites
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_ROT, observation_mask
from inference.metrics.errors import ClipMetrics, evaluate_clip, paired_difference, summarize
from inference.model.files import LoadedModel
from inference.poser.batched import reconstruct_many
from inference.poser.confidence import ConfidenceSettings, confidence_settings
from inference.poser.models import resolve_model
from inference.poser.poser import Poser, Reconstruction, reconstruct_offline
from inference.signals.resample import FPS_MODEL, STEP, downsample
from inference.signals.synthesis import NoiseModel, kinematics, synthesize

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
# (label, sites, insoles) of the report's rows
REPORT_SETS: tuple[tuple[str, tuple[str, ...], bool], ...] = (
    ("6 sites", SIX, False),
    ("6 sites + insoles", SIX, True),
    ("3 sites (pelvis, wrists)", ("pelvis", "l_wrist", "r_wrist"), False),
    ("2 sites (shanks)", ("l_shank", "r_shank"), False),
)
REPORT_MODELS: tuple[str, ...] = ("diffusion", "regressor", "floor")
# clips sharing each model call: 16 windows with mirror averaging, the fastest per window on one thread
DEFAULT_LANES = 8


def evaluation_noise() -> NoiseModel:
    """The sensor noise of an evaluation: ``NoiseModel.typical()`` white noise, biases and
    orientation error, without the mounting and heading rotations (calibration removes
    those, and a calibrated stream is what the poser sees)."""
    return replace(NoiseModel.typical(), mounting_deg=0.0, heading_deg=0.0)


@dataclass
class ClipInput:
    """What the poser is fed for one clip, and the truth to compare with (20 Hz)."""

    name: str
    body: Body
    features: np.ndarray  # (T, 190) observed entries filled, others 0
    mask: np.ndarray  # (T, 190) bool
    rot: np.ndarray  # (T, 24, 3, 3) truth
    root: np.ndarray  # (T, 3) truth
    joints: np.ndarray  # (T, 24, 3) truth
    points: np.ndarray | None = None  # (T, 16) tracked points' position input, for a model that reads it
    # the controllers for the arms' reach after the answer (inference/body/reach.py): hand
    # segment -> orientation (T, 3, 3), and the position input (T, 16)
    reach: tuple[dict[str, np.ndarray], np.ndarray] | None = None


def face_forward(motion: Motion) -> Motion:
    """The motion turned about the vertical and shifted so that its first frame's pelvis
    faces +X from above the origin.

    That is the frame a calibrated live session works in (DESIGN.md: after
    sensor-to-world calibration X is the subject's forward at calibration time) and the
    heading the poser's standing history has; clips in the data face wherever the
    capture did, and feeding them raw would start every evaluation with a sudden turn.
    A rigid motion of the world: every metric is unchanged by it for a perfect poser."""
    yaw = float(heading_of(motion.rot[0, 0, :, 0]))  # of the pelvis's forward (X) axis
    Rz = rot_z(-yaw)
    root = (motion.root - [motion.root[0, 0], motion.root[0, 1], 0.0]) @ Rz.T
    return replace(motion, rot=Rz @ motion.rot, root=root)


# signals of sites that are not IMUs (tracked points, app/evaluation/tracked_points.py): (aligned motion, seed)
# -> site -> (quat (T, 4) bone -> world, free acceleration (T, 3) world, unsmoothed) at 60 Hz
GivenSignals = Callable[[Motion, int], dict[str, tuple[np.ndarray, np.ndarray]]]
# tracked points for a model that reads them (ModelConfig.points): (aligned motion, seed) ->
# (segment name -> quat (T, 4) bone -> world, the position input (T, 16)) at 60 Hz
TrackedInput = Callable[[Motion, int], tuple[dict[str, np.ndarray], np.ndarray]]


def clip_input(motion: Motion, sites: Sequence[str], insoles: bool = False, noise: NoiseModel | None = None,
               seed: int = 0, align: bool = True, causal: bool = False,
               given: GivenSignals | None = None, tracked: TrackedInput | None = None,
               reach: TrackedInput | None = None) -> ClipInput:
    """Synthesize a motion's signals at `sites` and turn them into 20 Hz features and
    masks the way the live pipeline does (module docstring), plus the 20 Hz truth.
    ``align`` first turns the clip to face +X at its start (``face_forward``); ``causal``:
    the trailing acceleration filter of the low-latency live mode; ``given``: further
    sites whose 60 Hz signals come from elsewhere (a tracked point read as the live chain
    reads it), resampled and masked like the IMU sites; ``tracked``: tracked points for a
    model with a position input, their orientations as known segment entries and their
    positions as ``ClipInput.points``, both taken at the 20 Hz frames; ``reach``: the same
    for the arms' reach onto the controllers after the answer (``ClipInput.reach``)."""
    sites = parse_sites(list(sites))
    if align:
        motion = face_forward(motion)
    kin = kinematics(motion)
    rot = kin.rot[::STEP]
    T = rot.shape[0]
    feats = np.zeros((T, N_FEATURES))
    raws, quats = [], []
    if sites:
        sig = synthesize(motion, noise, rng=seed, sites=tuple(sites))
        raws.append(sig.meta["free_acc_raw"])  # unsmoothed, as a device streams it
        quats.append(sig.quat)
    if given is not None:
        extra = given(motion, seed)
        clash = sorted(set(extra) & set(sites))
        if clash:
            raise ValueError(f"site(s) {', '.join(clash)} given both as IMU and from elsewhere")
        sites = sites + parse_sites(list(extra))
        raws.append(np.stack([a for _, a in extra.values()], axis=1))
        quats.append(np.stack([q for q, _ in extra.values()], axis=1))
    if sites:
        n = min(len(r) for r in raws)
        raw = np.concatenate([r[:n] for r in raws], axis=1)
        acc20, quat20 = downsample(raw, np.concatenate([q[:n] for q in quats], axis=1), causal)
        R = quat_to_matrix(quat20)
        for k, s in enumerate(sites):
            seg = SEGMENT_INDEX[SITE_SEGMENT[s]]
            feats[:, SL_ROT.start + 6 * seg: SL_ROT.start + 6 * seg + 6] = matrix_to_rot6d(R[:, k])
            j = SITE_INDEX[s]
            feats[:, SL_ACC.start + 3 * j: SL_ACC.start + 3 * j + 3] = acc20[:, k]
    if insoles:
        feats[:, SL_CONTACT] = kin.contacts[::STEP].astype(np.float64)
    mask = np.broadcast_to(observation_mask(sites, insoles), (T, N_FEATURES)).copy()
    points = None
    if tracked is not None:
        segs, pf = tracked(motion, seed)
        for name, q in segs.items():
            cols = slice(SL_ROT.start + 6 * SEGMENT_INDEX[name], SL_ROT.start + 6 * SEGMENT_INDEX[name] + 6)
            feats[:, cols] = matrix_to_rot6d(quat_to_matrix(np.asarray(q)[::STEP][:T]))
            mask[:, cols] = True
        points = np.asarray(pf, np.float64)[::STEP][:T]
    reach_in = None
    if reach is not None:
        segs, pf = reach(motion, seed)
        hands = {n: quat_to_matrix(np.asarray(q)[::STEP][:T]) for n, q in segs.items() if n in ("l_hand", "r_hand")}
        reach_in = (hands, np.asarray(pf, np.float64)[::STEP][:T])
    return ClipInput(name=motion.name, body=motion.body, features=feats, mask=mask, rot=rot,
                     root=kin.root[::STEP], joints=kin.joints[::STEP], points=points, reach=reach_in)


def clip_seed(seed: int, name: str) -> int:
    """Per-clip noise seed: stable across runs and models, different across clips."""
    return (seed * 1_000_003 + zlib.crc32(name.encode())) & 0x7FFF_FFFF


@dataclass
class ClipResult:
    name: str
    metrics: ClipMetrics
    recon: Reconstruction
    inp: ClipInput


def clip_poser(model: LoadedModel | None, inp: ClipInput, steps=None, seed: int = 0, smoothing: bool = True,
               contact_detector="default", inpaint_noise: str | None = None, mirror: bool | None = None,
               stride_scale: bool = True, pelvis_odometry="default",
               confidence: ConfidenceSettings | bool | None = None, answer_lag: int | None = None,
               knee_twist: float | None = None) -> Poser:
    """The live poser for one clip, starting from a standing history at the clip's
    first root position (only for nicer exports: every metric is translation-free).
    ``inpaint_noise``: the poser's noise mode, ``mirror`` its mirror averaging (None: the
    model file's own), ``stride_scale`` its shank stride scaling of the root,
    ``pelvis_odometry`` its root walk without shanks (None: the model's own),
    ``confidence`` its spread (drawn with the clip's seed), ``answer_lag`` the frames each pose
    waits (``inference.poser.lag``; None: the model file's, 0 for the shipped ones), ``knee_twist``
    its knees' twist share (``inference.poser.knee_twist``; None: the model file's)."""
    conf = confidence_settings(confidence)
    if conf is not None:
        conf = replace(conf, seed=seed)
    return Poser(model, body=inp.body, steps=steps, seed=seed, root_xy0=(inp.root[0, 0], inp.root[0, 1]),
                 smoothing=smoothing, contact_detector=contact_detector, noise=inpaint_noise, mirror=mirror,
                 stride_scale=stride_scale, pelvis_odometry=pelvis_odometry, confidence=conf, answer_lag=answer_lag,
                 knee_twist=knee_twist)


def reconstruct_clip(model: LoadedModel | None, inp: ClipInput, steps=None, seed: int = 0,
                     progress: Callable[[int], object] | None = None, smoothing: bool = True,
                     contact_detector="default", inpaint_noise: str | None = None,
                     mirror: bool | None = None, stride_scale: bool = True,
                     pelvis_odometry="default", confidence: ConfidenceSettings | bool | None = None) -> Reconstruction:
    """``clip_poser`` frame by frame over one clip, as live."""
    poser = clip_poser(model, inp, steps, seed, smoothing, contact_detector, inpaint_noise, mirror, stride_scale,
                       pelvis_odometry, confidence)
    return reconstruct_offline(poser, inp.features, inp.mask, progress=progress, points=inp.points)


def evaluate_motions(
    motions: Sequence[Motion] | Callable[[], list[Motion]],
    model: LoadedModel | None,
    sites: Sequence[str],
    insoles: bool = False,
    steps=None,
    noise: NoiseModel | None = None,
    seed: int = 0,
    progress: bool = True,
    keep: bool = False,
    desc: str = "evaluate",
    smoothing: bool = True,
    contact_detector="default",
    inpaint_noise: str | None = None,
    mirror: bool | None = None,
    stride_scale: bool = True,
    pelvis_odometry="default",
    confidence: ConfidenceSettings | bool | None = None,
    lanes: int = DEFAULT_LANES,
    causal: bool = False,
    given: GivenSignals | None = None,
    tracked: TrackedInput | None = None,
    reach: TrackedInput | None = None,
    answer_lag: int | None = None,
    knee_twist: float | None = None,
) -> tuple[dict, list[ClipResult]]:
    """Evaluate one model and sensor set over motions; returns (pooled summary, per-clip
    results). ``keep`` retains reconstructions (for exports) instead of only metrics;
    ``smoothing=False`` scores the poser's outputs without its 1-Euro filters;
    ``contact_detector`` goes to the poser (None: the model's own contacts), and so do
    ``inpaint_noise`` and ``mirror`` (None: the model file's own), ``stride_scale``,
    ``pelvis_odometry`` and ``confidence``. ``lanes`` clips share each model call
    (``batched.reconstruct_many``: each clip's answer is its frame-by-frame one); 1 runs
    them one after the other. ``causal``: the signals through the low-latency mode's trailing
    acceleration filter (docs/latency.md); ``given``, ``tracked``: sites whose signals come
    from elsewhere, tracked points for a model with a position input (``clip_input``);
    ``reach``: tracked controllers the answer's arms reach for before it is scored
    (``inference.body.reach``); ``answer_lag``: frames each pose waits, ``knee_twist`` the knees'
    twist share (``clip_poser``)."""
    from tqdm import tqdm

    inputs = [clip_input(m, sites, insoles, noise, clip_seed(seed, m.name), causal=causal, given=given,
                         tracked=tracked, reach=reach) for m in motions]
    total = sum(i.features.shape[0] for i in inputs)
    posers = [clip_poser(model, inp, steps, clip_seed(seed, inp.name), smoothing, contact_detector, inpaint_noise,
                         mirror, stride_scale, pelvis_odometry, confidence, answer_lag, knee_twist)
              for inp in inputs]
    with tqdm(total=total, desc=desc, unit="frame", file=sys.stderr, disable=not progress,
              dynamic_ncols=True) as bar:
        recs = reconstruct_many(posers, [(i.features, i.mask) for i in inputs], lanes=lanes, progress=bar.update,
                                points=[i.points for i in inputs])
    results: list[ClipResult] = []
    for inp, rec in zip(inputs, recs):
        if inp.reach is not None:
            R2, j2 = reach_hands(rec.rot, rec.root, inp.body, *inp.reach)
            rec = replace(rec, rot=R2, joints=j2)
        cm = evaluate_clip(inp.name, rec.rot, rec.root, rec.joints, inp.rot, inp.root, inp.joints, FPS_MODEL)
        results.append(ClipResult(inp.name, cm, rec if keep else None, inp if keep else None))
    return summarize([r.metrics for r in results]), results


def load_motions(paths: Sequence[str | os.PathLike], limit: int | None = None) -> list[Motion]:
    """Every motion file under `paths` (sorted), the first `limit` of them; unreadable
    files are an error naming the file (an evaluation silently skipping clips would
    change the numbers)."""
    from inference.loaders import find_motion_files, load_motion

    files = find_motion_files([Path(p) for p in paths])
    if not files:
        raise FileNotFoundError(f"no motion files under {', '.join(map(str, paths))}")
    if limit is not None:
        files = files[:limit]
    out = []
    for f in files:
        m = load_motion(f)
        # clips from different folders may share a file name; keep them apart
        out.append(replace(m, name=m.name or f.stem))
    names = [m.name for m in out]
    if len(set(names)) != len(names):
        out = [replace(m, name=str(f.with_suffix("")).replace(os.sep, "_").lstrip("_")) for m, f in zip(out, files)]
    return out


def model_label(spec: str, model: LoadedModel | None) -> str:
    if model is None:
        return "floor"
    return spec if spec in REPORT_MODELS else f"{model.kind}:{Path(spec).name}"


def report_markdown(rows: list[dict], title: str = "Reconstruction accuracy") -> str:
    """Markdown table of evaluation summaries (one row per sensor set x model)."""

    def f(v, nd=2):
        return "n/a" if v is None else f"{v:.{nd}f}"

    lines = [
        f"## {title}", "",
        "| sensors | model | steps | clips | frames | GA deg | LA deg | JPE cm | jitter | RE2 m | RE5 m | RE10 m |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['label']} | {r['model']} | {r['steps']} | {r['clips']} | {r['frames']} | {f(r['ga_deg'], 1)} | "
            f"{f(r['la_deg'], 1)} | {f(r['jpe_cm'], 1)} | {f(r['jitter_ratio'])} | {f(r['re2_m'])} | "
            f"{f(r['re5_m'])} | {f(r['re10_m'])} |"
        )
    return "\n".join(lines) + "\n"


def compare_rows(per_clip: dict[tuple[str, str], list[ClipMetrics]], model: str = "diffusion",
                 baselines: Sequence[str] = ("regressor", "floor"), metric: str = "ga_deg",
                 seed: int = 0) -> list[dict]:
    """``model`` against each baseline on every sensor set both were scored on: the paired
    difference of ``metric`` over the same clips (``metrics.paired_difference``).
    per_clip: (set label, model spec) -> that evaluation's clip metrics."""
    rows = []
    for (label, spec), clips in per_clip.items():
        if spec != model:
            continue
        for base in baselines:
            other = per_clip.get((label, base))
            if other is None:
                continue
            d = paired_difference(clips, other, metric, seed=seed)
            rows.append({"label": label, "model": model, "baseline": base, "metric": metric, **d.as_dict()})
    return rows


def comparison_markdown(rows: list[dict]) -> str:
    """The side-by-side table: model minus baseline, with its interval over clips."""
    if not rows:
        return ""
    conf = round(100 * rows[0]["confidence"])
    lines = [
        "## Side by side, paired over clips", "",
        f"Model minus baseline on the same clips; {conf} % percentile bootstrap interval over clips (both "
        "models resampled together, frames pooled as in the table above). An interval that holds 0 means the "
        "clip sample does not settle which model is ahead. It covers the choice of clips only: two checkpoints of "
        "one training run can differ by more than it.", "",
        "| sensors | model | baseline | metric | difference | interval | clips where model lower |",
        "|---|---|---|---|---|---|---|",
    ]

    def f(v: float) -> str:
        return f"{round(v, 2) + 0.0:+.2f}"  # + 0.0: no "-0.00" for a difference that rounds to zero

    for r in rows:
        verdict = "" if r["decided"] else " (not settled)"
        lines.append(f"| {r['label']} | {r['model']} | {r['baseline']} | {r['metric']} | {f(r['difference'])} | "
                     f"[{f(r['low'])}, {f(r['high'])}]{verdict} | {r['model_lower']} of {r['clips']} |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- synthetic motion

def synthetic_motion(seconds: float = 4.0, fps: float = 60.0, height: float = 1.75, speed: float = 1.0,
                     turn_deg_per_s: float = 0.0, name: str = "synthetic_walk", seed: int = 0) -> Motion:
    """A simple walking-like motion on our body, for tests, smoke runs and benchmarks when
    no motion data is at hand: the pelvis moves forward at `speed` (m/s) with a small
    bob, turning at `turn_deg_per_s`; legs and arms swing at ~1 Hz from the N-pose.
    Not a physically planted gait; it only has to be smooth, varied and human-shaped."""
    rng = np.random.default_rng(seed)
    body = Body.from_height(height)
    T = int(round(seconds * fps)) + 1
    t = np.arange(T) / fps
    w = 2 * np.pi * (0.9 + 0.2 * rng.random())
    ph = rng.uniform(0, 2 * np.pi)
    s = np.sin(w * t + ph)
    c = np.cos(w * t + ph)
    L = np.broadcast_to(np.eye(3), (T, 24, 3, 3)).copy()
    # N-pose arms expressed as local rotations of the upper arms
    Rn = npose_rotations(1)[0]
    y_axis = np.array([0.0, 1.0, 0.0])
    x_axis = np.array([1.0, 0.0, 0.0])
    z_axis = np.array([0.0, 0.0, 1.0])
    yaw = np.deg2rad(turn_deg_per_s) * t
    L[:, 0] = (matrix_about_axis(z_axis, yaw) @ matrix_about_axis(x_axis, 0.03 * c)
               @ matrix_about_axis(y_axis, 0.05 + 0.02 * s))
    swing = 0.45
    L[:, SEGMENT_INDEX["l_thigh"]] = matrix_about_axis(y_axis, -swing * s)
    L[:, SEGMENT_INDEX["r_thigh"]] = matrix_about_axis(y_axis, swing * s)
    L[:, SEGMENT_INDEX["l_shank"]] = matrix_about_axis(y_axis, 0.5 * np.clip(c, 0, None) + 0.05)
    L[:, SEGMENT_INDEX["r_shank"]] = matrix_about_axis(y_axis, 0.5 * np.clip(-c, 0, None) + 0.05)
    L[:, SEGMENT_INDEX["l_foot"]] = matrix_about_axis(y_axis, -0.2 * s)
    L[:, SEGMENT_INDEX["r_foot"]] = matrix_about_axis(y_axis, 0.2 * s)
    L[:, SEGMENT_INDEX["spine2"]] = matrix_about_axis(z_axis, 0.08 * s)
    L[:, SEGMENT_INDEX["head"]] = matrix_about_axis(z_axis, -0.06 * s)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        ua = SEGMENT_INDEX[f"{side}_upperarm"]
        L[:, ua] = matrix_about_axis(y_axis, sign * 0.35 * s) @ Rn[ua]
        elbow = 0.3 + 0.2 * np.clip(sign * s, 0, None)
        L[:, SEGMENT_INDEX[f"{side}_forearm"]] = matrix_about_axis(z_axis, sign * elbow)
    rot = global_from_local(L)
    heading = heading_vector(yaw)[:, :2]
    xy = np.cumsum(heading * speed / fps, axis=0) - heading[0] * speed / fps
    root = np.zeros((T, 3))
    root[:, :2] = xy
    root[:, 2] = 0.53 * height * 1.0 + 0.015 * np.cos(2 * w * t + 2 * ph)
    return Motion(rot=rot, root=root, fps=fps, body=body, name=name, source="synthetic").floor_aligned()


def resolve_models(specs: Sequence[str]) -> dict[str, LoadedModel | None]:
    """Load each model spec once (the report reuses them over sensor sets)."""
    return {s: resolve_model(s) for s in specs}


__all__ = [
    "SIX", "REPORT_SETS", "REPORT_MODELS", "evaluation_noise", "face_forward", "ClipInput", "clip_input", "clip_seed",
    "ClipResult", "clip_poser", "reconstruct_clip", "DEFAULT_LANES",
    "evaluate_motions", "load_motions", "model_label", "report_markdown",
    "compare_rows", "comparison_markdown", "synthetic_motion", "resolve_models"
]
