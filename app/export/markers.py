"""Virtual markers of a reconstruction, as marker-based software expects them: one at
every joint centre and at the free ends of the leaf segments, named by the joint.

Names (in this order; ``l_``/``r_`` for left and right):

    pelvis (the root joint, between the hips), l_hip, r_hip, spine1, l_knee, r_knee,
    spine2, l_ankle, r_ankle, spine3, l_mtp, r_mtp (ball of the foot), neck,
    l_collar, r_collar (sternoclavicular), head (skull base), l_shoulder, r_shoulder,
    l_elbow, r_elbow, l_wrist, r_wrist, l_knuckles, r_knuckles,
    head_top, l_toe_tip, r_toe_tip, l_finger_tip, r_finger_tip (segment ends)

Joint ``i`` is where segment ``i`` starts (DESIGN.md), so the first 24 are the joint
positions the poser computes; the 5 ends sit along each leaf segment as in our BVH.
``app/validate`` reads the same names back (and the usual lab aliases).
"""

from __future__ import annotations

import numpy as np

from inference.body.body import Body, points_on_segments
from inference.body.skeleton import SEGMENT_INDEX, SEGMENTS
from inference.metrics.gait import debounced_contact

JOINT_NAMES: dict[str, str] = {
    "pelvis": "pelvis", "l_thigh": "l_hip", "r_thigh": "r_hip", "spine1": "spine1", "l_shank": "l_knee",
    "r_shank": "r_knee", "spine2": "spine2", "l_foot": "l_ankle", "r_foot": "r_ankle", "spine3": "spine3",
    "l_toes": "l_mtp", "r_toes": "r_mtp", "neck": "neck", "l_collar": "l_collar", "r_collar": "r_collar",
    "head": "head", "l_upperarm": "l_shoulder", "r_upperarm": "r_shoulder", "l_forearm": "l_elbow",
    "r_forearm": "r_elbow", "l_hand": "l_wrist", "r_hand": "r_wrist", "l_fingers": "l_knuckles",
    "r_fingers": "r_knuckles",
}
END_MARKERS: dict[str, str] = {"head_top": "head", "l_toe_tip": "l_toes", "r_toe_tip": "r_toes",
                               "l_finger_tip": "l_fingers", "r_finger_tip": "r_fingers"}


def marker_names() -> list[str]:
    return [JOINT_NAMES[s] for s in SEGMENTS] + list(END_MARKERS)


def _end_offset(seg: str, height: float) -> np.ndarray:
    """Where a leaf segment ends, in its own frame (as ``app.export.bvh``'s end sites)."""
    if seg == "head":
        return np.array([0.0, 0.0, 0.13 * height])
    if seg.endswith("toes"):
        return np.array([0.03 * height, 0.0, 0.0])
    return np.array([0.0, (1.0 if seg.startswith("l_") else -1.0) * 0.05 * height, 0.0])


def marker_positions(rot: np.ndarray, joints: np.ndarray, body: Body) -> np.ndarray:
    """(T, 29, 3) marker positions in our world (m), in ``marker_names()`` order."""
    segs = [SEGMENT_INDEX[s] for s in END_MARKERS.values()]
    local = np.stack([_end_offset(s, body.height) for s in END_MARKERS.values()])
    ends = points_on_segments(rot, joints, segs, local)
    return np.concatenate([joints, ends], axis=1)


def contact_events(time: np.ndarray, contacts: np.ndarray) -> list[tuple[float, str, str]]:
    """(time s, context 'Left'/'Right', 'Foot Strike' | 'Foot Off') from the contact
    flags (l_heel, l_toe, r_heel, r_toe): a strike when the foot's first point lands after
    both were up, an off when its last point leaves: the events gait software names so.
    Debounced as the gait numbers are (``gait.debounced_contact``): a foot up for less
    than ``gait.MIN_SWING_S`` was never up, so a flickering contact gives one strike and
    one off per step."""
    out = []
    for side, cols in (("Left", (0, 1)), ("Right", (2, 3))):
        down = debounced_contact(time, contacts[:, cols].any(axis=1))
        for k in np.flatnonzero(np.diff(down.astype(int)) != 0) + 1:
            out.append((float(time[k]), side, "Foot Strike" if down[k] else "Foot Off"))
    return sorted(out)


__all__ = ["JOINT_NAMES", "END_MARKERS", "marker_names", "marker_positions", "contact_events"]
