"""Importing one logged session: its devices on the grid, calibrated, written as a session
recording and reconstructed (the ``imucap import`` the CLI's docstring describes)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.recording import Recorder
from calibration.core import Calibration
from calibration.imported import calibrate_log
from drivers.hub import HubFrame
from drivers.ximu3 import read_log
from drivers.xsens_export import LAYOUTS, detect_layout, read_exports
from drivers.xsens_export.mvnx import MVN_SITES, is_mvnx, read_mvnx
from drivers.xsens_export.mvnx import TITLE as MVNX_TITLE
from inference.body.motion import Motion
from inference.body.skeleton import N_CONTACTS, SITES
from inference.poser.lag import OFFLINE_ANSWER_LAG

from .grid import RATE, align_clocks, check_acc, duplicates, on_grid
from .names import Source, assign_sites, unique

Calibrator = Callable[..., tuple[Calibration, dict[str, Any]]]  # (by_site, sites, quat, rate, present, acc)
FORMATS = ("auto", "ximu3", *LAYOUTS, "mvnx")
SOURCE_TITLES = {"ximu3": "x-IMU3 log", **{k: v.title for k, v in LAYOUTS.items()}, "mvnx": MVNX_TITLE}
EXPORT_SUFFIXES = (".txt", ".csv", ".tsv")


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


def log_name(log: str) -> str:
    """A log's name for messages: its folder's (a trial's) or its one file's."""
    first = Path(log.split(", ")[0])
    return first.parent.name if ", " in log or first.suffix else first.name


def _record(out: str | Path, sites: tuple[str, ...], meta: dict[str, Any], quat: np.ndarray, acc: np.ndarray,
            gyro: np.ndarray, present: np.ndarray, cal: Calibration, poses: Sequence[Any] = ()) -> None:
    """Write the grid as a session recording, the calibration at the stand's last frame,
    and ``poses`` (LivePose) as its reconstruction."""
    still = int(cal.meta["still_frames"]) if not cal.meta.get("still_from") else 0
    rec = Recorder(out, sites, metadata=meta)
    try:
        for pose in poses:
            rec.on_pose(pose)
        nan3 = np.full((len(sites), 3), np.nan)
        for i in range(len(quat)):
            rec.on_frame(HubFrame(t=i / RATE, index=i, sites=sites, quat=quat[i], free_acc=nan3, acc=acc[i],
                                  gyro=gyro[i], present=present[i], insole_force=np.full(2, np.nan),
                                  contacts=np.zeros(N_CONTACTS, bool), insole_present=False))
            if i == max(still - 1, 1):  # at the end of a still start, else from the start (t = 0 reads as unwritten)
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
    built = build_replay_poser(rec, ReplaySettings(model="diffusion"), body)  # offline: the full model
    res = replay_recording(rec, built.poser, causal=built.causal)
    meta = {**meta, "model": built.label, "model_spec": built.spec, **poser_metadata(built.poser, built.latency)}
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
                   calibration: str = "auto", reconstruct: bool = True,
                   calibrator: Calibrator | None = None) -> Imported:
    """Put the devices of one logged session on the 60 Hz grid, calibrate them from their
    still stand (each sensor's heading from the gait, ``calibration.imported``), or with
    ``calibrator`` (another trial's calibration, ``app.importing.trials``), and write them
    as a session recording at ``out``."""
    assigned, skipped = assign_sites(sources, mapping or {})
    by_site = {s: check_acc(src) for s, src in assigned.items()}
    sites = tuple(s for s in SITES if s in by_site)  # canonical order
    clock = align_clocks(by_site)
    quat, vec, t0 = on_grid(by_site, sites)
    acc, gyro, cal_rate = vec[:, :, 0], vec[:, :, 1], vec[:, :, 2]
    present = np.all(np.isfinite(quat), axis=-1)
    if calibrator is None:
        lc = calibrate_log(sites, quat, cal_rate, present, RATE, calibration, acc=acc, name=log_name(log))
        cal = lc.calibration
        summary = {"method": lc.method, "warnings": lc.warnings, "notes": lc.notes, "headings": lc.headings}
        label = f"{lc.method} (calibration/imported.py)"
    else:
        cal, summary = calibrator(by_site, sites, quat, cal_rate, present, acc)
        label = f"{summary['method']} (calibration/trials.py)"
    meta: dict[str, Any] = {
        "source": SOURCE_TITLES[fmt], "log": log, "sensors": list(sites), "insoles": False,
        "devices": {s: {"name": by_site[s].log.name, "serial": by_site[s].log.serial} for s in sites},
        "calibration": label, "calibration_warnings": summary["warnings"],
        "stride_scale": True,
        "pelvis_odometry": True, "clock": clock, "log_time_origin_s": float(t0),
        # a log never ran live: its poses may wait for the sensors after them (inference/poser/lag.py)
        "answer_lag": OFFLINE_ANSWER_LAG,
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
                    warnings=skipped, reconstruction=recon, calibration=summary)


def import_ximu3(log_dir: str | Path, out: str | Path, mapping: dict[str, str] | None = None,
                 height: float | None = None, calibration: str = "auto", reconstruct: bool = True) -> Imported:
    """An x-IMU3 log folder as a session recording at ``out`` (``import_sources``)."""
    sources = [Source(d, unique([d.name, d.serial])) for d in read_log(log_dir)]
    return import_sources(sources, out, "ximu3", str(log_dir), mapping, height, calibration, reconstruct)


def import_xsens(files: Sequence[str | Path], out: str | Path, layout: str | None = None,
                 mapping: dict[str, str] | None = None, height: float | None = None,
                 calibration: str = "auto", reconstruct: bool = True) -> Imported:
    """Xsens export files of one session (one per sensor; ``layout`` "mtmanager" or "dot",
    else told by each file) as a session recording at ``out`` (``import_sources``)."""
    files, copies = duplicates([Path(f) for f in files])
    logs = read_exports(files, layout)
    fmt = layout or logs[0].info["layout"]
    sources = [Source(d, unique([d.name, d.serial, f.stem]), str(f)) for d, f in zip(logs, files)]
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
    from inference.body.conventions import heading_of, rot_z

    R = rot_z(-heading_of(np.asarray(res.forward_G)[:2]))
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




__all__ = ["EXPORT_SUFFIXES", "FORMATS", "Imported", "SOURCE_TITLES", "import_mvnx", "import_paths",
           "import_sources", "import_xsens", "import_ximu3", "write_mvn_truth"]
