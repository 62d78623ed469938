"""Which site each sensor of an imported log is on: by ``--map``, by a name that says it."""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from drivers.device_log import DeviceLog
from inference.body.skeleton import SITES, parse_sites

# normalised device name -> site (words as suits and their GUIs name the segments)
DEVICE_SITES: dict[str, str] = {
    "pelvis": "pelvis", "hips": "pelvis", "sacrum": "pelvis", "torso": "torso", "chest": "torso",
    "sternum": "torso", "trunk": "torso", "head": "head",
    **{f"{side} {w}": f"{s}_{site}" for side, s in (("left", "l"), ("right", "r")) for w, site in (
        ("upper arm", "upperarm"), ("forearm", "wrist"), ("lower arm", "wrist"), ("wrist", "wrist"),
        ("hand", "wrist"), ("upper leg", "thigh"), ("thigh", "thigh"), ("lower leg", "shank"),
        ("shank", "shank"), ("shin", "shank"), ("foot", "foot"))},
}
# bone names as OpenSense and many lab tags use them, with a side letter or word before or after
BONES: dict[str, str] = {"femur": "thigh", "tibia": "shank", "calcn": "foot", "humerus": "upperarm",
                         "radius": "wrist", "ulna": "wrist", "hand": "wrist", "foot": "foot", "thigh": "thigh",
                         "shank": "shank", "upperarm": "upperarm", "forearm": "wrist", "wrist": "wrist"}
_SIDES = (("left", "l"), ("right", "r"), ("l", "l"), ("r", "r"))


def _norm(name: str) -> str:
    return re.sub(r"[\s_\-]+", " ", name.strip().lower())


def _compact(name: str) -> str:
    """Letters only, without a trailing "imu": ``femur_r_imu`` -> ``femurr``."""
    n = re.sub(r"[^a-z]", "", name.lower())
    return n[:-3] if n.endswith("imu") and len(n) > 3 else n


def _bone_site(name: str) -> str | None:
    """The site of a bone-style name (``LFemur``, ``tibia_r``, ``LeftFoot``), if it is one."""
    n = _compact(name)
    compact_sites = {k.replace(" ", ""): v for k, v in DEVICE_SITES.items()}
    if n in compact_sites:
        return compact_sites[n]
    for bone, site in BONES.items():
        for side, s in _SIDES:
            if n in (side + bone, bone + side):
                return f"{s}_{site}"
    return None


def site_for(name: str, mapping: dict[str, str]) -> str | None:
    """The site a device name stands for: an explicit ``--map`` entry, a site name, a
    segment name from ``DEVICE_SITES`` or a bone name from ``BONES``; None if none applies."""
    if name in mapping:
        return mapping[name]
    n = _norm(name)
    if n.replace(" ", "_") in SITES:
        return n.replace(" ", "_")
    return DEVICE_SITES.get(n) or _bone_site(name)


@dataclass
class Source:
    """One device's log and the names ``--map`` may call it by, the most telling first."""

    log: DeviceLog
    ids: tuple[str, ...]
    file: str = ""

    @property
    def label(self) -> str:
        return self.ids[0] if not self.file else f"{self.ids[0]} ({Path(self.file).name})"


def unique(names: Sequence[str]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(n for n in names if n))


def _key(name: str) -> str:
    return re.sub(r"[^0-9a-z]", "", name.lower())


def site_of(src: Source, mapping: dict[str, str]) -> str | None:
    """The site of one device: ``--map`` by any of its ids (exactly, else ignoring case and
    separators, so ``D4:CA:6E:F1:78:60`` matches ``D4CA6EF17860``), else by a name that says it."""
    loose = {_key(k): v for k, v in mapping.items()}
    for i in src.ids:
        if i in mapping:
            return mapping[i]
    for i in src.ids:
        if _key(i) in loose:
            return loose[_key(i)]
    return next((s for s in (site_for(i, {}) for i in src.ids) if s), None)


def assign_sites(sources: Sequence[Source], mapping: dict[str, str]) -> tuple[dict[str, Source], list[str]]:
    """(site -> its device, a warning per device without a site, which is skipped): a folder
    often holds sensors the study did not use. Refuses two devices on one site, and a log
    where no device has a site."""
    by_site: dict[str, Source] = {}
    unknown = []
    for src in sources:
        site = site_of(src, mapping)
        if site is None:
            unknown.append(src)
            continue
        site = parse_sites([site])[0]
        if site in by_site:
            raise ValueError(f"sensors {by_site[site].label} and {src.label} both map to {site}; use --map ID=SITE")
        by_site[site] = src
    if unknown and not by_site:
        example = unknown[0].ids[0]
        raise ValueError(f"no site for sensor(s) {', '.join(s.label for s in unknown)}; map each with --map ID=SITE "
                         f"(e.g. --map '{example}=pelvis'; sites: {', '.join(SITES)})")
    skipped = [f"{s.label}: no site, skipped (--map '{s.ids[0]}=SITE' to use it)" for s in unknown]
    return by_site, skipped




__all__ = ["BONES", "DEVICE_SITES", "Source", "assign_sites", "site_for", "site_of", "unique"]
