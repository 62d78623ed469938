"""Write motion of our 24-segment body as BVH, so reconstructions and ground truth can be
looked at in Blender, MotionBuilder, bvhacker or checked with other tools.

Conventions of the file (chosen so common tools and our own loader read it as it is):
- Units: **metres** (offsets and root positions). Our BVH loader picks the unit that
  makes a plausible body height; metres are unambiguous there (cm could be mistaken for
  inches when the first frame is a deep crouch).
- Axes: BVH's usual Y-up, character facing +Z, +X to the character's left. Our world is
  Z-up facing +X with +Y left, so a vector v (ours) is written as A v with
  A = [[0,1,0],[0,0,1],[1,0,0]] (a proper rotation: the handedness is unchanged).
- Joint names: the CMU 31-joint names for our 24 segments (Hips, LowerBack, Spine,
  Spine1, Neck, Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand, LeftFingerBase,
  LeftUpLeg, LeftLeg, LeftFoot, LeftToeBase, ...), which most tools and our loader map.
- Rest pose (all channels 0) = our T-pose with the subject's own bone offsets; leaf
  segments (head, toes, fingers) end in an End Site along their T-pose direction.
- Channels: root "Xposition Yposition Zposition Zrotation Xrotation Yrotation", others
  "Zrotation Xrotation Yrotation": intrinsic ZXY Euler angles in degrees of the local
  (parent-relative) rotation, R_local = Rz(a) Rx(b) Ry(c).

Round trip: our loader reads the file back to the same joint positions for any body,
and to the same orientations whenever the body's bones point along our T-pose
directions, which holds for every body the loaders produce (they retarget onto those
directions). For an anthropometric ``Body.from_height`` body the loader re-derives the
pelvis and neck frames from their slightly tilted bones (about 10 degrees), so those two
segments' orientations differ while all positions still match.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from inference.body.body import Body, local_from_global
from inference.body.motion import Motion
from inference.body.rotations import matrix_to_euler
from inference.body.skeleton import N_SEGMENTS, PARENTS, SEGMENTS

# ours -> BVH axes (module docstring)
A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

BVH_NAMES: dict[str, str] = {
    "pelvis": "Hips", "spine1": "LowerBack", "spine2": "Spine", "spine3": "Spine1", "neck": "Neck",
    "head": "Head",
}
for _side, _long in (("l", "Left"), ("r", "Right")):
    BVH_NAMES.update({
        f"{_side}_collar": f"{_long}Shoulder", f"{_side}_upperarm": f"{_long}Arm",
        f"{_side}_forearm": f"{_long}ForeArm", f"{_side}_hand": f"{_long}Hand",
        f"{_side}_fingers": f"{_long}FingerBase", f"{_side}_thigh": f"{_long}UpLeg",
        f"{_side}_shank": f"{_long}Leg", f"{_side}_foot": f"{_long}Foot", f"{_side}_toes": f"{_long}ToeBase",
    })
assert set(BVH_NAMES) == set(SEGMENTS)

_CHILDREN: dict[int, list[int]] = {i: [c for c in range(N_SEGMENTS) if PARENTS[c] == i] for i in range(N_SEGMENTS)}


def _end_site(seg: int, height: float) -> np.ndarray:
    """End-site offset (ours) of a leaf segment: along its T-pose direction."""
    name = SEGMENTS[seg]
    if name == "head":
        return np.array([0.0, 0.0, 0.13 * height])
    if name.endswith("toes"):
        return np.array([0.03 * height, 0.0, 0.0])
    sign = 1.0 if name.startswith("l_") else -1.0  # fingers
    return np.array([0.0, sign * 0.05 * height, 0.0])


def _fmt(v: np.ndarray) -> str:
    return " ".join(f"{x:.6f}" for x in v)


def bvh_text(rot: np.ndarray, root: np.ndarray, body: Body, fps: float) -> str:
    """BVH file contents for global orientations rot (T, 24, 3, 3) and root positions
    (T, 3) (metres, our world) on `body`, at `fps`."""
    rot = np.asarray(rot, dtype=np.float64)
    root = np.asarray(root, dtype=np.float64)
    T = rot.shape[0]
    if rot.shape != (T, N_SEGMENTS, 3, 3) or root.shape != (T, 3):
        raise ValueError(f"bvh: expected rot (T,24,3,3) and root (T,3), got {rot.shape} and {root.shape}")
    if not fps > 0:
        raise ValueError(f"bvh: fps must be positive, got {fps}")
    lines: list[str] = ["HIERARCHY"]
    order: list[int] = []

    def joint(i: int, depth: int) -> None:
        ind = "  " * depth
        head = "ROOT" if i == 0 else "JOINT"
        off = np.zeros(3) if i == 0 else A @ body.offsets[i]
        lines.append(f"{ind}{head} {BVH_NAMES[SEGMENTS[i]]}")
        lines.append(f"{ind}{{")
        lines.append(f"{ind}  OFFSET {_fmt(off)}")
        if i == 0:
            lines.append(f"{ind}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            lines.append(f"{ind}  CHANNELS 3 Zrotation Xrotation Yrotation")
        order.append(i)
        kids = _CHILDREN[i]
        for c in kids:
            joint(c, depth + 1)
        if not kids:
            lines.append(f"{ind}  End Site")
            lines.append(f"{ind}  {{")
            lines.append(f"{ind}    OFFSET {_fmt(A @ _end_site(i, body.height))}")
            lines.append(f"{ind}  }}")
        lines.append(f"{ind}}}")

    joint(0, 0)
    # local rotations in BVH axes: A L A^T, as intrinsic ZXY degrees
    L = local_from_global(rot)
    L_bvh = A @ L @ A.T
    eul = np.rad2deg(matrix_to_euler(L_bvh[:, order], "ZXY"))  # (T, 24, 3)
    pos = root @ A.T
    lines += ["MOTION", f"Frames: {T}", f"Frame Time: {1.0 / fps:.12f}"]
    for t in range(T):
        lines.append(_fmt(pos[t]) + " " + _fmt(eul[t].reshape(-1)))
    return "\n".join(lines) + "\n"


def write_bvh(path: str | os.PathLike, rot: np.ndarray, root: np.ndarray, body: Body, fps: float) -> Path:
    """Write a BVH file (see the module docstring for units and axes); returns the path.
    Written to a temporary name first, so a crash never leaves a truncated file."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(bvh_text(rot, root, body, fps))
    os.replace(tmp, path)
    return path


def write_motion_bvh(path: str | os.PathLike, motion: Motion) -> Path:
    """A Motion as BVH at its own frame rate."""
    return write_bvh(path, motion.rot, motion.root, motion.body, motion.fps)


__all__ = ["A", "BVH_NAMES", "bvh_text", "write_bvh", "write_motion_bvh"]

