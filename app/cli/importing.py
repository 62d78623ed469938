"""`imucap import`: another system's logged session -> an imucap session recording.

    imucap import FOLDER_OR_FILES... --out SESSION.h5 [--format auto|ximu3|mtmanager|dot|mvnx] [--truth T.npz]
                  [--calibration standing|walk|auto] [--map ID=SITE ...] [--height M] [--no-reconstruct] [--json]

Why: a researcher's sessions are often logged with the sensor maker's own software. Once
imported, ``imucap replay`` reconstructs them with any model, sensor subset or step list,
and ``imucap export`` writes BVH, OpenSim, HDF5 or CSV, exactly as for a session recorded
here. The import keeps the raw stream (on the 60 Hz grid the live hub uses, by the live
app's slerp resampler), adds one calibration computed from the standing start (the log
has no table or T-pose window), and reconstructs the body with the default model and
every imported sensor (``--no-reconstruct`` skips that), so ``imucap export`` works at once.

Calibration (``calibration.imported``): the stand fixes each sensor's tilt and
sensor-to-bone; the subject's forward comes from the knees. ``--calibration walk`` also
gives each sensor its own heading from the gait (the swing axis of thighs and shanks,
every sensor's path between two still moments: ``calibration.gait_heading``, as the live
walk protocol), for sensors whose frames do not share one heading; ``standing`` assumes
they do; ``auto`` (default) is ``walk`` when the log holds walking. ``--json`` lists under
``calibration.warnings`` each sensor whose heading is off the others' or that keeps the
shared one, a line starting with its site; they are printed on stderr too.

A messy folder imports: sensors without a site are skipped with a warning (``warnings``),
files that are not exports are listed as ignored, a byte-identical copy of an export is
skipped with a warning; a file that claims to be an export but is damaged stops the
import with its one-line reason. ``log_time_origin_s`` is the original log's time of the
recording's frame 0 (kept in the recording and in every export; a BVH's goes beside it
in ``NAME.bvh.json``).

Formats (``--format auto``, the default, tells them apart):
- ``ximu3``: the x-IMU3 GUI's data logs (``drivers.ximu3``): one folder holding a folder
  per device.
- ``mtmanager``: MT Manager text/CSV exports (MTi, MTw Awinda), one file per sensor;
- ``dot``: Xsens DOT app CSV exports, one file per sensor (``drivers.xsens_export``).
  Give the folder holding them (its .txt/.csv files that are exports are read, others
  are listed as ignored) or the files themselves.
- ``mvnx``: an Xsens MVN take exported as MVNX (``drivers.xsens_export.mvnx``), one file
  for the whole suit. Its sensors map to sites by their MVN labels (``RightLowerLeg`` ->
  r_shank, ``T8`` -> torso, ``RightForeArm`` -> r_wrist); the hands and shoulders have
  no site and are listed as not used. MVNX holds no sensor rate, so the calibration
  takes it from orientation; the subject's height is MVN's body's unless ``--height`` says
  otherwise. ``--truth TRUTH.npz`` also writes MVN's own solution of the
  take (all 23 segments), so ``imucap replay SESSION.h5 --sensors ... --truth TRUTH.npz``
  scores a re-run with a few of the suit's sensors against the whole suit's answer.

Sensors map to sites by ``--map ID=SITE``, where ID is any name the sensor goes by: its
device name or tag (x-IMU3 device name, DOT tag), its id (x-IMU3 serial, MT Manager
Device ID, DOT address) or its file's stem. Without a map, a name that says a segment
maps by itself: site names, the names suits use ("Left Lower Leg" -> l_shank, see
``DEVICE_SITES``) and OpenSense-style bone names ("LFemur", "tibia_r_imu", see ``BONES``).

An export without Gyr_* columns (the DOT app's default Quat + FreeAcc) is recorded
without gyro, as it was logged; the standing calibration, which needs a rate to find
the still start, gets one from the orientation (``gyro_from_orientation``).

Sensors whose clocks are not one (a DOT set that was not synchronised) are aligned at
their first samples, which is only as good as their simultaneous start; the summary says
which was done (``clock``).
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.recording import Recorder
from calibration.core import Calibration
from calibration.imported import MODES as CALIBRATIONS
from calibration.imported import calibrate_log
from drivers.device_log import DeviceLog
from drivers.hub import HubFrame
from drivers.ximu3 import read_log
from drivers.xsens_export import LAYOUTS, detect_layout, read_exports
from drivers.xsens_export.mvnx import MVN_SITES, is_mvnx, read_mvnx
from drivers.xsens_export.mvnx import TITLE as MVNX_TITLE
from inference.body.motion import Motion
from inference.body.rotations import quat_conjugate, quat_multiply, quat_to_axis_angle
from inference.body.skeleton import N_CONTACTS, SITES, parse_sites
from inference.signals.resample import to_grid

RATE = 60.0
FORMATS = ("auto", "ximu3", *LAYOUTS, "mvnx")
SOURCE_TITLES = {"ximu3": "x-IMU3 log", **{k: v.title for k, v in LAYOUTS.items()}, "mvnx": MVNX_TITLE}
EXPORT_SUFFIXES = (".txt", ".csv", ".tsv")
GYRO_WINDOW_S = 0.2  # wide enough that orientation jitter does not read as motion, short against a step
# normalised device name -> site (words as suits and their GUIs name the segments)
DEVICE_SITES: dict[str, str] = {
    "pelvis": "pelvis", "hips": "pelvis", "sacrum": "pelvis", "torso": "torso", "chest": "torso",
    "sternum": "torso", "trunk": "torso", "head": "head",
    **{f"{side} {w}": f"{s}_{site}" for side, s in (("left", "l"), ("right", "r")) for w, site in (
        ("upper arm", "upperarm"), ("forearm", "wrist"), ("lower arm", "wrist"), ("wrist", "wrist"),
        ("hand", "wrist"), ("upper leg", "thigh"), ("thigh", "thigh"), ("lower leg", "shank"),
        ("shank", "shank"), ("shin", "shank"), ("foot", "foot"))},
}
# bone names as OpenSense and many lab tags use them, with a side letter or word before or after
BONES: dict[str, str] = {"femur": "thigh", "tibia": "shank", "calcn": "foot", "humerus": "upperarm",
                         "radius": "wrist", "ulna": "wrist", "hand": "wrist", "foot": "foot", "thigh": "thigh",
                         "shank": "shank", "upperarm": "upperarm", "forearm": "wrist", "wrist": "wrist"}
_SIDES = (("left", "l"), ("right", "r"), ("l", "l"), ("r", "r"))


def _norm(name: str) -> str:
    return re.sub(r"[\s_\-]+", " ", name.strip().lower())


def _compact(name: str) -> str:
    """Letters only, without a trailing "imu": ``femur_r_imu`` -> ``femurr``."""
    n = re.sub(r"[^a-z]", "", name.lower())
    return n[:-3] if n.endswith("imu") and len(n) > 3 else n


def _bone_site(name: str) -> str | None:
    """The site of a bone-style name (``LFemur``, ``tibia_r``, ``LeftFoot``), if it is one."""
    n = _compact(name)
    compact_sites = {k.replace(" ", ""): v for k, v in DEVICE_SITES.items()}
    if n in compact_sites:
        return compact_sites[n]
    for bone, site in BONES.items():
        for side, s in _SIDES:
            if n in (side + bone, bone + side):
                return f"{s}_{site}"
    return None


def site_for(name: str, mapping: dict[str, str]) -> str | None:
    """The site a device name stands for: an explicit ``--map`` entry, a site name, a
    segment name from ``DEVICE_SITES`` or a bone name from ``BONES``; None if none applies."""
    if name in mapping:
        return mapping[name]
    n = _norm(name)
    if n.replace(" ", "_") in SITES:
        return n.replace(" ", "_")
    return DEVICE_SITES.get(n) or _bone_site(name)


@dataclass
class Source:
    """One device's log and the names ``--map`` may call it by, the most telling first."""

    log: DeviceLog
    ids: tuple[str, ...]
    file: str = ""

    @property
    def label(self) -> str:
        return self.ids[0] if not self.file else f"{self.ids[0]} ({Path(self.file).name})"


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
    format: str = "ximu3"
    clock: str = "shared"
    ignored: list[str] = field(default_factory=list)
    grid_t0: float = 0.0  # the log's time (s, its own clock) of the recording's frame 0
    truth: str = ""
    calibration: dict[str, Any] = field(default_factory=dict)  # method, warnings, notes, headings
    reconstruction: dict[str, Any] = field(default_factory=dict)  # poses, sensors, model; empty when not asked
    warnings: list[str] = field(default_factory=list)  # about the files and sensors, not the calibration


def _unique(names: Sequence[str]) -> tuple[str, ...]:
    return tuple(dict.fromkeys(n for n in names if n))


def _key(name: str) -> str:
    return re.sub(r"[^0-9a-z]", "", name.lower())


def _site_of(src: Source, mapping: dict[str, str]) -> str | None:
    """The site of one device: ``--map`` by any of its ids (exactly, else ignoring case and
    separators, so ``D4:CA:6E:F1:78:60`` matches ``D4CA6EF17860``), else by a name that says it."""
    loose = {_key(k): v for k, v in mapping.items()}
    for i in src.ids:
        if i in mapping:
            return mapping[i]
    for i in src.ids:
        if _key(i) in loose:
            return loose[_key(i)]
    return next((s for s in (site_for(i, {}) for i in src.ids) if s), None)


def _assign_sites(sources: Sequence[Source], mapping: dict[str, str]) -> tuple[dict[str, Source], list[str]]:
    """(site -> its device, a warning per device without a site, which is skipped): a folder
    often holds sensors the study did not use. Refuses two devices on one site, and a log
    where no device has a site."""
    by_site: dict[str, Source] = {}
    unknown = []
    for src in sources:
        site = _site_of(src, mapping)
        if site is None:
            unknown.append(src)
            continue
        site = parse_sites([site])[0]
        if site in by_site:
            raise ValueError(f"sensors {by_site[site].label} and {src.label} both map to {site}; use --map ID=SITE")
        by_site[site] = src
    if unknown and not by_site:
        example = unknown[0].ids[0]
        raise ValueError(f"no site for sensor(s) {', '.join(s.label for s in unknown)}; map each with --map ID=SITE "
                         f"(e.g. --map '{example}=pelvis'; sites: {', '.join(SITES)})")
    skipped = [f"{s.label}: no site, skipped (--map '{s.ids[0]}=SITE' to use it)" for s in unknown]
    return by_site, skipped


def _duplicates(files: Sequence[Path]) -> tuple[list[Path], list[str]]:
    """(the files without byte-identical copies of an earlier one, a warning per copy): one
    sensor's export copied under a second name would import as two sensors moving exactly
    alike, or clash on one site."""
    import hashlib

    first: dict[str, Path] = {}
    keep, warnings = [], []
    for f in files:
        h = hashlib.sha256(f.read_bytes()).hexdigest()
        if h in first:
            warnings.append(f"{f}: byte-identical to {first[h]} (one sensor's export twice?); skipped")
            continue
        first[h] = f
        keep.append(f)
    return keep, warnings


def gyro_from_orientation(t: np.ndarray, quat: np.ndarray, window_s: float = GYRO_WINDOW_S) -> np.ndarray:
    """(N, 3) angular rate in the sensor frame (rad/s) from orientations R_GS (N, 4) at
    times t: the least-squares slope of the rotation from each sample to its neighbours
    within ``window_s`` (fewer at the ends). A slope over a window, not a difference of
    two samples, so that orientation jitter does not read as motion."""
    n = len(t)
    h = max(1, int(round(window_s / float(np.median(np.diff(t))) / 2)))
    i = np.arange(n)
    steps = [np.clip(i + j, 0, n - 1) for j in range(-h, h + 1)]
    dt = np.stack([t[k] - t for k in steps])  # (W, N)
    rot = np.stack([quat_to_axis_angle(quat_multiply(quat_conjugate(quat), quat[k])) for k in steps])  # (W, N, 3)
    dt_c = dt - dt.mean(axis=0)
    rot_c = rot - rot.mean(axis=0)
    return np.einsum("wn,wnc->nc", dt_c, rot_c) / np.sum(dt_c**2, axis=0)[:, None]


def _check_acc(src: Source) -> Source:
    """The device, refused where its log has no acceleration at all: the model needs it."""
    if not np.isfinite(src.log.acc).any():
        raise ValueError(f"{src.label}: no acceleration columns (Acc_* or FreeAcc_*); export them too")
    return src


def _rate_for_calibration(d: DeviceLog) -> np.ndarray:
    """(N, 3) the device's gyro, or where its log has none, its rate from orientation."""
    return d.gyro if np.isfinite(d.gyro).any() else gyro_from_orientation(d.t, d.quat)


def _align_clocks(by_site: dict[str, Source]) -> str:
    """Keep the devices' own times when they share a clock (their spans overlap and no
    header says otherwise); else put each one's first sample at 0. Returns which."""
    logs = [s.log for s in by_site.values()]
    unsynced = any(d.info.get("syncstatus", "").strip().lower().startswith("un") for d in logs)
    if not unsynced and max(d.t[0] for d in logs) < min(d.t[-1] for d in logs):
        return "shared"
    for d in logs:
        d.t = d.t - d.t[0]
    return "aligned at each device's first sample (clocks not shared)"


def _on_grid(by_site: dict[str, Source], sites: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray, float]:
    """(quat (n,S,4), vectors (n,S,3,3): specific force, gyro as logged and the rate for
    calibration, the grid's first time on the logs' clock) of every device on one RATE
    grid, NaN where a device did not deliver."""
    logs = [by_site[s].log for s in sites]
    t0 = math.ceil(min(float(d.t[0]) for d in logs) * RATE) / RATE
    n = int(math.floor((max(float(d.t[-1]) for d in logs) - t0) * RATE)) + 1
    quat = np.full((n, len(sites), 4), np.nan)
    vec = np.full((n, len(sites), 3, 3), np.nan)
    for k, d in enumerate(logs):
        v = np.stack([d.acc, d.gyro, _rate_for_calibration(d)], axis=1)
        tg, q, v, ok = to_grid(d.t, d.quat, v, fps=RATE, t0=t0)
        idx = np.rint((tg - t0) * RATE).astype(int)
        keep = (idx >= 0) & (idx < n) & ok
        quat[idx[keep], k] = q[keep]
        vec[idx[keep], k] = v[keep]
    return quat, vec, t0


def _record(out: str | Path, sites: tuple[str, ...], meta: dict[str, Any], quat: np.ndarray, acc: np.ndarray,
            gyro: np.ndarray, present: np.ndarray, cal: Calibration, poses: Sequence[Any] = ()) -> None:
    """Write the grid as a session recording, the calibration at the stand's last frame,
    and ``poses`` (LivePose) as its reconstruction."""
    still = int(cal.meta["still_frames"])
    rec = Recorder(out, sites, metadata=meta)
    try:
        for pose in poses:
            rec.on_pose(pose)
        nan3 = np.full((len(sites), 3), np.nan)
        for i in range(len(quat)):
            rec.on_frame(HubFrame(t=i / RATE, index=i, sites=sites, quat=quat[i], free_acc=nan3, acc=acc[i],
                                  gyro=gyro[i], present=present[i], insole_force=np.full(2, np.nan),
                                  contacts=np.zeros(N_CONTACTS, bool), insole_present=False))
            if i == still - 1:
                rec.on_calibration(cal, i / RATE)
    finally:
        rec.close()


def _reconstruct(out: str | Path, sites: tuple[str, ...], meta: dict[str, Any], quat: np.ndarray, acc: np.ndarray,
                 gyro: np.ndarray, present: np.ndarray, cal: Calibration) -> dict[str, Any]:
    """Run the default poser over the written recording with every imported sensor, as
    ``imucap replay`` would, and write the recording again with those poses as its
    reconstruction and the poser's settings in its metadata: ``imucap export`` then works
    on an import as on a live session, and a plain ``imucap replay`` runs the same poser."""
    import os

    from app.export.formats import body_for_recording
    from app.recording import read_recording
    from app.replay import ReplaySettings, build_replay_poser, poser_metadata, replay_recording

    rec = read_recording(out)
    body, _ = body_for_recording(rec.metadata)
    built = build_replay_poser(rec, ReplaySettings(), body)
    res = replay_recording(rec, built.poser, causal=built.causal)
    meta = {**meta, "model": built.label, **poser_metadata(built.poser, built.latency)}
    tmp = Path(str(out) + ".recon.tmp")
    _record(tmp, sites, meta, quat, acc, gyro, present, cal, res.poses)
    os.replace(tmp, out)
    return {"poses": len(res.poses), "sensors": list(res.sensors), "model": built.label}


def _device_summary(src: Source, present: np.ndarray) -> dict[str, Any]:
    d = src.log
    out = {"name": d.name, "samples": int(len(d.t)), "rate_hz": round(d.rate_hz, 1),
           "grid_present": round(float(present.mean()), 3), "skipped": d.skipped}
    if src.file:
        gyro = d.info.get("gyro_from", "")
        out.update(id=d.serial, file=src.file, acc_from=d.info.get("acc_from", ""),
                   gyro_from=gyro if gyro != "none" else "not in the export (calibrated on the rate from orientation)")
    return out


def import_sources(sources: Sequence[Source], out: str | Path, fmt: str, log: str,
                   mapping: dict[str, str] | None = None, height: float | None = None,
                   calibration: str = "auto", reconstruct: bool = True) -> Imported:
    """Put the devices of one logged session on the 60 Hz grid, calibrate them from their
    standing start (each sensor's heading from the gait, ``calibration.imported``) and
    write them as a session recording at ``out``."""
    assigned, skipped = _assign_sites(sources, mapping or {})
    by_site = {s: _check_acc(src) for s, src in assigned.items()}
    sites = tuple(s for s in SITES if s in by_site)  # canonical order
    clock = _align_clocks(by_site)
    quat, vec, t0 = _on_grid(by_site, sites)
    acc, gyro, cal_rate = vec[:, :, 0], vec[:, :, 1], vec[:, :, 2]
    present = np.all(np.isfinite(quat), axis=-1)
    lc = calibrate_log(sites, quat, cal_rate, present, RATE, calibration, acc=acc)
    cal = lc.calibration
    meta: dict[str, Any] = {
        "source": SOURCE_TITLES[fmt], "log": log, "sensors": list(sites), "insoles": False,
        "devices": {s: {"name": by_site[s].log.name, "serial": by_site[s].log.serial} for s in sites},
        "calibration": f"{lc.method} (calibration/imported.py)", "calibration_warnings": lc.warnings,
        "stride_scale": True,
        "pelvis_odometry": True, "clock": clock, "log_time_origin_s": float(t0),
    }
    if height is not None:
        meta["body_height_m"] = float(height)
    _record(out, sites, meta, quat, acc, gyro, present, cal)
    recon = _reconstruct(out, sites, meta, quat, acc, gyro, present, cal) if reconstruct else {}
    n, still = len(quat), int(cal.meta["still_frames"])
    devices = {s: _device_summary(by_site[s], present[:, k]) for k, s in enumerate(sites)}
    return Imported(Path(out), sites, n, round(n / RATE, 3), round(still / RATE, 3),
                    [round(float(x), 4) for x in cal.meta["forward_G"]], str(cal.meta["forward_from"]), devices,
                    format=fmt, clock=clock, grid_t0=t0,
                    warnings=skipped, reconstruction=recon,
                    calibration={"method": lc.method, "warnings": lc.warnings, "notes": lc.notes,
                                 "headings": lc.headings})


def import_ximu3(log_dir: str | Path, out: str | Path, mapping: dict[str, str] | None = None,
                 height: float | None = None, calibration: str = "auto", reconstruct: bool = True) -> Imported:
    """An x-IMU3 log folder as a session recording at ``out`` (``import_sources``)."""
    sources = [Source(d, _unique([d.name, d.serial])) for d in read_log(log_dir)]
    return import_sources(sources, out, "ximu3", str(log_dir), mapping, height, calibration, reconstruct)


def import_xsens(files: Sequence[str | Path], out: str | Path, layout: str | None = None,
                 mapping: dict[str, str] | None = None, height: float | None = None,
                 calibration: str = "auto", reconstruct: bool = True) -> Imported:
    """Xsens export files of one session (one per sensor; ``layout`` "mtmanager" or "dot",
    else told by each file) as a session recording at ``out`` (``import_sources``)."""
    files, copies = _duplicates([Path(f) for f in files])
    logs = read_exports(files, layout)
    fmt = layout or logs[0].info["layout"]
    sources = [Source(d, _unique([d.name, d.serial, f.stem]), str(f)) for d, f in zip(logs, files)]
    res = import_sources(sources, out, fmt, ", ".join(map(str, files)), mapping, height, calibration, reconstruct)
    res.warnings = copies + res.warnings
    return res


def import_mvnx(file: str | Path, out: str | Path, mapping: dict[str, str] | None = None,
                height: float | None = None, truth: str | Path | None = None, calibration: str = "auto",
                reconstruct: bool = True) -> Imported:
    """An MVN take's MVNX export as a session recording at ``out`` (``import_sources``):
    the sensors at imucap's sites (by MVN label, or ``--map LABEL=SITE``); the others are
    listed in ``ignored``. ``truth``: also write MVN's full-suit solution there
    (``write_mvn_truth``)."""
    take = read_mvnx(file)
    mapping = mapping or {}
    labels = {d.name for d in take.logs}
    for name in mapping:
        if name not in labels:
            raise ValueError(f"--map {name}=...: no sensor {name!r} in {file} "
                             f"(its sensors: {', '.join(sorted(labels))})")
    chosen = {site: name for name, site in mapping.items()}
    sources, unused = [], []
    for d in take.logs:
        site = mapping.get(d.name) or MVN_SITES.get(d.name)
        if site is None:
            unused.append(f"{d.name} (no imucap site; --map {d.name}=SITE to use it)")
            continue
        if chosen.get(site, d.name) != d.name:
            unused.append(f"{d.name} ({site} is {chosen[site]} by --map)")
            continue
        sources.append(Source(d, (d.name, site), str(file)))
    motion = None
    if truth is not None or height is None:
        from inference.body.motion import MotionFormatError
        from inference.loaders.mvnx import load_mvnx

        try:  # the whole take for the truth; for the height, the body is in its first frames
            motion = load_mvnx(file, max_frames=None if truth is not None else 2)
        except MotionFormatError:
            if truth is not None:
                raise
    if height is None and motion is not None:
        height = round(float(motion.body.height), 3)  # MVN's body, as the subject was measured for the suit
    res = import_sources(sources, out, "mvnx", str(file), {s.ids[0]: s.ids[1] for s in sources}, height,
                         calibration, reconstruct)
    res.ignored = unused
    if truth is not None and motion is not None:
        write_mvn_truth(motion, res, truth)
    return res


def write_mvn_truth(motion: Motion, res: Imported, dest: str | Path) -> Path:
    """MVN's own solution of the take (its 23 segments, ``inference.loaders.mvnx.load_mvnx``) as the
    truth ``imucap replay --truth`` scores the imported recording against: turned from MVN's
    world into the recording's (X the subject's forward at the standing start), on the
    recording's clock, counted from the end of the standing start."""
    from app.capture.simulate import save_truth
    from inference.body.rotations import matrix_about_axis

    fx, fy = res.forward_G[0], res.forward_G[1]
    R = matrix_about_axis(np.array([0.0, 0.0, 1.0]), -math.atan2(fy, fx))
    t0 = motion.meta["first_index"] / motion.fps - res.grid_t0
    out = save_truth(dest, R @ motion.rot, motion.root @ R.T, motion.fps, t0, res.still_s - t0, motion.body.height,
                     motion.body.offsets, res.sites, "standing start")
    res.truth = str(out)
    return out


def _is_ximu3_log(path: Path) -> bool:
    return path.is_dir() and any(d.is_dir() and (d / "Inertial.csv").is_file() and (d / "Quaternion.csv").is_file()
                                 for d in path.iterdir())


def _export_files(paths: Sequence[Path], fmt: str) -> tuple[list[Path], list[Path], str | None]:
    """(export files, files of the given folders that are not exports, their one layout or
    None when only given files say it): folders give their export files, files are taken
    as given. Refuses an import of nothing and one of both layouts at once."""
    files, ignored = [], []
    for p in paths:
        if not p.is_dir():
            files.append(p)
            continue
        for f in sorted(q for q in p.iterdir() if q.is_file() and q.suffix.lower() in EXPORT_SUFFIXES):
            (files if detect_layout(f) else ignored).append(f)
    if not files:
        raise ValueError(f"{', '.join(map(str, paths))}: no x-IMU3 device folders and no Xsens export files "
                         f"({'/'.join(EXPORT_SUFFIXES)})")
    if fmt != "auto":
        return files, ignored, fmt
    layouts = {detect_layout(f) for f in files} - {None}
    if len(layouts) > 1:
        raise ValueError("both MT Manager and DOT exports given; import each session on its own")
    return files, ignored, next(iter(layouts), None)


def import_paths(paths: Sequence[str | Path], out: str | Path, fmt: str = "auto",
                 mapping: dict[str, str] | None = None, height: float | None = None,
                 truth: str | Path | None = None, calibration: str = "auto",
                 reconstruct: bool = True) -> Imported:
    """The CLI's import: an x-IMU3 log folder, or Xsens export folders and files (module docstring)."""
    paths = [Path(p) for p in paths]
    if fmt not in FORMATS:
        raise ValueError(f"unknown format {fmt!r} (known: {', '.join(FORMATS)})")
    for p in paths:
        if not p.exists():
            raise FileNotFoundError(f"{p}: no such file or folder")
    if fmt == "mvnx" or (fmt == "auto" and len(paths) == 1 and paths[0].is_file()
                         and (paths[0].suffix.lower() == ".mvnx" or is_mvnx(paths[0]))):
        if len(paths) != 1 or paths[0].is_dir():
            raise ValueError("an MVNX export is one file for the whole suit; give just that file")
        return import_mvnx(paths[0], out, mapping, height, truth, calibration, reconstruct)
    if truth is not None:
        raise ValueError("--truth: only an MVN take (.mvnx) holds a full-body solution to score against")
    if fmt == "ximu3" or (fmt == "auto" and len(paths) == 1 and _is_ximu3_log(paths[0])):
        if len(paths) != 1:
            raise ValueError("an x-IMU3 log is one folder; give just that folder")
        return import_ximu3(paths[0], out, mapping, height, calibration, reconstruct)
    files, ignored, layout = _export_files(paths, fmt)
    res = import_xsens(files, out, layout, mapping, height, calibration, reconstruct)
    res.ignored = [str(f) for f in ignored]
    return res


def _mapping(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--map {item!r}: expected ID=SITE")
        name, site = item.rsplit("=", 1)
        out[name.strip()] = parse_sites([site.strip()])[0]
    return out


def run_import(args: argparse.Namespace) -> int:
    res = import_paths(args.logs, args.out, args.format, _mapping(args.map), args.height, args.truth,
                       args.calibration, args.reconstruct)
    summary = {"recording": str(res.path), "format": res.format, "sites": list(res.sites), "frames": res.frames,
               "duration_s": res.duration_s, "still_start_s": res.still_s, "forward_G": res.forward_G,
               "forward_from": res.forward_from, "clock": res.clock, "log_time_origin_s": round(res.grid_t0, 6),
               "calibration": res.calibration, "reconstruction": res.reconstruction, "warnings": res.warnings,
               "devices": res.devices,
               "ignored": res.ignored, **({"truth": res.truth} if res.truth else {})}
    for w in res.warnings + res.calibration.get("warnings", []) + res.calibration.get("notes", []):
        print(f"imucap import: warning: {w}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"imported {len(res.sites)} sensors ({', '.join(res.sites)}) from an {SOURCE_TITLES[res.format]}, "
              f"{res.duration_s} s, calibrated ({res.calibration.get('method')}) on the first {res.still_s} s "
              f"standing -> {res.path}")
        if res.ignored:
            what = "not used" if res.format == "mvnx" else "ignored (not Xsens exports)"
            print(f"{what}: {', '.join(res.ignored)}")
    sys.stdout.flush()
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("import", help="turn another system's logged session into a session recording",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("logs", type=Path, nargs="+", metavar="FOLDER_OR_FILES",
                   help="an x-IMU3 log folder, Xsens export folders/files (one file per sensor), or an MVN "
                        "take's .mvnx file")
    p.add_argument("--out", type=Path, required=True, help="the session recording to write (.h5)")
    p.add_argument("--format", default="auto", choices=FORMATS, help="the log's format (default: told from the files)")
    p.add_argument("--map", action="append", default=[], metavar="ID=SITE",
                   help="sensor name, id or file stem -> site, where the name does not say it (repeatable)")
    p.add_argument("--height", type=float, default=None, help="the subject's height in m (stored for replay)")
    p.add_argument("--truth", type=Path, default=None, metavar="TRUTH.npz",
                   help="with an MVN take: also write MVN's own full-suit solution, for imucap replay --truth")
    p.add_argument("--calibration", default="auto", choices=CALIBRATIONS,
                   help="standing: one heading for all sensors; walk: each sensor's heading from the gait; auto "
                        "(default): walk when the log holds walking")
    p.add_argument("--no-reconstruct", dest="reconstruct", action="store_false",
                   help="only calibrate; by default the import also reconstructs the body with the default model "
                        "and every imported sensor, so imucap export works on it at once")
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.set_defaults(func=run_import)


__all__ = ["BONES", "DEVICE_SITES", "FORMATS", "Imported", "Source", "gyro_from_orientation", "import_mvnx",
           "import_paths", "import_sources", "import_xsens", "import_ximu3", "register", "site_for"]
