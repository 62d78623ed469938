"""Write a reconstructed motion as CSV: the format anyone can open (spreadsheets, pandas,
MATLAB's readtable, R) without knowing our code.

One row per 20 Hz frame, comma separated, one header row of column names, no comments
(so every reader takes the header as names). Columns, in order:

- ``time_s``: seconds since the recording's first raw frame;
- ``root_x_m, root_y_m, root_z_m``: pelvis joint in the world frame (right-handed, Z up,
  X = the subject's forward at calibration; metres);
- per segment, in DESIGN.md order (pelvis, l_thigh, r_thigh, spine1, ...):
  ``<segment>_qw, <segment>_qx, <segment>_qy, <segment>_qz``: global orientation R_WB
  (segment -> world) as a unit quaternion (w, x, y, z). A quaternion and its negative are
  the same rotation; we keep w >= 0 on the first frame and then the sign closest to the
  previous frame, so columns are continuous in time (plots and filters behave);
- per segment: ``<segment>_joint_x_m, _y_m, _z_m``: world position of the joint where the
  segment starts (the pelvis joint equals the root);
- ``contact_l_heel, contact_l_toe, contact_r_heel, contact_r_toe``: 1 if that point is
  on the ground, else 0;
- only when the poser computed a confidence (``inference/poser/confidence.py``): per
  segment ``<segment>_spread_deg``, how far other inpaintings put it (0 = measured; nan
  in frames without one), and ``root_spread_m``.

24 x 4 + 24 x 3 + 8 = 176 columns, 201 with the confidence. Numbers use 9 significant digits (well below the
reconstruction's own error, and a quaternion round trip stays within 1e-8).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from app.export.common import ExportMotion, atomic_target, continuous_quaternions
from inference.body.skeleton import CONTACTS, SEGMENTS


def csv_columns(spread: bool = False) -> list[str]:
    """The header row (see the module docstring); ``spread``: with the confidence columns."""
    cols = ["time_s", "root_x_m", "root_y_m", "root_z_m"]
    cols += [f"{s}_q{c}" for s in SEGMENTS for c in "wxyz"]
    cols += [f"{s}_joint_{c}_m" for s in SEGMENTS for c in "xyz"]
    cols += [f"contact_{c}" for c in CONTACTS]
    if spread:
        cols += [f"{s}_spread_deg" for s in SEGMENTS] + ["root_spread_m"]
    return cols


def csv_table(m: ExportMotion) -> np.ndarray:
    """(T, 176) numbers in ``csv_columns()`` order, (T, 201) with the confidence."""
    T = m.n_frames
    q = continuous_quaternions(m.rot).reshape(T, -1)
    parts = [m.time[:, None], m.root, q, m.joints.reshape(T, -1), m.contacts.astype(np.float64)]
    if m.spread_deg is not None:
        parts += [m.spread_deg, m.root_spread_m[:, None]]
    return np.concatenate(parts, axis=1)


def write_csv(path: str | os.PathLike, m: ExportMotion) -> Path:
    """Write ``m`` as CSV (module docstring); returns the path. Written to a temporary name
    and renamed, so a crash never leaves a half-written file."""
    path = Path(path)
    tmp = atomic_target(path)
    table = csv_table(m)
    spread = m.spread_deg is not None
    n_float = len(csv_columns()) - 4
    fmt = ["%.9g"] * n_float + ["%d"] * 4 + (["%.4g"] * (table.shape[1] - n_float - 4) if spread else [])
    np.savetxt(tmp, table, delimiter=",", fmt=fmt, header=",".join(csv_columns(spread)), comments="")
    os.replace(tmp, path)
    return path


__all__ = ["csv_columns", "csv_table", "write_csv"]
