"""Data logs written by the x-IMU3 GUI: one folder per device, named
``<device name> <serial> (<interface>)``, holding one CSV per message type.

Two of them carry what the pipeline needs:
- ``Inertial.csv``: timestamp (us, the device clock), gyroscope x/y/z (deg/s),
  accelerometer x/y/z (g, specific force: a still sensor reads +1 g along up);
- ``Quaternion.csv``: timestamp (us), w, x, y, z: the AHRS orientation, sensor -> Earth,
  Earth Z up (checked on a real log: R(q) f = (0, 0, 1 g) when still).
Each row of each file has its own timestamp; the two are joined on it, so a row lost
from one file drops that sample only. The devices of one log share a clock (the GUI
synchronises them), so their timestamps are comparable.

Why a reader and not a driver: a logged session is how x-IMU3 recordings reach a
researcher; ``imucap import`` turns one into a session recording that ``replay`` and
``export`` read like any other.
"""

from __future__ import annotations

import csv
import os
import re
from pathlib import Path

import numpy as np

from drivers.device_log import DeviceLog

G = 9.81
_FOLDER = re.compile(r"^(?P<name>.+?)\s+(?P<serial>[0-9A-Fa-f]{6,})\s*(\((?P<iface>[^)]*)\))?$")


class LogError(ValueError):
    """A folder that is not an x-IMU3 device log, or one without usable samples."""


def _read_csv(path: Path, columns: int) -> tuple[np.ndarray, int]:
    """Rows of ``columns`` numbers (header skipped); malformed rows are counted.

    Bytes that are not UTF-8 (a damaged sector, a file from another tool) only spoil
    the rows they are in, as the replacement character makes those rows malformed."""
    rows, bad = [], 0
    with open(path, newline="", encoding="utf-8", errors="replace") as f:
        reader = csv.reader(f)
        next(reader, None)
        for row in reader:
            if len(row) < columns:
                bad += 1
                continue
            try:
                vals = [float(x) for x in row[:columns]]
            except ValueError:
                bad += 1
                continue
            if not np.all(np.isfinite(vals)):
                bad += 1
                continue
            rows.append(vals)
    return np.array(rows, dtype=np.float64).reshape(-1, columns), bad


def read_device_log(folder: str | os.PathLike) -> DeviceLog:
    """One device folder of a log (see the module docstring)."""
    folder = Path(folder)
    m = _FOLDER.match(folder.name)
    name, serial = (m.group("name"), m.group("serial")) if m else (folder.name, "")
    for need in ("Inertial.csv", "Quaternion.csv"):
        if not (folder / need).is_file():
            raise LogError(f"{folder}: no {need}; not an x-IMU3 device log")
    inertial, bad_i = _read_csv(folder / "Inertial.csv", 7)
    quats, bad_q = _read_csv(folder / "Quaternion.csv", 5)
    ti, iu = np.unique(inertial[:, 0], return_index=True)
    tq, qu = np.unique(quats[:, 0], return_index=True)
    duplicate = len(inertial) - len(iu) + len(quats) - len(qu)
    common, ii, qi = np.intersect1d(ti, tq, assume_unique=True, return_indices=True)
    if common.size < 2:
        raise LogError(f"{folder}: fewer than two samples with both inertial data and a quaternion")
    inertial, quats = inertial[iu][ii], quats[qu][qi]
    q = quats[:, 1:5]
    norm = np.linalg.norm(q, axis=1)
    ok = norm > 0.5
    q = q / np.where(ok, norm, 1.0)[:, None]
    skipped = {"malformed": bad_i + bad_q, "duplicate": int(duplicate),
               "unpaired": int(len(ti) + len(tq) - 2 * common.size), "bad_quaternion": int((~ok).sum())}
    return DeviceLog(name=name, serial=serial, t=common[ok] * 1e-6, quat=q[ok],
                     acc=inertial[ok, 4:7] * G, gyro=np.deg2rad(inertial[ok, 1:4]), skipped=skipped)


def read_log(root: str | os.PathLike) -> list[DeviceLog]:
    """Every device folder under ``root`` (folders without the two CSVs are ignored),
    sorted by name."""
    root = Path(root)
    if not root.is_dir():
        raise LogError(f"{root}: not a folder")
    logs = [read_device_log(d) for d in sorted(root.iterdir())
            if d.is_dir() and (d / "Inertial.csv").is_file() and (d / "Quaternion.csv").is_file()]
    if not logs:
        raise LogError(f"{root}: no x-IMU3 device folders (each holds Inertial.csv and Quaternion.csv)")
    return logs


__all__ = ["DeviceLog", "LogError", "read_device_log", "read_log", "G"]
