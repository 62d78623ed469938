"""A left-out segment's error split into what is constant over a log and what is not.

Against a left-out sensor, the yardstick's "truth" is that sensor after calibration, so a
mounting or calibration error of the reference sensor (it sits turned on its segment, or
its stand was not the pose assumed) shows as a rotation between reconstruction and sensor
that stays the same all log long, in the segment's own frame. ``constant_and_dynamic``
estimates that rotation as the mean of the per-frame relative rotations and reports its
angle (the constant part) and the mean error left once the sensor is turned by it (the
dynamic part: what the model gets wrong as the body moves). A model error that happens to be
constant (a segment held bent the whole log) lands in the constant part too: the split says
how much of the error a fixed re-mounting of the reference would remove, not whose fault it is.
"""

from __future__ import annotations

import numpy as np

from calibration.core import mean_rotation
from inference.body.rotations import matrix_angle_between


def constant_and_dynamic(R_pred: np.ndarray, R_ref: np.ndarray) -> tuple[float, float]:
    """(constant, dynamic) in degrees for segment orientations R_pred and R_ref (T, 3, 3),
    world from segment: the angle of C, the chordal mean of R_ref_t^T R_pred_t (the
    relative rotation in the segment's frame), and the mean over frames of the angle
    between R_pred_t and R_ref_t C."""
    R_pred = np.asarray(R_pred, dtype=float)
    R_ref = np.asarray(R_ref, dtype=float)
    if R_pred.shape != R_ref.shape or R_pred.ndim != 3 or len(R_pred) == 0:
        raise ValueError(f"expected two (T, 3, 3) arrays of one shape, T > 0; got {R_pred.shape} and {R_ref.shape}")
    D = np.swapaxes(R_ref, -1, -2) @ R_pred
    C = mean_rotation(D)
    constant = float(np.degrees(matrix_angle_between(C, np.eye(3))))
    dynamic = float(np.degrees(np.mean(matrix_angle_between(R_pred, R_ref @ C))))
    return constant, dynamic


__all__ = ["constant_and_dynamic"]
