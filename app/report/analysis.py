"""One walk analysed: events, strides, their figures, the joint angles over the gait cycle.

``analyse`` works on arrays (a reconstruction, or a motion's truth), ``analyse_recording`` on a session
recording's reconstruction; ``figures`` is the JSON the report's ``--json`` prints (the keys the
command-line contract lists, and more). A walk with no walking stride gives 0 strides and ``None`` for
every figure: nothing is made up from a stand or a turn on the spot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from inference.body.skeleton import SEGMENT_INDEX
from inference.poser.models import CONTACT_THRESHOLD

from .angles import ANGLES, RANGE_ANGLES, angle_series, cycle_angle
from .events import SIDES, FootEvents, contact_source, foot_events
from .feet import foot_sensor_events
from .strides import StrideSummary, cycle_curves, mean_sd, stride_ranges, strides_of, summarize, symmetry_index


@dataclass
class GaitAnalysis:
    t: np.ndarray  # (T,) the reconstruction's times
    events: dict[str, FootEvents]
    summary: StrideSummary
    angles: dict[str, dict[str, np.ndarray]]  # side -> angle -> (T,)
    cycles: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # side -> angle -> (N, 101)
    ranges: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # side -> angle -> (N,) per stride

    @property
    def source(self) -> str:
        return self.events["l"].source

    @property
    def seconds(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0

    @property
    def walking_s(self) -> float:
        return float(sum(s.time_s for s in self.summary.walking())) / 2.0  # each second is in a stride of both feet

    def range_stats(self, side: str, angle: str) -> dict[str, float | None]:
        return mean_sd(self.ranges[side][angle])


def analyse(t: np.ndarray, R: np.ndarray, root: np.ndarray, contact_t: np.ndarray | None,
            contact_values: np.ndarray | None, source: str, threshold: float = CONTACT_THRESHOLD,
            events: dict[str, FootEvents] | None = None) -> GaitAnalysis:
    """t (T,), R (T, 24, 3, 3), root (T, 3): the reconstruction (or truth); contact_t / contact_values
    (T', 4): the contact signal the events come from (``events.foot_events``) on its own clock, or
    ``events`` found already (the foot sensors', ``feet.sensor_events``)."""
    t = np.asarray(t, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if events is None:
        events = foot_events(contact_t, contact_values, source, threshold=threshold)
    strides = strides_of(events, t, root, R[:, SEGMENT_INDEX["pelvis"]])
    summary = summarize(strides)
    angles = angle_series(R) if len(t) else {s: {a: np.zeros(0) for a in ANGLES} for s in SIDES}
    an = GaitAnalysis(t, events, summary, angles)
    for side in SIDES:
        walk = summary.walking(side)
        an.cycles[side] = {a: cycle_angle(a, cycle_curves(walk, t, angles[side][a])) for a in ANGLES}
        an.ranges[side] = {a: stride_ranges(walk, t, angles[side][a]) for a in ANGLES}
    return an


def analyse_recording(rec, source: str | None = None) -> GaitAnalysis:
    """A recording's (``app.recording.Recording``) reconstruction analysed, its events from the insoles
    when they were worn, else from both foot sensors when they were worn (``feet.foot_sensor_events``),
    else from the poser's contacts. ``source`` forces one of "insoles", "foot sensors", "model"
    (ValueError when the recording does not have it)."""
    recon = rec.recon
    if "t" not in recon or len(recon["t"]) == 0:
        raise ValueError(f"{rec.path}: the recording holds no reconstruction (imucap replay writes one)")
    if source not in (None, "insoles", "foot sensors", "model"):
        raise ValueError(f"unknown event source {source!r}")
    ct, cv, found = contact_source(recon, rec.raw if source != "model" else None)  # the insoles' or the model's
    if source == "insoles" and found != "insoles":
        raise ValueError(f"{rec.path}: no insoles' contacts in the recording")
    if source == "foot sensors" or (source is None and found != "insoles"):
        feet = foot_sensor_events(rec)
        if feet is not None:
            return analyse(recon["t"], recon["R"], recon["root"], None, None, "foot sensors", events=feet)
        if source == "foot sensors":
            raise ValueError(f"{rec.path}: no calibrated gyro from both foot sensors")
    return analyse(recon["t"], recon["R"], recon["root"], ct, cv, found)


def _num(x: float | None, nd: int = 3) -> float | int | None:
    if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
        return int(x)
    return None if x is None or not np.isfinite(x) else round(float(x), nd)


def figures(an: GaitAnalysis) -> dict[str, Any]:
    """The report's figures as JSON: ``strides`` (count per side), ``cadence_spm``, ``stride_time_s``
    (per side mean, sd), ``stance_pct``, ``knee_range_deg`` (per side, mean of the strides' ranges),
    ``speed_mps``; ``parameters`` (every stride parameter per side, mean / sd / n, with the symmetry
    index), ``ranges`` (every angle's range per side), ``excluded`` (strides left out, by kind)."""
    s = an.summary
    walking = s.walking()
    n = {side: s.count(side) for side in SIDES}
    ps = s.per_side
    out: dict[str, Any] = {
        "strides": n,
        "cadence_spm": _num(s.cadence_spm, 2),
        "stride_time_s": {side: {"mean": _num(ps[side]["time_s"]["mean"]), "sd": _num(ps[side]["time_s"]["sd"])}
                          for side in SIDES},
        "stance_pct": {side: _num(ps[side]["stance_pct"]["mean"], 2) for side in SIDES},
        "knee_range_deg": {side: _num(an.range_stats(side, "knee_flexion")["mean"], 2) for side in SIDES},
        "speed_mps": _num(float(np.mean([w.speed_mps for w in walking])) if walking else None),
        "events_from": an.source,
        "seconds": _num(an.seconds, 2),
        "walking_s": _num(an.walking_s, 2),
        "excluded": dict(s.excluded),
        "parameters": {p: {**{side: {k: _num(v, 4) for k, v in ps[side][p].items()} for side in SIDES},
                           "symmetry_index": _num(s.symmetry[p], 2)} for p in ps["l"]},
        "ranges": {},
    }
    for a in RANGE_ANGLES:
        st = {side: an.range_stats(side, a) for side in SIDES}
        out["ranges"][a] = {**{side: {k: _num(v, 3) for k, v in st[side].items()} for side in SIDES},
                            "symmetry_index": _num(symmetry_index(st["l"]["mean"], st["r"]["mean"]), 2)}
    return out
