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

How the angles are computed: ``inference.metrics.joint_angles`` (the one definition of
every joint angle imucap shows or writes; its docstring has the frames, the Z-X-Y
decomposition and the signs): this module writes its ``coordinates_deg`` as columns.

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
from inference.metrics.joint_angles import JOINTS, M_OS, coordinates_deg, opensim_default_pose

TRANSLATIONS = ("pelvis_tx", "pelvis_ty", "pelvis_tz")


def coordinate_names() -> list[str]:
    """The exported coordinates in column order (Rajagopal's order, translations after
    the pelvis rotations)."""
    names = [c for c, _, _ in JOINTS[0][3]] + list(TRANSLATIONS)
    for _, _, _, coords in JOINTS[1:]:
        names += [c for c, _, _ in coords]
    return names


def opensim_coordinates(rot: np.ndarray, root: np.ndarray) -> tuple[list[str], np.ndarray]:
    """(names, values (T, 29)): OpenSim coordinates of global orientations rot (T, 24, 3, 3)
    and pelvis positions root (T, 3) in our world; angles in degrees, translations in m."""
    rot = np.asarray(rot, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    T = rot.shape[0]
    names = coordinate_names()
    if not T:
        return names, np.zeros((0, len(names)))
    cols = coordinates_deg(rot)
    p = root @ M_OS.T
    for k, name in enumerate(TRANSLATIONS):
        cols[name] = p[:, k]
    return names, np.stack([cols[n] for n in names], axis=-1)


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
