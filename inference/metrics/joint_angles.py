"""Joint angles, defined once: knee, hip, ankle, elbow, pelvis (and the rest of the
OpenSim coordinates) from global segment orientations of our skeleton.

Every part of imucap that shows or writes a joint angle takes it from here: the outdoor
view's gait numbers (``inference.metrics.gait``), validation (``app.validate``), the
OpenSim exports (``app.export.opensim``, ``.mot``) and the gait report. One definition
means the knee range a runner sees, the one in a validation report and the one in a
``.mot`` file of the same recording are the same number.

Input: ``R`` (T, 24, 3, 3) global segment orientations (R_WB, our world: X forward, Y
left, Z up), indexed by ``inference.body.skeleton.SEGMENTS``; in our T-pose every
segment frame is the identity. Output: (T,) arrays in degrees, unwrapped over time (no
360-degree jumps when the subject turns round). ``side`` is ``'l'`` or ``'r'``.

Convention: the joint coordinate system of the ISB recommendations (Grood & Suntay 1983;
Wu et al. 2002 for hip and ankle, Wu et al. 2005 for the upper limb) as OpenSim's models
implement it (Rajagopal et al. 2016, ``Rajagopal2015.osim``; the same names and signs as
its descendants, e.g. OpenCap's Lai-Uhlrich model): a joint's rotation is the distal
body's frame in the proximal body's frame, L = G_parent^T G_child, decomposed as a
body-fixed Z-X-Y sequence, L = Rz(a) Rx(b) Ry(c), in OpenSim's body frames (X anterior,
Y superior, Z to the subject's right, every body frame aligned with ground in OpenSim's
default pose: upright, legs straight, arms hanging, palms forward). So

- a (about Z, the medio-lateral axis of the proximal body): flexion / extension,
- b (about the floating X, anterior): ab- / adduction (or list / obliquity),
- c (about Y, the long axis of the distal body): internal / external rotation.

Signs, as OpenSim's coordinates (the left side mirrored as the model mirrors it, so a
left and a right angle of the same movement have the same sign):

===========================  ==========================================  ==================
function                     positive                                    OpenSim coordinate
===========================  ==========================================  ==================
``knee_flexion_deg``         flexion (0 = straight)                      ``knee_angle_<s>``
``hip_angles_deg``           flexion, adduction, internal rotation       ``hip_flexion_<s>``,
                                                                         ``hip_adduction_<s>``,
                                                                         ``hip_rotation_<s>``
``ankle_dorsiflexion_deg``   dorsiflexion (0 = foot at 90 deg to shank)  ``ankle_angle_<s>``
``elbow_flexion_deg``        flexion (0 = straight)                      ``elbow_flex_<s>``
``pelvis_angles_deg``        tilt: posterior (anterior tilt negative,    ``pelvis_tilt``,
                             OpenSim's sign; clinical reports (Plug-in    ``pelvis_list``,
                             Gait) negate it); obliquity: right side     ``pelvis_rotation``
                             down; rotation: turned to the left (about
                             the vertical, counter-clockwise from above)
===========================  ==========================================  ==================

Gait2392 counts knee flexion negative: negate ``knee_angle_*`` for it.

How our frames become OpenSim's: a vector maps as v_os = M_OS v with
M_OS = [[1,0,0],[0,0,1],[0,-1,0]] (a proper rotation). Each OpenSim body frame is our
segment frame turned by that segment's orientation Q in OpenSim's default pose:
G_os = M_OS R Q^T M_OS^T, with Q = identity for pelvis, legs and trunk, the arm lowered
90 deg about the forward axis for the upper arm, and additionally turned 90 deg about the
vertical to palms forward for the forearm (our T-pose has the palms down).

Approximations (name them when publishing numbers): one segment pair per joint on
principal axes (the model's oblique ankle and elbow axes are taken as the frame's Z),
the knee's coupled small adduction, rotation and translation are not modelled, lumbar is
pelvis -> spine3, shoulder is spine3 -> upper arm (the collar lumped in).

Why not the total rotation angle between thigh and shank (as the gait numbers once
used): it adds the knee's few degrees of ab/adduction and rotation (and any sensor twist
error) to the flexion; why not the hinge angle between joint centres (as validation once
used): it has no sign (hyperextension reads as flexion) and is not what OpenSim reports.
A marker reference builds segment frames from its joint centres and comes through here too
(``app.validate.kinematics``).
"""

from __future__ import annotations

import numpy as np

from inference.body.conventions import rot_z
from inference.body.rotations import matrix_about_axis, matrix_to_euler
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX

__all__ = [
    "M_OS", "JOINTS", "SIDES", "opensim_default_pose", "opensim_frames", "joint_euler_deg",
    "coordinates_deg", "knee_flexion_deg", "hip_angles_deg", "ankle_dorsiflexion_deg",
    "elbow_flexion_deg", "pelvis_angles_deg", "lumbar_angles_deg", "shoulder_angles_deg",
]

# ours (X fwd, Y left, Z up) -> OpenSim ground (X fwd, Y up, Z right)
M_OS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])

SIDES = ("l", "r")

# (OpenSim joint, parent segment or None for ground, child segment,
#  ((coordinate, index into the Z-X-Y angles, sign), ...)) -- Rajagopal's joints and signs
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
_JOINT = {j[0]: j for j in JOINTS}


def _rx(deg: float) -> np.ndarray:
    return matrix_about_axis(np.array([1.0, 0.0, 0.0]), np.deg2rad(deg))


def opensim_default_pose() -> np.ndarray:
    """(24, 3, 3) our global segment orientations in OpenSim's default pose: upright, arms
    hanging (lowered 90 deg about the forward axis), forearms and hands turned palms
    forward (our T-pose has palms down). Mirror-symmetric left/right by construction.
    A read-only constant, made once (the live gait numbers ask for it a few times a second)."""
    return _DEFAULT_POSE


def _make_default_pose() -> np.ndarray:
    Q = np.broadcast_to(np.eye(3), (N_SEGMENTS, 3, 3)).copy()
    for side, down, palm in (("l", -90.0, 90.0), ("r", 90.0, -90.0)):
        Q[SEGMENT_INDEX[f"{side}_upperarm"]] = _rx(down)
        for seg in ("forearm", "hand", "fingers"):
            Q[SEGMENT_INDEX[f"{side}_{seg}"]] = rot_z(np.deg2rad(palm)) @ _rx(down)
    Q.flags.writeable = False
    return Q


_DEFAULT_POSE = _make_default_pose()


def opensim_frames(R: np.ndarray, segments: list[str] | None = None) -> np.ndarray:
    """OpenSim body frames in OpenSim's ground, G_os = M_OS R Q^T M_OS^T, of the given
    segments (all 24 when None): (T, len(segments), 3, 3)."""
    R = np.asarray(R, dtype=np.float64)
    idx = list(range(N_SEGMENTS)) if segments is None else [SEGMENT_INDEX[s] for s in segments]
    Q = opensim_default_pose()[idx]
    return M_OS @ R[:, idx] @ np.swapaxes(Q, -1, -2) @ M_OS.T


def _euler(R: np.ndarray, parent: str | None, child: str) -> np.ndarray:
    """(T, 3) Z-X-Y angles (rad, unwrapped over time) of child in parent (ground if None)."""
    segs = [child] if parent is None else [parent, child]
    G = opensim_frames(R, segs)
    L = G[:, 0] if parent is None else np.swapaxes(G[:, 0], -1, -2) @ G[:, 1]
    if L.shape[0] == 0:
        return np.zeros((0, 3))
    return np.unwrap(matrix_to_euler(L, "ZXY"), axis=0)


def joint_euler_deg(R: np.ndarray, joint: str) -> dict[str, np.ndarray]:
    """coordinate -> (T,) degrees, for one OpenSim joint of ``JOINTS`` (e.g. ``'hip_l'``)."""
    name, parent, child, coords = _JOINT[joint]
    eul = np.rad2deg(_euler(R, parent, child))
    return {c: sign * eul[:, k] for c, k, sign in coords}


def coordinates_deg(R: np.ndarray) -> dict[str, np.ndarray]:
    """Every rotational coordinate of ``JOINTS`` -> (T,) degrees (OpenSim's names)."""
    out: dict[str, np.ndarray] = {}
    for joint in _JOINT:
        out.update(joint_euler_deg(R, joint))
    return out


def _side(side: str) -> str:
    if side not in SIDES:
        raise ValueError(f"side must be 'l' or 'r', not {side!r}")
    return side


def knee_flexion_deg(R: np.ndarray, side: str) -> np.ndarray:
    """(T,) knee flexion (deg), positive flexed, 0 straight; OpenSim's ``knee_angle_<side>``."""
    s = _side(side)
    return joint_euler_deg(R, f"knee_{s}")[f"knee_angle_{s}"]


def hip_angles_deg(R: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flexion, adduction, internal rotation), each (T,) deg, of the thigh in the pelvis."""
    s = _side(side)
    c = joint_euler_deg(R, f"hip_{s}")
    return c[f"hip_flexion_{s}"], c[f"hip_adduction_{s}"], c[f"hip_rotation_{s}"]


def ankle_dorsiflexion_deg(R: np.ndarray, side: str) -> np.ndarray:
    """(T,) ankle dorsiflexion (deg), plantarflexion negative; OpenSim's ``ankle_angle_<side>``."""
    s = _side(side)
    return joint_euler_deg(R, f"ankle_{s}")[f"ankle_angle_{s}"]


def elbow_flexion_deg(R: np.ndarray, side: str) -> np.ndarray:
    """(T,) elbow flexion (deg), 0 straight; OpenSim's ``elbow_flex_<side>``."""
    s = _side(side)
    return joint_euler_deg(R, f"elbow_{s}")[f"elbow_flex_{s}"]


def pelvis_angles_deg(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(tilt, obliquity, rotation), each (T,) deg, of the pelvis in the world (OpenSim's
    ``pelvis_tilt, pelvis_list, pelvis_rotation``; signs in the module docstring). The
    rotation is the pelvis's heading, so it carries the subject's turns."""
    c = joint_euler_deg(R, "ground_pelvis")
    return c["pelvis_tilt"], c["pelvis_list"], c["pelvis_rotation"]


def lumbar_angles_deg(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(extension, bending, rotation), each (T,) deg, of spine3 in the pelvis."""
    c = joint_euler_deg(R, "back")
    return c["lumbar_extension"], c["lumbar_bending"], c["lumbar_rotation"]


def shoulder_angles_deg(R: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(flexion, adduction, rotation), each (T,) deg, of the upper arm in spine3."""
    s = _side(side)
    c = joint_euler_deg(R, f"acromial_{s}")
    return c[f"arm_flex_{s}"], c[f"arm_add_{s}"], c[f"arm_rot_{s}"]
