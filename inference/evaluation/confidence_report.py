"""`imucap evaluate --confidence`: does the poser's spread predict its error, and how often
does the error fall inside the bands made from it.

Pairs are (frame, segment) over the evaluated segments (GA's 18: no toes, hands,
fingers), the spread as the poser gave it live and the error of the displayed
orientation. The bands are ``max(floor, scale * spread)`` with the floor and scale of
``confidence.SEGMENT_BANDS`` / ``ROOT_BANDS``, fit by ``--fit-bands`` on clips of the
training actors (docs/confidence.md), never on the clips being scored.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from inference.body.skeleton import SEGMENTS
from inference.evaluation.runner import SIX, ClipResult
from inference.metrics.calibration import (
    Band,
    calibration_table,
    coverage,
    fit_bands,
    root_errors_m,
    segment_errors_deg,
    spearman,
)
from inference.metrics.errors import EVAL_SEGMENTS
from inference.poser.confidence import ROOT_BANDS, ROOT_HORIZON_S, SEGMENT_BANDS
from inference.signals.resample import FPS_MODEL

CONFIDENCE_SETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("6 sites", SIX),
    ("3 sites (pelvis, wrists)", ("pelvis", "l_wrist", "r_wrist")),
    ("2 sites (shanks)", ("l_shank", "r_shank")),
)


def pairs(clips: Sequence[ClipResult]) -> dict[str, np.ndarray]:
    """Errors and spreads of kept clip results, frames pooled: seg_error/seg_spread (T, 24)
    deg, root_error/root_spread (T,) m (the root error as the root spread measures it:
    height and the last second's horizontal displacement)."""
    h = int(round(ROOT_HORIZON_S * FPS_MODEL))
    return {
        "seg_error": np.concatenate([segment_errors_deg(c.recon.rot, c.inp.rot) for c in clips]),
        "seg_spread": np.concatenate([c.recon.spread_deg for c in clips]),
        "root_error": np.concatenate([root_errors_m(c.recon.root, c.inp.root, h) for c in clips]),
        "root_spread": np.concatenate([c.recon.root_spread_m for c in clips]),
    }


def shipped_bands() -> tuple[list[Band], list[Band]]:
    return ([Band(*b) for b in SEGMENT_BANDS], [Band(*b) for b in ROOT_BANDS])


def calibration(clips: Sequence[ClipResult], bands: tuple[list[Band], list[Band]] | None = None) -> dict:
    """The figures of one sensor set (``metrics.calibration.calibration_table``) and the
    root's: Spearman and band coverage."""
    seg_bands, root_bands = bands or shipped_bands()
    p = pairs(clips)
    out = calibration_table(p["seg_error"], p["seg_spread"], SEGMENTS, seg_bands, EVAL_SEGMENTS)
    out["frames"] = int(len(p["seg_error"]))
    out["root"] = {"spearman": spearman(p["root_spread"], p["root_error"]),
                   **{f"inside_{round(100 * b.level)}": coverage(p["root_error"], p["root_spread"], b)
                      for b in root_bands}}
    return out


def fit(clip_sets: Sequence[Sequence[ClipResult]]) -> dict:
    """Band factors from every (frame, evaluated segment) pair of the given evaluations
    pooled, and the root's, as ``confidence.SEGMENT_BANDS`` / ``ROOT_BANDS`` take them."""
    ps = [pairs(c) for c in clip_sets]
    cols = list(EVAL_SEGMENTS)
    e = np.concatenate([p["seg_error"][:, cols].ravel() for p in ps])
    s = np.concatenate([p["seg_spread"][:, cols].ravel() for p in ps])
    re = np.concatenate([p["root_error"] for p in ps])
    rs = np.concatenate([p["root_spread"] for p in ps])
    return {"segment": [(b.level, round(b.floor, 3), round(b.scale, 3)) for b in fit_bands(e, s)],
            "root": [(b.level, round(b.floor, 4), round(b.scale, 3)) for b in fit_bands(re, rs)]}


def markdown(rows: Sequence[tuple[str, dict]], source: str, command: str) -> str:
    """The calibration tables of the evaluated sets: a summary row per set, then per segment."""

    def f(v, nd=2):
        return "n/a" if v is None else f"{v:.{nd}f}"

    def pct(v):
        return "n/a" if v is None else f"{100 * v:.0f} %"

    lines = ["## Spread against error", "",
             "Spearman over every (frame, segment) pair of the evaluated segments; of the per-segment means; "
             "error inside the 50 / 90 % bands (factors fit on the training actors, not on these clips).", "",
             "| sensors | frames | Spearman, pairs | Spearman, segment means | inside 50 % band | inside 90 % band "
             "| root: Spearman | root inside 50 / 90 % |",
             "|---|---|---|---|---|---|---|---|"]
    for label, r in rows:
        root = r["root"]
        lines.append(f"| {label} | {r['frames']} | {f(r['spearman_pooled'])} | {f(r['spearman_segment_means'])} | "
                     f"{pct(r['inside_50'])} | {pct(r['inside_90'])} | {f(root['spearman'])} | "
                     f"{pct(root['inside_50'])} / {pct(root['inside_90'])} |")
    lines += ["", "Per segment: mean spread and error (deg), Spearman over frames (n/a: the spread never varies, "
              "i.e. the segment is measured), share inside the 50 / 90 % bands.", ""]
    head = "| segment | " + " | ".join(label for label, _ in rows) + " |"
    lines += [head, "|---|" + "---|" * len(rows)]
    names = list(rows[0][1]["segments"]) if rows else []
    for name in names:
        cells = []
        for _, r in rows:
            g = r["segments"][name]
            cells.append(f"{f(g['spread'], 1)} / {f(g['error'], 1)}, rho {f(g['spearman'])}, "
                         f"{pct(g['inside_50'])} / {pct(g['inside_90'])}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", f"{source}. Reproduce: `{command}`", ""]
    return "\n".join(lines)


__all__ = ["CONFIDENCE_SETS", "pairs", "calibration", "fit", "markdown", "shipped_bands"]
