"""The validation report: ``report.md`` with its plots beside it and ``validation.json``
(what ``--json`` prints), in the folder ``--report`` names.

Plots (matplotlib, no display needed): the joint flexion angles over time, every subset
against the reference; the per-segment errors of every subset and the baseline; one
Bland-Altman figure per joint for the ranges of motion per ``compare.WINDOW_S`` window
(imucap minus reference against their mean, bias and 95% limits of agreement).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from app.validate.compare import WINDOW_S
from app.validate.run import Validation

JOINT_ORDER = ("l_hip", "r_hip", "l_knee", "r_knee", "l_ankle", "r_ankle", "l_elbow", "r_elbow")
PLOT_SECONDS = 15.0  # of the angles over time: a trial's first strides, readable; the tables cover all of it


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_angles(v: Validation, path: Path) -> Path | None:
    plt = _plt()
    t_ref, a_ref = v.curves["reference"]
    ours = [a for k, (_, a) in v.curves.items() if k != "reference"]
    joints = [j for j in JOINT_ORDER if j in a_ref and any(j in a for a in ours)]
    if not joints:
        return None
    start = min(float(t[0]) for k, (t, _) in v.curves.items() if k != "reference" and len(t))
    fig, axes = plt.subplots(len(joints), 1, figsize=(9, 1.5 * len(joints)), sharex=True, squeeze=False)
    for ax, j in zip(axes[:, 0], joints):
        keep = (t_ref >= start) & (t_ref <= start + PLOT_SECONDS)
        ax.plot(t_ref[keep], a_ref[j][keep], color="black", lw=2.0, label="reference")
        for name, (t, a) in v.curves.items():
            if name != "reference" and j in a:
                keep = t <= start + PLOT_SECONDS
                ax.plot(t[keep], a[j][keep], lw=1.0, label=f"imucap {subset_label(name.split(','))}")
        ax.set_ylabel(f"{j} (deg)")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="upper right", ncol=2)
    axes[-1, 0].set_xlabel("time since the recording's first frame (s)")
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)
    return path


def plot_segments(v: Validation, path: Path) -> Path | None:
    plt = _plt()
    rows = [*v.subsets, v.baseline]
    segs = [s for s in rows[0]["segments"]]
    if not segs:
        return None
    fig, ax = plt.subplots(figsize=(10, 3.6))
    w = 0.8 / len(rows)
    x = np.arange(len(segs))
    for k, r in enumerate(rows):
        label = "baseline (standing)" if r is v.baseline else subset_label(r["sensors"])
        ax.bar(x + k * w, [r["segments"].get(s, np.nan) for s in segs], w, label=label)
    ax.set_xticks(x + 0.4 - w / 2, segs, rotation=60, fontsize=7)
    ax.set_ylabel("mean error (deg)")
    ax.legend(fontsize=7)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_bland_altman(v: Validation, path: Path) -> Path | None:
    plt = _plt()
    lead = v.subsets[0]
    joints = [j for j in JOINT_ORDER if j in lead["joints"] and len(lead["joints"][j]["window_ranges_deg"]) >= 2]
    if not joints:
        return None
    fig, axes = plt.subplots(1, len(joints), figsize=(2.6 * len(joints), 2.8), squeeze=False)
    for ax, j in zip(axes[0], joints):
        a = np.asarray(lead["joints"][j]["window_ranges_deg"], float)
        mean, diff = a.mean(axis=1), a[:, 0] - a[:, 1]
        ba = lead["bland_altman"][j]
        ax.scatter(mean, diff, s=10)
        for y, ls in ((ba["bias_deg"], "-"), (ba["loa_low_deg"], "--"), (ba["loa_high_deg"], "--")):
            ax.axhline(y, color="gray", ls=ls, lw=1)
        ax.set_title(j, fontsize=9)
        ax.set_xlabel("mean range (deg)", fontsize=8)
    axes[0, 0].set_ylabel("imucap - reference (deg)", fontsize=8)
    fig.suptitle(f"Range of motion per {WINDOW_S:g} s window, {subset_label(lead['sensors'])}", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def subset_label(sensors: list[str]) -> str:
    """A subset's name in tables and legends: its sites, or their count when long."""
    return ",".join(sensors) if len(sensors) <= 6 else f"{len(sensors)} sensors"


def _table(rows: list[tuple[str, dict[str, Any]]], key: str, cols: list[str], fmt) -> list[str]:
    lines = ["| | " + " | ".join(cols) + " |", "|---|" + "---|" * len(cols)]
    for name, r in rows:
        lines.append(f"| {name} | " + " | ".join(fmt(r[key].get(c)) for c in cols) + " |")
    return lines


def markdown(v: Validation, plots: dict[str, Path | None], command: str | None = None) -> str:
    s = v.summary()
    rows = [(subset_label(r["sensors"]), r) for r in v.subsets] + [("baseline (standing)", v.baseline)]
    corr = s["time_offset_correlation"]
    lines = [f"# imucap against {Path(v.reference.path).name}", "",
             f"Recording `{Path(v.recording).name}`, reference `{Path(v.reference.path).name}` "
             f"({v.reference.format}, {v.reference.n_frames} frames at {v.reference.fps:.4g} Hz).", ""]
    if command:
        lines += ["Made with:", "", f"    {command}", ""]
    long = [r["sensors"] for r in v.subsets if len(r["sensors"]) > 6]
    for sensors in long:
        lines += [f"{len(sensors)} sensors: {','.join(sensors)}.", ""]
    lines += ["## Alignment", "",
              f"- time offset (reference clock minus recording clock): **{s['time_offset_s']:.4f} s**"
              + (" (given)" if s["time_offset_given"] else
                 f", correlation {corr:.3f} of {', '.join(s['time_offset_joints'])}"),
              f"- heading (turns the recording's world onto the reference's): **{s['heading_deg']:.2f} deg** "
              f"(from {s['heading_from']})", ""]
    if len(s["time_offset_candidates"]) > 1:
        lines += ["Offset candidates (the search's best peaks): " + ", ".join(
            f"{c['time_offset_s']:+.3f} s ({c['correlation']:.3f})" for c in s["time_offset_candidates"]), ""]
    lines += [f"**Warning:** {w}" for w in s["warnings"]] + ([""] if s["warnings"] else [])
    if v.reference.mapping:
        lines += ["Mapping (ours <- reference):", "", *[f"    {m}" for m in v.reference.mapping], ""]
    for n in v.reference.notes:
        lines.append(f"- note: {n}")
    lines += ["", "## Segments: mean error (deg)", "",
              "Orientation error where the reference has the segment's orientation, else the angle between the "
              "segment directions.", ""]
    segs = list(v.subsets[0]["segments"])
    lines += _table(rows, "segments", segs + [], lambda x: "" if x is None else f"{x:.1f}")
    lines += ["", "| | mean over segments (deg) |", "|---|---|"]
    lines += [f"| {name} | {r['mean_deg']:.2f} |" if r["mean_deg"] is not None else f"| {name} | |"
              for name, r in rows]
    joints = [j for j in JOINT_ORDER if j in v.subsets[0]["joints"]]
    lines += ["", "## Joints: hip and knee flexion, ankle dorsiflexion, elbow flexion", "",
              "Defined once for imucap (`inference/metrics/joint_angles.py`: the ISB joint coordinate system as "
              "OpenSim's models use it). RMS of imucap minus reference, and the range of motion (max - min over "
              "the trial) of each.", ""]
    lines += ["| | " + " | ".join(f"{j} RMS / range / ref range" for j in joints) + " |",
              "|---|" + "---|" * len(joints)]
    for name, r in rows:
        cells = []
        for j in joints:
            d = r["joints"].get(j)
            cells.append("" if d is None else
                         f"{d['rms_deg']:.1f} / {d['range_deg']:.1f} / {d['reference_range_deg']:.1f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    ba = v.subsets[0].get("bland_altman", {})
    if ba:
        lines += ["", f"Bland-Altman of the ranges per window ({subset_label(v.subsets[0]['sensors'])}):", "",
                  "| joint | bias (deg) | 95% limits (deg) | windows |", "|---|---|---|---|"]
        for j in joints:
            b = ba.get(j)
            if b:
                lines.append(f"| {j} | {b['bias_deg']:.2f} | {b['loa_low_deg']:.2f} to {b['loa_high_deg']:.2f} "
                             f"| {b['n']} |")
    lines.append("")
    for title, key in ((f"Joint angles over time (the first {PLOT_SECONDS:g} s)", "angles"),
                       ("Segment errors", "segments"), ("Bland-Altman of the ranges", "bland_altman")):
        if plots.get(key) is not None:
            lines += [f"## {title}", "", f"![{title}]({plots[key].name})", ""]
    return "\n".join(lines)


def write_report(v: Validation, folder: str | os.PathLike, command: str | None = None) -> Path:
    """report.md, its PNGs and validation.json in ``folder``; returns the markdown's path."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    plots = {"angles": plot_angles(v, out / "joint_angles.png"), "segments": plot_segments(v, out / "segments.png"),
             "bland_altman": plot_bland_altman(v, out / "bland_altman.png")}
    (out / "validation.json").write_text(json.dumps(v.summary(), indent=1) + "\n")
    md = out / "report.md"
    md.write_text(markdown(v, plots, command))
    return md


__all__ = ["write_report", "markdown", "plot_angles", "plot_segments", "plot_bland_altman"]
