"""Write a reconstructed motion as HDF5: full precision arrays with their units, names and
provenance in one self-describing file (h5py, MATLAB ``h5read``, HDFView, ...).

Why not just the recording: a recording holds the raw sensor stream, calibrations and
the live reconstruction of *one* run, in a layout made to survive a crash. An export is
one motion -- the live one or any re-run with another model or sensor subset -- in plain
arrays a reader can use without knowing our session format.

Datasets (T = frames, float64 unless said):

    time (T,)             s since the recording's first raw frame
    rot (T, 24, 3, 3)     global segment orientations R_WB (segment -> world)
    quat (T, 24, 4)       the same as (w, x, y, z), continuous in sign (app/export/csv_file.py)
    root (T, 3)           pelvis joint, m
    joints (T, 24, 3)     joint positions, m (joint i starts segment i)
    contacts (T, 4) bool  l_heel, l_toe, r_heel, r_toe on the ground
    contact_prob (T, 4)   the model's contact values in [0, 1] (when known)
    body_offsets (24, 3)  bone offsets (joint i relative to its parent, parent's rest
                          frame, m): with rot and root they give joints by FK
    spread_deg (T, 24)    per segment, how far other inpaintings put it, deg (0 where
                          measured; NaN without one) -- only when the poser computed a
                          confidence (inference/poser/confidence.py)
    root_spread_m (T,)    the same for the root, m

Root attributes: ``format`` ("imucap-motion"), ``version``, ``fps``, ``segments``,
``parents``, ``contacts`` (names), ``body_height_m``, ``units`` (JSON), ``frame`` (the
world frame in words), ``time_origin`` (session clock value of time 0), and provenance:
``source_recording``, ``model``, ``steps``, ``sensors`` (JSON list), ``insoles``, ``what``
(live reconstruction or replay), ``meta`` (everything else, JSON).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.export.common import ExportMotion, atomic_target, continuous_quaternions
from inference.body.skeleton import CONTACTS, PARENTS, SEGMENTS

FORMAT = "imucap-motion"
VERSION = 1
UNITS = {"time": "s", "root": "m", "joints": "m", "body_offsets": "m", "rot": "rotation matrix R_WB",
         "quat": "unit quaternion (w, x, y, z) R_WB", "contacts": "bool", "contact_prob": "1", "spread_deg": "deg",
         "root_spread_m": "m"}
FRAME = "world: right-handed, Z up, gravity -Z, X = the subject's forward at calibration"


def _attr(v: Any) -> Any:
    """h5py stores str/int/float/bool; None and containers go in as JSON text."""
    if v is None or isinstance(v, (list, tuple, dict)):
        return json.dumps(v, default=str)
    return v


def write_hdf5(path: str | os.PathLike, m: ExportMotion) -> Path:
    """Write ``m`` (module docstring); returns the path. Temporary name, then rename."""
    path = Path(path)
    tmp = atomic_target(path)
    meta = dict(m.meta)
    str_dt = h5py.string_dtype()
    with h5py.File(tmp, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        f.attrs["created"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        f.attrs["fps"] = float(m.fps)
        f.attrs.create("segments", np.array(SEGMENTS, dtype=object), dtype=str_dt)
        f.attrs["parents"] = np.array(PARENTS, dtype=np.int64)
        f.attrs.create("contacts", np.array(CONTACTS, dtype=object), dtype=str_dt)
        f.attrs["body_height_m"] = float(m.body.height)
        f.attrs["units"] = json.dumps(UNITS)
        f.attrs["frame"] = FRAME
        for key in ("time_origin", "source_recording", "model", "steps", "sensors", "insoles", "what"):
            f.attrs[key] = _attr(meta.pop(key, None))
        f.attrs["meta"] = json.dumps(meta, default=str)
        f.create_dataset("time", data=m.time)
        f.create_dataset("rot", data=m.rot, compression="gzip", shuffle=True)
        f.create_dataset("quat", data=continuous_quaternions(m.rot), compression="gzip", shuffle=True)
        f.create_dataset("root", data=m.root)
        f.create_dataset("joints", data=m.joints, compression="gzip", shuffle=True)
        f.create_dataset("contacts", data=m.contacts)
        if m.contact_prob is not None:
            f.create_dataset("contact_prob", data=m.contact_prob)
        f.create_dataset("body_offsets", data=m.body.offsets)
        if m.spread_deg is not None:
            f.create_dataset("spread_deg", data=m.spread_deg, compression="gzip", shuffle=True)
            f.create_dataset("root_spread_m", data=m.root_spread_m)
    os.replace(tmp, path)
    return path


def read_hdf5(path: str | os.PathLike) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """(datasets, attributes) of an exported file; strings decoded, JSON attributes left
    as text (``units``, ``sensors``, ``meta`` ...: ``json.loads`` them)."""
    with h5py.File(path, "r") as f:
        if f.attrs.get("format") != FORMAT:
            raise ValueError(f"{path} is not an imucap motion export")
        data = {k: f[k][()] for k in f}
        attrs: dict[str, Any] = {}
        for k, v in f.attrs.items():
            if isinstance(v, bytes):
                v = v.decode()
            elif isinstance(v, np.ndarray) and v.dtype == object:
                v = [x.decode() if isinstance(x, bytes) else str(x) for x in v]
            attrs[k] = v
    return data, attrs


__all__ = ["write_hdf5", "read_hdf5", "FORMAT", "VERSION", "UNITS"]
