"""Known source skeletons and which of their joints drive our segments.

A file is matched to the first map whose joints it all has; a skeleton we do not know is
refused with the joints it lacks, rather than guessed at."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from inference.body.motion import MotionFormatError
from inference.body.rotations import so3_exp, so3_log
from inference.loaders.retarget import JointMap

# what the Acclaim sources we know (HDM05, CMU) capture at: AMC files do not say
ACCLAIM_FPS = 120.0


def _sides(template: dict[str, str]) -> dict[str, str]:
    """Expand {'l_thigh': 'UpperLeg_{L}'}-style entries to both sides."""
    out: dict[str, str] = {}
    for ours, theirs in template.items():
        if "{" not in theirs:
            out[ours] = theirs
            continue
        for s, (L, lower, long_) in (("l", ("L", "l", "Left")), ("r", ("R", "r", "Right"))):
            out[f"{s}_{ours}"] = theirs.format(L=L, s=lower, Side=long_)
    return out


def _turns(template: dict[str, tuple[float, float, float]]) -> dict[str, tuple[float, float, float]]:
    """Expand frame turns given for the left side ('thigh') and the midline ('pelvis') to
    both sides: the right side's turn is the left's mirrored in the sagittal plane, which
    keeps a rotation vector's Y and flips its X and Z."""
    out: dict[str, tuple[float, float, float]] = {}
    for seg, (x, y, z) in template.items():
        if seg in _MIDLINE:
            out[seg] = (x, y, z)
        else:
            out[f"l_{seg}"] = (x, y, z)
            out[f"r_{seg}"] = (-x, y, -z)
    return out


_MIDLINE = ("pelvis", "spine1", "spine2", "spine3", "neck", "head")

# Cgspeed's Daz collars against the reference, CMU's own ASF/AMC read as HDM05 is (what
# the shipped model learnt from). No take exists in both, so the figure is the mean
# posture (heading taken out, walking frames: root at 0.8-1.8 m/s) of Daz subjects 05,
# 06, 07, 08, 10, 12 against ASF subjects 02 and 03, as a right-multiplied turn: 33.8 deg,
# the 12 estimates (6 subjects x 2 sides, mirrored) within 5.3 deg (median), 9.6 (max).
# Subject to subject, the collars' mean posture differs by 8-12 deg among the ASF
# subjects (01, 02, 03) and up to 10 among the Daz ones, against 25-41 deg between any
# Daz and any ASF subject: a rig difference. Every other segment's Daz-to-ASF difference
# lies within the spread between subjects (pelvis 3.7 deg, thighs 2-6, spine2/3 13 against
# up to 11 between ASF subjects, neck 22 against 26, head 29 against 29-51, upper arms
# 16-18 against 17-41), so nothing else is corrected on that evidence.
_DAZ_COLLAR_TO_ASF = (28.4, 11.5, 14.3)

BANDAI = JointMap(
    name="bandai22",
    segments=_sides({
        "pelvis": "Hips", "spine1": "Spine", "spine2": "Chest", "neck": "Neck", "head": "Head",
        "collar": "Shoulder_{L}", "upperarm": "UpperArm_{L}", "forearm": "LowerArm_{L}", "hand": "Hand_{L}",
        "thigh": "UpperLeg_{L}", "shank": "LowerLeg_{L}", "foot": "Foot_{L}", "toes": "Toes_{L}",
    }),
    split={"spine3": 0.5},
    # Bandai's rig lies along X at zero rotation with joint axes rolled per chain. Measured
    # on 24 walk clips (d1 and d2): the roll of each segment relative to the pelvis, against
    # our standing N-pose, sat at these quarter turns in every clip (spine +90, collars -90,
    # right thigh 180; children follow their parent). test_real_data pins it.
    roll_quarters={"spine1": 1, "l_collar": 3, "r_collar": 3, "r_thigh": 2},
)

# The CMU names with our segments' meaning, as ``imucap export`` writes them (app/export/bvh.py)
_CMU_SEGMENTS = {
    "pelvis": "Hips", "spine1": "LowerBack", "spine2": "Spine", "spine3": "Spine1", "neck": "Neck",
    "head": "Head", "collar": "{Side}Shoulder", "upperarm": "{Side}Arm", "forearm": "{Side}ForeArm",
    "hand": "{Side}Hand", "fingers": "{Side}FingerBase", "thigh": "{Side}UpLeg", "shank": "{Side}Leg",
    "foot": "{Side}Foot", "toes": "{Side}ToeBase",
}
CMU_BVH = JointMap(name="cmu31", segments=_sides(_CMU_SEGMENTS))

# CMU's 31-joint BVH as cgspeed converted the CMU database from its Acclaim files: one BVH
# joint per ASF bone, so ``{Side}Hand`` is the Acclaim ``wrist`` bone (pronation, a twist
# about the forearm), ``{Side}FingerBase`` the ``hand`` and ``{Side}HandIndex1`` the
# ``fingers``. As for ASF below, our forearm takes the wrist bone's orientation. Told
# apart from the layout ``imucap export`` writes (``CMU_BVH``: the same names with our
# meaning) by the finger joints only the conversion has.
CMU_CGSPEED = JointMap(
    name="cmu31-cgspeed",
    segments=_sides({**_CMU_SEGMENTS, "hand": "{Side}FingerBase", "fingers": "{Side}HandIndex1"}),
    orient=_sides({"forearm": "{Side}Hand"}),
)

# cgspeed's "Daz-friendly" release of the CMU conversion: Daz Studio joint names, a T-pose
# at zero rotation, no toe joint (the foot bone's end site is where CMU's toes bone
# starts: the ball of the foot, so our toes joint goes there) and fingers of its own.
# The Acclaim radius and wrist bones became one ``{s}ForeArm`` that is a pure hinge (its
# rotation relative to ``{s}Shldr`` keeps one axis, measured on 05_01, 09_01, 12_01),
# and the wrist's pronation went into ``{s}Hand`` together with the wrist's flexion. A
# forearm sensor turns with the pronation, not with the flexion, so our forearm takes
# the hand's twist about the forearm (``twist``); our hand is the whole ``{s}Hand``.
CMU_DAZ = JointMap(
    name="cmu-daz",
    segments=_sides({
        "pelvis": "hip", "spine1": "abdomen", "spine2": "chest", "neck": "neck", "head": "head",
        "collar": "{s}Collar", "upperarm": "{s}Shldr", "forearm": "{s}ForeArm", "hand": "{s}Hand",
        "fingers": "{s}Mid1", "thigh": "{s}Thigh", "shank": "{s}Shin", "foot": "{s}Foot",
    }),
    split={"spine3": 0.5, "l_toes": 1.0, "r_toes": 1.0},
    twist=_sides({"forearm": "{s}Hand"}),
    # all 40 takes in this layout open with the T-pose at frame 0 (root unturned) and ease
    # into the take over the next frames, every joint along the same curve (speed relative
    # to frame 1->2: 0.94, 1, 0.89, 0.61, 0.24, 0.06, 0.14, 0.09, then the take's own,
    # 0.01 in a still one): the capture starts at frame 8
    lead_in=8,
    frame_turns=_turns({"collar": _DAZ_COLLAR_TO_ASF}),
)

# Mixamo-style and most game skeletons
MIXAMO = JointMap(
    name="mixamo",
    segments=_sides({
        "pelvis": "Hips", "spine1": "Spine", "spine2": "Spine1", "spine3": "Spine2", "neck": "Neck",
        "head": "Head", "collar": "{Side}Shoulder", "upperarm": "{Side}Arm", "forearm": "{Side}ForeArm",
        "hand": "{Side}Hand", "thigh": "{Side}UpLeg", "shank": "{Side}Leg", "foot": "{Side}Foot",
        "toes": "{Side}ToeBase",
    }),
)

# Xsens MVN's 23 segments (inference/loaders/mvnx.py): zero pose a T-pose in our axes, so
# the T-pose rotations are nearly identities. L3 lies between our spine1 and spine2 and
# drives none (the chest, where MVN's T8 sensor sits, is our spine3).
MVN = JointMap(
    name="mvn23",
    segments=_sides({
        "pelvis": "Pelvis", "spine1": "L5", "spine2": "T12", "spine3": "T8", "neck": "Neck", "head": "Head",
        "collar": "{Side}Shoulder", "upperarm": "{Side}UpperArm", "forearm": "{Side}ForeArm", "hand": "{Side}Hand",
        "thigh": "{Side}UpperLeg", "shank": "{Side}LowerLeg", "foot": "{Side}Foot", "toes": "{Side}Toe",
    }),
    # MVN's segment frames are the world's in the calibration pose, the foot flat, and MVN
    # counts its ankle angle from there; its ankle-to-ball-of-foot line slopes more than
    # ours (30 deg on MVN Studio 4.2.4's take against our 17), and laying that line on ours
    # tilted every foot 13 deg toes-down, a constant off MVN's own ankle angle
    neutral_zero_pose=("l_foot", "r_foot"),
)

# Acclaim ASF (HDM05, CMU): bone names; each bone's rotation acts at its start joint.
# The forearm is two bones on one line: ``radius`` (the elbow, a hinge: dof rx) and
# ``wrist`` (pronation, a twist about the forearm: dof ry). A sensor strapped near the
# wrist turns with the second, as a real forearm's distal end does and as Bandai's
# forearm bone does, so our forearm starts at the elbow and takes the wrist bone's
# orientation, and our hand is ``hand`` (docs/motion_data.md: mapping the wrist bone to
# our hand left HDM05's wrist sensors without pronation).
ASF = JointMap(
    name="acclaim",
    segments=_sides({
        "pelvis": "root", "spine1": "lowerback", "spine2": "upperback", "spine3": "thorax",
        "neck": "lowerneck", "head": "head", "collar": "{s}clavicle", "upperarm": "{s}humerus",
        "forearm": "{s}radius", "hand": "{s}hand", "fingers": "{s}fingers", "thigh": "{s}femur",
        "shank": "{s}tibia", "foot": "{s}foot", "toes": "{s}toes",
    }),
    orient=_sides({"forearm": "{s}wrist"}),
)

# Reallusion's Character Creator rig (CC_Base_*), as the iClone retargeting of the CMU
# takes exports it. Every bone points along its parent's Y at zero rotation (a vertical
# line: the legs point up), so the T-pose comes from bone directions alone (retarget).
# Twist bones (``*Twist01/02``) are skinning helpers on side branches: the elbow is a
# pure hinge in ``{L}_Upperarm``'s frame (the forearm turns relative to it about one axis,
# < 1 deg of twist in 005_01, 005_12, 006_05), so that bone carries the humerus's whole
# axial rotation and is our upper arm, while ``{L}_UpperarmTwist01/02`` unwind part of
# it for the mesh. ``{L}_Forearm`` is a hinge too: the pronation sits in ``{L}_Hand``,
# and the twist bones carry only part of it (``ForearmTwist02``, the child-most, ends up
# turned by 0.2-0.8 of the hand's twist, varying by clip). So neither the child-most
# twist bone nor the hand's parent frame (``{L}_Forearm``) has the full pronation: our
# forearm is ``{L}_Forearm`` turned by the hand's twist about the forearm (``twist``),
# as for CMU_DAZ, and our hand is the whole ``{L}_Hand``.
# The CC rig's segment frames sit a constant turn off the Daz conversion's for the same
# posture: its joints lie elsewhere (the waist bone, Hip to Waist to Spine01, points 12
# and 40 deg off Daz's hip-abdomen-chest) and its zero pose is a line. Measured on the two
# takes in both conversions, 05_01 = 005_01 and 06_01 = 006_01 (the same capture: knee and
# elbow angle traces correlate at 0.996 with iClone frame k at Daz frame 2k - 6 once the
# Daz lead-in is dropped, the same in each third of both takes): the rotation mean of
# R_iclone^T R_daz over the aligned frames (296 and 243), after a world heading the
# pelvis fixes (0.3 and 2.7 deg), each side's and each take's estimate mirrored onto the
# left and averaged. Per segment: angle, median spread over frames (05 / 06), largest
# difference of the 4 (limbs) or 2 (midline, symmetrised) estimates from their mean:
#   pelvis 12.0 (0.1/0.2, 0.4)   spine1 40.0 (2.8/3.3, 2.8)  spine3 5.1 (1.2/1.6, 1.0)
#   neck 10.1 (1.2/1.6, 2.0)     head 10.6 (1.2/1.5, 1.9)    collar 24.2 (1.2/1.6, 1.0)
#   upperarm 5.4 (1.3/1.4, 1.1)  forearm 19.6 (2.4/1.8, 7.3) thigh 5.3 (1.3/1.7, 0.8)
#   shank 1.4 (1.3/1.7, 0.7)     foot 7.9 (1.6/1.9, 2.8)
# A world (left-multiplied) offset per segment fits worse everywhere (pelvis spread
# 0.9/1.2 against 0.1/0.2). Not constant, so not in the table: spine2 (CC's Spine01 has
# no Daz bone: Daz's chest spans our spine2 and spine3; 2.0 deg, estimates 4.5 apart),
# the hands and fingers (26 deg, estimates 40 apart: the take's wrist, not the rig) and
# the toes (Daz has no toe joint). The hands and fingers stay as the rig has them (turned
# with the forearm they would fit one take better and the other worse); the toes, which
# nothing here measures, turn with the foot, keeping the rig's toe angle. The collars take Daz's own
# turn to the ASF reference (_DAZ_COLLAR_TO_ASF) after it, so both conversions land on it.
# test_cmu pins the agreement.
_ICLONE_COLLAR_TO_DAZ = (-13.7, 1.9, -19.9)
_ICLONE_TO_DAZ = {
    "pelvis": (0.0, -12.0, 0.0), "spine1": (0.0, -40.0, 0.0), "spine3": (0.0, 5.1, 0.0),
    "neck": (0.0, 10.1, 0.0), "head": (0.0, -10.6, 0.0),
    "collar": tuple(float(v) for v in np.round(np.degrees(so3_log(
        so3_exp(np.radians(_ICLONE_COLLAR_TO_DAZ)) @ so3_exp(np.radians(_DAZ_COLLAR_TO_ASF))
    )), 2)),
    "upperarm": (5.0, -1.6, -1.3), "forearm": (7.3, 1.0, -18.1),
    "thigh": (0.4, -5.3, 0.3), "shank": (-0.6, 1.3, -0.3),
    "foot": (5.2, 5.3, -2.5), "toes": (5.2, 5.3, -2.5),
}

ICLONE_CC = JointMap(
    name="iclone-cc",
    segments=_sides({
        "pelvis": "CC_Base_Hip", "spine1": "CC_Base_Waist", "spine2": "CC_Base_Spine01",
        "spine3": "CC_Base_Spine02", "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head",
        "collar": "CC_Base_{L}_Clavicle", "upperarm": "CC_Base_{L}_Upperarm", "forearm": "CC_Base_{L}_Forearm",
        "hand": "CC_Base_{L}_Hand", "fingers": "CC_Base_{L}_Mid1", "thigh": "CC_Base_{L}_Thigh",
        "shank": "CC_Base_{L}_Calf", "foot": "CC_Base_{L}_Foot", "toes": "CC_Base_{L}_ToeBase",
    }),
    twist=_sides({"forearm": "CC_Base_{L}_Hand"}),
    frame_turns=_turns(_ICLONE_TO_DAZ),
)

# CMU's Acclaim skeleton written to BVH bone for bone under its ASF names, the root
# renamed ``hip`` (bvh_cgspeed/16_01 and 16_02 come so): each joint is the start of its
# bone and turns it, as in the ASF, so the ASF map holds. Such a file's frame time is the
# converter's guess, as AMC carries no rate: these two say 30 fps, but their jumps fall
# at 9.95 and 9.99 m/s^2 when read at CMU's 120 Hz (0.62 at 30 Hz).
ACCLAIM_BVH = replace(
    ASF, name="acclaim-bvh", segments={**ASF.segments, "pelvis": "hip"}, capture_fps=ACCLAIM_FPS,
)

# MVN Analyze's BVH export: its 23 segments named by the joint at their start (Chest = L5,
# Chest2 = L3, which drives none of ours as in MVN above, Chest3 = T12, Chest4 = T8; the
# collar is the shoulder blade, "Shoulder" the upper arm), a T-pose at zero, centimetres.
MVN_BVH = JointMap(
    name="mvn-bvh",
    segments=_sides({
        "pelvis": "Hips", "spine1": "Chest", "spine2": "Chest3", "spine3": "Chest4", "neck": "Neck", "head": "Head",
        "collar": "{Side}Collar", "upperarm": "{Side}Shoulder", "forearm": "{Side}Elbow", "hand": "{Side}Wrist",
        "thigh": "{Side}Hip", "shank": "{Side}Knee", "foot": "{Side}Ankle", "toes": "{Side}Toe",
    }),
    # the foot keeps MVN's calibration-pose frame, as in MVN above: the export's zero pose
    # has the foot flat with its ankle-to-toe line 33 deg down (ours 17)
    neutral_zero_pose=("l_foot", "r_foot"),
)

BVH_MAPS = (BANDAI, CMU_CGSPEED, CMU_BVH, CMU_DAZ, ICLONE_CC, ACCLAIM_BVH, MIXAMO, MVN_BVH)


def _strip_prefix(name: str) -> str:
    return name.split(":")[-1]


def match_joint_map(names: list[str], path: str, maps: tuple[JointMap, ...] = BVH_MAPS) -> JointMap:
    """The known map this skeleton fits; namespace prefixes ('mixamorig:') are ignored."""
    plain = {_strip_prefix(n): n for n in names}
    best: tuple[int, JointMap, set[str]] | None = None
    for jm in maps:
        missing = jm.required() - set(plain)
        if not missing:
            if len(plain) != len(names) or any(plain[k] != k for k in jm.required()):
                segs = {s: plain[n] for s, n in jm.segments.items()}
                orient = {s: plain[n] for s, n in jm.orient.items()}
                twist = {s: plain[n] for s, n in jm.twist.items()}
                return replace(jm, segments=segs, orient=orient, twist=twist)
            return jm
        if best is None or len(missing) < best[0]:
            best = (len(missing), jm, missing)
    assert best is not None
    raise MotionFormatError(
        path,
        f"unknown skeleton: closest known layout {best[1].name!r} lacks joints {sorted(best[2])}; "
        f"file has {sorted(names)}",
    )
