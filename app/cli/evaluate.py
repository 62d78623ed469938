"""`imucap evaluate`: reconstruct motion files from synthesized sensor signals with the
live poser and score the result against the truth (GA, LA, JPE, jitter, RE2/5/10).

    imucap evaluate --data PATH|@SET... --sensors pelvis,head,l_wrist,r_wrist,l_shank,r_shank
                    [--insoles] [--steps K] [--model diffusion|regressor|floor|PATH.pt] [--against SPEC]
                    [--noise/--no-noise] [--inpaint-noise fresh|fixed|mean] [--limit N] [--seed S]
                    [--threads N] --json
                    [--report FILE.md] [--export-dir DIR]

Signals carry the sensor noise model (white noise, bias, orientation error; calibrated,
so no mounting/heading rotation) unless --no-noise. With --json, stdout holds exactly one
JSON object (clips, frames, ga_deg, la_deg, jpe_cm, jitter_ratio, re2_m, re5_m, re10_m,
model, sensors, insoles, steps, ...; and the three-point papers' mpjre_deg, mpjpe_cm,
mpjve_cms, jitter_1e2m_s3, hand/upper/lower/root_pe_cm: inference/metrics/vr.py); progress
goes to stderr. A metric that needs a longer clip than any given is null.

--data takes files, folders and the held-out sets by name (inference/training/splits.py,
``HELD_OUT_SETS``): @dg (HDM05 actor dg), @sad (Bandai's held-out style), @cmu-val (the CMU
validation subjects), read from $IMUCAP_DATA; a report's reproduce line keeps the name.
``segments`` gives each segment's GA (deg) over all frames.

@real scores real recordings instead (app/evaluation/real.py): every real log under
$IMUCAP_DATA (x-IMU3 log folders under ximu3/, the OpenSense Xsens MTw trial under
opensense/ with its sensor map) is imported as ``imucap import`` does, replayed as a replay of
the import poses (each frame four frames late: inference/poser/lag.py; --answer-lag 0 for the
live answer) with each standard sensor set (pelvis+shanks, shanks, pelvis+shanks+feet, pelvis+thighs) and with every
sensor, and each left-out segment is compared with what its own sensor measured: key
``held_out`` (log -> set -> ``deg`` per left-out site, ``mean_deg``, ``frames``; ``phases``:
walking / turning / standing / other -> ``seconds`` and ``deg``; ``constant_deg`` and
``dynamic_deg``: the mean rotation between reconstruction and sensor and the error left
after it), and with --against the same for that model under ``against.held_out`` and, per log,
set and left-out site, --model minus it with a percentile bootstrap interval over 2 s blocks
of the log (``against.held_out_differences``: one take's frames are not independent, so a
block of about two strides stands in for a clip). --sensors does not apply to it.

--against SPEC scores a second model on the same clips, sensors and noise, and adds
``against``: its figures and, for GA, LA, JPE and the papers' metrics, --model minus it with a percentile
bootstrap interval over clips (a lead whose interval holds 0 is not settled by the clips).

--report FILE.md also evaluates the standard table (6 sites, 6 sites + insoles, 3 sites
pelvis+wrists, 2 sites shanks) x (diffusion, regressor, floor) and writes it as markdown;
a model whose weights are missing gets a row saying so instead of stopping the table.
Below it, the diffusion model's GA minus each baseline's on the same clips, with a bootstrap
interval over clips, says which leads the clip sample settles (``comparisons`` in the JSON).
--export-dir DIR writes <clip>.recon.bvh and <clip>.truth.bvh (20 Hz, metres, Y up; see
app/export/bvh.py) for the main evaluation.

--confidence turns on the poser's per-segment spread (inference/poser/confidence.py) and
adds ``confidence``: Spearman between spread and error (per segment over frames, over all
(frame, segment) pairs, over the segment means) and how often the error falls inside the
50 / 90 % bands. --confidence-report FILE.md writes those tables for 6, 3 and 2 sites;
--fit-bands fits the band factors on the given clips (docs/confidence.md).

Clips share each model call (``--lanes``, inference/poser/batched.py); every clip's
reconstruction is its frame-by-frame one to float tolerance.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from pathlib import Path

from app.cli.replay import KNEE_TWIST_HELP
from app.cli.train import NOISE_MODES

REAL = "@real"


def data_paths(data: list) -> list:
    """--data with every ``@NAME`` replaced by the files of that held-out set (``@real`` is
    not motion files and is left out: ``real_held_out`` scores it)."""
    out: list = []
    for d in data:
        if str(d) == REAL:
            continue
        if str(d).startswith("@"):
            from inference.training.splits import held_out_files

            out += held_out_files(str(d))
        else:
            out.append(d)
    return out


def real_held_out(spec: str, seed: int, progress: bool, answer_lag: int | None = None,
                  knee_twist: float | None = None) -> dict:
    """``held_out`` of --data @real for the model ``spec`` (app/evaluation/real.py); an error
    naming the folder when it holds no real log."""
    from app.cli.importing import import_paths
    from app.evaluation.real import real_logs, score_logs
    from inference.training.data import data_root

    root = data_root()
    logs = real_logs(root)
    if not logs:
        raise FileNotFoundError(f"--data @real: no real log (x-IMU3 log folder under {root / 'ximu3'}, "
                                f"OpenSense trial folder under {root / 'opensense'})")

    def import_log(log, out):
        import_paths([log.path], out, mapping=dict(log.mapping), reconstruct=False)

    def say(msg: str) -> None:
        if progress:
            print(f"evaluate: {msg}", file=sys.stderr, flush=True)

    return score_logs(logs, import_log, spec, seed, progress=say, answer_lag=answer_lag, knee_twist=knee_twist)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("evaluate", help="score reconstructions of motion files from synthesized sensors",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", nargs="+", required=True, metavar="PATH",
                   help="motion files or folders (BVH, AMC, npz), or held-out sets by name: @dg, @sad, @cmu-val; "
                        "@real: the real logs under $IMUCAP_DATA, held-out scoring")
    p.add_argument("--sensors", default="pelvis,head,l_wrist,r_wrist,l_shank,r_shank",
                   help="comma separated sensor sites (default: the paper's 6)")
    p.add_argument("--insoles", action="store_true", help="also observe the 4 foot contacts (pressure insoles)")
    p.add_argument("--points", default="", metavar="POINTS",
                   help="tracked VR points too (head,l_hand,r_hand[,pelvis]), read as the live vmc-in chain reads "
                        "them: each stands for a model site (a controller for the wrist; "
                        "app/evaluation/tracked_points.py); --sensors none for the points alone")
    p.add_argument("--reach", action="store_true",
                   help="with --points: each tracked hand's arm reaches its controller after the model's answer "
                        "(inference/body/reach.py), as a VR avatar's arm IK does; needs the headset")
    p.add_argument("--steps", default=None,
                   help="diffusion steps: K (evenly spaced), 'paper' (10D list) or a list 1000,500,0; "
                        "default: the model's own")
    p.add_argument("--model", default="diffusion",
                   help="diffusion | fast | regressor | floor (shipped weights / baseline) or a model file PATH.pt")
    p.add_argument("--noise", action=argparse.BooleanOptionalAction, default=True,
                   help="sensor noise model on the synthesized signals (default on)")
    p.add_argument("--inpaint-noise", choices=NOISE_MODES, default=None,
                   help="diffusion only: how inpainting starts each frame (fresh draw, one fixed draw, or the "
                        "prior's mean); default: the model file's own")
    p.add_argument("--smoothing", action=argparse.BooleanOptionalAction, default=True,
                   help="the poser's 1-Euro output filters (root, unmeasured orientations); --no-smoothing "
                        "scores the raw per-frame reconstructions")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="average each denoiser answer with the answer for the mirror-image window "
                        "(default: what the model file says)")
    p.add_argument("--contact-detector", action=argparse.BooleanOptionalAction, default=True,
                   help="contacts for the root correction from the shank contact detector when both shanks are "
                        "measured (default); --no-contact-detector uses the model's own contact outputs")
    p.add_argument("--stride-scale", action=argparse.BooleanOptionalAction, default=True,
                   help="scale the root path by the shanks' inertial strides when both shanks are measured "
                        "(inference/poser/stride.py; default; docs/model.md 'Stride scaling')")
    p.add_argument("--pelvis-odometry", action=argparse.BooleanOptionalAction, default=True,
                   help="without both shanks, the root's walk from the pelvis sensor "
                        "(inference/poser/pelvis_odometry.py; default; docs/model.md 'Pelvis odometry'); "
                        "--no-pelvis-odometry uses the model's own root displacement corrected by its contacts")
    p.add_argument("--against", default=None, metavar="SPEC",
                   help="also score this model (same forms as --model) on the same clips and sensors, and "
                        "report --model minus it per metric with a bootstrap interval over clips")
    p.add_argument("--repair-truth", action="store_true",
                   help="put back feet the motion-capture solver broke (ankle past 90 deg) before synthesizing and "
                        "scoring (inference.plausibility.repair_feet); off by default so figures stay comparable")
    p.add_argument("--limit", type=int, default=None, help="only the first N motion files (sorted)")
    p.add_argument("--seed", type=int, default=0, help="seed of sensor noise and inpainting noise")
    p.add_argument("--answer-lag", type=int, default=None, metavar="K",
                   help="frames each pose waits for the sensors after it, as an import or replay may "
                        "(inference/poser/lag.py); default: the live 0 for motion files, an import's 4 for @real")
    p.add_argument("--knee-twist", type=float, default=None, metavar="S", help=KNEE_TWIST_HELP)
    p.add_argument("--latency", default="centred", choices=("centred", "low"),
                   help="low: accelerations through the trailing filter of the low-latency live mode, and the "
                        "default diffusion model becomes the one trained on it if installed (docs/latency.md)")
    # default 1: the live loop is one small model call per step, and with more threads two
    # evaluations at once spin in OpenMP barriers (~15x slower)
    p.add_argument("--threads", type=int, default=1, help="torch threads (0 = torch's default)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--report", type=Path, default=None, metavar="FILE.md",
                   help="also write the markdown table over the standard sensor sets x models")
    p.add_argument("--export-dir", type=Path, default=None, metavar="DIR",
                   help="write <clip>.recon.bvh and <clip>.truth.bvh per clip")
    p.add_argument("--confidence", action="store_true",
                   help="the per-segment spread on; report how well it predicts the error (docs/confidence.md)")
    p.add_argument("--confidence-report", type=Path, default=None, metavar="FILE.md",
                   help="with --confidence: write the calibration tables at 6, 3 and 2 sites")
    p.add_argument("--fit-bands", action="store_true",
                   help="with --confidence: fit the band factors on these clips at 6, 3 and 2 sites (bands_fit)")
    p.add_argument("--lanes", type=int, default=None,
                   help="clips sharing each model call (default 8; 1 = one clip after the other)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("_") or "clip"


def _steps_label(poser_steps: list[int], kind: str) -> int:
    """Model calls per frame: the step count for diffusion, 1 for the regressor, 0 for floor."""
    if kind == "diffusion":
        return len(poser_steps)
    return 1 if kind == "regressor" else 0


def _confidence(args: argparse.Namespace, result: dict, clips: list, sites: list[str], one) -> None:
    """The ``confidence`` key, and with --confidence-report / --fit-bands the three standard sets."""
    from inference.evaluation.confidence_report import CONFIDENCE_SETS, calibration, fit, markdown

    if result["kind"] != "diffusion":
        raise ValueError("--confidence needs a diffusion model (the spread comes from its inpaintings)")
    result["confidence"] = calibration(clips)
    if not (args.confidence_report or args.fit_bands):
        return
    runs = []
    for label, set_sites in CONFIDENCE_SETS:
        same = list(set_sites) == list(sites) and not args.insoles
        runs.append((label, clips if same else one(args.model, list(set_sites), args.insoles,
                                                     label=f"{args.model} {label}", confidence=True)[1]))
    if args.fit_bands:
        result["bands_fit"] = fit([c for _, c in runs])
    if args.confidence_report:
        rows = [(label, calibration(c)) for label, c in runs]
        command = (f"imucap evaluate --data {' '.join(map(str, args.data))}"
                   f"{' --limit ' + str(args.limit) if args.limit else ''} --confidence "
                   f"--confidence-report {args.confidence_report} --json")
        source = (f"{len(clips)} clip(s) from {', '.join(map(str, args.data))}, signals with the sensor noise model, "
                  f"seed {args.seed}, the live poser frame by frame")
        args.confidence_report.parent.mkdir(parents=True, exist_ok=True)
        args.confidence_report.write_text(markdown(rows, source, command))
        result["confidence_report"] = {"path": str(args.confidence_report), "rows": dict(rows)}


def run(args: argparse.Namespace) -> int:

    from app.live.model_choice import set_torch_threads
    from inference.body.skeleton import parse_sites
    from inference.evaluation.runner import (
        DEFAULT_LANES,
        REPORT_MODELS,
        REPORT_SETS,
        compare_rows,
        comparison_markdown,
        evaluate_motions,
        evaluation_noise,
        load_motions,
        report_markdown,
    )
    from inference.evaluation.subjects import per_subject, per_subject_markdown
    from inference.metrics.errors import VR_METRICS, paired_difference, segment_errors
    from inference.model.diffusion import parse_steps
    from inference.poser.models import default_steps, mirror_for, noise_mode_for, resolve_model
    from inference.signals.resample import FPS_MODEL

    set_torch_threads(args.threads)
    sites = [] if args.sensors.strip().lower() in ("", "none") else parse_sites(args.sensors)
    given, tracked_input, points = None, None, []
    if args.points:
        from app.evaluation.tracked_points import check_sites, parse_points, tracked_points_input, tracked_signals

        points = parse_points(args.points)
        check_sites(sites, points)
        if args.report or args.confidence_report or REAL in map(str, args.data):
            raise ValueError("--points scores the sets given; it takes no --report, --confidence-report or @real")
        given = tracked_signals(points)
        tracked_input = tracked_points_input(points) if "head" in points else None
        if args.reach and (tracked_input is None or not {"l_hand", "r_hand"} & set(points)):
            raise ValueError("--reach needs the headset and a controller in --points (head,l_hand,r_hand)")
    elif args.reach:
        raise ValueError("--reach needs --points: the controllers to reach for")
    elif not sites:
        raise ValueError("--sensors none needs --points: nothing would be observed")
    if args.limit is not None and args.limit < 1:
        raise ValueError("--limit must be at least 1")
    steps = parse_steps(args.steps) if args.steps is not None else None
    noise = evaluation_noise() if args.noise else None
    progress = not args.no_progress
    t0 = time.time()
    real = REAL in map(str, args.data)
    paths = data_paths(args.data)
    if real and not paths:
        if args.report or args.export_dir or args.confidence:
            raise ValueError("--data @real alone takes no --report, --export-dir or --confidence (no truth)")
        result = {"clips": 0, "frames": 0, **{k: None for k in ("ga_deg", "la_deg", "jpe_cm", "jitter_ratio",
                                                                "re2_m", "re5_m", "re10_m")},
                  "segments": None, "model": str(args.model), "seed": args.seed}
        if args.against is not None:
            result["against"] = {"model": str(args.against)}
        _score_real(result, args, progress)
        result["seconds"] = round(time.time() - t0, 2)
        _print_real(result, args.json)
        return 0
    motions = load_motions(paths, args.limit)
    print(f"evaluate: {len(motions)} clip(s) loaded", file=sys.stderr)
    repaired = None
    if args.repair_truth:
        from inference.metrics.plausibility import repair_feet

        fixes = [repair_feet(m) for m in motions]
        motions = [m for m, _ in fixes]
        repaired = {"clips": sum(r.changed > 0 for _, r in fixes), "twisted_frames": sum(r.twisted for _, r in fixes),
                    "interpolated_frames": sum(r.interpolated for _, r in fixes),
                    "left_broken_frames": sum(r.left_broken for _, r in fixes),
                    "source_frames": sum(m.n_frames for m in motions)}
        print(f"evaluate: feet repaired in {repaired['clips']} clip(s)", file=sys.stderr)

    models: dict[str, object] = {}

    def get_model(spec: str):
        if spec not in models:
            models[spec] = resolve_model(spec)
        return models[spec]

    if (args.confidence_report or args.fit_bands) and not args.confidence:
        raise ValueError("--confidence-report and --fit-bands need --confidence")
    lanes = DEFAULT_LANES if args.lanes is None else max(1, args.lanes)

    def one(spec: str, set_sites, insoles: bool, keep: bool = False, label: str = "", confidence: bool = False):
        from app.live.latency import model_spec_for, resolve_filter
        from inference.poser.models import model_for_sites

        # the live default ("auto") poses with the file it chooses for these sensors
        model = get_model(model_for_sites(model_spec_for(args.latency, spec), set_sites))
        causal, latency_warning = resolve_filter(args.latency, model)
        if latency_warning:
            print(f"evaluate: warning: {latency_warning}", file=sys.stderr)
        kind = "floor" if model is None else model.kind
        # a model with a position input reads the points as points, any other as the IMUs they imply
        reads_points = kind == "diffusion" and bool(getattr(model.config, "points", False))
        if reads_points and given is not None and tracked_input is None:
            raise ValueError(f"{spec} reads tracked positions against the headset: add head to --points")
        st = (steps if steps is not None else default_steps(model)) if kind == "diffusion" else []
        summary, clips = evaluate_motions(motions, model, set_sites, insoles, st or None, noise, args.seed,
                                          progress=progress, keep=keep or confidence, desc=f"{label or spec}",
                                          smoothing=args.smoothing,
                                          contact_detector="default" if args.contact_detector else None,
                                          inpaint_noise=args.inpaint_noise, mirror=args.mirror,
                                          stride_scale=args.stride_scale,
                                          pelvis_odometry="default" if args.pelvis_odometry else None,
                                          causal=causal, confidence=confidence and kind == "diffusion",
                                          answer_lag=args.answer_lag if kind == "diffusion" else None,
                                          knee_twist=args.knee_twist,
                                          lanes=lanes, given=None if reads_points else given,
                                          tracked=tracked_input if reads_points else None,
                                          reach=tracked_input if args.reach else None)
        summary.update({
            "model": str(spec), "kind": kind, "sensors": list(set_sites), "points": list(points),
            "points_read_as": ("positions" if reads_points else "imu") if points else None,
            "reach": bool(args.reach),
            "insoles": insoles, "steps": _steps_label(st, kind), "step_list": st if kind == "diffusion" else None,
            "noise": bool(noise is not None), "seed": args.seed, "smoothing": args.smoothing,
            "inpaint_noise": noise_mode_for(model, args.inpaint_noise) if kind == "diffusion" else None,
            "contact_detector": args.contact_detector and kind != "floor",
            "mirror": mirror_for(model, args.mirror),
            "stride_scale": args.stride_scale and kind != "floor",
            "pelvis_odometry": args.pelvis_odometry and kind != "floor",
            "latency_mode": args.latency, "acc_filter": "causal" if causal else "centred",
        })
        return summary, clips

    keep = args.export_dir is not None
    result, clips = one(args.model, sites, args.insoles, keep=keep, label=f"{args.model} {','.join(sites)}",
                        confidence=args.confidence)
    if args.confidence:
        _confidence(args, result, clips, sites, one)
    result["segments"] = segment_errors([c.metrics for c in clips])
    result["per_clip"] = [{"name": c.name, **c.metrics.summary()} for c in clips]
    result["per_subject"] = per_subject([c.metrics for c in clips])
    result["truth_repaired"] = repaired

    if args.against is not None:
        other, other_clips = one(args.against, sites, args.insoles, label=f"{args.against} {','.join(sites)}")
        mine, theirs = [c.metrics for c in clips], [c.metrics for c in other_clips]
        diffs = {m: paired_difference(mine, theirs, m, seed=args.seed)
                 for m in ("ga_deg", "la_deg", "jpe_cm", *VR_METRICS)}
        result["against"] = {
            **{k: other[k] for k in ("model", "kind", "steps", "mirror", "ga_deg", "la_deg", "jpe_cm",
                                     "jitter_ratio", "re2_m", "re5_m", "re10_m", *VR_METRICS, "jitter_true_1e2m_s3")},
            "differences": {m: d.as_dict() for m, d in diffs.items()},
            "segments": segment_errors(theirs),
            "per_clip": [{"name": c.name, **c.metrics.summary()} for c in other_clips],
            "per_subject": per_subject([c.metrics for c in other_clips]),
        }

    if args.export_dir is not None:
        from app.export.bvh import write_bvh

        out = args.export_dir
        out.mkdir(parents=True, exist_ok=True)
        for c in clips:
            base = _safe(c.name)
            write_bvh(out / f"{base}.recon.bvh", c.recon.rot, c.recon.root, c.inp.body, FPS_MODEL)
            write_bvh(out / f"{base}.truth.bvh", c.inp.rot, c.inp.root, c.inp.body, FPS_MODEL)
        result["export_dir"] = str(out)

    if args.report is not None:
        rows = []
        per_clip: dict[tuple[str, str], list] = {}
        for label, set_sites, insoles in REPORT_SETS:
            for spec in REPORT_MODELS:
                try:
                    s, set_clips = one(spec, list(set_sites), insoles, label=f"{spec} {label}")
                except FileNotFoundError as exc:
                    print(f"evaluate: report row {label} / {spec} skipped: {exc}", file=sys.stderr)
                    rows.append({"label": label, "model": f"{spec} (weights missing)", "steps": "-", "clips": 0,
                                 "frames": 0, **{k: None for k in ("ga_deg", "la_deg", "jpe_cm", "jitter_ratio",
                                                                    "re2_m", "re5_m", "re10_m")}})
                    continue
                rows.append({"label": label, **s})
                per_clip[label, spec] = [c.metrics for c in set_clips]
        comparisons = compare_rows(per_clip, seed=args.seed)
        subject_tables = {f"{spec} {label}": per_subject(cs) for (label, spec), cs in per_clip.items()
                          if spec != "floor" and label in ("6 sites", "3 sites (pelvis, wrists)", "2 sites (shanks)")}
        noise_txt = "with the sensor noise model" if noise is not None else "without sensor noise"
        text = report_markdown(rows) + ("\n" + comparison_markdown(comparisons) if comparisons else "") + (
            "\n" + per_subject_markdown(subject_tables) if subject_tables else "") + (
            f"\n{len(motions)} clip(s) from {', '.join(map(str, args.data))}; signals synthesized {noise_txt}; "
            f"seed {args.seed}; live poser frame by frame at 20 Hz; mirror averaging: "
            f"{', '.join(sorted({str(r['model']) for r in rows if r.get('mirror')})) or 'none'}"
            f"{'; broken feet in the truth repaired (--repair-truth)' if repaired else ''}.\n\n"
            f"Reproduce: `imucap evaluate --data {' '.join(map(str, args.data))}"
            f"{' --limit ' + str(args.limit) if args.limit else ''}{' --repair-truth' if repaired else ''}"
            f" --json --report {args.report}`\n"
        )
        args.report.parent.mkdir(parents=True, exist_ok=True)
        args.report.write_text(text)
        result["report"] = {"path": str(args.report), "rows": rows, "comparisons": comparisons}

    if real:
        _score_real(result, args, progress)
    result["seconds"] = round(time.time() - t0, 2)
    if args.json:
        print(json.dumps(result))
    else:
        def f(v, nd=2):
            return "n/a" if v is None else f"{v:.{nd}f}"

        print(f"{result['clips']} clips, {result['frames']} frames, model {result['model']}, "
              f"sensors {','.join(sites)}{' + insoles' if args.insoles else ''}, steps {result['steps']}")
        print(f"GA {f(result['ga_deg'], 1)} deg  LA {f(result['la_deg'], 1)} deg  JPE {f(result['jpe_cm'], 1)} cm  "
              f"jitter {f(result['jitter_ratio'])}  RE2 {f(result['re2_m'])} m  RE5 {f(result['re5_m'])} m  "
              f"RE10 {f(result['re10_m'])} m")
        if args.against is not None:
            a = result["against"]
            for m, d in a["differences"].items():
                print(f"{m} minus {a['model']}: {d['difference']:+.2f} "
                      f"[{d['low']:+.2f}, {d['high']:+.2f}] ({round(100 * d['confidence'])} % over clips; "
                      f"lower on {d['model_lower']} of {result['clips']} clips)")
    return 0


def _score_real(result: dict, args: argparse.Namespace, progress: bool) -> None:
    """``held_out`` of the real logs for --model, and with --against its own and, per log,
    set and left-out site, the difference with a block bootstrap interval
    (``held_out_differences``: app/evaluation/real.py, ``compare_held_out``)."""
    from app.evaluation.real import compare_held_out, drop_frame_errors

    mine = real_held_out(args.model, args.seed, progress, args.answer_lag, args.knee_twist)
    result["held_out"] = drop_frame_errors(mine)
    if args.against is not None:
        theirs = real_held_out(args.against, args.seed, progress, args.answer_lag, args.knee_twist)
        result["against"]["held_out"] = drop_frame_errors(theirs)
        result["against"]["held_out_differences"] = compare_held_out(mine, theirs, seed=args.seed)


def _real_cell(site: str, deg: float, other: dict | None, diff: dict | None) -> str:
    """One left-out site of the text output: its error, the other model's, and the difference's interval."""
    if not other:
        return f"{site} {deg}"
    ci = f", {diff['difference']:+.2f} [{diff['low']:+.2f}, {diff['high']:+.2f}]" if diff else ""
    return f"{site} {deg} (against {other['deg'][site]}{ci})"


def _print_real(result: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(result))
        return
    for name, sets in result["held_out"].items():
        for label, r in sets.items():
            other = result.get("against", {}).get("held_out", {}).get(name, {}).get(label)
            diff = result.get("against", {}).get("held_out_differences", {}).get(name, {}).get(label, {})
            cells = ", ".join(_real_cell(s, v, other, diff.get(s)) for s, v in r["deg"].items())
            print(f"{name} {label}: {cells}; mean {r['mean_deg']} deg over {r['frames']} frames")
            if "constant_deg" in r:
                print("  constant / dynamic: " + ", ".join(f"{s} {r['constant_deg'][s]} / {r['dynamic_deg'][s]}"
                                                           for s in r["deg"]))
            for phase, p in r.get("phases", {}).items():
                if p["seconds"]:
                    print(f"  {phase} ({p['seconds']} s): " + ", ".join(f"{s} {v}" for s, v in p["deg"].items()))


__all__ = ["register", "run", "real_held_out"]
