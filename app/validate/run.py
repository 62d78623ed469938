"""``imucap validate``'s work, without the command line: re-run a recording for each
sensor subset, read the reference, align the two (``align.py``) and score every subset
and the standing baseline (``compare.py``)."""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.validate.align import (
    Alignment,
    heading_from_directions,
    heading_from_rotations,
    search_time_offset,
)
from app.validate.compare import Track, bland_altman, compare, reference_at
from app.validate.kinematics import JOINT_INDEX, directions, paired_joint_angles
from app.validate.reference import Reference, read_reference
from inference.body.body import Body, forward_kinematics, npose_rotations
from inference.body.conventions import rot_z
from inference.body.skeleton import SEGMENT_INDEX, SEGMENTS
from inference.metrics.errors import EVAL_SEGMENTS

ALL_JOINTS = set(JOINT_INDEX)
# the angles the clock is found from: large and well reconstructed from few sensors (the
# ankle, rarely measured, would only add noise to the correlation)
OFFSET_JOINTS = ("knee", "hip", "elbow")


@dataclass
class SubsetRun:
    """One subset's reconstruction on the recording's clock (s since its first raw frame)."""

    sensors: tuple[str, ...]
    track: Track


@dataclass
class Validation:
    """Everything the report and ``--json`` show."""

    recording: str
    reference: Reference
    alignment: Alignment
    subsets: list[dict[str, Any]]
    baseline: dict[str, Any]
    curves: dict[str, Any] = field(default_factory=dict)  # for the plots: times and angles per side

    def summary(self) -> dict[str, Any]:
        a, ref = self.alignment, self.reference
        return {"recording": self.recording, "reference": ref.path, "reference_format": ref.format,
                "reference_frames": ref.n_frames, "reference_fps": round(ref.fps, 3),
                "time_offset_s": round(a.time_offset_s, 4),
                "time_offset_correlation": None if a.correlation is None else round(a.correlation, 4),
                "time_offset_joints": a.joints, "time_offset_given": a.time_given,
                "time_offset_candidates": [{"time_offset_s": round(o, 4), "correlation": round(c, 4)}
                                           for o, c in a.candidates],
                "warnings": list(a.warnings),
                "heading_deg": round(a.heading_deg, 3), "heading_from": a.heading_from,
                "heading_given": a.heading_given,
                "mapping": ref.mapping, "notes": ref.notes,
                "subsets": self.subsets, "baseline": self.baseline}


def track_from_poses(poses: Sequence[Any], t_origin: float) -> Track:
    t = np.array([p.t for p in poses], float) - t_origin
    rot = np.stack([p.pose.rot for p in poses])
    joints = np.stack([p.pose.joints for p in poses])
    return Track(t, rot, joints, set(ALL_JOINTS))


def replay_subsets(rec: Any, body: Body, subsets: Sequence[str | Sequence[str] | None], model: str = "diffusion",
                   steps: str | None = None, seed: int | None = None,
                   progress: Callable[[str], None] | None = None) -> list[SubsetRun]:
    """The recording re-run once per subset (``None``: every recorded sensor), as
    ``imucap replay --sensors`` runs it."""
    from app.replay import ReplaySettings, build_replay_poser, replay_recording, resolve_sensors

    built = build_replay_poser(rec, ReplaySettings(model=model, steps=steps, seed=seed), body)
    t0 = float(rec.raw["t"][0]) if len(rec.raw["t"]) else 0.0
    runs = []
    for k, sub in enumerate(subsets):
        sensors = resolve_sensors(rec, sub)
        if progress is not None:
            progress(f"re-running with {','.join(sensors)} ({built.label})")
        res = replay_recording(rec, built.poser if k == 0 else built.fresh(), sensors=sensors, causal=built.causal)
        if not res.poses:
            raise ValueError(f"{rec.path}: the replay with {','.join(sensors)} produced no frames")
        runs.append(SubsetRun(tuple(res.sensors), track_from_poses(res.poses, t0)))
    return runs


def align(run: Track, ref: Reference, time_offset: float | None = None, heading_deg: float | None = None) -> Alignment:
    """Clock first (joint angles need no heading), then the heading (module docstrings of
    ``align.py``)."""
    if time_offset is None:
        a_run, a_ref = paired_joint_angles(run, ref)
        keep = [j for j in a_run if j.split("_")[1] in OFFSET_JOINTS]
        lag, corr, used, cands, warns = search_time_offset(run.t, {j: a_run[j] for j in keep}, ref.t,
                                                           {j: a_ref[j] for j in keep})
    else:
        lag, corr, used, cands, warns = float(time_offset), None, [], [], []
    inside, r = reference_at(ref, run.t + lag)
    if not inside.any():
        raise ValueError(f"{ref.path}: no reference frame overlaps the recording at a time offset of {lag:.3f} s")
    if heading_deg is not None:
        return Alignment(lag, corr, used, float(heading_deg), "given", time_offset is not None, True, cands, warns)
    segs = [i for i in EVAL_SEGMENTS if SEGMENTS[i] in ref.have_rot]
    if r.rot is not None and segs:
        yaw, how = heading_from_rotations(run.rot[inside][:, segs], r.rot[:, segs]), "orientations"
    else:
        yaw = heading_from_directions(directions(run.joints[inside], run.have_joints),
                                      directions(r.joints, r.have_joints))
        how = "segment directions"
    return Alignment(lag, corr, used, float(np.rad2deg(yaw)), how, time_offset is not None, False, cands, warns)


def turned(track: Track, yaw_deg: float, inside: np.ndarray) -> Track:
    Z = rot_z(np.deg2rad(yaw_deg))
    rot = None if track.rot is None else Z @ track.rot[inside]
    frames = None if track.frames is None else Z @ track.frames[inside]
    return Track(track.t[inside], rot, track.joints[inside] @ Z.T, track.have_joints, track.have_rot, frames,
                 track.have_frames)


def reference_facing(r: Track) -> np.ndarray:
    """(T,) the reference's facing at each frame (rad about Z): its pelvis's forward axis,
    or the normal of its hip line; frames where neither is known take the nearest known
    facing (the trial's mean when none is)."""
    if r.rot is not None and "pelvis" in r.have_rot:
        fwd = r.rot[:, SEGMENT_INDEX["pelvis"], :, 0]
    else:
        left = r.joints[:, JOINT_INDEX["l_hip"]] - r.joints[:, JOINT_INDEX["r_hip"]]
        fwd = np.cross(left, [0.0, 0.0, 1.0])
    n = np.linalg.norm(fwd[:, :2], axis=-1)
    ok = np.isfinite(n) & (n > 1e-6)
    if not ok.any():
        return np.zeros(len(fwd))
    yaw = np.unwrap(np.arctan2(fwd[ok, 1], fwd[ok, 0]))
    idx = np.arange(len(fwd))
    return np.interp(idx, idx[ok], yaw)


def standing_track(t: np.ndarray, body: Body, yaw: float | np.ndarray) -> Track:
    """A subject standing still, arms by the sides, facing ``yaw`` (rad; one value, or one
    per frame to turn with the subject): the baseline a number has to beat to mean anything."""
    R = rot_z(np.broadcast_to(np.asarray(yaw, float), (len(t),)))[:, None] @ npose_rotations(len(t))
    J = forward_kinematics(R, np.zeros((len(t), 3)), body.offsets)
    return Track(t, R, J, set(ALL_JOINTS))


def validate(rec_path: str | os.PathLike, reference: str | os.PathLike, subsets: Sequence[str | None] = (None,),
             model: str = "diffusion", steps: str | None = None, seed: int | None = None,
             time_offset: float | None = None, heading_deg: float | None = None, height: float | None = None,
             progress: Callable[[str], None] | None = None, static: str | os.PathLike | None = None) -> Validation:
    """Score a recording's re-runs against a reference (module docstring); ``static``: a
    static trial of a marker reference (``reference.read_reference``)."""
    from app.export.formats import body_for_recording
    from app.recording import read_recording

    if not os.path.exists(rec_path):
        raise FileNotFoundError(f"recording {rec_path} not found")
    rec = read_recording(rec_path)
    body, note = body_for_recording(rec.metadata, height)
    ref = read_reference(reference, body, static)
    if note:
        ref.notes.append(note)
    runs = replay_subsets(rec, body, list(subsets), model, steps, seed, progress)
    lead = max(runs, key=lambda r: len(r.sensors))
    al = align(lead.track, ref, time_offset, heading_deg)
    out, curves = [], {}
    fps = 1.0 / float(np.median(np.diff(lead.track.t))) if len(lead.track.t) > 1 else 20.0
    for run in runs:
        inside, r = reference_at(ref, run.track.t + al.time_offset_s)
        rec_track = turned(run.track, al.heading_deg, inside)
        res = compare(rec_track, r, fps)
        res = {"sensors": list(run.sensors), **res}
        res["bland_altman"] = {j: bland_altman(v["window_ranges_deg"]) for j, v in res["joints"].items()}
        out.append(res)
        a_rec, a_ref = paired_joint_angles(rec_track, r)
        curves[",".join(run.sensors)] = (rec_track.t, a_rec)
        curves["reference"] = (r.t - al.time_offset_s, a_ref)
    inside, r = reference_at(ref, lead.track.t + al.time_offset_s)
    base = standing_track(lead.track.t[inside], body, reference_facing(r))
    baseline = {"sensors": [], "what": "standing still, arms by the sides, turned with the reference's heading "
                                       "frame by frame",
                **compare(base, r, fps)}
    return Validation(str(rec_path), ref, al, out, baseline, curves)


__all__ = ["Validation", "SubsetRun", "validate", "replay_subsets", "align", "standing_track", "track_from_poses"]
