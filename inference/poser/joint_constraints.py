"""The knee as a hinge: a kinematic prior applied to reconstructed orientations.

A small model given the pelvis and a shank sensor predicts the thigh with as much
twist and ab/adduction error as flexion error, although the knee barely allows any:
in every dataset here the knee's local rotation lies on one axis, the thigh's lateral
(y) axis of our T-pose (mean deviation off that axis: HDM05 0.0 deg, its knees are
1-DoF in the ASF files; Bandai 0.2-0.3 deg, measured in docs/model.md, "Output filters and joint constraints").
So when one side of a knee is measured, the other side is the measured one turned
about that axis, and only the flexion angle is left to the model: the
reconstruction keeps the model's flexion and takes everything else from the sensor.

A living knee is not quite a hinge: the shin turns about its long axis against the thigh
(5-15 deg through a stride, more when the body pivots on a planted foot in a turn), and the
motion capture skeletons the model learned from cannot show it. Where the thigh is rebuilt
from a measured shank, ``twist`` keeps that share of the model's own turn of the thigh about
its long axis (z) away from the hinge's: 0 is the strict hinge, 1 the model's twist whole.
The poser chooses the share frame by frame, by how fast the body turns (``knee_twist``).

Elbows are not treated this way: a forearm sensor turns with pronation, a twist about
the forearm the elbow's hinge does not constrain. Both datasets' forearms carry it
(HDM05's from its wrist bone, see joint_maps.ASF; Bandai's in its forearm bone).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import Tensor

from inference.body.conventions import yaw_of
from inference.body.rotations import matrix_about_axis, matrix_about_axis_np
from inference.body.skeleton import SEGMENT_INDEX

KNEE_AXIS = (0.0, 1.0, 0.0)  # in the thigh's frame (our T-pose: lateral)
BONE_AXIS = (0.0, 0.0, 1.0)  # the thigh's long axis in its frame, what the shin turns about
KNEES: tuple[tuple[int, int], ...] = tuple(
    (SEGMENT_INDEX[f"{s}_thigh"], SEGMENT_INDEX[f"{s}_shank"]) for s in ("l", "r")
)


def hinge_angle(local: Tensor | np.ndarray, axis: Tensor | np.ndarray) -> Tensor | np.ndarray:
    """Angle of the rotation about ``axis`` closest (Frobenius) to ``local`` (..., 3, 3)
    (torch tensors, or numpy arrays for the live poser's per-frame path)."""
    if isinstance(local, np.ndarray):
        flat = local.reshape(*local.shape[:-2], 9)
        s = 0.5 * ((flat[..., _SKEW_PLUS] - flat[..., _SKEW_MINUS]) @ axis)
        c = 0.5 * (flat[..., _DIAG].sum(-1) - (local @ axis) @ axis)
        return np.arctan2(s, c)
    skew = 0.5 * torch.stack([local[..., 2, 1] - local[..., 1, 2], local[..., 0, 2] - local[..., 2, 0],
                              local[..., 1, 0] - local[..., 0, 1]], dim=-1)
    s = skew @ axis
    along = torch.einsum("i,...ij,j->...", axis, local, axis)
    c = 0.5 * (local.diagonal(dim1=-2, dim2=-1).sum(-1) - along)
    return torch.atan2(s, c)


# row-major entries of a 3x3 matrix: the skew part's (21 - 12, 02 - 20, 10 - 01) and the diagonal
_SKEW_PLUS, _SKEW_MINUS, _DIAG = np.array([7, 2, 3]), np.array([5, 6, 1]), np.array([0, 4, 8])


_THIGHS = [t for t, _ in KNEES]
_SHANKS = [s for _, s in KNEES]


def constrain_knees(R: Tensor | np.ndarray, measured: Tensor | np.ndarray,
                    twist: float = 0.0) -> Tensor | np.ndarray:
    """Global orientations (..., 24, 3, 3) with each knee made a hinge about KNEE_AXIS.

    measured (..., 24) bool: segments whose orientation is a measurement, never changed.
    Shank measured, thigh not: the thigh is rebuilt from the shank and the predicted
    flexion, then turned about its long axis by ``twist`` times the model thigh's own twist
    away from that hinge (0: the strict hinge; module docstring). Thigh measured, shank not,
    or neither: the shank is rebuilt from the thigh (with neither measured the model's thigh
    is kept; it carries the hip's three degrees of freedom, the shank only adds flexion).
    Both measured: unchanged.
    Numpy arrays in (the live poser's per-frame path): numpy out, the same formulas.
    """
    if isinstance(R, np.ndarray):
        return _constrain_knees_np(R, measured, twist)
    axis = torch.tensor(KNEE_AXIS, dtype=R.dtype)
    Rt, Rs = R[..., _THIGHS, :, :], R[..., _SHANKS, :, :]  # (..., 2, 3, 3), both knees at once
    theta = hinge_angle(Rt.transpose(-1, -2) @ Rs, axis)
    hinge = matrix_about_axis(axis.expand(*theta.shape, 3), theta)
    mt, ms = measured[..., _THIGHS], measured[..., _SHANKS]
    out = R.clone()
    thigh = Rs @ hinge.transpose(-1, -2)
    if twist:
        bone = torch.tensor(BONE_AXIS, dtype=R.dtype)
        # the turn about the bone (z) of the model thigh against the hinge's: the twist of their swing-twist split
        psi = twist * torch.as_tensor(yaw_of((thigh.transpose(-1, -2) @ Rt).detach().numpy()), dtype=R.dtype)
        thigh = thigh @ matrix_about_axis(bone.expand(*psi.shape, 3), psi)
    out[..., _THIGHS, :, :] = torch.where((ms & ~mt)[..., None, None], thigh, Rt)
    out[..., _SHANKS, :, :] = torch.where((~ms)[..., None, None], Rt @ hinge, Rs)
    return out


_THIGH_IDX, _SHANK_IDX = np.array(_THIGHS), np.array(_SHANKS)


def _constrain_knees_np(R: np.ndarray, measured: np.ndarray, twist: float) -> np.ndarray:
    mt, ms = measured.take(_THIGH_IDX, -1), measured.take(_SHANK_IDX, -1)
    fix_thigh, fix_shank = ms & ~mt, ~ms  # exclusive: the thigh is rebuilt only from a measured shank
    out = R.copy()
    if not (fix_thigh.any() or fix_shank.any()):
        return out
    axis = np.asarray(KNEE_AXIS, dtype=R.dtype)
    Rt, Rs = R.take(_THIGH_IDX, -3), R.take(_SHANK_IDX, -3)
    hinge = matrix_about_axis_np(axis, hinge_angle(np.swapaxes(Rt, -1, -2) @ Rs, axis))
    thigh = Rs @ np.swapaxes(hinge, -1, -2)
    if twist and fix_thigh.any():
        psi = twist * yaw_of(np.swapaxes(thigh, -1, -2) @ Rt)  # the twist about the bone (z) of their swing-twist split
        thigh = thigh @ matrix_about_axis_np(np.asarray(BONE_AXIS, dtype=R.dtype), psi)
    if R.ndim == 3:  # one frame: each knee on its own
        for k, (t, s) in enumerate(KNEES):
            if fix_thigh[k]:
                out[t] = thigh[k]
            elif fix_shank[k]:
                out[s] = Rt[k] @ hinge[k]
        return out
    out[..., _THIGH_IDX, :, :] = np.where(fix_thigh[..., None, None], thigh, Rt)
    out[..., _SHANK_IDX, :, :] = np.where(fix_shank[..., None, None], Rt @ hinge, Rs)
    return out
