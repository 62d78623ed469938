"""What both sides of a comparison can give, whatever they measured: joint centres, the
directions of the segments between them, and joint angles.

Joint angles (deg) are ``inference.metrics.joint_angles``'s, the one definition imucap
uses everywhere (ISB / OpenSim: knee flexion, hip flexion, ankle dorsiflexion, elbow
flexion; signs in that module), computed from segment orientations. Which orientations,
per joint, the richest that the reference has (``paired_joint_angles``):

1. the reference's own orientations of both segments (MVN, BVH, OpenSim coordinates,
   imucap's truth): the reconstruction's orientations against them;
2. segment frames the reference's markers define (a lab's segment axes, anatomical
   landmarks: ``app.validate.frames``): the reconstruction's orientations against them;
3. joint centres only: both sides' frames built from their joint centres the same way
   (``frames.hinge_frames``: long axes and the plane of three centres), from the centres
   both sides have, so a definition that differs between the two systems stays out of
   the error (a knee angle from orientations carries the segments' twist, one from three
   centres does not).

Segment directions (``DIRECTIONS``) are what the segment errors of a marker reference
compare: a marker set shows where a bone points, not how it is twisted about itself.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from app.export.markers import JOINT_NAMES
from app.validate.frames import hinge_frames, unit
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.metrics import joint_angles as ja

# joint centre (marker) names: joint i is where segment i starts (DESIGN.md); the C3D/TRC exports write them
JOINT_INDEX: dict[str, int] = {j: SEGMENT_INDEX[s] for s, j in JOINT_NAMES.items()}

# segment -> (from joint, to joint): the direction compared for a marker reference. The
# pelvis has no long axis between two joint centres; its left-right axis stands for it.
DIRECTIONS: dict[str, tuple[str, str]] = {
    "pelvis": ("r_hip", "l_hip"),
    "spine3": ("spine3", "neck"),
    **{f"{s}_{seg}": (f"{s}_{a}", f"{s}_{b}") for s in "lr" for seg, a, b in (
        ("thigh", "hip", "knee"), ("shank", "knee", "ankle"), ("foot", "ankle", "mtp"),
        ("upperarm", "shoulder", "elbow"), ("forearm", "elbow", "wrist"))},
}

# joint -> (proximal segment, distal segment, angle of the one module)
JOINT_ANGLES: dict[str, tuple[str, str, str]] = {
    **{f"{s}_knee": (f"{s}_thigh", f"{s}_shank", "knee_flexion") for s in "lr"},
    **{f"{s}_hip": ("pelvis", f"{s}_thigh", "hip_flexion") for s in "lr"},
    **{f"{s}_ankle": (f"{s}_shank", f"{s}_foot", "ankle_dorsiflexion") for s in "lr"},
    **{f"{s}_elbow": (f"{s}_upperarm", f"{s}_forearm", "elbow_flexion") for s in "lr"},
}


class Side(Protocol):
    """One side of a comparison: a Track or a Reference."""

    joints: np.ndarray
    have_joints: set[str]
    rot: np.ndarray | None
    have_rot: set[str]
    frames: np.ndarray | None
    have_frames: set[str]


def directions(joints: np.ndarray, have: set[str]) -> dict[str, np.ndarray]:
    """segment -> (T, 3) unit direction, for the segments whose two joints are in ``have``."""
    out = {}
    for seg, (a, b) in DIRECTIONS.items():
        if a in have and b in have:
            out[seg] = unit(joints[:, JOINT_INDEX[b]] - joints[:, JOINT_INDEX[a]])
    return out


def angle_of(R: np.ndarray, joint: str) -> np.ndarray:
    """(T,) the angle of ``joint`` (``JOINT_ANGLES``) from full (T, 24, 3, 3) orientations."""
    side, kind = joint[0], JOINT_ANGLES[joint][2]
    if kind == "knee_flexion":
        return ja.knee_flexion_deg(R, side)
    if kind == "hip_flexion":
        return ja.hip_angles_deg(R, side)[0]
    if kind == "ankle_dorsiflexion":
        return ja.ankle_dorsiflexion_deg(R, side)
    return ja.elbow_flexion_deg(R, side)


def _full(T: int, parts: dict[str, np.ndarray]) -> np.ndarray:
    R = np.broadcast_to(np.eye(3), (T, N_SEGMENTS, 3, 3)).copy()
    for s, r in parts.items():
        R[:, SEGMENT_INDEX[s]] = r
    return R


def centre_frames(joints: np.ndarray, have: set[str]) -> dict[str, np.ndarray]:
    """segment -> (T, 3, 3) frames from the joint centres in ``have`` (``frames.hinge_frames``)."""
    return hinge_frames({j: joints[:, JOINT_INDEX[j]] for j in have if j in JOINT_INDEX})


def joint_angles(side: Side, joints_only: set[str] | None = None) -> dict[str, np.ndarray]:
    """joint -> (T,) deg of one side alone, from its own richest data: its orientations,
    else its marker frames, else its joint centres (restricted to ``joints_only`` if given)."""
    T = side.joints.shape[0]
    centres = centre_frames(side.joints, side.have_joints if joints_only is None else joints_only)
    out: dict[str, np.ndarray] = {}
    for joint, (p, c, _) in JOINT_ANGLES.items():
        pair = None
        for src, have in ((side.rot, side.have_rot), (side.frames, side.have_frames)):
            if src is not None and p in have and c in have:
                pair = {p: src[:, SEGMENT_INDEX[p]], c: src[:, SEGMENT_INDEX[c]]}
                break
        if pair is None and p in centres and c in centres:
            pair = {p: centres[p], c: centres[c]}
        if pair is not None:
            out[joint] = angle_of(_full(T, pair), joint)
    return out


def paired_joint_angles(rec: Side, ref: Side) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """(recording's, reference's) joint -> (T,) deg, each joint computed both sides from the
    same kind of data (module docstring): the reference's orientations or marker frames
    against the recording's orientations, else both from the joint centres both have."""
    T_rec, T_ref = rec.joints.shape[0], ref.joints.shape[0]
    shared = rec.have_joints & ref.have_joints
    c_rec, c_ref = centre_frames(rec.joints, shared), centre_frames(ref.joints, shared)
    p_rec: dict[str, np.ndarray] = {}
    p_ref: dict[str, np.ndarray] = {}
    for joint, (p, c, _) in JOINT_ANGLES.items():
        got = None
        for src, have in ((ref.rot, ref.have_rot), (ref.frames, ref.have_frames)):
            if src is not None and p in have and c in have and rec.rot is not None:
                got = ({s: rec.rot[:, SEGMENT_INDEX[s]] for s in (p, c)},
                       {s: src[:, SEGMENT_INDEX[s]] for s in (p, c)})
                break
        if got is None and p in c_rec and c in c_rec and p in c_ref and c in c_ref:
            got = ({p: c_rec[p], c: c_rec[c]}, {p: c_ref[p], c: c_ref[c]})
        if got is None:
            continue
        a, b = got
        # one joint's pair at a time: the pelvis may come from orientations for one hip and
        # from centres for another joint, so each joint gets its own full arrays
        p_rec[joint] = angle_of(_full(T_rec, a), joint)
        p_ref[joint] = angle_of(_full(T_ref, b), joint)
    return p_rec, p_ref


__all__ = ["JOINT_NAMES", "JOINT_INDEX", "DIRECTIONS", "JOINT_ANGLES", "directions", "joint_angles",
           "paired_joint_angles", "centre_frames", "angle_of"]
