"""The joint angles a gait report shows, all from ``inference.metrics.joint_angles`` (ISB joint
coordinate systems as OpenSim's Rajagopal model; its names and signs).

Per side: hip flexion and adduction, knee flexion, ankle dorsiflexion, and the pelvis's tilt, obliquity
and rotation over that side's cycles. The pelvis rotation is its heading, which carries every turn of the
walk: over a cycle it is shown about its own mean (``cycle_angle``), the swing of the pelvis about the
line of walking.
"""

from __future__ import annotations

import numpy as np

from inference.metrics.joint_angles import (
    ankle_dorsiflexion_deg,
    hip_angles_deg,
    knee_flexion_deg,
    pelvis_angles_deg,
)

# name -> (label, sign note, segments it depends on ("{s}" the side))
ANGLES: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "hip_flexion": ("Hip flexion", "flexion +", ("pelvis", "{s}_thigh")),
    "hip_adduction": ("Hip adduction", "adduction +", ("pelvis", "{s}_thigh")),
    "knee_flexion": ("Knee flexion", "flexion +", ("{s}_thigh", "{s}_shank")),
    "ankle_dorsiflexion": ("Ankle dorsiflexion", "dorsiflexion +", ("{s}_shank", "{s}_foot")),
    "pelvis_tilt": ("Pelvis tilt", "posterior + (OpenSim)", ("pelvis",)),
    "pelvis_obliquity": ("Pelvis obliquity", "right side down +", ("pelvis",)),
    "pelvis_rotation": ("Pelvis rotation", "to the left +, about its cycle mean", ("pelvis",)),
}
RANGE_ANGLES = ("hip_flexion", "knee_flexion", "ankle_dorsiflexion")  # the ranges tabled per side


def segments_of(angle: str, side: str) -> tuple[str, ...]:
    return tuple(s.format(s=side) for s in ANGLES[angle][2])


def angle_series(R: np.ndarray) -> dict[str, dict[str, np.ndarray]]:
    """side -> angle name -> (T,) degrees, from (T, 24, 3, 3) global segment orientations."""
    R = np.asarray(R, dtype=np.float64)
    tilt, obliquity, rotation = pelvis_angles_deg(R)
    out: dict[str, dict[str, np.ndarray]] = {}
    for side in ("l", "r"):
        flex, add, _ = hip_angles_deg(R, side)
        out[side] = {
            "hip_flexion": flex, "hip_adduction": add, "knee_flexion": knee_flexion_deg(R, side),
            "ankle_dorsiflexion": ankle_dorsiflexion_deg(R, side),
            "pelvis_tilt": tilt, "pelvis_obliquity": obliquity, "pelvis_rotation": rotation,
        }
    return out


def cycle_angle(name: str, curves: np.ndarray) -> np.ndarray:
    """Curves (N, 101) of one angle over N cycles as the report shows them: the pelvis rotation about
    each cycle's own mean, the others as they are."""
    if name == "pelvis_rotation" and len(curves):
        return curves - curves.mean(axis=1, keepdims=True)
    return curves
