"""The knee as a hinge: a kinematic prior applied to reconstructed orientations.

A small model given the pelvis and a shank sensor predicts the thigh with as much
twist and ab/adduction error as flexion error, although the knee barely allows any:
in every dataset here the knee's local rotation lies on one axis, the thigh's lateral
(y) axis of our T-pose (mean deviation off that axis: HDM05 0.0 deg, its knees are
1-DoF in the ASF files; Bandai 0.2-0.3 deg, measured in docs/model.md, "Output filters and joint constraints").
So when one side of a knee is measured, the other side is the measured one turned
about that axis, and only the flexion angle is left to the model: the
reconstruction keeps the model's flexion and takes everything else from the sensor.

Elbows are not treated this way: a forearm sensor turns with pronation, a twist about
the forearm the elbow's hinge does not constrain. Both datasets' forearms carry it
(HDM05's from its wrist bone, see joint_maps.ASF; Bandai's in its forearm bone).
"""

from __future__ import annotations

import torch
from torch import Tensor

from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import SEGMENT_INDEX

KNEE_AXIS = (0.0, 1.0, 0.0)  # in the thigh's frame (our T-pose: lateral)
KNEES: tuple[tuple[int, int], ...] = tuple(
    (SEGMENT_INDEX[f"{s}_thigh"], SEGMENT_INDEX[f"{s}_shank"]) for s in ("l", "r")
)


def hinge_angle(local: Tensor, axis: Tensor) -> Tensor:
    """Angle of the rotation about ``axis`` closest (Frobenius) to ``local`` (..., 3, 3)."""
    skew = 0.5 * torch.stack([local[..., 2, 1] - local[..., 1, 2], local[..., 0, 2] - local[..., 2, 0],
                              local[..., 1, 0] - local[..., 0, 1]], dim=-1)
    s = skew @ axis
    along = torch.einsum("i,...ij,j->...", axis, local, axis)
    c = 0.5 * (local.diagonal(dim1=-2, dim2=-1).sum(-1) - along)
    return torch.atan2(s, c)


_THIGHS = [t for t, _ in KNEES]
_SHANKS = [s for _, s in KNEES]


def constrain_knees(R: Tensor, measured: Tensor) -> Tensor:
    """Global orientations (..., 24, 3, 3) with each knee made a hinge about KNEE_AXIS.

    measured (..., 24) bool: segments whose orientation is a measurement, never changed.
    Shank measured, thigh not: the thigh is rebuilt from the shank and the predicted
    flexion. Thigh measured, shank not, or neither: the shank is rebuilt from the thigh
    (with neither measured the model's thigh is kept; it carries the hip's three
    degrees of freedom, the shank only adds flexion). Both measured: unchanged.
    """
    axis = torch.tensor(KNEE_AXIS, dtype=R.dtype)
    Rt, Rs = R[..., _THIGHS, :, :], R[..., _SHANKS, :, :]  # (..., 2, 3, 3), both knees at once
    theta = hinge_angle(Rt.transpose(-1, -2) @ Rs, axis)
    hinge = matrix_about_axis(axis.expand(*theta.shape, 3), theta)
    mt, ms = measured[..., _THIGHS], measured[..., _SHANKS]
    out = R.clone()
    out[..., _THIGHS, :, :] = torch.where((ms & ~mt)[..., None, None], Rs @ hinge.transpose(-1, -2), Rt)
    out[..., _SHANKS, :, :] = torch.where((~ms)[..., None, None], Rt @ hinge, Rs)
    return out
