"""Held-out scoring on real recordings: the yardstick ``imucap evaluate --data @real`` adds
beside the synthesized sets.

Every figure from synthesized signals measures the model on signals the project made
itself; a real log recorded with more sensors than a set under test needs no motion
capture to check it: replay the log with the set, replay it again with every sensor, and
the angle between each left-out segment in the two is the error
(``app.replay.held_out_errors``). The logs are imported as ``imucap import`` does
(calibration from the standing start and each sensor's heading from the gait), each with
the sensor-to-site map its folder needs (``RealLog.mapping``).

Per log and set, beside the error per left-out site (``deg``, ``axis_deg``):
- ``phases``: the same error over the frames of each phase (walking, turning, standing,
  other), told from the measured orientations (``app/evaluation/phases.py``);
- ``constant_deg`` / ``dynamic_deg``: the angle of the mean rotation between reconstruction
  and left-out sensor (what a re-mounted or re-calibrated reference would remove) and the
  mean error left after it (``app/evaluation/offset.py``).
"""

from __future__ import annotations

import tempfile
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.recording import Recording, read_recording
from app.replay import ReplaySettings, build_replay_poser, held_out_errors, replay_recording
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from inference.signals.resample import FPS_MODEL

from .offset import constant_and_dynamic
from .phases import PHASES, classify_phases, quat_matrices

# (label, sites): the standard sets, each scored on every log that holds its sites and more
REAL_SETS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("pelvis+shanks", ("pelvis", "l_shank", "r_shank")),
    ("shanks", ("l_shank", "r_shank")),
    ("pelvis+shanks+feet", ("pelvis", "l_shank", "r_shank", "l_foot", "r_foot")),
    ("pelvis+thighs", ("pelvis", "l_thigh", "r_thigh")),
)

# OpenSim's OpenSense example trial (MT_012005D6_009-001, eight Xsens MTw): MT device id ->
# site. OpenSim's code lists the ids by segment without confirming left and right; checked
# against the signals (docs/real_signals.md, "The OpenSense sensor map"): each thigh, shank
# and foot swing together, the legs alternate, each foot lands ~0.35 s after its own shank's
# swing peak, the pelvis turns forward on the side of the swinging leg, and every sensor's
# z axis points into its segment (back, outside of the leg, top of the foot).
OPENSENSE_MAP: dict[str, str] = {
    "00B42268": "torso", "00B42279": "pelvis",
    "00B4227C": "r_thigh", "00B4227D": "r_shank", "00B421EF": "r_foot",
    "00B421EE": "l_thigh", "00B421ED": "l_shank", "00B421E6": "l_foot",
}
EXPORT_SUFFIXES = (".txt", ".csv", ".tsv")

# where ``split_errors`` keeps each site's per-frame errors (site -> {"t", "deg"})
FRAMES_KEY = "frame_errors"

# the block a comparison of two models on one log resamples: about two strides
BLOCK_SECONDS = 2.0


@dataclass(frozen=True)
class RealLog:
    """One real log under the data folder: its name in reports, where it lies, and the
    ``--map ID=SITE`` entries its import needs (empty when its device names say the sites)."""

    name: str
    path: Path
    mapping: Mapping[str, str] = field(default_factory=dict)

    def map_args(self) -> list[str]:
        """The map as ``imucap import`` arguments."""
        return [a for k, v in self.mapping.items() for a in ("--map", f"{k}={v}")]


def _is_ximu3_log(d: Path) -> bool:
    return any(s.is_dir() and (s / "Inertial.csv").is_file() and (s / "Quaternion.csv").is_file()
               for s in d.iterdir())


def _is_opensense_log(d: Path) -> bool:
    """A folder of sensor exports (one text file per sensor) whose ids the OpenSense map knows."""
    files = [f for f in d.iterdir() if f.is_file() and f.suffix.lower() in EXPORT_SUFFIXES]
    return any(any(i in f.stem for i in OPENSENSE_MAP) for f in files)


def real_logs(root: Path) -> list[RealLog]:
    """The real logs under ``root`` (``$IMUCAP_DATA``): every x-IMU3 log folder in
    ``root/ximu3`` (a folder whose device folders hold Inertial.csv and Quaternion.csv),
    named ``ximu3/<folder>``, and every OpenSense trial folder in ``root/opensense`` (the
    MT Manager exports of the example trial's sensors), named ``opensense/<folder>`` and
    imported with ``OPENSENSE_MAP``. An empty list when there are none."""
    out = []
    for kind, test, mapping in (("ximu3", _is_ximu3_log, {}), ("opensense", _is_opensense_log, OPENSENSE_MAP)):
        base = root / kind
        if not base.is_dir():
            continue
        for d in sorted(p for p in base.iterdir() if p.is_dir()):
            if test(d):
                out.append(RealLog(f"{kind}/{d.name}", d, dict(mapping)))
    return out


def held_out_sets(sites: Sequence[str],
                  sets: Sequence[tuple[str, Sequence[str]]] = REAL_SETS) -> list[tuple[str, tuple[str, ...]]]:
    """The sets a recording of ``sites`` can score: all their sites worn, some left over."""
    have = set(sites)
    return [(label, tuple(s)) for label, s in sets if set(s) <= have and have - set(s)]


def recording_phases(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """(t (N,), phase label (N,)) of every raw frame of ``rec``, from its sensors' raw
    orientations (no calibration needed: ``classify_phases``)."""
    t = np.asarray(rec.raw["t"], dtype=float)
    fps = 1.0 / float(np.median(np.diff(t))) if len(t) > 1 else 60.0
    R = {s: quat_matrices(rec.raw[s]["quat"]) for s in rec.sites}
    return t, classify_phases(R, fps)


def phase_at(t_raw: np.ndarray, labels: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The label of the raw frame nearest each time in ``t``."""
    hi = np.clip(np.searchsorted(t_raw, t), 0, len(t_raw) - 1)
    lo = np.maximum(hi - 1, 0)
    return labels[np.where(np.abs(t - t_raw[lo]) <= np.abs(t_raw[hi] - t), lo, hi)]


def split_errors(poses: Sequence[Any], measured: Sequence[Any], sites: Sequence[str],
                 phase_of: Callable[[np.ndarray], np.ndarray], fps: float = FPS_MODEL) -> dict[str, Any]:
    """Per left-out site, over the frames ``held_out_errors`` pairs (both replays at the
    same time, the site delivered): ``phases`` (phase -> seconds of paired frames and deg
    per site, None where the phase has no frame), ``constant_deg`` and ``dynamic_deg``
    (``constant_and_dynamic``), and under ``FRAMES_KEY`` each site's per-frame errors with
    their times, for a paired comparison of two models (``compare_held_out``; not written
    out). ``phase_of(t)`` labels the pose times."""
    by_t = {round(lp.t, 6): lp for lp in measured}
    pairs = [(lp, by_t[round(lp.t, 6)]) for lp in poses if round(lp.t, 6) in by_t]
    labels = phase_of(np.array([a.t for a, _ in pairs])) if pairs else np.array([], dtype=str)
    phases: dict[str, Any] = {p: {"seconds": round(float(np.sum(labels == p)) / fps, 2), "deg": {}} for p in PHASES}
    constant: dict[str, float | None] = {}
    dynamic: dict[str, float | None] = {}
    frames: dict[str, dict[str, list[float]]] = {}
    for s in sites:
        k, seg = SITE_INDEX[s], SITE_SEGMENT_INDEX[SITE_INDEX[s]]
        use = np.array([b.observed_sites[k] for _, b in pairs], dtype=bool)
        if not use.any():
            constant[s] = dynamic[s] = None
            for p in PHASES:
                phases[p]["deg"][s] = None
            continue
        Ra = np.stack([pairs[i][0].pose.rot[seg] for i in np.flatnonzero(use)])
        Rb = np.stack([pairs[i][1].pose.rot[seg] for i in np.flatnonzero(use)])
        err = np.degrees(matrix_angle_between(Ra, Rb))
        lab = labels[use]
        for p in PHASES:
            m = lab == p
            phases[p]["deg"][s] = round(float(np.mean(err[m])), 2) if m.any() else None
        c, d = constant_and_dynamic(Ra, Rb)
        constant[s], dynamic[s] = round(c, 2), round(d, 2)
        frames[s] = {"t": [round(pairs[i][0].t, 6) for i in np.flatnonzero(use)], "deg": err.tolist()}
    return {"phases": phases, "constant_deg": constant, "dynamic_deg": dynamic, FRAMES_KEY: frames}


def score_recording(rec: Recording, model: str = "diffusion", seed: int = 0,
                    sets: Sequence[tuple[str, Sequence[str]]] = REAL_SETS,
                    loaded: Any = "resolve", answer_lag: int | None = None,
                    knee_twist: float | None = None) -> dict[str, Any]:
    """Per standard set the recording can score: the held-out sites' errors (deg) against
    the replay with every sensor, as ``imucap replay --held-out`` reports them, split by
    phase and into constant and dynamic parts (``split_errors``).
    ``loaded``: the model for ``model`` already loaded (scoring several logs loads it once);
    ``answer_lag``: frames each pose waits (None: as the recording says; an import's 4);
    ``knee_twist``: the poser's twist share (None: as the recording says, else the model's)."""
    from app.export.formats import body_for_recording
    from inference.poser.models import model_for_sites

    body, _ = body_for_recording(rec.metadata)
    # the live default ("auto") poses each set with the file it chooses for those sites
    models = {str(model_for_sites(model)): loaded}
    built_for: dict[str, Any] = {}

    def built(sites: Sequence[str]):
        spec = str(model_for_sites(model, sites))
        if spec not in built_for:
            built_for[spec] = build_replay_poser(rec, ReplaySettings(model=spec, seed=seed, answer_lag=answer_lag,
                                                                     knee_twist=knee_twist), body,
                                                 models.get(spec, "resolve"))
        return built_for[spec]

    ref = built(rec.sites)
    full = replay_recording(rec, ref.fresh(), sensors=rec.sites, causal=ref.causal).poses
    t_raw, labels = recording_phases(rec)
    out: dict[str, Any] = {}
    for label, sites in held_out_sets(rec.sites, sets):
        b = built(sites)
        poses = replay_recording(rec, b.fresh(), sensors=sites, causal=b.causal).poses
        left = [s for s in rec.sites if s not in sites]
        out[label] = {"sensors": list(sites), **held_out_errors(poses, full, left),
                      **split_errors(poses, full, left, lambda t: phase_at(t_raw, labels, t))}
    return out


ImportFn = Callable[[RealLog, Path], Any]


def score_logs(logs: Sequence[RealLog], import_log: ImportFn, model: str = "diffusion", seed: int = 0,
               sets: Sequence[tuple[str, Sequence[str]]] = REAL_SETS, loaded: Any = "resolve",
               progress: Callable[[str], None] | None = None, answer_lag: int | None = None,
               knee_twist: float | None = None) -> dict[str, Any]:
    """``held_out`` for ``imucap evaluate``: log name -> set label -> the set's scoring
    (``score_recording``). ``import_log(log, out_h5)`` writes the session recording of
    ``log`` with its map (the CLI passes ``imucap import``'s function: the app layer does
    not reach up into the CLI)."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="imucap-real-") as tmp:
        for k, log in enumerate(logs):
            h5 = Path(tmp) / f"log{k}.h5"
            import_log(log, h5)
            if progress is not None:
                progress(f"{log.name}: imported, scoring {model}")
            out[log.name] = score_recording(read_recording(h5), model, seed, sets, loaded, answer_lag, knee_twist)
    return out


def compare_held_out(held_out: dict[str, Any], against: dict[str, Any], block_s: float = BLOCK_SECONDS,
                     seed: int = 0, fps: float = FPS_MODEL) -> dict[str, Any]:
    """log -> set -> site -> the error of ``held_out`` minus ``against``'s (deg) on the
    frames both scored, with a paired bootstrap interval over ``block_s`` blocks of the log
    (``paired_block_difference``: one take's frames are not independent) and ``decided``
    when it excludes zero. Both must keep their per-frame errors (``FRAMES_KEY``)."""
    from inference.metrics.errors import paired_block_difference

    block = max(1, int(round(block_s * fps)))
    out: dict[str, Any] = {}
    for log, sets in held_out.items():
        for label, r in sets.items():
            other = against.get(log, {}).get(label)
            if other is None:
                continue
            for site, fa in r.get(FRAMES_KEY, {}).items():
                fb = other.get(FRAMES_KEY, {}).get(site)
                if fb is None:
                    continue
                tb = {t: i for i, t in enumerate(fb["t"])}
                both = [(i, tb[t]) for i, t in enumerate(fa["t"]) if t in tb]
                if not both:
                    continue
                ia, ib = np.array(both).T
                d = paired_block_difference(np.asarray(fa["deg"])[ia], np.asarray(fb["deg"])[ib], block, seed=seed)
                row = {k: round(v, 2) if isinstance(v, float) else v for k, v in d.as_dict().items()}
                row["blocks"] = row.pop("clips")
                out.setdefault(log, {}).setdefault(label, {})[site] = row
    return out


def drop_frame_errors(held_out: dict[str, Any]) -> dict[str, Any]:
    """``held_out`` without the per-frame errors (what is written out)."""
    return {log: {label: {k: v for k, v in r.items() if k != FRAMES_KEY} for label, r in sets.items()}
            for log, sets in held_out.items()}


def mean_over(held_out: dict[str, Any], label: str) -> dict[str, float] | None:
    """Site -> error (deg) of set ``label``, averaged over the logs that scored it."""
    per: dict[str, list[float]] = {}
    for sets in held_out.values():
        for site, v in sets.get(label, {}).get("deg", {}).items():
            if v is not None:
                per.setdefault(site, []).append(v)
    return {s: round(float(np.mean(v)), 2) for s, v in per.items()} or None


__all__ = ["BLOCK_SECONDS", "FRAMES_KEY", "OPENSENSE_MAP", "REAL_SETS", "RealLog", "compare_held_out",
           "drop_frame_errors", "held_out_sets", "mean_over", "real_logs", "recording_phases",
           "score_logs", "score_recording", "split_errors"]
