"""Who a clip shows, so an evaluation can say per person how far off it is: a gain on one
kind of body must be visible, not averaged away by another."""

from __future__ import annotations

import re
from collections.abc import Sequence

from inference.metrics.errors import ClipMetrics, summarize

_CMU = re.compile(r"^(\d{2,3})_\d+")


def subject_of(name: str) -> str:
    """``hdm05 dg``, ``cmu 07``, ``bandai`` (one retargeted skeleton for its actors) or the
    clip's own name's first part."""
    stem = str(name).replace("\\", "/").split("/")[-1]
    if stem.startswith("HDM_"):
        return f"hdm05 {stem.split('_')[1]}"
    m = _CMU.match(stem)
    if m:
        return f"cmu {int(m.group(1)):02d}"
    if stem.startswith("dataset-"):
        return "bandai"
    return stem.split("_")[0]


def per_subject(clips: Sequence[ClipMetrics]) -> dict[str, dict]:
    """Per subject: clips, frames and the pooled figures (``summarize`` over its clips)."""
    groups: dict[str, list[ClipMetrics]] = {}
    for c in clips:
        groups.setdefault(subject_of(c.name), []).append(c)
    return {s: {"clips": len(cs), **{k: v for k, v in summarize(cs).items() if k != "clips"}}
            for s, cs in sorted(groups.items())}


def per_subject_markdown(tables: dict[str, dict[str, dict]]) -> str:
    """A table of GA per subject (rows) for each evaluated model (columns)."""
    subjects = sorted({s for t in tables.values() for s in t})
    models = list(tables)
    out = ["## Per subject (GA deg)", "", "| subject | clips | frames | " + " | ".join(models) + " |",
           "|---|---|---|" + "---|" * len(models)]
    for s in subjects:
        first = next(t[s] for t in tables.values() if s in t)
        cells = [f"{tables[m][s]['ga_deg']:.1f}" if s in tables[m] and tables[m][s]["ga_deg"] is not None else "-"
                 for m in models]
        out.append(f"| {s} | {first['clips']} | {first['frames']} | " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"
