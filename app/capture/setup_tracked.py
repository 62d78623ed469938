"""The setup file's ``[tracked]`` table: VR rigs, each one device observing several sites.

``vr = "vmc-in://127.0.0.1:39540?head=SERIAL&l_hand=SERIAL&r_hand=SERIAL"``: the name is the
device's (any name that is not a site), its sites come from the URL, as the model names
them (``drivers.vmc.device.MODEL_SITES``: a controller stands for its wrist's site). A site
is observed by one device: under ``[sensors]`` or by one rig, never both.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from inference.body.skeleton import SITES


@dataclass
class TrackedEntry:
    """A VR rig (``[tracked]``): one device, several of the model's sites (``sites``, in the
    URL's order, as the hub names them: ``drivers.vmc.device.MODEL_SITES``)."""

    name: str
    url: str
    sites: tuple[str, ...]
    line: int | None = field(default=None, compare=False)


def parse_tracked(parser: Any, table: dict[str, Any] | None, sensors: dict[str, Any],
                  url_problem: Callable[[Any, str], tuple[str, str] | None], example: str) -> dict[str, TrackedEntry]:
    """The ``[tracked]`` table's rigs; the first problem as the setup parser's one-line error
    (``parser``: ``setup_file._Parser``; ``url_problem`` and ``example`` are that module's,
    passed in so that this one does not import it back)."""
    import drivers

    out: dict[str, TrackedEntry] = {}
    owner: dict[str, str] = {s: "[sensors]" for s in sensors}
    for name, value in (table or {}).items():
        line = parser.line("tracked", name)
        if name in SITES or name == "insoles":
            raise parser.error(f"[tracked] {name}: a tracked device is named for itself, not for a site",
                               f'name it e.g. vr = "{example}"', line)
        url = parser._text("tracked", name, value, line).strip()
        problem = url_problem(url, "tracked")
        if problem is not None:
            raise parser.error(f"[tracked] {name}: {problem[0]}", problem[1], line)
        device = drivers.make_device(url)  # built only: nothing is bound
        sites = tuple(device.site_names.values())  # type: ignore[attr-defined]
        for site in sites:
            if site in owner:
                where = owner[site] if owner[site] == "[sensors]" else f"[tracked] {owner[site]}"
                raise parser.error(f"site {site} is given twice: under {where} and by [tracked] {name}",
                                   f"keep one device for {site}", line)
            owner[site] = name
        out[name] = TrackedEntry(name, url, sites, line=line)
    return out
