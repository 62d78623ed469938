"""The report's figures (matplotlib, Agg: no display), each returned as PNG bytes to be inlined.

- ``cycle_figure``: every angle over the gait cycle (0-100 %, foot strike to foot strike), left and right
  side by side: the comparison band (grey, mean +- SD), the walk's mean +- SD over its strides, the mean
  foot off (a dotted line), and with a second session its mean as a dashed line;
- ``timeline_figure``: each foot's stances over the recording's time, every stride coloured by what it
  was taken for (walking, turning, standing, not walking), so what the figures leave out is seen.
"""

from __future__ import annotations

import io

import numpy as np

from .analysis import GaitAnalysis
from .angles import ANGLES
from .normal import NormalBand

SIDE_COLOURS = {"l": "#c0392b", "r": "#1f5fa8"}
SIDE_NAMES = {"l": "left", "r": "right"}
KIND_COLOURS = {"walking": "#2e8b57", "turning": "#e0a100", "standing": "#9a9a9a", "not walking": "#8e44ad"}
DPI = 110


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    _plt().close(fig)
    return buf.getvalue()


def _foot_off_pct(an: GaitAnalysis, side: str) -> float | None:
    st = an.summary.per_side[side]["stance_pct"]["mean"]
    return None if st is None else float(st)


def cycle_figure(an: GaitAnalysis, band: NormalBand | None, angles=tuple(ANGLES), other: GaitAnalysis | None = None,
                 labels: tuple[str, str] = ("this session", "earlier session")) -> bytes:
    plt = _plt()
    pct = np.arange(101)
    fig, axes = plt.subplots(len(angles), 2, figsize=(8.0, 1.75 * len(angles) + 0.6), sharex=True, squeeze=False)
    for row, name in enumerate(angles):
        label, sign, _ = ANGLES[name]
        for col, side in enumerate(("l", "r")):
            ax = axes[row, col]
            if band is not None and band.get(name) is not None:
                m, sd = band.get(name)
                ax.fill_between(pct, m - sd, m + sd, color="#d5d5d5", lw=0, label="comparison band (mocap walks)")
                ax.plot(pct, m, color="#9a9a9a", lw=0.8)
            for a, style, lab in ((other, "--", labels[1]), (an, "-", labels[0])):
                if a is None:
                    continue
                curves = a.cycles[side][name]
                if len(curves) == 0:
                    continue
                mean = curves.mean(axis=0)
                if a is an:
                    sd = curves.std(axis=0)
                    ax.fill_between(pct, mean - sd, mean + sd, color=SIDE_COLOURS[side], alpha=0.22, lw=0)
                ax.plot(pct, mean, style, color=SIDE_COLOURS[side] if a is an else "black", lw=1.5,
                        label=f"{lab} (n={len(curves)})")
                off = _foot_off_pct(a, side)
                if off is not None:
                    ax.axvline(off, color=SIDE_COLOURS[side] if a is an else "black", ls=":", lw=1.0)
            ax.set_xlim(0, 100)
            ax.grid(alpha=0.3)
            ax.tick_params(labelsize=7)
            if col == 0:
                ax.set_ylabel(f"{label}\n{sign} (deg)", fontsize=7)
            if row == 0:
                ax.set_title(f"{SIDE_NAMES[side]} side", fontsize=9)
            if row == len(angles) - 1:
                ax.set_xlabel("gait cycle (% from foot strike)", fontsize=8)
            if row == 0 and col == 1 and ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=6, loc="upper right")
    fig.tight_layout()
    return _png(fig)


def timeline_figure(an: GaitAnalysis) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(8.0, 1.9))
    t0 = float(an.t[0]) if len(an.t) else 0.0
    for row, side in enumerate(("l", "r")):
        y = 1 - row
        for s in an.events[side].stances:
            ax.plot([s.start - t0, s.end - t0], [y + 0.18, y + 0.18], color="black", lw=3, solid_capstyle="butt")
        for st in an.summary.strides:
            if st.side == side:
                ax.barh(y, st.end - st.start - 0.02, left=st.start - t0 + 0.01, height=0.22,
                        color=KIND_COLOURS[st.kind], alpha=0.85)
    for kind, c in KIND_COLOURS.items():
        ax.barh(0, 0, color=c, label=kind)
    ax.plot([], [], color="black", lw=3, label="foot down")
    ax.set_yticks([1, 0], ["left", "right"], fontsize=8)
    ax.set_xlabel("time since the first pose (s)", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.set_ylim(-0.5, 1.6)
    ax.legend(fontsize=6, ncol=5, loc="upper center", bbox_to_anchor=(0.5, 1.32), frameon=False)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    return _png(fig)
