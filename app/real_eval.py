"""Held-out scoring on real recordings: the yardstick ``imucap evaluate --data @real`` adds
beside the synthesized sets.

Every figure from synthesized signals measures the model on signals the project made
itself; a real log recorded with more sensors than a set under test needs no motion
capture to check it: replay the log with the set, replay it again with every sensor, and
the angle between each left-out segment in the two is the error
(``app.replay.held_out_errors``). The logs are imported as ``imucap import`` does
(calibration from the standing start and each sensor's heading from the gait).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from app.recording import Recording, read_recording
from app.replay import ReplaySettings, build_replay_poser, held_out_errors, replay_recording

# (label, sites): the standard sets, each scored on every log that holds its sites and more
REAL_SETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("pelvis+shanks", ("pelvis", "l_shank", "r_shank")),
    ("shanks", ("l_shank", "r_shank")),
    ("pelvis+shanks+feet", ("pelvis", "l_shank", "r_shank", "l_foot", "r_foot")),
    ("pelvis+thighs", ("pelvis", "l_thigh", "r_thigh")),
)


@dataclass(frozen=True)
class RealLog:
    """One real log under the data folder: its name in reports and where it lies."""

    name: str
    path: Path


def real_logs(root: Path) -> list[RealLog]:
    """The real logs under ``root`` (``$IMUCAP_DATA``): every x-IMU3 log folder in
    ``root/ximu3`` (a folder whose device folders hold Inertial.csv and Quaternion.csv),
    named ``ximu3/<folder>``. An empty list when there are none."""
    base = root / "ximu3"
    if not base.is_dir():
        return []
    out = []
    for d in sorted(p for p in base.iterdir() if p.is_dir()):
        if any(s.is_dir() and (s / "Inertial.csv").is_file() and (s / "Quaternion.csv").is_file()
               for s in d.iterdir()):
            out.append(RealLog(f"ximu3/{d.name}", d))
    return out


def held_out_sets(sites: Sequence[str],
                  sets: Sequence[tuple[str, Sequence[str]]] = REAL_SETS) -> list[tuple[str, tuple[str, ...]]]:
    """The sets a recording of ``sites`` can score: all their sites worn, some left over."""
    have = set(sites)
    return [(label, tuple(s)) for label, s in sets if set(s) <= have and have - set(s)]


def score_recording(rec: Recording, model: str = "diffusion", seed: int = 0,
                    sets: Sequence[tuple[str, Sequence[str]]] = REAL_SETS,
                    loaded: Any = "resolve") -> dict[str, Any]:
    """Per standard set the recording can score: the held-out sites' errors (deg) against
    the replay with every sensor, as ``imucap replay --held-out`` reports them.
    ``loaded``: the model for ``model`` already loaded (scoring several logs loads it once)."""
    from app.export.formats import body_for_recording

    body, _ = body_for_recording(rec.metadata)
    built = build_replay_poser(rec, ReplaySettings(model=model, seed=seed), body, loaded)
    full = replay_recording(rec, built.fresh(), sensors=rec.sites, causal=built.causal).poses
    out: dict[str, Any] = {}
    for label, sites in held_out_sets(rec.sites, sets):
        poses = replay_recording(rec, built.fresh(), sensors=sites, causal=built.causal).poses
        left = [s for s in rec.sites if s not in sites]
        out[label] = {"sensors": list(sites), **held_out_errors(poses, full, left)}
    return out


ImportFn = Callable[[Path, Path], Any]


def score_logs(logs: Sequence[RealLog], import_log: ImportFn, model: str = "diffusion", seed: int = 0,
               sets: Sequence[tuple[str, Sequence[str]]] = REAL_SETS, loaded: Any = "resolve",
               progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """``held_out`` for ``imucap evaluate``: log name -> set label -> the set's scoring
    (``score_recording``). ``import_log(log_path, out_h5)`` writes the session recording
    (the CLI passes ``imucap import``'s function: the app layer does not reach up into the
    CLI)."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="imucap-real-") as tmp:
        for k, log in enumerate(logs):
            h5 = Path(tmp) / f"log{k}.h5"
            import_log(log.path, h5)
            if progress is not None:
                progress(f"{log.name}: imported, scoring {model}")
            out[log.name] = score_recording(read_recording(h5), model, seed, sets, loaded)
    return out


def mean_over(held_out: dict[str, Any], label: str) -> dict[str, float] | None:
    """Site -> error (deg) of set ``label``, averaged over the logs that scored it."""
    import numpy as np

    per: dict[str, list[float]] = {}
    for sets in held_out.values():
        for site, v in sets.get(label, {}).get("deg", {}).items():
            if v is not None:
                per.setdefault(site, []).append(v)
    return {s: round(float(np.mean(v)), 2) for s, v in per.items()} or None


__all__ = ["REAL_SETS", "RealLog", "real_logs", "held_out_sets", "score_recording", "score_logs", "mean_over"]
