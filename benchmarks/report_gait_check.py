"""The gait report's figures on synthesized walks against the truth's: does the report measure a walk?

    .venv/bin/python benchmarks/report_gait_check.py [--data DIR] [--clips 20] [--seconds 8]
        [--sets "6 sites" "pelvis+shanks" shanks "lower body" "shank detector" "shank gyro" "foot sensors"]
        [--json] [--write-expected] [--keep DIR]

``--sets "foot sensors"`` measures the foot sensors as the event source alone: the events from the
synthesized foot sensors' gyro (``app.report.feet.sensor_events``, typical noise with mounting
rotations, undone by the synthesis's own sensor-to-bone as a calibration would), the body from the
truth, so only the events differ from the truth's analysis (joint ranges are 0 by construction).

``--keep DIR`` stores each reconstruction (times, orientations, root, contact values) as
DIR/<set>/<clip>.npz and, when they are there already, reads them instead of reconstructing again: a
change to the event detection or the stride rules is measured in seconds on the same reconstructions.

``--sets "shank detector"`` measures the report's events with both shanks worn and no foot sensor or
insole (every set above) alone: the shank contact detector on the shanks' synthesized features, exactly
the contact values the poser gives after its first 0.45 s, with the body from the truth; it needs no
reconstruction (seconds for the 20 clips). ``"shank gyro"``: the same with the events from the shanks'
gyro instead (``shank_gyro_analysis``), the standard alternative, to compare with.

Clips: the walking trials the comparison band keeps (``app.report.normal.trial_curves``: enough straight
walking strides at 0.8-1.8 m/s) whose skeleton bends its toes (``moves_toes``: the truth's foot off is its
toe point leaving the ground, which on a rigid foot comes with the heel's rise; CMU's cgspeed conversion
has no toe joint), half from CMU's takes (never seen by the shipped model: ASF/AMC and the iClone
conversion), half from Bandai's "walk" clips of every style (its training data); HDM05 has no walk among
its takes here. The same rule for every dataset. Each clip (its first ``--seconds``) is reconstructed from
noise-free synthesized signals of each sensor set by the live poser frame by frame, then analysed by the
report (``app.report.analysis.analyse``: events from the model's contacts at 20 Hz) and compared with the
same analysis of the truth (events from the heel and toe points' speed at 60 Hz).

Stride time and stance are compared stride by stride (``app.report.strides.match_strides``): a report's
stride is the truth's when both its strikes lie within half a stride of the truth stride's; per clip, the
mean |difference| over the strides both call walking. The shares of the truth's walking strides found and
missed and of the report's walking strides with no truth stride there (extra) are over all the clips'
strides. The take means (the report's mean stride time and stance against the truth's, each over its own
strides) are kept beside them (``take_*``): with 2-4 strides a take, one stride more or less moves them.
Per clip and set also: the absolute difference of the cadence (%), of the walking speed (%) and of the
mean per-stride range of hip, knee and ankle flexion (both sides); and the event timing (each truth strike
/ off to the nearest one found, ms). The table is the mean over the clips, then split by dataset with the
median strike and foot-off differences. ``--write-expected`` stores the means per set under
``synthesized`` in app/report/expected_error.json, where the report reads its expected errors.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from app.report.analysis import analyse
from app.report.confidence import EXPECTED_FILE
from app.report.events import (
    MIN_SWING_S,
    WARMUP_S,
    coordinate_events,
    foot_events,
    model_contact_values,
    truth_contact_values,
)
from app.report.feet import sensor_events
from app.report.normal import dataset_of, trial_curves
from app.report.strides import match_strides
from inference.evaluation.runner import SIX, evaluate_motions, face_forward, resolve_models
from inference.loaders import find_motion_files, load_motion
from inference.poser.models import CONTACT_THRESHOLD, model_for_sites
from inference.signals.resample import FPS_MODEL, STEP
from inference.signals.synthesis import FPS_SIGNAL, NoiseModel, kinematics, synthesize
from inference.training.data import data_root

SETS = {
    "6 sites": SIX,
    "pelvis+shanks": ("pelvis", "l_shank", "r_shank"),
    "shanks": ("l_shank", "r_shank"),
    "lower body": ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot"),
}
RANGES = ("hip_flexion", "knee_flexion", "ankle_dorsiflexion")
FEET = "foot sensors"
DETECTOR = "shank detector"
SHANK_GYRO = "shank gyro"
LIMITS = {"stride_time_s": 0.020, "stance_pct": 3.0, "cadence_pct": 2.0, "knee_flexion_range_deg": 5.0}


TOE_MOVES_DEG = 5.0  # the toes' rotation on the foot over a clip: less is a rigid foot


def moves_toes(motion) -> bool:
    """Whether the skeleton bends its toes (range of the toes' rotation relative to the foot over the clip,
    left foot, above ``TOE_MOVES_DEG``). The truth's foot off is its toe point leaving the ground: on a
    rigid foot (the cgspeed conversion of CMU has no toe joint) that point lifts with the heel, so the
    truth's stance ends 0.1-0.2 s early (docs/report.md)."""
    from inference.body.skeleton import SEGMENT_INDEX

    rel = np.swapaxes(motion.rot[:, SEGMENT_INDEX["l_foot"]], -1, -2) @ motion.rot[:, SEGMENT_INDEX["l_toes"]]
    cos = np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    ang = np.degrees(np.arccos(cos))
    return bool(ang.max() - ang.min() > TOE_MOVES_DEG)


def pick_clips(root: Path, n: int, seconds: float) -> list:
    """n walking clips (cut to ``seconds``), half CMU, half Bandai, in file order, among the clips whose
    skeleton bends its toes (``moves_toes``; the rule for every dataset) and that the comparison band would
    keep as a walk (``trial_curves``)."""
    cmu = find_motion_files([root / "cmu" / "asf_amc", root / "cmu" / "bvh_cgspeed", root / "cmu" / "bvh_iclone"])
    bandai = [p for p in find_motion_files([root / "bandai"]) if "_walk_" in p.name]
    out: dict[str, list] = {"cmu": [], "bandai": []}
    for key, paths, want in (("cmu", cmu, n // 2), ("bandai", bandai, n - n // 2)):
        for p in paths:
            if len(out[key]) >= want:
                break
            try:
                m = load_motion(p)
            except (ValueError, OSError):
                continue
            m = m.slice(0, min(m.n_frames, int(seconds * m.fps) + 1))
            if moves_toes(m) and trial_curves(m) is not None:
                out[key].append(m)
    return out["cmu"] + out["bandai"]


def _mean(xs) -> float | None:
    v = [x for x in xs if x is not None and np.isfinite(x)]
    return float(np.mean(v)) if v else None


def clip_figures(an) -> dict[str, float | None]:
    walk = an.summary.walking()
    fig = {"stride_time_s": _mean([s.time_s for s in walk]), "stance_pct": _mean([s.stance_pct for s in walk]),
           "cadence": an.summary.cadence_spm, "speed": _mean([s.speed_mps for s in walk]), "strides": len(walk)}
    for a in RANGES:
        fig[a] = _mean(list(an.ranges["l"][a]) + list(an.ranges["r"][a]))
    return fig


def stride_errors(truth_an, found_an) -> dict:
    """The same strides compared (``match_strides``): over the truth's walking strides, how many the
    report found as walking strides (``found``), missed (``missed``: none found there, or found but left
    out as another kind); the report's walking strides with no truth stride there (``extra``); and over
    the pairs both call walking, the mean |difference| of stride time (s) and stance (points), and the
    signed strike and foot-off differences (found - truth, s)."""
    tw = truth_an.summary.walking()
    pairs = match_strides(truth_an.summary.strides, found_an.summary.strides)
    both = [(a, b) for a, b in pairs if a.kind == "walking" and b.kind == "walking"]
    matched_found = {id(b) for _, b in pairs}
    fw = found_an.summary.walking()
    out = {"truth_strides": len(tw), "found": len(both), "missed": len(tw) - len(both),
           "extra": sum(1 for b in fw if id(b) not in matched_found), "report_strides": len(fw)}
    out["stride_time_s"] = _mean([abs(b.time_s - a.time_s) for a, b in both])
    out["stance_pct"] = _mean([abs(b.stance_pct - a.stance_pct) for a, b in both])
    out["strike_s"] = [b.start - a.start for a, b in both]
    out["off_s"] = [b.off - a.off for a, b in both]
    return out


def timing_ms(truth, found, after: float = WARMUP_S) -> float | None:
    """Mean |t_truth - nearest t_found| over the truth's events from ``after`` s on (ms): the poser's warm-up
    gives no event (``app.report.events.model_contact_values``), so a truth event there has none to meet."""
    diffs = []
    for side in ("l", "r"):
        for kind in ("strikes", "offs"):
            a, b = getattr(truth[side], kind), getattr(found[side], kind)
            a = a[a >= after]
            if len(a) and len(b):
                diffs += [float(np.min(np.abs(b - x))) for x in a]
    return 1000.0 * float(np.mean(diffs)) if diffs else None


def stride_shares(clips: list[dict]) -> dict:
    """Over all the clips' strides: the share of the truth's walking strides found and missed, the share
    of the report's walking strides that are extra (no truth stride there), and the median strike and
    foot-off differences (found - truth, ms) over the matched strides."""
    n_t = sum(c["strides"]["truth_strides"] for c in clips)
    n_f = sum(c["strides"]["report_strides"] for c in clips)
    strike = [x for c in clips for x in c["strides"]["strike_s"]]
    off = [x for c in clips for x in c["strides"]["off_s"]]
    return {"found_share": sum(c["strides"]["found"] for c in clips) / n_t if n_t else None,
            "missed_share": sum(c["strides"]["missed"] for c in clips) / n_t if n_t else None,
            "extra_share": sum(c["strides"]["extra"] for c in clips) / n_f if n_f else None,
            "strike_median_ms": 1000.0 * float(np.median(strike)) if strike else None,
            "off_median_ms": 1000.0 * float(np.median(off)) if off else None}


TRUTHS = ("speed", "coordinates")


def truth_analysis(motion, truth: str = "speed"):
    """The truth's analysis: its own body with events by ``truth``: "speed", the heel and toe points' speed
    under the contact labels' threshold (``truth_contact_values``, the rule the contact detector learned);
    "coordinates", the heel furthest ahead of the pelvis and the toe furthest behind it (Zeni et al. 2008,
    ``app.report.events.coordinate_events``), a second definition to tell the report's error from the
    definitions' spread (docs/report.md, "Which truth")."""
    m = face_forward(motion)
    kin = kinematics(m, FPS_SIGNAL)
    t = np.arange(len(kin.rot)) / kin.fps
    if truth == "coordinates":
        return analyse(t, kin.rot, kin.root, None, None, "truth",
                       events=coordinate_events(t, kin.contact_pos, kin.root, "truth"))
    if truth != "speed":
        raise ValueError(f"unknown truth events {truth!r} ({', '.join(TRUTHS)})")
    return analyse(t, kin.rot, kin.root, t, truth_contact_values(kin.contact_pos, kin.fps), "truth", threshold=0.0)


def errors(truth: dict, found: dict) -> dict[str, float | None]:
    def d(k, rel=False):
        a, b = truth.get(k), found.get(k)
        if a is None or b is None:
            return None
        return abs(b - a) / abs(a) * 100.0 if rel else abs(b - a)
    out = {"stride_time_s": d("stride_time_s"), "stance_pct": d("stance_pct"), "cadence_pct": d("cadence", True),
           "speed_pct": d("speed", True)}
    for a in RANGES:
        out[f"{a}_range_deg"] = d(a)
    return out


def feet_analysis(motion, seed: int = 0):
    """The truth's body with the events of its synthesized foot sensors (module docstring)."""
    m = face_forward(motion)
    kin = kinematics(m, FPS_SIGNAL)
    t = np.arange(len(kin.rot)) / kin.fps
    sig = synthesize(m, NoiseModel.typical(), rng=seed, sites=("l_foot", "r_foot"))
    n = min(len(t), len(sig.t))
    events = {side: sensor_events(sig.t[:n], sig.gyro[:n, k], sig.meta["R_SB"][k], side=side,
                                  acc=sig.specific_force[:n, k]) for k, side in enumerate(("l", "r"))}
    return analyse(t, kin.rot, kin.root, None, None, FEET, events=events)


def shank_gyro_analysis(motion, seed: int = 0):
    """The truth's body with events from the shanks' synthesized gyro by the foot sensors' method
    (``app.report.feet.sensor_events`` on the shank's sagittal rate: mid-swing peak, foot off the rate's
    maximum before it, strike the first maximum after it; the shank-gyro events of Aminian et al. 2002 /
    Salarian et al. 2004), typical noise with mounting rotations undone as for the foot sensors: a
    candidate event source, measured against the detector's."""
    m = face_forward(motion)
    kin = kinematics(m, FPS_SIGNAL)
    t = np.arange(len(kin.rot)) / kin.fps
    sig = synthesize(m, NoiseModel.typical(), rng=seed, sites=("l_shank", "r_shank"))
    n = min(len(t), len(sig.t))
    events = {side: sensor_events(sig.t[:n], sig.gyro[:n, k], sig.meta["R_SB"][k], side=side)
              for k, side in enumerate(("l", "r"))}
    return analyse(t, kin.rot, kin.root, None, None, SHANK_GYRO, events=events)


def detector_analysis(motion, seed: int = 0):
    """The truth's body with the events the report gets from the shank contact detector when both shanks
    are worn: the detector (``inference.poser.contact_detector``, the shipped weights) run on the shanks'
    synthesized 20 Hz features as the model sets' reconstructions get them (noise-free, the same per-clip
    seed; with the evaluation's calibrated sensor noise the figures move by under 0.3 ms and 0.1 points), as
    the live poser runs it on its kept history; the first ``CONTEXT - 1`` frames, where the poser's history
    still holds its standing start, give no event. The poser's own contact values are these to 1e-6."""
    from inference.evaluation.runner import clip_input, clip_seed
    from inference.poser.contact_detector import DETECTOR_THRESHOLD, SHANK_INDEX, DetectorKernel
    from inference.poser.models import resolve_detector

    global _DETECTOR
    if _DETECTOR is None:
        _DETECTOR = DetectorKernel(resolve_detector("default"))
    det = _DETECTOR
    inp = clip_input(motion, SETS["shanks"], False, None, clip_seed(seed, motion.name))
    f = inp.features[:, SHANK_INDEX].astype(np.float32)
    prob = np.full((len(f), 4), np.nan)
    for i in range(det.context - 1, len(f)):
        prob[i] = det(f[i - det.context + 1: i + 1])
    m = face_forward(motion)
    kin = kinematics(m, FPS_SIGNAL)
    t = np.arange(len(kin.rot)) / kin.fps
    tc = np.arange(len(f)) * STEP / FPS_SIGNAL
    return analyse(t, kin.rot, kin.root, tc, prob, DETECTOR, threshold=DETECTOR_THRESHOLD)


_DETECTOR = None


def reconstructions(motions, model_spec: str, label: str, keep: Path | None,
                    smoothing: bool = True, answer_lag: int | None = None) -> list[tuple[str, dict]]:
    """(clip name, {t, rot, root, contact_prob}) per motion for one set, from ``keep`` where stored there
    (only the clips not stored are reconstructed). ``smoothing=False``: the poser's answer before its
    display filter (the 1-Euro filters of the root and the unmeasured segments). ``answer_lag``: each frame
    as the window that many frames later answered it, as an import poses it (inference/poser/lag.py)."""
    folder = None if keep is None else keep / (label.replace(" ", "_") + ("" if smoothing else "_unsmoothed")
                                               + (f"_lag{answer_lag}" if answer_lag else ""))
    stored = {} if folder is None else {m.name: dict(np.load(folder / f"{m.name}.npz")) for m in motions
                                        if (folder / f"{m.name}.npz").is_file()}
    todo = [m for m in motions if m.name not in stored]
    if todo:
        spec = str(model_for_sites(model_spec, SETS[label]))  # the live default chooses by the set
        model = resolve_models([spec])[spec]
        _, results = evaluate_motions(todo, model, SETS[label], keep=True, desc=label, smoothing=smoothing,
                                      answer_lag=answer_lag)
        assert abs(1.0 / FPS_MODEL - STEP / FPS_SIGNAL) < 1e-9
        for r in results:
            rec = r.recon
            d = {"t": np.arange(len(rec.rot)) * STEP / FPS_SIGNAL, "rot": rec.rot, "root": rec.root,
                 "contact_prob": rec.contact_prob}
            if folder is not None:
                folder.mkdir(parents=True, exist_ok=True)
                np.savez_compressed(folder / f"{r.name}.npz", **d)
            stored[r.name] = d
    out = [(m.name, stored[m.name]) for m in motions]
    return out


def run(motions, sets: list[str], model_spec: str = "diffusion", done=None, keep: Path | None = None,
        threshold: float = CONTACT_THRESHOLD, min_swing_s: float = MIN_SWING_S, smoothing: bool = True,
        answer_lag: int | None = None, truth: str = "speed") -> dict:
    """Every set over every motion; ``done(result so far)`` after each set. ``threshold`` / ``min_swing_s``:
    the model contacts' event detection (``app.report.events.foot_events``), to try others."""
    truths = {m.name: truth_analysis(m, truth) for m in motions}
    out = {}
    for label in sets:
        clips = []
        if label == FEET:
            found = [(m.name, feet_analysis(m)) for m in motions]
        elif label == DETECTOR:
            found = [(m.name, detector_analysis(m)) for m in motions]
        elif label == SHANK_GYRO:
            found = [(m.name, shank_gyro_analysis(m)) for m in motions]
        else:
            found = [(name, analyse(d["t"], d["rot"], d["root"], None, None, "model", events=foot_events(
                d["t"], model_contact_values(d["t"], d["contact_prob"]), "model", threshold=threshold,
                min_swing_s=min_swing_s)))
                     for name, d in reconstructions(motions, model_spec, label, keep, smoothing, answer_lag)]
        for name, an in found:
            tr = truths[name]
            ft, ff = clip_figures(tr), clip_figures(an)
            err = errors(ft, ff)
            matched = stride_errors(tr, an)
            err = {"stride_time_s": matched["stride_time_s"], "stance_pct": matched["stance_pct"],
                   **{k: v for k, v in err.items() if k not in ("stride_time_s", "stance_pct")},
                   "take_stride_time_s": err["stride_time_s"], "take_stance_pct": err["stance_pct"]}
            clips.append({"clip": name, "truth": ft, "found": ff, "errors": err, "strides": matched,
                          "timing_ms": timing_ms(tr.events, an.events)})
        keys = clips[0]["errors"].keys() if clips else []
        mean = {k: _mean([c["errors"][k] for c in clips]) for k in keys}
        mean["timing_ms"] = _mean([c["timing_ms"] for c in clips])
        mean.update(stride_shares(clips))
        passed = {k: (mean[k] is not None and mean[k] <= lim) for k, lim in LIMITS.items()}
        sites = SETS.get(label, ("l_foot", "r_foot") if label == FEET else ("l_shank", "r_shank"))
        out[label] = {"sites": list(sites), "errors": mean, "passed": passed,
                      "clips": clips}
        if done is not None:
            done(out)
    return out


def write_expected(result: dict, model: str, n_clips: int, path: Path = EXPECTED_FILE,
                   answer_lag: int | None = None) -> None:
    """The means per set as the report's expected errors: ``synthesized`` for live poses, ``synthesized_late``
    for poses answered late (``answer_lag``), which a report of late poses reads."""
    d = json.loads(path.read_text())
    late = bool(answer_lag)
    d["synthesized_late" if late else "synthesized"] = {
        "about": (f"Mean over {n_clips} synthesized walks (half CMU, half Bandai) of the absolute difference "
                  "between the report's figure from the reconstruction and from the truth (stride time and stance "
                  "stride by stride over the strides both found, take_*: the take means); "
                  f"benchmarks/report_gait_check.py{f' --answer-lag {answer_lag}' if late else ''}, model {model}, "
                  f"{'posed late' if late else 'the live answer'}. *_pct of cadence and speed are relative (%)."),
        "sets": {k: {"sites": v["sites"], "errors": {e: (None if x is None else round(x, 4))
                                                     for e, x in v["errors"].items()}} for k, v in result.items()
                 if k not in (FEET, DETECTOR, SHANK_GYRO)}}
    path.write_text(json.dumps(d, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--clips", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--sets", nargs="+", default=["pelvis+shanks", "shanks", "6 sites", "lower body"],
                    choices=[*SETS, FEET, DETECTOR, SHANK_GYRO])
    ap.add_argument("--model", default="diffusion")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--out", default=None, help="write the whole result (per clip) as JSON here")
    ap.add_argument("--write-expected", action="store_true")
    ap.add_argument("--contact-threshold", type=float, default=CONTACT_THRESHOLD,
                    help="the model contacts' threshold for the events (to try others)")
    ap.add_argument("--min-swing", type=float, default=MIN_SWING_S,
                    help="gaps in contact shorter than this are closed (s; to try others)")
    ap.add_argument("--keep", default=None, help="store / reuse the reconstructions here (module docstring)")
    ap.add_argument("--answer-lag", type=int, default=None,
                    help="frames each pose waits for the sensors after it, as an import poses it")
    ap.add_argument("--truth", choices=TRUTHS, default="speed",
                    help="the truth's events: the heel and toe points' speed (default, the contact labels' rule) "
                         "or their place against the pelvis (Zeni et al. 2008)")
    ap.add_argument("--no-smoothing", action="store_true",
                    help="analyse the poser's answer before its display filter (1-Euro), as the report does")
    args = ap.parse_args(argv)
    root = Path(args.data) if args.data else data_root()
    motions = pick_clips(root, args.clips, args.seconds)
    print(f"{len(motions)} clips: {', '.join(m.name for m in motions)}", file=sys.stderr)
    def done(res: dict) -> None:
        if args.out:
            Path(args.out).write_text(json.dumps(res, indent=1))

    res = run(motions, args.sets, args.model, done, None if args.keep is None else Path(args.keep),
              args.contact_threshold, args.min_swing, smoothing=not args.no_smoothing, answer_lag=args.answer_lag,
              truth=args.truth)
    if args.write_expected:
        write_expected(res, args.model, len(motions), answer_lag=args.answer_lag)
    if args.json:
        print(json.dumps({k: {"errors": v["errors"], "passed": v["passed"]} for k, v in res.items()}))
    else:
        g = lambda x, s=1.0, nd=1: "n/a" if x is None else f"{x * s:.{nd}f}"  # noqa: E731
        print("| set | stride time (ms) | stance (points) | cadence (%) | speed (%) | knee range (deg) | "
              "hip range (deg) | ankle range (deg) | strides found / missed / extra (%) | "
              "take means: stride time (ms), stance (points) |")
        print("|---|---|---|---|---|---|---|---|---|---|")
        for k, v in res.items():
            e = v["errors"]
            print(f"| {k} | {g(e['stride_time_s'], 1000)} | {g(e['stance_pct'])} | {g(e['cadence_pct'], nd=2)} | "
                  f"{g(e['speed_pct'])} | {g(e['knee_flexion_range_deg'])} | {g(e['hip_flexion_range_deg'])} | "
                  f"{g(e['ankle_dorsiflexion_range_deg'])} | {g(e['found_share'], 100, 0)} / "
                  f"{g(e['missed_share'], 100, 0)} / {g(e['extra_share'], 100, 0)} | "
                  f"{g(e['take_stride_time_s'], 1000)}, {g(e['take_stance_pct'])} |")
        print("\n| set | clips | stride time (ms) | stance (points) | cadence (%) | strides found / missed / extra (%) "
              "| strike, foot off: found - truth (median ms) |")
        print("|---|---|---|---|---|---|---|")
        for k, v in res.items():
            for src in ("bandai", "cmu", "hdm05"):
                cs = [c for c in v["clips"] if dataset_of(c["clip"]) == src]
                if not cs:
                    continue
                e = {x: _mean([c["errors"][x] for c in cs]) for x in ("stride_time_s", "stance_pct", "cadence_pct")}
                e.update(stride_shares(cs))
                print(f"| {k} | {src} ({len(cs)}) | {g(e['stride_time_s'], 1000)} | {g(e['stance_pct'])} | "
                      f"{g(e['cadence_pct'], nd=2)} | {g(e['found_share'], 100, 0)} / {g(e['missed_share'], 100, 0)}"
                      f" / {g(e['extra_share'], 100, 0)} | {g(e['strike_median_ms'], nd=0)}, "
                      f"{g(e['off_median_ms'], nd=0)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
