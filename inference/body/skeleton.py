"""Names and topology of the 24-segment body, its 13 sensor sites and 4 contact points.

These names are the public vocabulary of the CLI, the GUI and the recordings, so
everything else indexes through the tables here instead of hard-coding numbers.
The tree is SMPL's kinematic tree; segment ``i`` starts at joint ``i``.
"""

from __future__ import annotations

SEGMENTS: tuple[str, ...] = (
    "pelvis", "l_thigh", "r_thigh", "spine1", "l_shank", "r_shank", "spine2", "l_foot", "r_foot",
    "spine3", "l_toes", "r_toes", "neck", "l_collar", "r_collar", "head", "l_upperarm", "r_upperarm",
    "l_forearm", "r_forearm", "l_hand", "r_hand", "l_fingers", "r_fingers",
)
N_SEGMENTS = len(SEGMENTS)
SEGMENT_INDEX: dict[str, int] = {n: i for i, n in enumerate(SEGMENTS)}

# parent of each segment (-1 for the root), SMPL order
PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21)

# The 13 sensor sites: name -> segment carrying the sensor. Limb sensors sit distally
# (wrist on the forearm near the wrist, shank near the ankle) as in the paper.
SITES: tuple[str, ...] = (
    "pelvis", "torso", "head", "l_upperarm", "r_upperarm", "l_wrist", "r_wrist",
    "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot",
)
N_SITES = len(SITES)
SITE_INDEX: dict[str, int] = {n: i for i, n in enumerate(SITES)}
SITE_SEGMENT: dict[str, str] = {
    "pelvis": "pelvis", "torso": "spine3", "head": "head",
    "l_upperarm": "l_upperarm", "r_upperarm": "r_upperarm",
    "l_wrist": "l_forearm", "r_wrist": "r_forearm",
    "l_thigh": "l_thigh", "r_thigh": "r_thigh",
    "l_shank": "l_shank", "r_shank": "r_shank",
    "l_foot": "l_foot", "r_foot": "r_foot",
}
SITE_SEGMENT_INDEX: tuple[int, ...] = tuple(SEGMENT_INDEX[SITE_SEGMENT[s]] for s in SITES)

CONTACTS: tuple[str, ...] = ("l_heel", "l_toe", "r_heel", "r_toe")
N_CONTACTS = len(CONTACTS)

# Segments left out of the orientation metrics (the paper excludes hands, fingers, toes
# and the wrist joints, which no sensor set constrains).
METRIC_EXCLUDED: tuple[str, ...] = ("l_toes", "r_toes", "l_hand", "r_hand", "l_fingers", "r_fingers")


def parse_sites(text: str | list[str] | tuple[str, ...]) -> list[str]:
    """Parse a comma separated site list (as on the CLI) and reject unknown names clearly."""
    items = [s.strip() for s in text.split(",")] if isinstance(text, str) else list(text)
    items = [s for s in items if s]
    unknown = [s for s in items if s not in SITE_INDEX]
    if unknown:
        raise ValueError(f"unknown sensor site(s) {unknown}; known sites: {', '.join(SITES)}")
    return items
