"""What the skeleton's colours mean, shared by the 3D and the 2D views and their legend.

Why colour by measurement: with six sensors on 24 segments most of the body on screen is
the model's guess. A clinician must see at a glance which segments a sensor measured and,
when the poser reports how far its other inpaintings spread, how sure the guess is.
"""

from __future__ import annotations

import numpy as np

from inference.body.skeleton import N_SEGMENTS, SITE_SEGMENT_INDEX

MEASURED = (0.30, 0.70, 1.00, 1.0)  # a sensor sits on it
INFERRED = (0.86, 0.88, 0.92, 1.0)  # the model's, no spread known
JOINT = (1.00, 0.75, 0.30, 1.0)
CONTACT_ON = (0.20, 1.00, 0.30, 1.0)
CONTACT_OFF = (0.50, 0.50, 0.50, 1.0)
TRAIL = (1.00, 0.55, 0.20, 0.9)
RERUN = (1.00, 0.62, 0.35, 1.0)  # the re-run skeleton beside the recorded one in the replay
SPREAD_STOPS = ((0.0, (0.25, 0.85, 0.35)), (12.0, (0.98, 0.85, 0.25)), (30.0, (0.95, 0.25, 0.20)))
SPREAD_MAX_DEG = SPREAD_STOPS[-1][0]


def spread_colour(deg: float | np.ndarray) -> np.ndarray:
    """Green (sure) -> yellow -> red (the inpaintings disagree by 30 deg or more)."""
    d = np.clip(np.asarray(deg, dtype=float), 0.0, SPREAD_MAX_DEG)
    xs = [s[0] for s in SPREAD_STOPS]
    rgb = np.stack([np.interp(d, xs, [s[1][c] for s in SPREAD_STOPS]) for c in range(3)], axis=-1)
    return np.concatenate([rgb, np.ones(rgb.shape[:-1] + (1,))], axis=-1)


def segment_colours(observed_sites: np.ndarray | None, spread_deg: np.ndarray | None = None) -> np.ndarray:
    """(24, 4) RGBA per segment: measured ones in MEASURED, the rest INFERRED, or by their
    spread when the pose carries one."""
    out = np.tile(np.asarray(INFERRED), (N_SEGMENTS, 1))
    if spread_deg is not None:
        s = np.asarray(spread_deg, dtype=float)
        if s.shape == (N_SEGMENTS,) and np.isfinite(s).any():
            out = spread_colour(np.nan_to_num(s, nan=0.0))
    if observed_sites is not None:
        obs = np.asarray(observed_sites, dtype=bool)
        segs = [SITE_SEGMENT_INDEX[k] for k in np.flatnonzero(obs)]
        out[segs] = MEASURED
    return out


def difference_colours(deg: np.ndarray) -> np.ndarray:
    """(24, 4) per-segment colours for an angle difference between two skeletons."""
    return spread_colour(np.nan_to_num(np.asarray(deg, dtype=float), nan=0.0))


def qcolor_tuple(rgba: tuple[float, ...] | np.ndarray) -> tuple[int, int, int]:
    r, g, b = (int(round(255 * float(c))) for c in tuple(rgba)[:3])
    return r, g, b
