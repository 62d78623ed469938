"""Axis conventions between AMASS/SMPL files and our body, in one place.

The AMASS generator (sim_devices.motions) and the AMASS loader (inference.loaders) both
use these functions, so a file we write reads back as the motion we meant, and a real
AMASS file reads the same way.

Conventions
-----------
- SMPL rest frame (every segment at zero pose): x left, y up, z forward.
- Our rest frame (inference.body): x forward, y left, z up (T-pose = identity).
- AMASS world: Z up. We take it to coincide with our world (x, y, z the same axes); the
  heading of a file is arbitrary anyway.

``C = SMPL_TO_OURS`` maps SMPL rest coordinates to ours (v_ours = C v_smpl; a cyclic
permutation, det +1). A global segment orientation in AMASS convention maps SMPL-rest
coordinates to the world; ours maps our rest coordinates to the world, hence

    R_ours = R_amass @ C^T,      R_amass = R_ours @ C,
    L_ours = C L_amass C^T       for parent-relative (local) rotations of non-root joints.

At our identity T-pose the AMASS root orientation is C itself, the rotation that stands a
Y-up SMPL body up in a Z-up world (facing +X), as real AMASS root orientations do.

AMASS ``poses`` is SMPL-H: 52 joints x 3 axis-angle = 156 numbers; the first 22 joints are
SMPL's body joints in SMPL order, which is our segment order. Our segments 22/23
(l_fingers/r_fingers, SMPL's hand joints) are not in the body part of SMPL-H and are
written as identity (and read as identity).
"""

from __future__ import annotations

import numpy as np

from inference.body.body import global_from_local, local_from_global
from inference.body.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from inference.body.skeleton import N_SEGMENTS

SMPL_TO_OURS = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
N_SMPLH_BODY_JOINTS = 22
N_SMPLH_POSE = 156


def smpl_rest_to_ours(R: np.ndarray) -> np.ndarray:
    """Global orientations (..., 3, 3) in AMASS convention (SMPL rest frame -> world) to ours."""
    return np.asarray(R) @ SMPL_TO_OURS.T


def ours_to_smpl_rest(R: np.ndarray) -> np.ndarray:
    """Our global orientations (..., 3, 3) to AMASS convention (inverse of smpl_rest_to_ours)."""
    return np.asarray(R) @ SMPL_TO_OURS


def amass_poses_to_global(poses: np.ndarray) -> np.ndarray:
    """SMPL-H ``poses`` (T, >=66) axis-angle -> our global orientations (T, 24, 3, 3).

    Joints beyond the 22 body joints are ignored; our finger segments inherit the hand's
    orientation (identity local)."""
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] < 3 * N_SMPLH_BODY_JOINTS:
        raise ValueError(f"AMASS poses must be (T, >=66), got {poses.shape}")
    T = poses.shape[0]
    aa = np.zeros((T, N_SEGMENTS, 3))
    aa[:, :N_SMPLH_BODY_JOINTS] = poses[:, : 3 * N_SMPLH_BODY_JOINTS].reshape(T, N_SMPLH_BODY_JOINTS, 3)
    L = axis_angle_to_matrix(aa)
    G_amass = global_from_local(L)
    return smpl_rest_to_ours(G_amass)


def global_to_amass_poses(R: np.ndarray) -> np.ndarray:
    """Our global orientations (T, 24, 3, 3) -> SMPL-H ``poses`` (T, 156) axis-angle; the
    hand joints (and our finger segments' own rotation) are written as zero."""
    R = np.asarray(R, dtype=np.float64)
    G_amass = ours_to_smpl_rest(R)
    L = local_from_global(G_amass)
    aa = matrix_to_axis_angle(L[:, :N_SMPLH_BODY_JOINTS])
    out = np.zeros((R.shape[0], N_SMPLH_POSE))
    out[:, : 3 * N_SMPLH_BODY_JOINTS] = aa.reshape(R.shape[0], -1)
    return out


__all__ = [
    "SMPL_TO_OURS", "smpl_rest_to_ours", "ours_to_smpl_rest", "amass_poses_to_global",
    "global_to_amass_poses", "N_SMPLH_POSE",
]
