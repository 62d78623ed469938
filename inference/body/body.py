"""The 24-segment body: rest-pose bone offsets, sensor sites, foot contact points, and
forward kinematics from global segment orientations.

Offsets come either from body height through anthropometric segment ratios or from a
source skeleton (retargeting), so a clip keeps the bone lengths it was captured with and
its feet stay planted. The rest pose is the T-pose: every segment's global orientation
is the identity, the subject faces +X, left is +Y, up is +Z.

Height ratios: Drillis, R. & Contini, R. (1966), "Body Segment Parameters", Report
1166-03, New York University, School of Engineering and Science; as tabulated in
Winter, D. A., "Biomechanics and Motor Control of Human Movement", 4th ed., Wiley 2009,
Fig. 4.1 (segment lengths as fractions of body height H). Values used: hip joint
height 0.530 H, knee 0.285 H, ankle 0.039 H, foot length 0.152 H, shoulder height
0.818 H, chin 0.870 H, shoulder width 0.259 H, hip width 0.191 H, upper arm 0.186 H,
forearm 0.146 H, hand 0.108 H. The split of the trunk between spine1..3 and neck has no
line in that table; it follows SMPL's proportions.

Forward kinematics works on numpy arrays and torch tensors alike (same code path), so the
training losses and the synthesis use one implementation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from inference.body.rotations import matrix_about_axis
from inference.body.skeleton import (
    N_SEGMENTS,
    PARENTS,
    SEGMENT_INDEX,
    SITE_SEGMENT_INDEX,
    SITES,
)

# Drillis & Contini fractions of body height (see module docstring)
HIP_Z, KNEE_Z, ANKLE_Z = 0.530, 0.285, 0.039
FOOT_LEN = 0.152
SHOULDER_Z, CHIN_Z = 0.818, 0.870
SHOULDER_W, HIP_W = 0.259, 0.191
UPPERARM, FOREARM, HAND = 0.186, 0.146, 0.108
HEAD_TOP_ABOVE_CHIN = 1.0 - CHIN_Z

# contact points: (segment carrying it) for l_heel, l_toe, r_heel, r_toe
CONTACT_SEGMENTS: tuple[int, ...] = (
    SEGMENT_INDEX["l_foot"], SEGMENT_INDEX["l_toes"], SEGMENT_INDEX["r_foot"], SEGMENT_INDEX["r_toes"],
)

# where along its bone each site sits (fraction of the bone from the segment's joint to
# its main child) and how far out from the bone on the skin, as a fraction of height,
# in the segment's rest frame. Limbs: distal (paper, sec. 3.1); pelvis: sacrum; torso: sternum.
_SITE_PLACEMENT: dict[str, tuple[float, tuple[float, float, float]]] = {
    "pelvis": (0.0, (-0.055, 0.0, 0.02)),
    "torso": (0.6, (0.06, 0.0, 0.0)),
    "head": (0.5, (0.06, 0.0, 0.03)),
    "l_upperarm": (0.75, (0.0, 0.0, 0.025)),
    "r_upperarm": (0.75, (0.0, 0.0, 0.025)),
    "l_wrist": (0.9, (0.0, 0.0, 0.02)),
    "r_wrist": (0.9, (0.0, 0.0, 0.02)),
    "l_thigh": (0.75, (0.045, 0.0, 0.0)),
    "r_thigh": (0.75, (0.045, 0.0, 0.0)),
    "l_shank": (0.8, (0.03, 0.0, 0.0)),
    "r_shank": (0.8, (0.03, 0.0, 0.0)),
    "l_foot": (0.5, (0.0, 0.0, 0.025)),
    "r_foot": (0.5, (0.0, 0.0, 0.025)),
}

# the child that defines each segment's bone direction (end of the segment)
MAIN_CHILD: dict[int, int] = {
    SEGMENT_INDEX[a]: SEGMENT_INDEX[b]
    for a, b in [
        ("pelvis", "spine1"), ("l_thigh", "l_shank"), ("r_thigh", "r_shank"), ("spine1", "spine2"),
        ("l_shank", "l_foot"), ("r_shank", "r_foot"), ("spine2", "spine3"), ("l_foot", "l_toes"),
        ("r_foot", "r_toes"), ("spine3", "neck"), ("neck", "head"), ("l_collar", "l_upperarm"),
        ("r_collar", "r_upperarm"), ("l_upperarm", "l_forearm"), ("r_upperarm", "r_forearm"),
        ("l_forearm", "l_hand"), ("r_forearm", "r_hand"), ("l_hand", "l_fingers"), ("r_hand", "r_fingers"),
    ]
}


def _mirror_y(v: tuple[float, float, float]) -> tuple[float, float, float]:
    return (v[0], -v[1], v[2])


def anthropometric_offsets(height: float) -> np.ndarray:
    """Rest-pose offsets (24, 3) in metres of each joint from its parent joint for a body
    of the given height, from the Drillis & Contini ratios (module docstring)."""
    h = float(height)
    pelvis_z = 0.56
    left = {
        "l_thigh": (0.0, 0.55 * HIP_W / 2, HIP_Z - pelvis_z),
        "l_shank": (0.0, 0.0, KNEE_Z - HIP_Z),
        "l_foot": (0.0, 0.0, ANKLE_Z - KNEE_Z),
        "l_toes": (0.5 * FOOT_LEN, 0.0, -0.6 * ANKLE_Z),
        "l_collar": (0.0, 0.03, 0.045),
        "l_upperarm": (0.0, SHOULDER_W / 2 - 0.03, SHOULDER_Z - 0.805),
        "l_forearm": (0.0, UPPERARM, 0.0),
        "l_hand": (0.0, FOREARM, 0.0),
        "l_fingers": (0.0, 0.45 * HAND, 0.0),
    }
    centre = {
        "spine1": (0.0, 0.0, 0.06),
        "spine2": (0.0, 0.0, 0.07),
        "spine3": (0.0, 0.0, 0.07),
        "neck": (0.0, 0.0, 0.06),
        "head": (0.0, 0.0, CHIN_Z - 0.82),
    }
    off = np.zeros((N_SEGMENTS, 3))
    for name, v in centre.items():
        off[SEGMENT_INDEX[name]] = v
    for name, v in left.items():
        off[SEGMENT_INDEX[name]] = v
        off[SEGMENT_INDEX["r" + name[1:]]] = _mirror_y(v)
    return off * h


@dataclass(frozen=True)
class Body:
    """A body's rest-pose geometry.

    offsets: (24, 3) joint i relative to its parent joint, in the parent's rest frame (m).
    site_offsets: (13, 3) each site relative to its segment's joint, in the segment frame.
    contact_offsets: (4, 3) heel/toe points relative to their segment's joint.
    height: standing height (m).
    """

    offsets: np.ndarray
    height: float
    site_offsets: np.ndarray = field(repr=False)
    contact_offsets: np.ndarray = field(repr=False)

    @classmethod
    def from_height(cls, height: float = 1.75) -> Body:
        if not 0.5 < height < 2.8:
            raise ValueError(f"body height {height} m is not a human height")
        return cls.from_offsets(anthropometric_offsets(height), height)

    @classmethod
    def from_offsets(cls, offsets: np.ndarray, height: float | None = None) -> Body:
        """Body from source-skeleton offsets; sites and contact points are placed on the
        bones the source defines, with skin offsets and foot geometry scaled by height."""
        offsets = np.asarray(offsets, dtype=np.float64).reshape(N_SEGMENTS, 3).copy()
        offsets[0] = 0.0
        if not np.all(np.isfinite(offsets)):
            raise ValueError("body offsets contain NaN or infinite values")
        if height is None:
            height = estimate_height(offsets)
        h = float(height)
        sites = np.zeros((len(SITES), 3))
        for k, name in enumerate(SITES):
            seg = SITE_SEGMENT_INDEX[k]
            frac, skin = _SITE_PLACEMENT[name]
            bone = offsets[MAIN_CHILD[seg]] if seg in MAIN_CHILD else np.zeros(3)
            skin_v = np.array(skin) * h
            if name.startswith("r_"):
                skin_v[1] = -skin_v[1]
            sites[k] = frac * bone + skin_v
        contacts = np.zeros((4, 3))
        for side, (heel_i, toe_i) in (("l", (0, 1)), ("r", (2, 3))):
            toes_off = offsets[SEGMENT_INDEX[f"{side}_toes"]]
            ground_z = toes_off[2] - 0.012 * h  # ball-of-foot joint sits ~2 cm above the sole
            contacts[heel_i] = (-0.2 * FOOT_LEN * h, 0.0, ground_z)
            contacts[toe_i] = (0.3 * FOOT_LEN * h, 0.0, -0.012 * h)
        return cls(offsets=offsets, height=h, site_offsets=sites, contact_offsets=contacts)

    def rest_joints(self) -> np.ndarray:
        """(24, 3) joint positions in the T-pose with the root at the origin."""
        R = np.broadcast_to(np.eye(3), (N_SEGMENTS, 3, 3))
        return forward_kinematics(R, np.zeros(3), self.offsets)

    def bone_lengths(self) -> np.ndarray:
        return np.linalg.norm(self.offsets, axis=-1)


def estimate_height(offsets: np.ndarray) -> float:
    """Standing height from rest offsets: floor (sole) to the head's chin-level joint,
    divided by the chin-height ratio, so a skeleton without a head-top point still gets a
    sensible figure."""
    R = np.broadcast_to(np.eye(3), (N_SEGMENTS, 3, 3))
    j = forward_kinematics(R, np.zeros(3), offsets)
    foot_z = min(j[SEGMENT_INDEX["l_toes"], 2], j[SEGMENT_INDEX["r_toes"], 2])
    head_z = j[SEGMENT_INDEX["head"], 2]
    # toes joint ~1.2% of height above the sole: solve (head - foot) = (CHIN_Z - 0.012) H
    return float((head_z - foot_z) / (CHIN_Z - 0.012))


def _xp(a: Any):
    if isinstance(a, np.ndarray):
        return np
    import torch

    return torch


def _as_like(value: Any, like: Any):
    if isinstance(like, np.ndarray):
        return np.asarray(value, dtype=like.dtype)
    import torch

    if isinstance(value, torch.Tensor):
        return value.to(dtype=like.dtype, device=like.device)
    return torch.as_tensor(np.asarray(value), dtype=like.dtype, device=like.device)


def forward_kinematics(R: Any, root: Any, offsets: Any) -> Any:
    """Joint positions (..., 24, 3) from global segment orientations R (..., 24, 3, 3),
    root (pelvis joint) positions (..., 3) and rest offsets (24, 3) or (..., 24, 3).

    Because orientations are global, each joint is its parent plus the parent's rotation
    applied to the offset; no chain of local products is needed, and numpy and torch take
    the same path (differentiable in torch)."""
    xp = _xp(R)
    offsets = _as_like(offsets, R)
    # rotated offsets of every joint by its parent's orientation, all at once
    parents = list(PARENTS)
    par = [max(p, 0) for p in parents]
    rot_off = (R[..., par, :, :] @ offsets[..., :, :, None])[..., 0]  # (..., 24, 3)
    joints = [None] * N_SEGMENTS
    joints[0] = root + 0 * rot_off[..., 0, :]
    for i in range(1, N_SEGMENTS):
        joints[i] = joints[parents[i]] + rot_off[..., i, :]
    return xp.stack(joints, axis=-2) if xp is np else xp.stack(joints, dim=-2)


def points_on_segments(R: Any, joints: Any, segments: tuple[int, ...] | list[int], local: Any) -> Any:
    """World positions (..., K, 3) of K points fixed on segments (local offsets (K, 3) from
    each segment's joint, in the segment frame)."""
    seg = list(segments)
    local = _as_like(local, R)
    return joints[..., seg, :] + (R[..., seg, :, :] @ local[..., :, :, None])[..., 0]


def site_positions(R: Any, joints: Any, body: Body) -> Any:
    """(..., 13, 3) world positions of the 13 sensor sites."""
    return points_on_segments(R, joints, SITE_SEGMENT_INDEX, body.site_offsets)


def contact_points(R: Any, joints: Any, body: Body | Any) -> Any:
    """(..., 4, 3) world positions of l_heel, l_toe, r_heel, r_toe. `body` may be a Body
    or the (4, 3) contact offsets directly (training code carries arrays, not Bodies)."""
    local = body.contact_offsets if isinstance(body, Body) else body
    return points_on_segments(R, joints, CONTACT_SEGMENTS, local)


def local_from_global(R: Any) -> Any:
    """Parent-relative joint rotations (..., 24, 3, 3) from global orientations; the root
    keeps its global orientation."""
    xp = _xp(R)
    par = [max(p, 0) for p in PARENTS]
    Rp = R[..., par, :, :]
    Rt = Rp.swapaxes(-1, -2) if xp is np else Rp.transpose(-1, -2)
    L = Rt @ R
    if xp is np:
        L = L.copy()
        L[..., 0, :, :] = R[..., 0, :, :]
        return L
    return xp.cat([R[..., :1, :, :], L[..., 1:, :, :]], dim=-3)


def global_from_local(L: Any) -> Any:
    """Global orientations from parent-relative rotations (inverse of local_from_global)."""
    xp = _xp(L)
    out = [None] * N_SEGMENTS
    out[0] = L[..., 0, :, :]
    for i in range(1, N_SEGMENTS):
        out[i] = out[PARENTS[i]] @ L[..., i, :, :]
    return xp.stack(out, axis=-3) if xp is np else xp.stack(out, dim=-3)


def tpose(n: int = 1) -> np.ndarray:
    """(n, 24, 3, 3) identity orientations: the rest (T) pose."""
    return np.broadcast_to(np.eye(3), (n, N_SEGMENTS, 3, 3)).copy()


def npose_rotations(n: int = 1, arm_down_deg: float = 80.0) -> np.ndarray:
    """(n, 24, 3, 3) the N-pose: the T-pose with the arms lowered by `arm_down_deg` about
    the forward axis (used as a standing, arms-by-the-side default)."""
    R = tpose(n)
    a = np.deg2rad(arm_down_deg)
    left = matrix_about_axis([1.0, 0.0, 0.0], -a)  # +Y (the left arm) turned toward -Z about X
    right = matrix_about_axis([1.0, 0.0, 0.0], a)
    for side, M in (("l", left), ("r", right)):
        for seg in ("upperarm", "forearm", "hand", "fingers"):
            R[:, SEGMENT_INDEX[f"{side}_{seg}"]] = M
    return R
