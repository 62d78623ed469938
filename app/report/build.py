"""A recording (and optionally an earlier one) -> the report's HTML (and PDF) and its figures as JSON.

A recording is a path or a ``Recording`` in memory: ``with_poses`` puts a replay's poses in place of
the recording's own reconstruction (``imucap batch --report`` reports on the batch's replay)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from app.recording import Recording, read_recording

from .analysis import GaitAnalysis, analyse_recording, figures
from .angles import ANGLES
from .compare import compare
from .confidence import confidence_of, worn_sites
from .feet import feet_check
from .html import ReportInput, render
from .normal import load_band
from .plots import cycle_figure, timeline_figure
from .session import session_info


@dataclass
class Report:
    html: Path
    pdf: Path | None
    summary: dict[str, Any]


def with_poses(rec: Recording, poses: Sequence, **meta: Any) -> Recording:
    """``rec`` with ``poses`` (``app.live.LivePose``, a replay's) as its reconstruction, laid out as the
    recorder writes it; ``meta`` updates its metadata (the replay's model, steps, sensors)."""
    n = len(poses)
    nan24 = np.full(24, np.nan)
    recon: dict[str, np.ndarray] = {
        "t": np.array([p.t for p in poses], dtype=np.float64),
        "index": np.array([p.index for p in poses], dtype=np.int64),
        "R": np.stack([p.pose.rot for p in poses]) if n else np.zeros((0, 24, 3, 3)),
        "root": np.stack([p.pose.root for p in poses]) if n else np.zeros((0, 3)),
        "contacts": np.stack([p.pose.contacts for p in poses]) if n else np.zeros((0, 4), bool),
        "contact_prob": np.stack([p.pose.contact_prob for p in poses]) if n else np.zeros((0, 4)),
        "observed_sites": np.stack([p.observed_sites for p in poses]) if n else np.zeros((0, 13), bool),
        "insoles": np.array([bool(p.insoles) for p in poses]),
        "spread_deg": np.stack([nan24 if p.pose.spread_deg is None else p.pose.spread_deg for p in poses])
        if n else np.zeros((0, 24)),
    }
    return replace(rec, recon=recon, metadata={**rec.metadata, **meta})


def posed_again(path: str | Path | Recording, lag: int, say: Callable[[str], None] | None = None) -> Recording:
    """The recording with the full model's replay poses as its reconstruction, each pose shown ``lag``
    frames late (``inference/poser/lag.py``): a live capture's poses had to be the newest frame's and
    cheap, a report's need not be either (the knee range of docs/report.md's walks 13.1 -> 5.9 deg off
    with pelvis + shanks at 4)."""
    from app.export.formats import body_for_recording
    from app.replay.run import ReplaySettings, build_replay_poser, replay_recording

    if lag < 0:
        raise ValueError(f"answer lag {lag}: a number of frames, 0 or more")
    rec = path if isinstance(path, Recording) else read_recording(path)
    body, _ = body_for_recording(rec.metadata, None)
    # offline, the full model: a live capture's poses were the live default's, chosen for its compute
    built = build_replay_poser(rec, ReplaySettings(model="diffusion", answer_lag=lag), body)
    k = built.poser.answer_lag
    if say is not None:
        say(f"posing {rec.path} again, {k} frames late ({built.label})")
    res = replay_recording(rec, built.poser, causal=built.causal)
    return with_poses(rec, res.poses, model=f"{built.label} (posed again {k} frames late)", steps=built.steps,
                      sensors=list(res.sensors), insoles=bool(res.insoles), answer_lag=k)


def poses_to_report(path: str | Path | Recording, lag: int | None = None,
                    say: Callable[[str], None] | None = None) -> tuple[Recording, str]:
    """The recording a report reads and which poses those are. ``lag`` None: a live capture's poses (the newest
    frame's, from the live default chosen for its compute) are posed again with the full model
    ``OFFLINE_ANSWER_LAG`` frames late, as an import poses; poses late already are read as they are; a recording
    that cannot be replayed (no raw stream, no calibration) is read on its own poses, and says why. ``lag`` 0:
    its own poses; ``lag`` K: posed again K frames late (an error if it cannot be)."""
    from inference.poser.lag import OFFLINE_ANSWER_LAG

    rec = path if isinstance(path, Recording) else read_recording(path)
    if lag is not None:
        if lag == 0:
            return rec, "its own poses"
        return posed_again(rec, lag, say), f"posed again {lag} frames late"
    if int(rec.metadata.get("answer_lag") or 0) >= OFFLINE_ANSWER_LAG:
        return rec, "its own poses, late already"
    try:
        return posed_again(rec, OFFLINE_ANSWER_LAG, say), f"posed again {OFFLINE_ANSWER_LAG} frames late"
    except ValueError as exc:  # nothing to replay: the recording's own poses, said
        return rec, f"its own poses ({exc})"


def report_input(path: str | Path | Recording) -> ReportInput:
    """One recording read and analysed, its plots not yet drawn."""
    rec = path if isinstance(path, Recording) else read_recording(path)
    an: GaitAnalysis = analyse_recording(rec)
    info = session_info(rec)
    sites = worn_sites(rec.recon.get("observed_sites"), tuple(info.sensors))
    conf = confidence_of(sites, rec.recon.get("spread_deg"), late=int(rec.metadata.get("answer_lag") or 0) > 0)
    fig = figures(an)
    fig["feet_check"] = feet_check(rec, an.events)
    return ReportInput(info, an, fig, conf, load_band())


def summary_json(r: ReportInput) -> dict[str, Any]:
    return {"sensors": list(r.confidence.sites), **r.figures, "session": r.info.as_json(),
            "confidence": r.confidence.as_json(),
            "comparison_band": None if r.band is None else {"trials": r.band.trials, "strides": r.band.strides,
                                                            "sources": r.band.sources}}


def make_report(path: str | Path | Recording, out: str | Path, compare_with: str | Path | Recording | None = None,
                pdf: bool = False) -> Report:
    r = report_input(path)
    r.images["timeline"] = timeline_figure(r.analysis)
    if r.analysis.summary.walking():
        r.images["cycles"] = cycle_figure(r.analysis, r.band)
    summary = summary_json(r)
    if compare_with is not None:
        before = report_input(compare_with)
        r.earlier = before
        r.rows = compare(before.analysis, before.confidence, r.analysis, r.confidence)
        r.images["compare_cycles"] = cycle_figure(r.analysis, r.band, angles=tuple(a for a in ANGLES
                                                  if not a.startswith("pelvis")), other=before.analysis,
                                                  labels=("after", "before"))
        summary["compare"] = {"file": str(before.info.path), "rows": [w.as_json() for w in r.rows],
                              "marked": sum(w.marked for w in r.rows)}
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render(r), encoding="utf-8")
    pdf_path = None
    if pdf:
        from .browser import print_pdf

        pdf_path = print_pdf(out, out.with_suffix(".pdf"))
    summary["html"] = str(out)
    summary["pdf"] = None if pdf_path is None else str(pdf_path)
    return Report(out, pdf_path, summary)
