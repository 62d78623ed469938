"""How sure each figure is: which segments were measured and which inferred, the poser's own spread
for each (``inference/poser/confidence.py``, when the recording has it), and the expected error of the
sensor set, from ``expected_error.json`` beside this file:

- ``real``: per standard sensor set, the orientation error of each segment the set leaves out, on the
  real logs' walking phases (``imucap evaluate --data @real``; the truth is the left-out sensor). A
  recording's set is matched by its lower-body sites (pelvis, thighs, shanks, feet: what decides the
  legs); the paper's six sites match pelvis + shanks.
- ``synthesized``: per set, how far the report's figures land from the truth's on synthesized walks
  (``benchmarks/report_gait_check.py``): stride time, stance, cadence, joint ranges.

A joint angle's expected error is the root sum of squares of its inferred segments' errors (a measured
segment adds its sensor's own error, which no figure here knows: it is counted as 0 and the joint is
marked measured). Those are errors of a whole orientation; one angle of it is usually closer.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from inference.body.skeleton import SEGMENT_INDEX, SITE_SEGMENT, SITES

from .angles import ANGLES, segments_of

EXPECTED_FILE = Path(__file__).with_name("expected_error.json")
LOWER_BODY = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")
LEG_SEGMENTS = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")
MEASURED_SHARE = 0.5  # a site observed in at least this share of the poses counts as worn


def load_expected(path: str | Path = EXPECTED_FILE) -> dict[str, Any]:
    p = Path(path)
    return json.loads(p.read_text()) if p.exists() else {"real": {"sets": {}}, "synthesized": {"sets": {}}}


def expected_section(name: str, late: bool = False) -> dict[str, Any]:
    """``name`` ("real" or "synthesized") of the expected errors for poses answered live, or with ``late``
    for poses answered late (an import's, a report posed again: ``<name>_late``, when the file has it)."""
    exp = load_expected()
    return (exp.get(f"{name}_late") if late else None) or exp.get(name) or {"sets": {}}


def set_label(sites, late: bool = False) -> str | None:
    """The standard set whose lower-body sites are the recording's (None when no standard set is)."""
    lower = sorted(s for s in sites if s in LOWER_BODY)
    for label, entry in expected_section("real", late)["sets"].items():
        if sorted(entry["sites"]) == lower:
            return label
    return None


def synthesized_label(sites, late: bool = False) -> str | None:
    """The set of the synthesized check with exactly these sites, else one with the same lower body."""
    sets = expected_section("synthesized", late).get("sets", {})
    for label, entry in sets.items():
        if sorted(entry["sites"]) == sorted(sites):
            return label
    lower = sorted(s for s in sites if s in LOWER_BODY)
    for label, entry in sets.items():
        if sorted(s for s in entry["sites"] if s in LOWER_BODY) == lower:
            return label
    return None


@dataclass
class Confidence:
    sites: tuple[str, ...]  # worn (observed in most poses)
    measured: tuple[str, ...]  # segments carrying a worn sensor
    spread_deg: dict[str, float | None] = field(default_factory=dict)  # leg segment -> mean spread
    expected_deg: dict[str, float | None] = field(default_factory=dict)  # leg segment -> real-log error
    real_set: str | None = None
    synthesized_set: str | None = None
    synthesized: dict[str, Any] = field(default_factory=dict)  # figure -> expected error on synthesized walks

    def joint(self, angle: str, side: str) -> dict[str, Any]:
        """status (measured / inferred), the inferred segments, expected error (deg or None), spread."""
        segs = segments_of(angle, side)
        inferred = [s for s in segs if s not in self.measured]
        if not inferred:
            return {"status": "measured", "inferred": [], "expected_deg": None, "spread_deg": 0.0}
        errs = [self.expected_deg.get(s) for s in inferred]
        exp = None if any(e is None for e in errs) else float(np.sqrt(sum(e * e for e in errs)))
        spreads = [self.spread_deg.get(s) for s in inferred]
        spread = None if any(v is None for v in spreads) else float(np.sqrt(sum(v * v for v in spreads)))
        return {"status": "inferred", "inferred": inferred, "expected_deg": exp, "spread_deg": spread}

    def as_json(self) -> dict[str, Any]:
        joints = {f"{side}_{a}": self.joint(a, side) for a in ANGLES if not a.startswith("pelvis")
                  for side in ("l", "r")}
        joints["pelvis"] = self.joint("pelvis_tilt", "l")
        return {"sites": list(self.sites), "measured": list(self.measured), "real_set": self.real_set,
                "synthesized_set": self.synthesized_set,
                "segments": {s: {"measured": s in self.measured, "spread_deg": self.spread_deg.get(s),
                                 "expected_deg": self.expected_deg.get(s)} for s in LEG_SEGMENTS},
                "joints": joints, "synthesized": self.synthesized}


def worn_sites(observed: np.ndarray | None, recorded: tuple[str, ...]) -> tuple[str, ...]:
    """Sites observed in at least ``MEASURED_SHARE`` of the poses; the recording's sites when it has no
    per-pose record."""
    if observed is None or len(observed) == 0:
        return tuple(recorded)
    share = np.asarray(observed, dtype=bool).mean(axis=0)
    return tuple(s for k, s in enumerate(SITES) if share[k] >= MEASURED_SHARE)


def confidence_of(sites, spread: np.ndarray | None = None, late: bool = False) -> Confidence:
    """The confidence of a reconstruction from ``sites`` (worn), with the poser's per-segment spread
    (T, 24) when it was computed (NaN rows where not); ``late``: its poses were answered late
    (``inference/poser/lag.py``), whose expected errors are smaller (``expected_section``)."""
    sites = tuple(s for s in SITES if s in set(sites))
    measured = tuple(dict.fromkeys(SITE_SEGMENT[s] for s in sites))
    real_sets = expected_section("real", late)["sets"]
    real = set_label(sites, late)
    expected: dict[str, float | None] = {}
    for seg in LEG_SEGMENTS:
        if seg in measured:
            expected[seg] = None
            continue
        vals = []
        if real is not None:
            vals = [v for v in real_sets[real]["segments"].get(seg, []) if v is not None]
        expected[seg] = float(np.mean(vals)) if vals else None
    spreads: dict[str, float | None] = {s: None for s in LEG_SEGMENTS}
    if spread is not None and np.isfinite(spread).any():
        for seg in LEG_SEGMENTS:
            col = np.asarray(spread, dtype=np.float64)[:, SEGMENT_INDEX[seg]]
            spreads[seg] = float(np.nanmean(col)) if np.isfinite(col).any() else None
    syn = synthesized_label(sites, late)
    syn_fig = expected_section("synthesized", late).get("sets", {}).get(syn, {}).get("errors", {}) if syn else {}
    return Confidence(sites, measured, spreads, expected, real, syn, dict(syn_fig))
