"""Synthesized signals written as an x-IMU3 GUI data log (the layout ``drivers.ximu3``
reads), so the import of a logged session is tested end to end without the sensors.

Like a real log: one folder per device named ``<name> <serial> (UDP)``, ``Inertial.csv``
(timestamp in us, gyro in deg/s, specific force in g) and ``Quaternion.csv`` (timestamp,
w, x, y, z) with one header line, timestamps on a clock shared by the devices; a dropped
packet is a row missing from both files.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from drivers.ximu3.log import G
from inference.signals.site_signals import SiteSignals

INERTIAL_HEADER = ("Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),"
                   "Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)")
QUATERNION_HEADER = "Timestamp (us),W,X,Y,Z"


def write_ximu3_log(sig: SiteSignals, root: str | os.PathLike, names: dict[str, str], t0_us: int = 917_400_000,
                    drop: Sequence[int] = (), rng: np.random.Generator | int | None = 0) -> Path:
    """Write ``sig`` (its sites named by ``names``: site -> device name) under ``root``.
    ``drop``: sample indices lost from every device; each device's clock also starts a
    few hundred us apart, as the real ones do."""
    root = Path(root)
    rng = np.random.default_rng(rng)
    keep = np.setdiff1d(np.arange(len(sig.t)), np.asarray(drop, dtype=int))
    for k, site in enumerate(sig.sites):
        folder = root / f"{names[site]} {0x64F61C00 + k:08X} (UDP)"
        folder.mkdir(parents=True, exist_ok=True)
        ts = t0_us + int(rng.integers(0, 900)) + np.rint(sig.t[keep] * 1e6).astype(np.int64)
        gyro = np.rad2deg(sig.gyro[keep, k])
        acc = sig.specific_force[keep, k] / G
        q = sig.quat[keep, k]
        with open(folder / "Inertial.csv", "w") as f:
            f.write(INERTIAL_HEADER + "\n")
            for t, g, a in zip(ts, gyro, acc):
                f.write(f"{t},{g[0]:.6f},{g[1]:.6f},{g[2]:.6f},{a[0]:.6f},{a[1]:.6f},{a[2]:.6f}\n")
        with open(folder / "Quaternion.csv", "w") as f:
            f.write(QUATERNION_HEADER + "\n")
            for t, qq in zip(ts, q):
                f.write(f"{t},{qq[0]:.6f},{qq[1]:.6f},{qq[2]:.6f},{qq[3]:.6f}\n")
    return root


__all__ = ["write_ximu3_log"]
