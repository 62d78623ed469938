"""Sensor sets a clinician can pick instead of clicking sites one by one.

Why these: the classic six is what TransPose, PIP, TIP and DiffusionPoser compare on;
the others are the paper's Table 1, the best 4-, 3- and 2-sensor sets for each task
(whole body by GA, legs and back by local angle, root translation by RE10), so a user
with few sensors straps them where they help the question being asked.
"""

from __future__ import annotations

from dataclasses import dataclass

from inference.body.skeleton import SITES


@dataclass(frozen=True)
class Preset:
    name: str
    sites: tuple[str, ...]
    why: str


CLASSIC_6 = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
ALL_I_HAVE = "all I have"

PRESETS: tuple[Preset, ...] = (
    Preset("classic 6: pelvis, head, wrists, shanks", CLASSIC_6, "the set every sparse-IMU paper compares on"),
    Preset("whole body, 4: pelvis, head, wrists", ("pelvis", "head", "l_wrist", "r_wrist"),
           "paper's Table 1: lowest global angle error with 4"),
    Preset("whole body, 3: pelvis, wrists", ("pelvis", "l_wrist", "r_wrist"), "Table 1: best whole body with 3"),
    Preset("whole body, 2: upper arms", ("l_upperarm", "r_upperarm"), "Table 1: best whole body with 2"),
    Preset("legs, 4: pelvis, head, thighs", ("pelvis", "head", "l_thigh", "r_thigh"),
           "Table 1: best leg joint angles with 4"),
    Preset("legs, 3: pelvis, thighs", ("pelvis", "l_thigh", "r_thigh"), "Table 1: best leg joint angles with 3"),
    Preset("legs, 2: pelvis, right shank", ("pelvis", "r_shank"), "Table 1: best leg joint angles with 2"),
    Preset("back, 4: pelvis, head, upper arms", ("pelvis", "head", "l_upperarm", "r_upperarm"),
           "Table 1: best back angles with 4"),
    Preset("back, 3: pelvis, upper arms", ("pelvis", "l_upperarm", "r_upperarm"), "Table 1: best back angles with 3"),
    Preset("back, 2: upper arms", ("l_upperarm", "r_upperarm"), "Table 1: best back angles with 2"),
    Preset("root translation, 4: thighs, shanks", ("l_thigh", "r_thigh", "l_shank", "r_shank"),
           "Table 1: least root drift (RE10) with 4"),
    Preset("root translation, 3: pelvis, shanks", ("pelvis", "l_shank", "r_shank"), "Table 1: least root drift with 3"),
    Preset("root translation, 2: shanks", ("l_shank", "r_shank"), "Table 1: least root drift with 2"),
    Preset(ALL_I_HAVE, SITES, "every site that has a device; all 13 when none is assigned yet"),
)


def preset(name: str) -> Preset:
    for p in PRESETS:
        if p.name == name or p.name.startswith(name):
            return p
    raise KeyError(f"no preset {name!r}; presets: {', '.join(p.name for p in PRESETS)}")


def sites_of(p: Preset, assigned: dict[str, str]) -> tuple[str, ...]:
    """The sites a preset selects; "all I have" depends on which sites have a device."""
    if p.name == ALL_I_HAVE:
        have = tuple(s for s in SITES if assigned.get(s))
        return have or SITES
    return tuple(s for s in SITES if s in p.sites)
