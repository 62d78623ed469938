"""Write a reconstruction as C3D, the file a gait lab's software (Vicon Nexus, Visual3D,
Mokka, OpenSim's C3D adapter) opens first: virtual markers at the joint centres and
segment ends (``markers.py`` names them), at the reconstruction's rate, in millimetres,
in our world (Z up, X the subject's forward at calibration), and events: ``Foot Strike``
and ``Foot Off`` per side from the contacts (context ``Left``/``Right``), as Vicon
labels them. Written with ezc3d, the maintained C3D library, not by hand.

Frame 0 is the first exported frame; a C3D's frames are equally spaced (``time`` of each
frame = first + k / rate), so a gap the live poser left (dropped frames) becomes frames
marked as not measured: their points are written as NaN, which ezc3d stores as residual
-1 (the C3D standard's invalid point; ezc3d reads it back as NaN, the ``c3d`` package as a
negative residual). Events come from the contacts debounced as the gait numbers debounce
them (``inference.metrics.gait.debounced_contact``): one strike and one off per step even
when the contact flickers.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from app.export.common import ExportMotion, atomic_target
from app.export.markers import contact_events, marker_names, marker_positions

UNITS = "mm"
SCALE = 1000.0


def regular_frames(m: ExportMotion) -> np.ndarray:
    """Index of the motion frame at each equally spaced output frame (nearest in time)."""
    n = int(round((m.time[-1] - m.time[0]) * m.fps)) + 1 if m.n_frames else 0
    grid = m.time[0] + np.arange(n) / m.fps
    k = np.clip(np.searchsorted(m.time, grid), 1, max(m.n_frames - 1, 1))
    k -= (grid - m.time[k - 1]) < (m.time[np.minimum(k, m.n_frames - 1)] - grid)
    return np.clip(k, 0, m.n_frames - 1)


def filled(m: ExportMotion, k: np.ndarray) -> np.ndarray:
    """(len(k),) bool: output frames with no motion frame of their own (the nearest one,
    more than half a frame away, stands in for them)."""
    grid = m.time[0] + np.arange(len(k)) / m.fps if m.n_frames else np.zeros(0)
    return np.abs(m.time[k] - grid) > 0.5 / m.fps


def write_c3d(path: str | os.PathLike, m: ExportMotion) -> Path:
    from drivers.extras import need

    ezc3d = need("ezc3d", "writing .c3d")

    path = Path(path)
    k = regular_frames(m)
    pos = marker_positions(m.rot, m.joints, m.body)[k] * SCALE  # (T, N, 3)
    pos[filled(m, k)] = np.nan  # not measured: residual -1
    names = marker_names()
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [float(m.fps)]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(names)
    c["parameters"]["POINT"]["DESCRIPTIONS"]["value"] = tuple(
        "imucap virtual marker (joint centre)" if i < 24 else "imucap virtual marker (segment end)"
        for i in range(len(names)))
    c.add_parameter("POINT", "UNITS", [UNITS])
    pts = np.ones((4, len(names), len(k)))
    pts[:3] = np.transpose(pos, (2, 1, 0))
    c["data"]["points"] = pts
    t_first = float(m.time[0])
    for t, side, label in contact_events(m.time, m.contacts):
        s = t - t_first  # events on the file's clock: frame 0 at 0 s
        c.add_event(time=[int(s // 60), float(s - 60 * (s // 60))], context=side, label=label,
                    description="from imucap's contact estimate")
    c.add_parameter("MANUFACTURER", "SOFTWARE", ["imucap"])
    tmp = atomic_target(path).with_suffix(".tmp.c3d")
    c.write(str(tmp))
    os.replace(tmp, path)
    return path


__all__ = ["write_c3d", "regular_frames", "filled", "UNITS"]
