"""Write a reconstructed motion as an OpenSim motion file (``.mot``): joint angles that a
generic OpenSim full-body model plays directly (File > Load Motion), ready for inverse
dynamics, muscle analysis or comparison with optical motion capture -- no marker
inverse kinematics needed.

File format (OpenSim "storage", version 1): a header of ``<name>``, ``version=1``,
``nRows=T``, ``nColumns=1+K`` (time counts), ``inDegrees=yes``, ``endheader``, then one
tab-separated row of column labels starting with ``time`` and T rows of numbers. Angles
are in degrees (as ``inDegrees`` says), translations in metres, time in seconds since
the recording's first raw frame.

Target model: the coordinate names and sign conventions of Rajagopal et al. (2016),
``Rajagopal2015.osim`` (the same names are used by its descendants, e.g. the Lai-Uhlrich
model of OpenCap; Gait2392 shares the pelvis/hip/ankle/lumbar names but counts knee
flexion *negative*: negate ``knee_angle_*`` for it).

Exported coordinates (29; axes of the body-fixed rotation sequence Z, X, Y, i.e. the
model's rotation1/2/3, in OpenSim's frames: X forward, Y up, Z to the subject's right):

    pelvis_tilt, pelvis_list, pelvis_rotation   pelvis in ground: Z, X, Y
    pelvis_tx, pelvis_ty, pelvis_tz             our pelvis joint in ground (m)
    hip_flexion_r, hip_adduction_r, hip_rotation_r   femur in pelvis: Z, X, Y
    knee_angle_r                                tibia in femur: flexion positive (-Z)
    ankle_angle_r                               foot in tibia: dorsiflexion positive (Z)
    (the same five for _l: adduction and rotation about -X and -Y, as the model mirrors them)
    lumbar_extension, lumbar_bending, lumbar_rotation   torso in pelvis: Z, X, Y
    arm_flex_r, arm_add_r, arm_rot_r            humerus in torso: Z, X, Y (left: Z, -X, -Y)
    elbow_flex_r                                forearm in humerus: Z, flexion positive
    pro_sup_r                                   forearm twist about its long axis (Y; left -Y),
                                                0 = palm forward, pronation positive
    (arm_*_l, elbow_flex_l, pro_sup_l likewise)

How the angles are computed. Our world is X forward, Y left, Z up; OpenSim's ground is X
forward, Y up, Z right, so a vector maps as v_os = M v with M = [[1,0,0],[0,0,1],[0,-1,0]]
(a proper rotation). In OpenSim's default pose (every coordinate 0: upright, legs
straight, arms hanging with palms forward) every body frame is aligned with ground; in
ours (the T-pose) every segment frame is the identity. So each OpenSim body frame is our
segment frame turned by that segment's orientation Q in OpenSim's default pose:
G_os = M R Q^T M^T, with Q = identity for pelvis, legs and trunk, the arm lowered 90 deg
about the forward axis for the upper arm (as ``body.npose_rotations``), and additionally
turned 90 deg about the vertical to palms forward for the forearm (our T-pose has the
palms down, SMPL's convention). A joint's rotation is L = G_os[parent]^T G_os[child],
decomposed as L = Rz(a) Rx(b) Ry(c) (``matrix_to_euler(L, "ZXY")``); each coordinate is
one of a, b, c with the model axis's sign. Every column is unwrapped over time (no
360-degree jumps when the subject turns round).

Approximations (say so when publishing numbers from this file):
- One segment pair per joint, principal axes: the model's slightly oblique axes (ankle
  about 10-20 deg, elbow about 13 deg, pro_sup along the forearm) are taken as its
  frame's Z/Y axes; the knee's coupled small adduction, rotation and translation, and
  the knee/ankle/elbow rotation components the model does not have, are dropped.
- Lumbar = pelvis -> spine3 (our three spine joints lumped); shoulder = spine3 -> upper
  arm (the collar's motion lumped into it); the model's torso carries neck and head.
- Not exported (left at the model's defaults): subtalar_angle, mtp_angle (no sensor sees
  them and our foot/toe estimate is weak), wrist_flex/wrist_dev (locked in the model),
  knee_angle_beta (coupled to the knee).
- pelvis_t* is our pelvis joint (between the hips), not the model's pelvis origin, so a
  scaled model sits a few cm off in pelvis_ty; segment lengths are not transferred
  (scale the model to the subject as usual).
- arm_add = +-90 deg (arm straight out sideways, e.g. a T-pose) is the Z-X-Y sequence's
  singularity: there arm_flex and arm_rot share one rotation arbitrarily, as in OpenSim.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from app.export.common import ExportMotion, atomic_target
from inference.body.conventions import rot_z
from inference.body.rotations import matrix_about_axis, matrix_to_euler
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX

# ours (X fwd, Y left, Z up) -> OpenSim ground (X fwd, Y up, Z right)
M_OS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

# (OpenSim joint, parent segment or None for ground, child segment,
#  ((coordinate, index into the Z-X-Y angles, sign), ...))
JOINTS: tuple[tuple[str, str | None, str, tuple[tuple[str, int, int], ...]], ...] = (
    ("ground_pelvis", None, "pelvis", (("pelvis_tilt", 0, 1), ("pelvis_list", 1, 1), ("pelvis_rotation", 2, 1))),
    ("hip_r", "pelvis", "r_thigh", (("hip_flexion_r", 0, 1), ("hip_adduction_r", 1, 1), ("hip_rotation_r", 2, 1))),
    ("knee_r", "r_thigh", "r_shank", (("knee_angle_r", 0, -1),)),
    ("ankle_r", "r_shank", "r_foot", (("ankle_angle_r", 0, 1),)),
    ("hip_l", "pelvis", "l_thigh", (("hip_flexion_l", 0, 1), ("hip_adduction_l", 1, -1), ("hip_rotation_l", 2, -1))),
    ("knee_l", "l_thigh", "l_shank", (("knee_angle_l", 0, -1),)),
    ("ankle_l", "l_shank", "l_foot", (("ankle_angle_l", 0, 1),)),
    ("back", "pelvis", "spine3", (("lumbar_extension", 0, 1), ("lumbar_bending", 1, 1), ("lumbar_rotation", 2, 1))),
    ("acromial_r", "spine3", "r_upperarm", (("arm_flex_r", 0, 1), ("arm_add_r", 1, 1), ("arm_rot_r", 2, 1))),
    ("elbow_r", "r_upperarm", "r_forearm", (("elbow_flex_r", 0, 1), ("pro_sup_r", 2, 1))),
    ("acromial_l", "spine3", "l_upperarm", (("arm_flex_l", 0, 1), ("arm_add_l", 1, -1), ("arm_rot_l", 2, -1))),
    ("elbow_l", "l_upperarm", "l_forearm", (("elbow_flex_l", 0, 1), ("pro_sup_l", 2, -1))),
)
TRANSLATIONS = ("pelvis_tx", "pelvis_ty", "pelvis_tz")


def coordinate_names() -> list[str]:
    """The exported coordinates in column order (Rajagopal's order, translations after
    the pelvis rotations)."""
    names = [c for c, _, _ in JOINTS[0][3]] + list(TRANSLATIONS)
    for _, _, _, coords in JOINTS[1:]:
        names += [c for c, _, _ in coords]
    return names


def _rx(deg: float) -> np.ndarray:
    return matrix_about_axis(np.array([1.0, 0.0, 0.0]), np.deg2rad(deg))


def opensim_default_pose() -> np.ndarray:
    """(24, 3, 3) our global segment orientations in OpenSim's default pose: upright, arms
    hanging (lowered 90 deg about the forward axis), forearms and hands turned palms
    forward (our T-pose has palms down). Mirror-symmetric left/right by construction."""
    Q = np.broadcast_to(np.eye(3), (N_SEGMENTS, 3, 3)).copy()
    for side, down, palm in (("l", -90.0, 90.0), ("r", 90.0, -90.0)):
        Q[SEGMENT_INDEX[f"{side}_upperarm"]] = _rx(down)
        for seg in ("forearm", "hand", "fingers"):
            Q[SEGMENT_INDEX[f"{side}_{seg}"]] = rot_z(np.deg2rad(palm)) @ _rx(down)
    return Q


def opensim_coordinates(rot: np.ndarray, root: np.ndarray) -> tuple[list[str], np.ndarray]:
    """(names, values (T, 29)): OpenSim coordinates of global orientations rot (T, 24, 3, 3)
    and pelvis positions root (T, 3) in our world; angles in degrees, translations in m."""
    rot = np.asarray(rot, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    T = rot.shape[0]
    Q = opensim_default_pose()
    G = M_OS @ rot @ np.swapaxes(Q, -1, -2) @ M_OS.T  # OpenSim body frames in ground
    cols: dict[str, np.ndarray] = {}
    for _, parent, child, coords in JOINTS:
        Gc = G[:, SEGMENT_INDEX[child]]
        L = Gc if parent is None else np.swapaxes(G[:, SEGMENT_INDEX[parent]], -1, -2) @ Gc
        eul = np.unwrap(matrix_to_euler(L, "ZXY"), axis=0) if T else np.zeros((0, 3))
        for name, k, sign in coords:
            cols[name] = sign * np.rad2deg(eul[:, k])
    p = root @ M_OS.T
    for k, name in enumerate(TRANSLATIONS):
        cols[name] = p[:, k]
    names = coordinate_names()
    return names, np.stack([cols[n] for n in names], axis=-1) if T else np.zeros((0, len(names)))


def mot_text(name: str, time: np.ndarray, names: list[str], values: np.ndarray) -> str:
    """The .mot file contents (module docstring)."""
    time = np.asarray(time, dtype=np.float64)
    T = len(time)
    if values.shape != (T, len(names)):
        raise ValueError(f"mot: {values.shape} values for {T} rows x {len(names)} columns")
    lines = [name, "version=1", f"nRows={T}", f"nColumns={len(names) + 1}", "inDegrees=yes", "endheader",
             "\t".join(["time", *names])]
    for t in range(T):
        lines.append("\t".join([f"{time[t]:.6f}", *(f"{v:.6f}" for v in values[t])]))
    return "\n".join(lines) + "\n"


def write_mot(path: str | os.PathLike, m: ExportMotion) -> Path:
    """Write ``m`` as an OpenSim .mot (module docstring); returns the path. Temporary name,
    then rename."""
    path = Path(path)
    names, values = opensim_coordinates(m.rot, m.root)
    tmp = atomic_target(path)
    tmp.write_text(mot_text(path.stem, m.time, names, values))
    os.replace(tmp, path)
    return path


def read_mot(path: str | os.PathLike) -> tuple[dict[str, str], list[str], np.ndarray]:
    """(header key=value pairs plus ``name``, column labels, data (nRows, nColumns)) of a
    .mot/.sto storage file: enough to check an export or load it without OpenSim."""
    lines = Path(path).read_text().splitlines()
    header: dict[str, str] = {"name": lines[0].strip()} if lines else {}
    i = 1
    while i < len(lines) and lines[i].strip() != "endheader":
        if "=" in lines[i]:
            k, v = lines[i].split("=", 1)
            header[k.strip()] = v.strip()
        i += 1
    if i >= len(lines):
        raise ValueError(f"{path}: no 'endheader' line")
    labels = lines[i + 1].split("\t")
    rows = [ln.split("\t") for ln in lines[i + 2:] if ln.strip()]
    data = np.array(rows, dtype=np.float64).reshape(len(rows), len(labels))
    return header, labels, data


__all__ = ["M_OS", "JOINTS", "coordinate_names", "opensim_default_pose", "opensim_coordinates", "mot_text",
           "write_mot", "read_mot"]
