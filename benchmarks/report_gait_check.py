"""The gait report's figures on synthesized walks against the truth's: does the report measure a walk?

    .venv/bin/python benchmarks/report_gait_check.py [--data DIR] [--clips 20] [--seconds 8]
        [--sets "6 sites" "pelvis+shanks" shanks "lower body"] [--json] [--write-expected] [--keep DIR]

``--sets "foot sensors"`` measures the foot sensors as the event source alone: the events from the
synthesized foot sensors' gyro (``app.report.feet.sensor_events``, typical noise with mounting
rotations, undone by the synthesis's own sensor-to-bone as a calibration would), the body from the
truth, so only the events differ from the truth's analysis (joint ranges are 0 by construction).

``--keep DIR`` stores each reconstruction (times, orientations, root, contact values) as
DIR/<set>/<clip>.npz and, when they are there already, reads them instead of reconstructing again: a
change to the event detection or the stride rules is measured in seconds on the same reconstructions.

Clips: the walking trials the comparison band keeps (``app.report.normal.trial_curves``: enough straight
walking strides at 0.8-1.8 m/s), half from CMU's takes (never seen by the shipped model), half from
Bandai's "walk" clips of every style (its training data); HDM05 has no walk among its takes here. Each
clip (its first ``--seconds``) is reconstructed from synthesized signals of each sensor set as
``imucap evaluate`` does (the live poser frame by frame, the sensor noise model), then analysed by the
report (``app.report.analysis.analyse``: events from the model's contacts at 20 Hz) and compared with
the same analysis of the truth (events from the heel and toe points' speed at 60 Hz).

Per clip and set: the absolute difference of the mean stride time (both feet), of the mean stance %,
of the cadence (%), of the walking speed (%) and of the mean per-stride range of hip, knee and ankle
flexion (both sides); and the event timing (each truth strike / off to the nearest one found, ms).
The table is the mean over the clips. ``--write-expected`` stores the means per set under
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
from app.report.events import MIN_SWING_S, foot_events, truth_contact_values
from app.report.feet import sensor_events
from app.report.normal import trial_curves
from inference.evaluation.runner import SIX, evaluate_motions, face_forward, resolve_models
from inference.loaders import find_motion_files, load_motion
from inference.poser.models import CONTACT_THRESHOLD
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
LIMITS = {"stride_time_s": 0.020, "stance_pct": 3.0, "cadence_pct": 2.0, "knee_flexion_range_deg": 5.0}


def pick_clips(root: Path, n: int, seconds: float) -> list:
    """n walking clips (cut to ``seconds``), half CMU, half Bandai, in file order."""
    cmu = find_motion_files([root / "cmu" / "asf_amc", root / "cmu" / "bvh_cgspeed"])
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
            if trial_curves(m) is not None:
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


def timing_ms(truth, found) -> float | None:
    """Mean |t_truth - nearest t_found| over the truth's events (ms)."""
    diffs = []
    for side in ("l", "r"):
        for kind in ("strikes", "offs"):
            a, b = getattr(truth[side], kind), getattr(found[side], kind)
            if len(a) and len(b):
                diffs += [float(np.min(np.abs(b - x))) for x in a]
    return 1000.0 * float(np.mean(diffs)) if diffs else None


def truth_analysis(motion):
    m = face_forward(motion)
    kin = kinematics(m, FPS_SIGNAL)
    t = np.arange(len(kin.rot)) / kin.fps
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


def reconstructions(motions, model_spec: str, label: str, keep: Path | None) -> list[tuple[str, dict]]:
    """(clip name, {t, rot, root, contact_prob}) per motion for one set, from ``keep`` when stored there."""
    folder = None if keep is None else keep / label.replace(" ", "_")
    if folder is not None and all((folder / f"{m.name}.npz").is_file() for m in motions):
        return [(m.name, dict(np.load(folder / f"{m.name}.npz"))) for m in motions]
    model = resolve_models([model_spec])[model_spec]
    _, results = evaluate_motions(motions, model, SETS[label], keep=True, desc=label)
    assert abs(1.0 / FPS_MODEL - STEP / FPS_SIGNAL) < 1e-9
    out = []
    for r in results:
        rec = r.recon
        d = {"t": np.arange(len(rec.rot)) * STEP / FPS_SIGNAL, "rot": rec.rot, "root": rec.root,
             "contact_prob": rec.contact_prob}
        if folder is not None:
            folder.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(folder / f"{r.name}.npz", **d)
        out.append((r.name, d))
    return out


def run(motions, sets: list[str], model_spec: str = "diffusion", done=None, keep: Path | None = None,
        threshold: float = CONTACT_THRESHOLD, min_swing_s: float = MIN_SWING_S) -> dict:
    """Every set over every motion; ``done(result so far)`` after each set. ``threshold`` / ``min_swing_s``:
    the model contacts' event detection (``app.report.events.foot_events``), to try others."""
    truths = {m.name: truth_analysis(m) for m in motions}
    out = {}
    for label in sets:
        clips = []
        if label == FEET:
            found = [(m.name, feet_analysis(m)) for m in motions]
        else:
            found = [(name, analyse(d["t"], d["rot"], d["root"], None, None, "model", events=foot_events(
                d["t"], d["contact_prob"], "model", threshold=threshold, min_swing_s=min_swing_s)))
                     for name, d in reconstructions(motions, model_spec, label, keep)]
        for name, an in found:
            tr = truths[name]
            ft, ff = clip_figures(tr), clip_figures(an)
            clips.append({"clip": name, "truth": ft, "found": ff, "errors": errors(ft, ff),
                          "timing_ms": timing_ms(tr.events, an.events)})
        keys = clips[0]["errors"].keys() if clips else []
        mean = {k: _mean([c["errors"][k] for c in clips]) for k in keys}
        mean["timing_ms"] = _mean([c["timing_ms"] for c in clips])
        passed = {k: (mean[k] is not None and mean[k] <= lim) for k, lim in LIMITS.items()}
        out[label] = {"sites": list(SETS.get(label, ("l_foot", "r_foot"))), "errors": mean, "passed": passed,
                      "clips": clips}
        if done is not None:
            done(out)
    return out


def write_expected(result: dict, model: str, n_clips: int, path: Path = EXPECTED_FILE) -> None:
    d = json.loads(path.read_text())
    d["synthesized"] = {
        "about": (f"Mean over {n_clips} synthesized walks (half CMU, half Bandai) of the absolute difference "
                  "between the report's figure from the reconstruction and from the truth; "
                  f"benchmarks/report_gait_check.py, model {model}. *_pct of cadence and speed are relative (%)."),
        "sets": {k: {"sites": v["sites"], "errors": {e: (None if x is None else round(x, 4))
                                                     for e, x in v["errors"].items()}} for k, v in result.items()
                 if k != FEET}}
    path.write_text(json.dumps(d, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--clips", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=8.0)
    ap.add_argument("--sets", nargs="+", default=["pelvis+shanks", "shanks", "6 sites", "lower body"],
                    choices=[*SETS, FEET])
    ap.add_argument("--model", default="diffusion")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--out", default=None, help="write the whole result (per clip) as JSON here")
    ap.add_argument("--write-expected", action="store_true")
    ap.add_argument("--contact-threshold", type=float, default=CONTACT_THRESHOLD,
                    help="the model contacts' threshold for the events (to try others)")
    ap.add_argument("--min-swing", type=float, default=MIN_SWING_S,
                    help="gaps in contact shorter than this are closed (s; to try others)")
    ap.add_argument("--keep", default=None, help="store / reuse the reconstructions here (module docstring)")
    args = ap.parse_args(argv)
    root = Path(args.data) if args.data else data_root()
    motions = pick_clips(root, args.clips, args.seconds)
    print(f"{len(motions)} clips: {', '.join(m.name for m in motions)}", file=sys.stderr)
    def done(res: dict) -> None:
        if args.out:
            Path(args.out).write_text(json.dumps(res, indent=1))

    res = run(motions, args.sets, args.model, done, None if args.keep is None else Path(args.keep),
              args.contact_threshold, args.min_swing)
    if args.write_expected:
        write_expected(res, args.model, len(motions))
    if args.json:
        print(json.dumps({k: {"errors": v["errors"], "passed": v["passed"]} for k, v in res.items()}))
    else:
        print("| set | stride time (ms) | stance (points) | cadence (%) | speed (%) | knee range (deg) | "
              "hip range (deg) | ankle range (deg) | event timing (ms) |")
        print("|---|---|---|---|---|---|---|---|---|")
        for k, v in res.items():
            e = v["errors"]
            g = lambda x, s=1.0, nd=1: "n/a" if x is None else f"{x * s:.{nd}f}"  # noqa: E731
            print(f"| {k} | {g(e['stride_time_s'], 1000)} | {g(e['stance_pct'])} | {g(e['cadence_pct'], nd=2)} | "
                  f"{g(e['speed_pct'])} | {g(e['knee_flexion_range_deg'])} | {g(e['hip_flexion_range_deg'])} | "
                  f"{g(e['ankle_dorsiflexion_range_deg'])} | {g(e['timing_ms'])} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
