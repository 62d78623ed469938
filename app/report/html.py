"""The report as one self-contained HTML page (figures inlined as PNG data URIs, styles inline), laid out
to print as the PDF: the first page (who, when, which sensors, the calibration, the warnings and the
headline figures), then the strides, the joint ranges, the gait-cycle plots, how sure each figure is,
the comparison with an earlier session when there is one, and how it was all made.

Every section is a ``<section id=...>`` (``SECTIONS``) so a reader, a test or a script finds it."""

from __future__ import annotations

import base64
import html
from dataclasses import dataclass, field
from typing import Any

from .analysis import GaitAnalysis
from .angles import ANGLES, RANGE_ANGLES
from .compare import Row
from .confidence import LEG_SEGMENTS, Confidence
from .events import MIN_STANCE_S, MIN_SWING_S, SIDES
from .normal import NormalBand
from .session import SessionInfo
from .strides import MAX_STANCE_PCT, MAX_STRIDE_S, MIN_SPEED_MPS, MIN_STANCE_PCT, MIN_STRIDE_S, TURN_DEG

SECTIONS = ("summary", "strides", "ranges", "cycles", "confidence", "compare", "methods")
PARAM_ROWS = (("time_s", "Stride time", "s", 3), ("stance_pct", "Stance", "% of stride", 1),
              ("swing_pct", "Swing", "% of stride", 1), ("double_support_pct", "Double support", "% of stride", 1),
              ("length_m", "Stride length", "m", 2), ("speed_mps", "Speed", "m/s", 2))
SOURCES = {"model": "the model's foot contacts", "insoles": "the insoles' contacts", "truth": "the motion's truth",
           "foot sensors": "the foot sensors' angular rate"}

CSS = """
body{font-family:'DejaVu Sans',Arial,sans-serif;font-size:10.5pt;color:#222;max-width:60em;margin:1.5em auto;
 padding:0 1em}
h1{font-size:17pt;margin:0 0 .2em}h2{font-size:13pt;border-bottom:2px solid #1f5fa8;padding-bottom:.15em;
 margin-top:1.2em}
table{border-collapse:collapse;margin:.4em 0 .8em}td,th{border:1px solid #bbb;padding:.2em .5em;text-align:right}
th{background:#eef2f7}td.l,th.l{text-align:left}.muted{color:#666;font-size:9pt}
.warn{color:#9c2a00}.mark{background:#ffe2b8;font-weight:bold}.big{font-size:14pt;font-weight:bold}
.cards{display:flex;gap:.8em;flex-wrap:wrap;margin:.5em 0}.card{border:1px solid #bbb;border-radius:4px;
 padding:.4em .8em;min-width:8em}img{max-width:100%}
.meas{color:#1b7a3a}.inf{color:#9c5a00}
section.page{break-before:page}@media print{body{margin:0}}
"""


@dataclass
class ReportInput:
    info: SessionInfo
    analysis: GaitAnalysis
    figures: dict[str, Any]
    confidence: Confidence
    band: NormalBand | None
    images: dict[str, bytes] = field(default_factory=dict)  # timeline, cycles
    earlier: ReportInput | None = None
    rows: list[Row] = field(default_factory=list)


def e(x: Any) -> str:
    return html.escape(str(x))


def f(v: float | None, nd: int = 2, unit: str = "") -> str:
    if v is None:
        return "&mdash;"
    return f"{v:.{nd}f}{(' ' + unit) if unit else ''}"


def _img(png: bytes | None, alt: str) -> str:
    if not png:
        return ""
    return f'<img alt="{e(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode()}">'


def _mean_sd(d: dict[str, Any], nd: int) -> str:
    if d.get("mean") is None:
        return "&mdash;"
    sd = d.get("sd")
    return f(d["mean"], nd) + ("" if sd is None else f" &plusmn; {sd:.{nd}f}")


def _no_walk(r: ReportInput) -> str:
    ex = r.figures["excluded"]
    left = ", ".join(f"{n} {k}" for k, n in ex.items() if n)
    return (f'<p class="warn big">No walking found: 0 walking strides in {f(r.analysis.seconds, 1, "s")}'
            f'{" (strides left out: " + left + ")" if left else ""}. No stride figure is given.</p>')


def summary_section(r: ReportInput) -> str:
    i, fig = r.info, r.figures
    rows = "".join(
        f'<tr><th class="l">{e(k)}</th><td class="l">{v}</td></tr>' for k, v in (
            ("Subject", e(i.subject)), ("Recorded", e(i.date)), ("File", e(i.path.name)),
            ("Sensor set", e(", ".join(i.sensors)) + (" + insoles" if i.insoles else "")),
            ("Model", e(i.model)), ("Source", e(i.source)),
            ("Duration", f(i.duration_s, 1, "s") + f" ({f(fig['walking_s'], 1, 's')} of it in walking strides)"),
            ("Gait events from", e(SOURCES.get(fig["events_from"], fig["events_from"]))),
            ("Calibration", e(i.calibration_summary))))
    n = fig["strides"]
    if n["l"] + n["r"] == 0:
        cards = _no_walk(r)
    else:
        st = fig["stride_time_s"]
        cards = '<div class="cards">' + "".join(
            f'<div class="card"><div class="muted">{k}</div><div class="big">{v}</div></div>' for k, v in (
                ("Walking strides (L / R)", f"{n['l']} / {n['r']}"), ("Cadence", f(fig["cadence_spm"], 1, "steps/min")),
                ("Speed", f(fig["speed_mps"], 2, "m/s")),
                ("Stride time L / R", f"{f(st['l']['mean'], 2)} / {f(st['r']['mean'], 2)} s"),
                ("Stance L / R", f"{f(fig['stance_pct']['l'], 1)} / {f(fig['stance_pct']['r'], 1)} %"),
                ("Knee range L / R", f"{f(fig['knee_range_deg']['l'], 1)} / {f(fig['knee_range_deg']['r'], 1)} deg"))
        ) + "</div>"
    cal = ""
    if i.calibration:
        cal = ("<table><tr><th class='l'>site</th><th>calibrated</th><th>still (deg)</th><th>pose (deg)</th></tr>"
               + "".join(f"<tr><td class='l'>{e(c['site'])}</td><td>{'yes' if c['valid'] else 'NO'}</td>"
                         f"<td>{f(c['still_deg'])}</td><td>{f(c['pose_deg'])}</td></tr>" for c in i.calibration)
               + "</table><p class='muted'>Residuals: how far each sensor moved during the calibration's "
               "still and pose windows (RMS about their mean); under ~2 deg is a steady hold.</p>")
    warn = ("<ul>" + "".join(f'<li class="warn">{e(w)}</li>' for w in i.warnings) + "</ul>") if i.warnings \
        else "<p>No warnings.</p>"
    return (f'<section id="summary"><h1>Gait report</h1><p class="muted">imucap, from body-worn inertial sensors. '
            f'Figures marked inferred come from a model, not a sensor; see "How sure".</p>'
            f"<table>{rows}</table>{cards}<h2>Calibration quality</h2>{cal}<h2>Warnings</h2>{warn}</section>")


def strides_section(r: ReportInput) -> str:
    fig = r.figures
    ps = fig["parameters"]
    body = ""
    if fig["strides"]["l"] + fig["strides"]["r"]:
        body = ("<table><tr><th class='l'>parameter</th><th>unit</th><th>left, mean &plusmn; SD</th>"
                "<th>right, mean &plusmn; SD</th><th>symmetry index (%)</th></tr>")
        for key, label, unit, nd in PARAM_ROWS:
            p = ps[key]
            body += (f"<tr><td class='l'>{label}</td><td>{unit}</td><td>{_mean_sd(p['l'], nd)}</td>"
                     f"<td>{_mean_sd(p['r'], nd)}</td><td>{f(p['symmetry_index'], 1)}</td></tr>")
        body += (f"<tr><td class='l'>Cadence</td><td>steps/min</td><td colspan=2>{f(fig['cadence_spm'], 1)}</td>"
                 "<td></td></tr></table>")
    else:
        body = _no_walk(r)
    ex = fig["excluded"]
    left = "; ".join(f"{n} {k}" for k, n in ex.items() if n) or "none"
    return (f'<section id="strides"><h2>Strides</h2>{body}{feet_table(fig.get("feet_check"))}'
            f"<p>Strides left out of the figures: {e(left)} (a turn: the pelvis turned more than {TURN_DEG:.0f} deg "
            f"in the stride; standing: longer than {MAX_STRIDE_S} s, slower than {MIN_SPEED_MPS} m/s or stance over "
            f"{MAX_STANCE_PCT:.0f} %; not walking: shorter than {MIN_STRIDE_S} s or stance under "
            f"{MIN_STANCE_PCT:.0f} %).</p>"
            f"{_img(r.images.get('timeline'), 'strides over time')}"
            "<p class='muted'>Symmetry index: 100 (L - R) / mean(L, R); 0 is symmetric, positive means the left is "
            "larger.</p></section>")


def feet_table(check: dict[str, Any] | None) -> str:
    """The foot sensors' still periods against the stances found (``feet.check``)."""
    if not check:
        return ""
    rows = "".join(
        f"<tr><td class='l'>{'left' if side == 'l' else 'right'}</td><td>{c['still_steps']}</td><td>{c['covered']}"
        f"</td><td>{c['found_stances']}</td><td>{c['found_without_still']}</td><td>{f(c['strike_lead_ms'], 0)}</td>"
        f"<td>{f(c['off_lag_ms'], 0)}</td></tr>" for side, c in check.items())
    return ("<p>Checked against the foot sensors (a still foot is a foot on the ground):</p><table><tr>"
            "<th class='l'>foot</th><th>steps the sensor saw</th><th>inside a stance found</th><th>stances found</th>"
            "<th>found with no still foot</th><th>strike before still (ms)</th><th>off after still (ms)</th></tr>"
            f"{rows}</table>")


def _status(conf: Confidence, angle: str, side: str) -> str:
    j = conf.joint(angle, side)
    if j["status"] == "measured":
        return '<span class="meas">measured</span>'
    return (f'<span class="inf">inferred</span> <span class="muted">({", ".join(j["inferred"])}; '
            f'expected error {f(j["expected_deg"], 0, "deg") if j["expected_deg"] is not None else "not known"})'
            "</span>")


def ranges_section(r: ReportInput) -> str:
    rg = r.figures["ranges"]
    rows = ""
    for a in RANGE_ANGLES:
        rows += (f"<tr><td class='l'>{ANGLES[a][0]}</td><td>{_mean_sd(rg[a]['l'], 1)}</td>"
                 f"<td>{_mean_sd(rg[a]['r'], 1)}</td><td>{f(rg[a]['symmetry_index'], 1)}</td>"
                 f"<td class='l'>L: {_status(r.confidence, a, 'l')}<br>R: {_status(r.confidence, a, 'r')}</td></tr>")
    return ("<section id=\"ranges\"><h2>Joint ranges per stride</h2><table><tr><th class='l'>joint</th>"
            "<th>left (deg)</th><th>right (deg)</th><th>symmetry index (%)</th><th class='l'>how it was known</th>"
            f"</tr>{rows}</table><p class='muted'>Range: the largest minus the smallest angle within each walking "
            "stride, mean &plusmn; SD over strides.</p></section>")


def cycles_section(r: ReportInput) -> str:
    band = r.band
    note = ("No comparison band is installed." if band is None else
            f"Grey: the comparison band, mean &plusmn; 1 SD of {band.trials} walking trials ({band.strides} "
            f"strides) of adult motion capture ({e(', '.join(f'{k} {v}' for k, v in band.sources.items()))} "
            "trials), made with the same events and angle definitions as this report. It is a reference from "
            "the motion capture imucap learns from, <b>not clinical normative data</b>.")
    plot = _img(r.images.get("cycles"), "joint angles over the gait cycle") or \
        "<p class='warn'>No walking stride: no gait cycle to draw.</p>"
    span = lambda c: "&mdash;" if c is None or len(c) == 0 else f"{c.min():.1f} to {c.max():.1f}"  # noqa: E731
    rows = ""
    for a in ANGLES:
        mean = {side: (r.analysis.cycles[side][a].mean(axis=0) if len(r.analysis.cycles[side][a]) else None)
                for side in SIDES}
        b = None if band is None or band.get(a) is None else band.get(a)[0]
        rows += (f"<tr><td class='l'>{ANGLES[a][0]} ({e(ANGLES[a][1])})</td><td>{span(mean['l'])}</td>"
                 f"<td>{span(mean['r'])}</td><td>{span(b)}</td></tr>")
    plot += ("<table><tr><th class='l'>mean curve, deg</th><th>left</th><th>right</th><th>comparison band</th></tr>"
             f"{rows}</table>")
    return (f'<section id="cycles" class="page"><h2>Joint angles over the gait cycle</h2>{plot}'

            f"<p class='muted'>Coloured: this walk's mean &plusmn; SD over its walking strides; the dotted line is "
            f"the mean foot off. {note} Angles as OpenSim's Rajagopal model defines them (ISB joint coordinate "
            "systems): hip, knee and ankle flexion positive, pelvis tilt posterior positive.</p></section>")


def confidence_section(r: ReportInput) -> str:
    c = r.confidence
    rows = ""
    for seg in LEG_SEGMENTS:
        meas = seg in c.measured
        sp = c.spread_deg.get(seg)
        rows += (f"<tr><td class='l'>{seg}</td><td class='l'>"
                 f"{'<span class=meas>measured</span>' if meas else '<span class=inf>inferred</span>'}</td>"
                 f"<td>{'0' if meas else f(sp, 1)}</td>"
                 f"<td>{'&mdash;' if meas else f(c.expected_deg.get(seg), 1)}</td></tr>")
    syn = c.synthesized
    syn_txt = ("No synthesized check of this sensor set." if not syn else
               f"On synthesized walks with this set ({e(c.synthesized_set)}): stride time within "
               f"{f(syn.get('stride_time_s'), 3, 's')}, stance within {f(syn.get('stance_pct'), 1)} points, cadence "
               f"within {f(syn.get('cadence_pct'), 1)} %, knee range within {f(syn.get('knee_flexion_range_deg'), 1)} "
               "deg of the truth's (mean over the clips).")
    return (f'<section id="confidence"><h2>How sure each figure is</h2>'
            f"<p>Worn: {e(', '.join(c.sites))}. Segments with a sensor are measured; the others are inferred by "
            "the model from the rest.</p><table><tr><th class='l'>segment</th><th class='l'>how</th>"
            "<th>model's spread (deg)</th><th>expected error on real walks (deg)</th></tr>"
            f"{rows}</table><p class='muted'>Spread: how far other answers of the model that fit the same "
            "sensors put the segment (mean over the recording; &mdash; when the recording was made without it: "
            "<code>imucap replay --confidence</code>). Expected error: the segment's orientation error when left "
            f"out of this set ({e(c.real_set or 'no standard set matches')}) on real recorded walks, the left-out "
            f"sensor taken as truth.</p><p>{syn_txt}</p></section>")


def compare_section(r: ReportInput) -> str:
    if r.earlier is None:
        return ""
    a, b = r.earlier.info, r.info
    head = ("<table><tr><th></th><th class='l'>before</th><th class='l'>after</th></tr>" + "".join(
        f"<tr><th class='l'>{k}</th><td class='l'>{e(x)}</td><td class='l'>{e(y)}</td></tr>" for k, x, y in (
            ("File", a.path.name, b.path.name), ("Recorded", a.date, b.date),
            ("Sensor set", ", ".join(a.sensors), ", ".join(b.sensors)),
            ("Walking strides (L / R)", f"{r.earlier.figures['strides']['l']} / {r.earlier.figures['strides']['r']}",
             f"{r.figures['strides']['l']} / {r.figures['strides']['r']}"))) + "</table>")
    rows = "".join(
        f"<tr class='{'mark' if w.marked else ''}'><td class='l'>{e(w.figure)}</td><td>{e(w.unit)}</td>"
        f"<td>{f(w.before, 3)}</td><td>{f(w.after, 3)}</td><td>{f(w.diff, 3)}</td><td>{f(w.expected, 3)}</td>"
        f"<td>{f(w.se2, 3)}</td><td>{'changed' if w.marked else ''}</td></tr>" for w in r.rows)
    n = sum(w.marked for w in r.rows)
    return (f'<section id="compare" class="page"><h2>Compared with the earlier session</h2>{head}'
            "<table><tr><th class='l'>figure</th><th>unit</th><th>before</th><th>after</th><th>difference</th>"
            f"<th>expected error</th><th>2 SE</th><th></th></tr>{rows}</table>"
            f"<p>{n} difference(s) exceed both the expected error of the two sensor sets and twice the standard "
            "error of the stride-to-stride variation (marked).</p>"
            f"{_img(r.images.get('compare_cycles'), 'gait cycles, before and after')}"
            "<p class='muted'>Solid with band: after; dashed black: before.</p></section>")


def methods_section(r: ReportInput) -> str:
    src = r.figures["events_from"]
    if src == "foot sensors":
        how = (": each foot's angular rate about its medio-lateral axis peaks once per stride in mid-swing; the "
               "peak of the roll over the toes before it is foot off, the first peak of the foot flattening after "
               "it is foot strike (Rampp et al. 2014, IEEE TBME 62(4)); a step turning on the spot is told by the "
               "foot's still periods")
    else:
        how = " (either heel or toe down is stance), the crossing interpolated between frames"
    return ('<section id="methods"><h2>How these figures were made</h2><ul>'
            f"<li>Foot strike and foot off: from {e(SOURCES.get(src, src))}{e(how)}, debounced: gaps under "
            f"{MIN_SWING_S} s closed, contacts under {MIN_STANCE_S} s dropped. Insoles, when worn, come first, "
            "then foot sensors, then the model's contacts.</li>"
            "<li>A stride runs from a foot strike to the next of the same foot. Stride length and speed come from "
            "the reconstructed pelvis path between the two strikes.</li>"
            "<li>Joint angles: <code>inference/metrics/joint_angles.py</code> (ISB / OpenSim Rajagopal), on the "
            "reconstructed segment orientations; over the cycle, each stride resampled to 0-100 %.</li>"
            "<li>Expected errors: <code>imucap evaluate --data @real</code> (real logs) and "
            "<code>benchmarks/report_gait_check.py</code> (synthesized walks); docs/report.md.</li></ul></section>")


def render(r: ReportInput) -> str:
    title = f"Gait report: {r.info.subject}, {r.info.path.name}"
    parts = [summary_section(r), strides_section(r), ranges_section(r), cycles_section(r), confidence_section(r),
             compare_section(r), methods_section(r)]
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>{e(title)}</title>'
            f"<style>{CSS}</style></head><body>{''.join(parts)}</body></html>\n")


__all__ = ["ReportInput", "SECTIONS", "SIDES", "render"]
