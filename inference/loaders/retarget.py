"""Retarget a source skeleton's animation onto our 24 segments.

Sources disagree on everything: which way is up, the units, the pose at zero rotation
(Bandai lies along X, HDM05 stands with legs apart, AMASS is a T-pose) and how many
joints the spine and hands have. The method here needs only the source's zero-pose
joint positions and global joint rotations:

1. Build the source's T-pose: for each source joint a global rotation Q_j that turns its
   zero-pose bone (towards the child mapped to our segment's end) onto our T-pose bone
   direction, by the smallest rotation from its parent's Q (so bone twist is inherited,
   not invented). The root is turned so its up (towards the spine) and left (right hip
   to left hip) match ours.
2. Our segment orientation is R_i(t) = W G_j(t) Q_j^T W^T, with W the fixed map from the
   source world (its up axis) to ours: identity in the T-pose, and it carries every bone
   of the source onto the corresponding bone of ours.
3. Our bone offsets are the source's T-pose joint differences (scaled to metres), so the
   retargeted body has the source's proportions and the feet stay where they were.
Segments the source lacks copy their parent's orientation; a split source bone (Bandai's
one chest bone for our spine2+spine3) keeps exact positions.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.body.body import MAIN_CHILD, Body, anthropometric_offsets
from inference.body.motion import Motion
from inference.body.rotations import (
    axis_angle_to_matrix,
    matrix_to_quat,
    quat_about_axis,
    quat_between_vectors,
    quat_to_matrix,
    triad,
)
from inference.body.skeleton import N_SEGMENTS, PARENTS, SEGMENT_INDEX, SEGMENTS

# our T-pose bone directions, the target of step 1 (unit vectors, our world frame)
_ANTHRO = anthropometric_offsets(1.0)
TPOSE_DIRECTIONS: dict[int, np.ndarray] = {
    i: _ANTHRO[c] / np.linalg.norm(_ANTHRO[c]) for i, c in MAIN_CHILD.items()
}
for _name in ("pelvis", "spine1", "spine2", "spine3", "neck", "head"):
    TPOSE_DIRECTIONS[SEGMENT_INDEX[_name]] = np.array([0.0, 0.0, 1.0])
for _side, _sign in (("l", 1.0), ("r", -1.0)):
    TPOSE_DIRECTIONS[SEGMENT_INDEX[f"{_side}_toes"]] = np.array([1.0, 0.0, 0.0])
    TPOSE_DIRECTIONS[SEGMENT_INDEX[f"{_side}_fingers"]] = np.array([0.0, _sign, 0.0])


@dataclass
class SourceSkeleton:
    """A parsed source animation, in source units and source world axes.

    names/parents: source joints (parents[i] < i). rest: (J, 3) joint positions at zero
    rotation. glob: (T, J, 3, 3) global joint rotations. pos: (T, J, 3) global joint
    positions. end_sites: joint index -> (3,) zero-pose position of an end point, for
    leaf joints whose bone ends in an "End Site".
    """

    names: list[str]
    parents: list[int]
    rest: np.ndarray
    glob: np.ndarray
    pos: np.ndarray
    fps: float
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)

    def index(self, name: str) -> int:
        return self.names.index(name)


@dataclass(frozen=True)
class JointMap:
    """Which source joint drives each of our segments.

    segments: our segment name -> source joint name. A segment missing here copies its
    parent's orientation. `split` names our segments that sit partway along a source
    bone: segment -> fraction of the parent's bone at which its joint lies; the bone runs
    to the source joint of our segment's main child or, where the source has none, to
    the parent's end site (toes at the end of a foot bone). `orient` names segments whose
    orientation comes from a source bone further along the same line than the one that
    places their joint (the Acclaim forearm, see joint_maps.ASF). `twist` names segments
    whose source bone is a hinge while the next joint (the hand) holds the pronation: the
    segment adds that joint's twist about the segment's own bone (``twist_about_bone``).
    """

    name: str
    segments: dict[str, str]
    split: dict[str, float] = field(default_factory=dict)
    # quarter turns about the bone that the rig's joint axes add to a segment (relative to
    # its parent), which a zero pose cannot show: the smallest-rotation T-pose would leave
    # the segment rolled by that much in every frame (see joint_maps.BANDAI)
    roll_quarters: dict[str, int] = field(default_factory=dict)
    orient: dict[str, str] = field(default_factory=dict)
    twist: dict[str, str] = field(default_factory=dict)
    # frames a conversion spends easing from its zero pose at frame 0 into the take: not
    # part of the capture, dropped when a file opens with that pose (joint_maps.CMU_DAZ)
    lead_in: int = 0
    # the rate every file of this layout was captured at, where the files' own frame time
    # is a converter's guess (joint_maps.ACCLAIM_BVH); None: trust the file
    capture_fps: float | None = None
    # segment -> constant turn (rotation vector, degrees, in the segment's own frame) that
    # the retargeted orientation is right-multiplied by: a rig whose bone geometry (where
    # it puts joints, how its zero pose lies) leaves a segment's frame a fixed rotation off
    # the reference's for the same posture (joint_maps.ICLONE_CC). Joint positions do not
    # move: the children's offsets turn back by as much (``retarget``).
    frame_turns: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    # segments whose source frame at zero rotation is the anatomical neutral the source's
    # own joint angles count from (MVN's foot: flat in the calibration pose, whatever the
    # slope of its ankle-to-ball-of-foot line): their T-pose rotation is their parent's,
    # not the turn that lays that line on ours, so a zero pose keeps the joint at 0
    # (joint_maps.MVN). Their bone keeps the source's slope.
    neutral_zero_pose: tuple[str, ...] = ()

    def required(self) -> set[str]:
        return set(self.segments.values()) | set(self.orient.values()) | set(self.twist.values())


def _source_direction(src: SourceSkeleton, j: int, children: list[int]) -> np.ndarray | None:
    """Zero-pose bone direction of source joint j towards the first of `children` (down
    our main-child chain) that is not at the same place, else its end site. Acclaim
    skeletons start the lower back at the root, so the pelvis must look one bone further."""
    ends = [src.rest[c] for c in children]
    if j in src.end_sites:
        ends.append(src.end_sites[j])
    for e in ends:
        d = e - src.rest[j]
        n = np.linalg.norm(d)
        if n > 1e-6 * max(1.0, float(np.abs(src.rest).max())):
            return d / n
    return None


def detect_up_axis(src: SourceSkeleton, jmap: JointMap) -> np.ndarray:
    """The source world's up axis (a signed unit axis), read off the animation itself:
    the mean direction from the feet to the head. Files rarely say which axis is up, and
    the zero pose (lying, for Bandai) cannot tell."""
    head = src.index(jmap.segments["head"])
    feet = [src.index(jmap.segments[s]) for s in ("l_foot", "r_foot")]
    v = (src.pos[:, head] - src.pos[:, feet].mean(axis=1)).mean(axis=0)
    k = int(np.argmax(np.abs(v)))
    axis = np.zeros(3)
    axis[k] = np.sign(v[k]) or 1.0
    return axis


def world_map(up: np.ndarray) -> np.ndarray:
    """A proper rotation W taking the source up axis to our +Z (heading is arbitrary:
    clips start facing wherever the subject faced)."""
    k = int(np.argmax(np.abs(up)))
    s = float(np.sign(up[k]))
    # cyclic permutation keeps handedness: source axis k -> our Z, k+1 -> X, k+2 -> Y
    W = np.zeros((3, 3))
    W[2, k] = s
    W[0, (k + 1) % 3] = 1.0
    W[1, (k + 2) % 3] = s
    assert abs(np.linalg.det(W) - 1.0) < 1e-9
    return W


# beyond this angle between a zero-pose bone and its T-pose direction the smallest
# rotation's axis is set by the rig's stray millimetres, not by anything meaningful
_OPPOSITE_COS = -0.9  # about 154 deg


def bone_turn(a: np.ndarray, b: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """The rotation taking bone direction ``a`` onto ``b`` in the T-pose: the smallest
    one, which inherits the parent's roll, unless ``a`` points nearly opposite ``b``. Then
    the smallest rotation's axis is arbitrary (a rig whose zero pose is a vertical line,
    iClone's Character Creator, has its legs pointing up and 0.5 deg off straight), and a
    wrong one rolls the leg half a turn: the knee would bend forwards. Such a bone turns
    half a turn about the body's ``forward`` axis instead, through the frontal plane, as
    the same rig's arms reach the T-pose (up to sideways, about forward), then the small
    rest of the way."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    if a @ b > _OPPOSITE_COS:
        return quat_to_matrix(quat_between_vectors(a, b))
    n = forward - (forward @ a) * a
    half = quat_to_matrix(quat_about_axis(n / np.linalg.norm(n), np.pi))
    return quat_to_matrix(quat_between_vectors(half @ a, b)) @ half


def tpose_rotations(
    src: SourceSkeleton, jmap: JointMap, W: np.ndarray, ours_to_src: dict[int, int], src_child: dict[int, list[int]]
) -> np.ndarray:
    """Step 1: each source joint's global rotation Q_j in the source's T-pose, from the
    zero-pose geometry of ``src`` (its rest and end sites; no animation is used)."""
    Wt = W.T
    J = len(src.names)
    src_to_ours = {j: i for i, j in ours_to_src.items()}
    Q = np.zeros((J, 3, 3))
    pelvis = ours_to_src[0]
    up0 = _source_direction(src, pelvis, src_child[pelvis])
    lhip, rhip = ours_to_src[SEGMENT_INDEX["l_thigh"]], ours_to_src[SEGMENT_INDEX["r_thigh"]]
    left0 = src.rest[lhip] - src.rest[rhip]
    Q_root = triad(up0, left0, Wt @ np.array([0.0, 0.0, 1.0]), Wt @ np.array([0.0, 1.0, 0.0]))
    # a rig whose zero pose is not upright (Bandai's lies along X) has rolled joint axes
    # (JointMap.roll_quarters); one exported in a T-pose under the same names does not
    lying_rig = abs(float(up0 @ (Wt @ np.array([0.0, 0.0, 1.0])))) < 0.7
    for j in range(J):
        p = src.parents[j]
        if j == pelvis or p < 0 and j not in src_to_ours:
            Q[j] = Q_root
            continue
        Qp = Q[p] if p >= 0 else Q_root
        i = src_to_ours.get(j)
        d0 = _source_direction(src, j, src_child.get(j, [])) if i is not None else None
        if i is None or d0 is None or i not in TPOSE_DIRECTIONS or SEGMENTS[i] in jmap.neutral_zero_pose:
            Q[j] = Qp
            continue
        target = Wt @ TPOSE_DIRECTIONS[i]
        Q[j] = bone_turn(Qp @ d0, target, Wt @ np.array([1.0, 0.0, 0.0])) @ Qp
        k = jmap.roll_quarters.get(SEGMENTS[i], 0) if lying_rig else 0
        if k % 4:
            # the rig rolls this joint's axes by k quarter turns about the bone (JointMap)
            Q[j] = quat_to_matrix(quat_about_axis(target, k * np.pi / 2)) @ Q[j]

    return Q


# T-pose rotations by rig: they depend on the zero pose alone, and every file of a dataset
# (Bandai's 2,300, each actor's HDM05 and CMU takes) shares a few rigs; a third of a
# Bandai file's load was spent finding the same rotations again
_TPOSE_CACHE: dict[tuple, np.ndarray] = {}
_TPOSE_CACHE_SIZE = 64


def _tpose_rotations_cached(src: SourceSkeleton, jmap: JointMap, W: np.ndarray, ours_to_src: dict[int, int],
                            src_child: dict[int, list[int]]) -> np.ndarray:
    key = (tuple(src.names), tuple(src.parents), np.ascontiguousarray(src.rest, float).tobytes(),
           tuple(sorted((j, np.asarray(e, float).tobytes()) for j, e in src.end_sites.items())),
           repr(jmap), np.ascontiguousarray(W, float).tobytes())
    Q = _TPOSE_CACHE.get(key)
    if Q is None:
        Q = tpose_rotations(src, jmap, W, ours_to_src, src_child)
        if len(_TPOSE_CACHE) >= _TPOSE_CACHE_SIZE:
            _TPOSE_CACHE.pop(next(iter(_TPOSE_CACHE)))
        _TPOSE_CACHE[key] = Q
    return Q.copy()


def retarget(
    src: SourceSkeleton,
    jmap: JointMap,
    scale: float,
    W: np.ndarray,
    name: str = "",
    source: str = "",
    meta: dict | None = None,
    template: SourceSkeleton | None = None,
) -> Motion:
    """Our Motion from a source animation (see the module docstring for the method).

    ``template``: another skeleton of the same rig whose zero pose defines the T-pose
    rotations (step 1) instead of this one's (see ``tpose_rotations``)."""
    J = len(src.names)
    ours_to_src: dict[int, int] = {SEGMENT_INDEX[s]: src.index(n) for s, n in jmap.segments.items()}
    # our main-child mapping expressed on source joints: bone direction of source joint j
    # is towards the source joint that drives our segment's main child
    src_child: dict[int, list[int]] = {}
    for i, j in ours_to_src.items():
        chain = []
        c = MAIN_CHILD.get(i)
        while c is not None:
            if c in ours_to_src:
                chain.append(ours_to_src[c])
            c = MAIN_CHILD.get(c)
        src_child[j] = chain

    Wt = W.T
    if template is not None and (template.names != src.names or template.parents != src.parents):
        raise ValueError("a retargeting template must be a skeleton of the same rig (same joints)")
    Q = _tpose_rotations_cached(template or src, jmap, W, ours_to_src, src_child)
    pelvis = ours_to_src[0]

    # source T-pose joint positions (FK with Q), root at the origin
    P = np.zeros((J, 3))
    for j in range(J):
        p = src.parents[j]
        if p >= 0:
            # zero-pose offset of j from its parent, rotated by the parent's T-pose rotation
            P[j] = P[p] + Q[p] @ (src.rest[j] - src.rest[p])

    # step 2: our orientations; segments without a source copy their parent. A bone named
    # in ``jmap.orient`` lies on its segment's line and drives no segment of its own, so
    # its T-pose rotation is its parent's (tpose_rotations) and a zero pose adds nothing.
    T = src.glob.shape[0]
    rot = np.zeros((T, N_SEGMENTS, 3, 3))
    orient = {SEGMENT_INDEX[s]: src.index(n) for s, n in jmap.orient.items()}
    twist = {SEGMENT_INDEX[s]: src.index(n) for s, n in jmap.twist.items()}
    turns = {SEGMENT_INDEX[s]: axis_angle_to_matrix(np.radians(np.asarray(v, dtype=np.float64)))
             for s, v in jmap.frame_turns.items()}
    for i in range(N_SEGMENTS):
        if i in ours_to_src:
            j = orient.get(i, ours_to_src[i])
            G = src.glob[:, j] if i not in twist else _with_twist_of(src, j, twist[i])
            rot[:, i] = W @ G @ Q[j].T @ Wt
        else:
            rot[:, i] = rot[:, PARENTS[i]]
        if i in turns:
            rot[:, i] = rot[:, i] @ turns[i]

    # step 3: offsets from the source T-pose
    offsets = np.zeros((N_SEGMENTS, 3))
    tpose_pos: dict[int, np.ndarray] = {i: W @ P[j] * scale for i, j in ours_to_src.items()}
    anthro = None
    for i in range(1, N_SEGMENTS):
        par = PARENTS[i]
        if i in tpose_pos and par in tpose_pos:
            offsets[i] = tpose_pos[i] - tpose_pos[par]
        elif SEGMENTS[i] in jmap.split:
            # a joint partway along the parent's bone: the parent keeps the first part
            frac = jmap.split[SEGMENTS[i]]
            child = MAIN_CHILD.get(i)
            if child in tpose_pos:
                end = tpose_pos[child]
            else:
                end = W @ _tpose_end_site(src, Q, P, ours_to_src[par]) * scale
            offsets[i] = frac * (end - tpose_pos[par])
            tpose_pos[i] = tpose_pos[par] + offsets[i]
        else:
            if anthro is None:
                anthro = anthropometric_offsets(1.75 * _height_scale(tpose_pos))
            offsets[i] = anthro[i]
            tpose_pos[i] = tpose_pos[par] + offsets[i]
    # a turned segment's frame holds its children's offsets turned back by as much, so
    # every joint stays where the source puts it (JointMap.frame_turns)
    for i in range(1, N_SEGMENTS):
        if PARENTS[i] in turns:
            offsets[i] = turns[PARENTS[i]].T @ offsets[i]
    root = (src.pos[:, pelvis] @ W.T) * scale
    body = Body.from_offsets(offsets)
    return Motion(rot=rot, root=root, fps=src.fps, body=body, name=name, source=source,
                  meta=dict(meta or {})).floor_aligned()


def twist_about_bone(local: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The twist part (T, 3, 3) of rotations ``local`` about the unit ``axis`` (same frame):
    the rotation about the axis that is left when the swing (a turn about an axis at right
    angles to it) is taken out. Read off the quaternion as (w, axis component), it does
    not depend on whether the swing comes before or after the twist. A half turn of pure
    swing leaves no twist to speak of: it counts as none."""
    q = matrix_to_quat(local)
    w, along = q[..., 0], q[..., 1:] @ axis
    n = np.hypot(w, along)
    ok = n > 1e-9
    tw = np.zeros(q.shape)
    tw[..., 0] = np.where(ok, w / np.where(ok, n, 1.0), 1.0)
    tw[..., 1:] = np.where(ok, along / np.where(ok, n, 1.0), 0.0)[..., None] * axis
    return quat_to_matrix(tw)


def _with_twist_of(src: SourceSkeleton, j: int, c: int) -> np.ndarray:
    """Global rotations of source joint j turned by the twist that joint c (further down
    the line: the hand) has relative to it, about the bone from j to c. A sensor near the
    wrist turns with the radius, which turns with the hand: a rig that keeps its elbow a
    pure hinge and puts pronation in the hand bone hides it from the forearm otherwise.
    The bone is read in j's frame off the zero pose, where BVH and our Acclaim reader
    both have every global rotation at the identity."""
    axis = src.rest[c] - src.rest[j]
    axis = axis / np.linalg.norm(axis)
    G = src.glob[:, j]
    local = np.swapaxes(G, -1, -2) @ src.glob[:, c]
    return G @ twist_about_bone(local, axis)


def _tpose_end_site(src: SourceSkeleton, Q: np.ndarray, P: np.ndarray, j: int) -> np.ndarray:
    """T-pose position (source units and axes) of joint j's end site, for a segment the
    source has no joint for (toes where the foot bone simply ends)."""
    if j not in src.end_sites:
        raise ValueError(f"source joint {src.names[j]!r} has no end site to place its child segment at")
    return P[j] + Q[j] @ (src.end_sites[j] - src.rest[j])


def _height_scale(tpose_pos: dict[int, np.ndarray]) -> float:
    """Rough height / 1.75 from the leg length, to size segments the source lacks."""
    hip = tpose_pos.get(SEGMENT_INDEX["l_thigh"])
    ankle = tpose_pos.get(SEGMENT_INDEX["l_foot"])
    if hip is None or ankle is None:
        return 1.0
    return float(np.linalg.norm(hip - ankle) / (0.530 - 0.039) / 1.75)


def pick_scale(height_in_units: float, candidates: dict[str, float]) -> tuple[str, float]:
    """The unit whose scale puts the skeleton's height nearest 1.7 m, for files that do
    not state their units."""
    best = min(candidates.items(), key=lambda kv: abs(np.log(height_in_units * kv[1] / 1.7)))
    return best
