"""Write a reconstruction's virtual markers (``markers.py``) as a TRC, the marker file
OpenSim's marker inverse kinematics and scaling read (``TRCFileAdapter``).

Layout (tab-separated): ``PathFileType 4 (X/Y/Z) NAME``; a line of keys ``DataRate
CameraRate NumFrames NumMarkers Units OrigDataRate OrigDataStartFrame OrigNumFrames`` and
one of their values; ``Frame# Time`` and the marker names (each over three columns);
``X1 Y1 Z1 X2 ...``; an empty line; one row per frame. Millimetres, in OpenSim's ground
(X forward, Y up, Z to the subject's right: ``app.export.opensim.M_OS``), time in seconds
since the recording's first raw frame. Equally spaced frames as the C3D's; a frame the
poser dropped is written with empty cells (TRC's missing marker), as the C3D marks it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from app.export.c3d_file import filled, regular_frames
from app.export.common import ExportMotion, atomic_target
from app.export.markers import marker_names, marker_positions
from app.export.opensim import M_OS


def trc_text(name: str, time: np.ndarray, names: list[str], pos_mm: np.ndarray, rate: float) -> str:
    T, N = pos_mm.shape[:2]
    lines = [f"PathFileType\t4\t(X/Y/Z)\t{name}",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate:.2f}\t{rate:.2f}\t{T}\t{N}\tmm\t{rate:.2f}\t1\t{T}",
             "\t".join(["Frame#", "Time"] + [f"{n}\t\t" for n in names]).rstrip("\t"),
             "\t".join(["", ""] + [f"X{i}\tY{i}\tZ{i}" for i in range(1, N + 1)]), ""]
    for t in range(T):
        lines.append("\t".join([str(t + 1), f"{time[t]:.6f}",
                                *("" if np.isnan(v) else f"{v:.4f}" for v in pos_mm[t].reshape(-1))]))
    return "\n".join(lines) + "\n"


def write_trc(path: str | os.PathLike, m: ExportMotion) -> Path:
    path = Path(path)
    k = regular_frames(m)
    pos = marker_positions(m.rot, m.joints, m.body)[k] @ M_OS.T * 1000.0
    pos[filled(m, k)] = np.nan
    time = m.time[0] + np.arange(len(k)) / m.fps
    tmp = atomic_target(path)
    tmp.write_text(trc_text(path.name, time, marker_names(), pos, m.fps))
    os.replace(tmp, path)
    return path


__all__ = ["write_trc", "trc_text"]
