"""Known source skeletons and which of their joints drive our segments.

A file is matched to the first map whose joints it all has; a skeleton we do not know is
refused with the joints it lacks, rather than guessed at."""

from __future__ import annotations

from inference.body.motion import MotionFormatError
from inference.loaders.retarget import JointMap


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

# The CMU names with our segments' meaning, as ``imucap export`` writes them (app/export_bvh.py)
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

BVH_MAPS = (BANDAI, CMU_CGSPEED, CMU_BVH, MIXAMO)


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
                return JointMap(name=jm.name, segments=segs, split=jm.split, roll_quarters=jm.roll_quarters,
                                orient=orient)
            return jm
        if best is None or len(missing) < best[0]:
            best = (len(missing), jm, missing)
    assert best is not None
    raise MotionFormatError(
        path,
        f"unknown skeleton: closest known layout {best[1].name!r} lacks joints {sorted(best[2])}; "
        f"file has {sorted(names)}",
    )
