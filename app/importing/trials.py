"""A session of trials: a walk calibrated from another trial of the same session, and a whole
session folder imported trial by trial.

Why: a lab records an N-pose, a leg cycle per leg and several walks, and a walk trial often
starts with the subject already walking, so it has no still stand of its own. Its sensors
are the calibration trials' sensors, known by the id every export carries (the DOT's
Bluetooth address in its file name, MT Manager's device id): ``calibration.trials`` takes
each sensor's tilt and mounting from those trials and its heading in the walk from the
walk itself.

    imucap import WALK_FILES... --calibration-trial NPOSE_FILES... [LEG_CYCLE_FILES...] --out S.h5 [--json]
    imucap import SESSION_DIR --out-dir DIR [--json]

A session folder holds one folder per trial; a trial named like ``npose``, ``n-pose``,
``static``, ``stand`` or ``calib...`` is a standing calibration trial, one named like
``leg...``, ``swing`` or ``cycle`` a leg-cycle (functional) calibration trial, every other
one is imported as a walk with the session's calibration trials, each to ``DIR/<trial>.h5``.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from calibration.core import Calibration
from calibration.trials import Trial, calibrate_from_trials
from drivers.xsens_export import read_exports

from .grid import RATE, align_clocks, check_acc, on_grid
from .log import EXPORT_SUFFIXES, Imported, _export_files, import_sources
from .names import Source, unique

STAND_NAMES = re.compile(r"n[-_ ]?pose|static|stand|calib|t[-_ ]?pose", re.I)
SWING_NAMES = re.compile(r"leg|swing|cycle", re.I)


def sensor_key(src: Source) -> str:
    """The id a sensor is matched by across trials: its serial (DOT address, MT device id),
    else its first name; case and separators ignored."""
    serial = src.log.serial or src.ids[0]
    return re.sub(r"[^0-9a-z]", "", serial.lower())


def _trial_name(files: Sequence[Path]) -> str:
    parents = {f.parent.name for f in files}
    return parents.pop() if len(parents) == 1 else ", ".join(f.name for f in files)


def trial_sources(paths: Sequence[str | Path], fmt: str = "auto") -> tuple[str, list[Source], str]:
    """(the trial's name, its sensors, its layout) from its folder or files."""
    files, _, layout = _export_files([Path(p) for p in paths], fmt)
    logs = read_exports(files, layout)
    return (_trial_name(files), [Source(d, unique([d.name, d.serial, f.stem]), str(f)) for d, f in zip(logs, files)],
            layout or logs[0].info["layout"])


def group_trials(paths: Sequence[str | Path]) -> list[list[Path]]:
    """The calibration trials given on the command line: each folder one trial, loose files
    one trial per folder they lie in."""
    groups: dict[Path, list[Path]] = {}
    for p in map(Path, paths):
        if p.is_dir():
            groups[p] = [p]
        else:
            groups.setdefault(p.parent, []).append(p)
    return list(groups.values())


def _on_grid_by_key(sources: list[Source], keys: dict[str, str]) -> tuple[dict[str, Source], list[str]]:
    """The trial's sensors by the walk's site (keys: sensor key -> site), and the keys of
    sensors the walk does not have."""
    by_site, extra = {}, []
    for src in sources:
        site = keys.get(sensor_key(src))
        if site is None:
            extra.append(src.log.serial or src.ids[0])
        else:
            by_site[site] = check_acc(src)
    return by_site, extra


def _trial_arrays(name: str, by_site: dict[str, Source], sites: tuple[str, ...]) -> Trial:
    """A calibration trial on the grid, in the walk's site order (NaN for its missing sensors)."""
    have = tuple(s for s in sites if s in by_site)
    align_clocks(by_site)
    quat, vec, _ = on_grid(by_site, have)
    T, S = len(quat), len(sites)
    q, acc, rate = np.full((T, S, 4), np.nan), np.full((T, S, 3), np.nan), np.full((T, S, 3), np.nan)
    for j, s in enumerate(have):
        k = sites.index(s)
        q[:, k], acc[:, k], rate[:, k] = quat[:, j], vec[:, j, 0], vec[:, j, 2]
    return Trial(name, q, rate, np.all(np.isfinite(q), axis=-1), RATE, acc)


def trial_calibrator(walk_name: str, calibration_trials: Sequence[tuple[str, list[Source]]]):
    """The ``calibrator`` of ``import_sources`` that calibrates the walk from the given trials,
    matching sensors by id; refuses, naming the ids, a trial that shares no sensor with the
    walk and a walk sensor no trial holds."""

    def calibrate(by_site: dict[str, Source], sites: tuple[str, ...], quat: np.ndarray, rate: np.ndarray,
                  present: np.ndarray, acc: np.ndarray) -> tuple[Calibration, dict[str, Any]]:
        keys = {sensor_key(by_site[s]): s for s in sites}
        ids = {s: by_site[s].log.serial or by_site[s].ids[0] for s in sites}
        trials, held = [], set()
        for name, sources in calibration_trials:
            mine, extra = _on_grid_by_key(sources, keys)
            if not mine:
                raise ValueError(f"calibration trial {name}: none of its sensors ({', '.join(extra)}) is in "
                                 f"{walk_name} ({', '.join(ids[s] for s in sites)}); a trial of another session?")
            held |= set(mine)
            trials.append(_trial_arrays(name, mine, sites))
        missing = [s for s in sites if s not in held]
        if missing:
            theirs = sorted({src.log.serial or src.ids[0] for _, srcs in calibration_trials for src in srcs})
            raise ValueError(f"the calibration trials ({', '.join(n for n, _ in calibration_trials)}) have no sensor "
                             + ", ".join(f"{ids[s]} ({s})" for s in missing) + f" of {walk_name}; theirs: "
                             + ", ".join(theirs))
        walk = Trial(walk_name, quat, rate, present, RATE, acc)
        tc = calibrate_from_trials(sites, walk, trials)
        return tc.calibration, {"method": "calibration trial", "trials": [t.name for t in trials],
                                "sensors": tc.sensors, "warnings": tc.warnings, "notes": []}

    return calibrate


def import_with_calibration(paths: Sequence[str | Path], calibration: Sequence[str | Path], out: str | Path,
                            fmt: str = "auto", mapping: dict[str, str] | None = None, height: float | None = None,
                            reconstruct: bool = True) -> Imported:
    """A walk trial's exports as a session recording, calibrated from the calibration trials'
    exports (each folder, or the files of each folder, one trial)."""
    name, sources, layout = trial_sources(paths, fmt)
    cal_trials = [trial_sources(group, fmt)[:2] for group in group_trials(calibration)]
    return import_sources(sources, out, layout, ", ".join(map(str, paths)), mapping, height,
                          reconstruct=reconstruct, calibrator=trial_calibrator(name, cal_trials))


def session_trials(folder: str | Path) -> tuple[list[Path], list[Path]]:
    """(calibration trial folders, walk trial folders) of a session folder, by their names
    (module docstring): stands first, then leg cycles."""
    folder = Path(folder)
    trials = sorted(p for p in folder.iterdir() if p.is_dir()
                    and any(f.suffix.lower() in EXPORT_SUFFIXES for f in p.iterdir()))
    if not trials:
        raise ValueError(f"{folder}: no trial folders (a session folder holds one folder of exports per trial)")
    stands = [p for p in trials if STAND_NAMES.search(p.name)]
    swings = [p for p in trials if p not in stands and SWING_NAMES.search(p.name)]
    walks = [p for p in trials if p not in stands and p not in swings]
    if not stands:
        raise ValueError(f"{folder}: no calibration trial (a folder named npose, static or stand; trials: "
                         f"{', '.join(p.name for p in trials)}); give one with --calibration-trial")
    if not walks:
        raise ValueError(f"{folder}: only calibration trials ({', '.join(p.name for p in trials)}); nothing to import")
    return stands + swings, walks


def import_session(folder: str | Path, out_dir: str | Path, calibration: Sequence[str | Path] = (),
                   fmt: str = "auto", mapping: dict[str, str] | None = None, height: float | None = None,
                   reconstruct: bool = True) -> tuple[list[Path], list[tuple[str, Imported]]]:
    """Every walk trial of a session folder as ``out_dir/<trial>.h5``, each calibrated from the
    session's calibration trials (or the ``calibration`` given)."""
    cal, walks = session_trials(folder)
    cal = [Path(c) for c in calibration] or cal
    walks = [w for w in walks if w not in cal]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cal_trials = [trial_sources(group, fmt)[:2] for group in group_trials(cal)]
    done = []
    for w in walks:
        name, sources, layout = trial_sources([w], fmt)
        res = import_sources(sources, out_dir / f"{w.name}.h5", layout, str(w), mapping, height,
                             reconstruct=reconstruct, calibrator=trial_calibrator(name, cal_trials))
        done.append((w.name, res))
    return cal, done


__all__ = ["import_session", "import_with_calibration", "sensor_key", "session_trials", "trial_calibrator"]
