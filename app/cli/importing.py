"""`imucap import`: another system's logged session -> an imucap session recording.

    imucap import LOG_DIR --out SESSION.h5 [--format ximu3] [--map NAME=SITE ...] [--height M] [--json]

Why: a researcher's sessions are often logged with the sensor maker's own software. Once
imported, ``imucap replay`` reconstructs them with any model, sensor subset or step list,
and ``imucap export`` writes BVH, OpenSim, HDF5 or CSV, exactly as for a session recorded
here. The import keeps the raw stream (on the 60 Hz grid the live hub uses, by the live
app's slerp resampler) and adds one calibration, computed from the standing start
(``calibration.standing``: the log has no table or T-pose window).

Formats: ``ximu3``, the x-IMU3 GUI's data logs (``drivers.ximu3``). Device names map to
sites by the names the x-IMU3 suits use ("Left Lower Leg" -> l_shank, ...; see
``DEVICE_SITES``), or by ``--map "Left Lower Leg=l_shank"``.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.recording import Recorder
from calibration.standing import calibrate_standing
from drivers.hub import HubFrame
from drivers.ximu3 import DeviceLog, read_log
from inference.body.skeleton import N_CONTACTS, SITES, parse_sites
from inference.signals.resample import to_grid

RATE = 60.0
# normalised device name -> site (words as suits and their GUIs name the segments)
DEVICE_SITES: dict[str, str] = {
    "pelvis": "pelvis", "hips": "pelvis", "sacrum": "pelvis", "torso": "torso", "chest": "torso",
    "sternum": "torso", "trunk": "torso", "head": "head",
    **{f"{side} {w}": f"{s}_{site}" for side, s in (("left", "l"), ("right", "r")) for w, site in (
        ("upper arm", "upperarm"), ("forearm", "wrist"), ("lower arm", "wrist"), ("wrist", "wrist"),
        ("hand", "wrist"), ("upper leg", "thigh"), ("thigh", "thigh"), ("lower leg", "shank"),
        ("shank", "shank"), ("shin", "shank"), ("foot", "foot"))},
}


def _norm(name: str) -> str:
    return re.sub(r"[\s_\-]+", " ", name.strip().lower())


def site_for(name: str, mapping: dict[str, str]) -> str | None:
    """The site a device name stands for: an explicit ``--map`` entry, a site name, or a
    segment name from ``DEVICE_SITES``; None if none applies."""
    if name in mapping:
        return mapping[name]
    n = _norm(name)
    if n.replace(" ", "_") in SITES:
        return n.replace(" ", "_")
    return DEVICE_SITES.get(n)


@dataclass
class Imported:
    """What an import produced, for the summary."""

    path: Path
    sites: tuple[str, ...]
    frames: int
    duration_s: float
    still_s: float
    forward_G: list[float]
    forward_from: str
    devices: dict[str, dict[str, Any]]


def import_ximu3(log_dir: str | Path, out: str | Path, mapping: dict[str, str] | None = None,
                 height: float | None = None) -> Imported:
    """Read an x-IMU3 log, put it on the 60 Hz grid, calibrate it from its standing start
    and write it as a session recording at ``out``."""
    mapping = mapping or {}
    logs = read_log(log_dir)
    by_site: dict[str, DeviceLog] = {}
    unknown = []
    for d in logs:
        site = site_for(d.name, mapping)
        if site is None:
            unknown.append(d.name)
            continue
        site = parse_sites([site])[0]
        if site in by_site:
            raise ValueError(f"devices {by_site[site].name!r} and {d.name!r} both map to {site}; use --map")
        by_site[site] = d
    if unknown:
        raise ValueError(f"no site for device(s) {', '.join(map(repr, unknown))}; pass --map 'NAME=SITE' "
                         f"(sites: {', '.join(SITES)})")
    sites = tuple(s for s in SITES if s in by_site)  # canonical order
    t_start = min(float(d.t[0]) for d in by_site.values())
    t_end = max(float(d.t[-1]) for d in by_site.values())
    t0 = math.ceil(t_start * RATE) / RATE
    n = int(math.floor((t_end - t0) * RATE)) + 1
    S = len(sites)
    quat = np.full((n, S, 4), np.nan)
    vec = np.full((n, S, 2, 3), np.nan)  # specific force, gyro
    for k, s in enumerate(sites):
        d = by_site[s]
        tg, q, v, ok = to_grid(d.t, d.quat, np.stack([d.acc, d.gyro], axis=1), fps=RATE, t0=t0)
        idx = np.rint((tg - t0) * RATE).astype(int)
        keep = (idx >= 0) & (idx < n) & ok
        quat[idx[keep], k] = q[keep]
        vec[idx[keep], k] = v[keep]
    present = np.all(np.isfinite(quat), axis=-1)
    acc, gyro = vec[:, :, 0], vec[:, :, 1]
    cal = calibrate_standing(sites, quat, acc=acc, gyro=gyro, present=present, rate=RATE)
    still = int(cal.meta["still_frames"])
    meta: dict[str, Any] = {
        "source": "x-IMU3 log", "log": str(log_dir), "sensors": list(sites), "insoles": False,
        "devices": {s: {"name": by_site[s].name, "serial": by_site[s].serial} for s in sites},
        "calibration": "standing start (calibration/standing.py)", "stride_scale": True,
        "pelvis_odometry": True,
    }
    if height is not None:
        meta["body_height_m"] = float(height)
    rec = Recorder(out, sites, metadata=meta)
    try:
        nan3 = np.full((S, 3), np.nan)
        for i in range(n):
            rec.on_frame(HubFrame(t=i / RATE, index=i, sites=sites, quat=quat[i], free_acc=nan3, acc=acc[i],
                                  gyro=gyro[i], present=present[i], insole_force=np.full(2, np.nan),
                                  contacts=np.zeros(N_CONTACTS, bool), insole_present=False))
            if i == still - 1:
                rec.on_calibration(cal, i / RATE)
    finally:
        rec.close()
    devices = {s: {"name": by_site[s].name, "samples": int(len(by_site[s].t)), "rate_hz": round(by_site[s].rate_hz, 1),
                   "grid_present": round(float(present[:, k].mean()), 3), "skipped": by_site[s].skipped}
               for k, s in enumerate(sites)}
    return Imported(Path(out), sites, n, round(n / RATE, 3), round(still / RATE, 3),
                    [round(float(x), 4) for x in cal.meta["forward_G"]], str(cal.meta["forward_from"]), devices)


def _mapping(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--map {item!r}: expected NAME=SITE")
        name, site = item.rsplit("=", 1)
        out[name.strip()] = parse_sites([site.strip()])[0]
    return out


def run_import(args: argparse.Namespace) -> int:
    if args.format != "ximu3":
        raise ValueError(f"unknown format {args.format!r}")
    res = import_ximu3(args.log, args.out, _mapping(args.map), args.height)
    summary = {"recording": str(res.path), "sites": list(res.sites), "frames": res.frames,
               "duration_s": res.duration_s, "still_start_s": res.still_s, "forward_G": res.forward_G,
               "forward_from": res.forward_from,
               "devices": res.devices}
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"imported {len(res.sites)} sensors ({', '.join(res.sites)}), {res.duration_s} s, calibrated on the "
              f"first {res.still_s} s standing -> {res.path}")
    sys.stdout.flush()
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("import", help="turn another system's logged session into a session recording",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("log", type=Path, help="the log folder (x-IMU3: the folder holding one folder per device)")
    p.add_argument("--out", type=Path, required=True, help="the session recording to write (.h5)")
    p.add_argument("--format", default="ximu3", choices=["ximu3"], help="the log's format (default ximu3)")
    p.add_argument("--map", action="append", default=[], metavar="NAME=SITE",
                   help="device name -> site, where the name does not say it (repeatable)")
    p.add_argument("--height", type=float, default=None, help="the subject's height in m (stored for replay)")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.set_defaults(func=run_import)


__all__ = ["import_ximu3", "site_for", "DEVICE_SITES", "register"]
