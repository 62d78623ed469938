"""`imucap replay` and `imucap export`: the researcher's workflow for recorded sessions
(`imucap demo --record FILE.h5`, the GUI's record button, or any ``Recorder``).

    imucap replay REC.h5 [--model diffusion|fast|auto|regressor|floor|PATH.pt] [--sensors SITE,...]
                  [--insoles/--no-insoles] [--steps K] [--seed S] [--every-frame] [--threads N] [--height M]
                  [--out FILE.{bvh,csv,h5,mot}]... [--json] [--no-progress]
                  [--stream lsl,vmc,vrchat [--stream-host HOST] [--stream-speed X]]
    imucap export REC.h5 --out FILE.{bvh,csv,h5,mot,c3d,trc} | NAME_orientations.sto [--out ...] [--height M] [--json]

``replay`` re-runs the poser over the recording's raw sensor stream with the recorded
calibration(s): another model or step count, or only some of the recorded sensors (the
others are inpainted, as with a smaller suit live). With no ``--model`` it poses with the
model the session ran (so with no options it gives back the live reconstruction); ``--model
diffusion`` re-poses a live capture with the full model, as an import and a report do.
Frames the live loop had no time to pose are left out as live left them (``--every-frame``
poses them too). Progress goes to stderr; ``--json`` prints one JSON object on stdout
(frames, duration_s, sensors, insoles, model, steps, vs_recorded_ga_deg = how far the
re-run is from the live reconstruction, outputs ...).
``--out`` writes the re-run poses (repeat it for several formats).

``--stream`` sends the replayed body to other programs as a live session would
(docs/streams.md), at the recording's own pace (``--stream-speed X``: X times real time,
0 = as fast as it goes), with the recorded markers.

``export`` writes the poses stored in the recording (the live reconstruction).

Formats by extension: .bvh (skeleton, metres, Y up), .csv (one row per 20 Hz frame),
.h5/.hdf5 (arrays + units and provenance), .mot (OpenSim joint angles, Rajagopal-model
coordinates), .c3d (virtual markers at the joint centres, foot strike/off events), .trc (the same
markers for OpenSim), NAME_orientations.sto (OpenSense's IMU orientations).
See app/export/formats.py and the export_*.py modules for the exact layouts.
The subject's body comes from the recording (bone offsets or height); ``--height``
overrides it.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from app.streams import add_stream_arguments, parse_stream_spec, sinks_from_args, stream_summary
from app.streams.pacing import Pacer

# --answer-lag of the commands that replay recordings (replay, batch)
ANSWER_LAG_HELP = ("frames each pose waits for the sensors after it (inference/poser/lag.py): 0 shows the newest "
                   "frame's answer, as live; default: as recorded (0 for a live capture, 4 for an imported log)")

# --knee-twist of the commands that pose (replay, batch, evaluate)
KNEE_TWIST_HELP = ("the most of the model's own thigh twist a thigh rebuilt from its shank keeps while the body turns "
                   "(inference/poser/knee_twist.py): 0 is the strict knee hinge; default: as recorded, else the "
                   "model file's (0.5)")

OUT_HELP = ("write the poses to FILE; format by extension: .bvh, .csv, .h5/.hdf5, .mot, .c3d, .trc, "
            "NAME_orientations.sto (OpenSense) (repeatable)")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("replay", help="re-run the poser over a recorded session (other model, sensor subset)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", type=Path, metavar="REC.h5", help="a session recording")
    p.add_argument("--model", default=None,
                   help="diffusion | fast | auto | regressor | floor | PATH.pt (default: the model the recording was "
                        "posed with)")
    p.add_argument("--sensors", default=None,
                   help="comma separated recorded sites to use (default: all the recording has)")
    p.add_argument("--insoles", action=argparse.BooleanOptionalAction, default=None,
                   help="use the insoles' contacts (default: as the session did)")
    p.add_argument("--steps", default=None,
                   help="diffusion steps: K, 'paper', '10D:K' or a list (default: the model's)")
    p.add_argument("--mirror", action=argparse.BooleanOptionalAction, default=None,
                   help="mirror averaging (default: as recorded, else the model file's own)")
    p.add_argument("--stride-scale", action=argparse.BooleanOptionalAction, default=None,
                   help="scale the root path by the shanks' inertial strides (default: as recorded; sessions "
                        "recorded before it existed ran without it)")
    p.add_argument("--pelvis-odometry", action=argparse.BooleanOptionalAction, default=None,
                   help="without both shanks, the root's walk from the pelvis sensor (default: as recorded; "
                        "sessions recorded before it existed ran without it)")
    p.add_argument("--held-out", action="store_true",
                   help="with --sensors a subset: replay again with every recorded sensor and report, per site "
                        "left out, the mean angle between its reconstructed segment and what its sensor measured")
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the inpainting noise (default: the session's; replays are reproducible)")
    p.add_argument("--confidence", action="store_true",
                   help="the per-segment spread with every pose (inference/poser/confidence.py): in --out's CSV "
                        "and HDF5, and spread_mean_deg in the JSON")
    p.add_argument("--answer-lag", type=int, default=None, metavar="K",
                   help=ANSWER_LAG_HELP)
    p.add_argument("--knee-twist", type=float, default=None, metavar="S", help=KNEE_TWIST_HELP)
    p.add_argument("--latency", default=None, choices=("centred", "low"),
                   help="acceleration filter of the replay: low = the trailing one of the low-latency mode "
                        "(docs/latency.md); default: as recorded, else centred")
    p.add_argument("--every-frame", action="store_true",
                   help="also pose the frames the live loop had no time for (default: leave them out, as live "
                        "did, so that the replay gives back the live reconstruction)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (0 = torch's default)")
    p.add_argument("--height", type=float, default=None, help="subject height in m (default: from the recording)")
    p.add_argument("--out", action="append", type=Path, default=[], metavar="FILE", help=OUT_HELP)
    p.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    p.add_argument("--truth", type=Path, metavar="TRUTH.npz",
                   help="score against the motion a simulated subject played (imucap devices simulate --truth): "
                        "ga_deg of this replay, recorded_ga_deg of the live reconstruction")
    p.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    add_stream_arguments(p, replay=True)
    p.set_defaults(func=run_replay)

    e = subparsers.add_parser("export", help="write a recording's reconstruction as BVH, CSV, HDF5, OpenSim .mot, "
                                                  "C3D, TRC or OpenSense .sto",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    e.add_argument("recording", type=Path, metavar="REC.h5", help="a session recording")
    e.add_argument("--out", action="append", type=Path, required=True, metavar="FILE", help=OUT_HELP)
    e.add_argument("--height", type=float, default=None, help="subject height in m (default: from the recording)")
    e.add_argument("--json", action="store_true", help="print one JSON summary on stdout")
    e.set_defaults(func=run_export)


# ---------------------------------------------------------------------------- helpers


def _open(path: Path, command: str):
    from app.recording import read_recording

    if not path.exists():
        raise FileNotFoundError(f"recording {path} not found")
    rec = read_recording(path)
    # whatever failed its checksum or was cut off is left out, never replayed as motion; say what
    for line in rec.damage:
        print(f"{command}: warning: {path}: {line}", file=sys.stderr, flush=True)
    return rec


def _check_outs(outs: list[Path]) -> None:
    from app.export.formats import check_export_path

    for o in outs:
        check_export_path(o)


def _emit(summary: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary))
    else:
        for k, v in summary.items():
            print(f"{k}: {v}")
    sys.stdout.flush()


class _Progress:
    """'replay: 40% (2400/6000 hub frames, 760 poses)' on stderr every 10%."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.next = 10

    def __call__(self, done: int, total: int, poses: int) -> None:
        if not self.enabled or total <= 0:
            return
        pct = 100 * done // total
        if pct >= self.next or done == total:
            print(f"replay: {pct}% ({done}/{total} hub frames, {poses} poses)", file=sys.stderr, flush=True)
            self.next = (pct // 10 + 1) * 10


# ---------------------------------------------------------------------------- commands


def _mean_spread(poses) -> dict[str, float] | None:
    """Per segment, the mean spread over the replayed poses (deg; 0 = measured)."""
    from inference.body.skeleton import SEGMENTS

    got = [p.pose.spread_deg for p in poses if p.pose.spread_deg is not None]
    if not got:
        return None
    mean = np.mean(got, axis=0)
    return {name: round(float(v), 2) for name, v in zip(SEGMENTS, mean)}


def run_replay(args: argparse.Namespace) -> int:
    from app.export.formats import body_for_recording, export_motion, motion_from_poses
    from app.live.model_choice import set_torch_threads
    from app.replay import (
        ReplaySettings,
        build_replay_poser,
        compare_to_recorded,
        held_out_errors,
        replay_recording,
        resolve_insoles,
        resolve_sensors,
    )

    _check_outs(args.out)
    streaming = bool(parse_stream_spec(args.stream))  # a bad --stream fails before any work
    pacer = Pacer(args.stream_speed) if streaming else None
    truth = None
    if args.truth is not None:
        from app.capture.simulate import read_truth

        truth = read_truth(args.truth)
    rec = _open(args.recording, "replay")
    sensors = resolve_sensors(rec, args.sensors)
    insoles = resolve_insoles(rec, args.insoles)
    body, note = body_for_recording(rec.metadata, args.height)
    if note:
        print(f"replay: warning: {note}", file=sys.stderr)
    set_torch_threads(args.threads)
    built = build_replay_poser(rec, ReplaySettings(
        model=args.model, steps=args.steps, seed=args.seed, mirror=args.mirror, stride_scale=args.stride_scale,
        pelvis_odometry=args.pelvis_odometry, confidence=args.confidence or None, latency=args.latency,
        answer_lag=args.answer_lag, knee_twist=args.knee_twist), body, sites=sensors)
    if built.warning:
        print(f"replay: warning: {built.warning}", file=sys.stderr)
    poser, causal, latency, label, steps = built.poser, built.causal, built.latency, built.label, built.steps
    if not args.no_progress:
        print(f"replay: {args.recording} ({rec.n_frames} hub frames, {len(rec.calibrations)} calibration(s)), "
              f"sensors {','.join(sensors)}{' + insoles' if insoles else ''}, model {label}, {steps} step(s)",
              file=sys.stderr, flush=True)
    sinks = sinks_from_args(args, clock_map=pacer.to_monotonic) if pacer is not None else []
    if sinks and not args.no_progress:
        pace = f"{args.stream_speed:g}x real time" if args.stream_speed > 0 else "as fast as it goes"
        print(f"replay: streaming {args.stream} to {args.stream_host}, {pace}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    res = replay_recording(rec, poser, sensors=sensors, insoles=insoles, progress=_Progress(not args.no_progress),
                           sinks=sinks, pace=pacer, causal=causal, every_frame=args.every_frame)
    held_out = None
    left_out = [s for s in rec.sites if s not in res.sensors]
    if args.held_out:
        if not left_out:
            raise ValueError("--held-out needs --sensors to leave out some of the recorded sensors "
                             f"({', '.join(rec.sites)})")
        full = built.fresh()
        held_out = held_out_errors(res.poses, replay_recording(rec, full, sensors=rec.sites, insoles=insoles,
                                                               causal=causal, every_frame=args.every_frame).poses,
                                  left_out)
    seconds = time.perf_counter() - t0
    outputs = []
    motion = None
    if args.out:
        motion = motion_from_poses(res.poses, body, rec, meta={
            "model": label, "steps": steps, "sensors": list(res.sensors), "insoles": res.insoles,
            "what": f"imucap replay (seed {poser.seed})", "step_list": list(poser.steps), "mirror": poser.mirror,
            "stride_scale": poser.stride is not None, "pelvis_odometry": poser.pelvis_odometry is not None})
        for o in args.out:
            outputs.append(str(export_motion(o, motion)))
            if not args.no_progress:
                print(f"replay: wrote {o}", file=sys.stderr)
    n = len(res.poses)
    span = (res.poses[-1].t - res.poses[0].t + 0.05) if n else 0.0
    summary: dict[str, Any] = {
        "recording": str(args.recording), "frames": n, "duration_s": round(span, 3),
        "sensors": list(res.sensors), "insoles": res.insoles, "model": label, "kind": poser.kind,
        "steps": steps, "step_list": list(poser.steps) if poser.kind == "diffusion" else None, "seed": poser.seed,
        "latency_mode": latency, "acc_filter": "causal" if causal else "centred",
        "mirror": poser.mirror, "stride_scale": poser.stride is not None,
        "pelvis_odometry": poser.pelvis_odometry is not None, "answer_lag": poser.answer_lag,
        "knee_twist": poser.knee_twist, "recorded_sensors": list(rec.sites),
        "recorded_model": rec.metadata.get("model"),
        "calibrations": res.calibrations_used, "hub_frames": res.hub_frames,
        "frames_filled": res.stats.get("frames_filled"), "poses_skipped": res.stats.get("poses_skipped"),
        "resampler_restarts": res.stats.get("resampler_restarts"),
        "step_p50_ms": res.stats.get("step_p50_ms"), "body_height_m": round(float(body.height), 3),
        **compare_to_recorded(rec, res.poses),
        **({"held_out": held_out} if held_out is not None else {}),
        "outputs": outputs, "seconds": round(seconds, 2),
        **({"spread_mean_deg": _mean_spread(res.poses)} if poser.confidence is not None else {}),
        **({"streams": stream_summary(sinks)} if sinks else {}),
    }
    if truth is not None:
        from app.replay import truth_errors

        R = np.stack([p.pose.rot for p in res.poses]) if res.poses else np.zeros((0, 24, 3, 3))
        summary.update(truth_errors(np.array([p.t for p in res.poses]), R, truth))
        live = truth_errors(rec.recon["t"], rec.recon["R"], truth)
        summary["recorded_ga_deg"] = live["ga_deg"]
    if note:
        summary["warning"] = note
    if rec.damage:
        summary["damage"] = rec.damage
    _emit(summary, args.json)
    return 0


def run_export(args: argparse.Namespace) -> int:
    from app.export.formats import body_for_recording, export_motion, motion_from_recording

    _check_outs(args.out)
    rec = _open(args.recording, "export")
    body, note = body_for_recording(rec.metadata, args.height)
    if note:
        print(f"export: warning: {note}", file=sys.stderr)
    motion = motion_from_recording(rec, body)
    outputs = [str(export_motion(o, motion)) for o in args.out]
    summary: dict[str, Any] = {
        "recording": str(args.recording), "frames": motion.n_frames, "duration_s": round(motion.duration, 3),
        "gaps": motion.gaps(), "model": motion.meta.get("model"), "sensors": motion.meta.get("sensors"),
        "insoles": motion.meta.get("insoles"), "body_height_m": round(float(body.height), 3), "outputs": outputs,
    }
    if note:
        summary["warning"] = note
    if rec.damage:
        summary["damage"] = rec.damage
    _emit(summary, args.json)
    return 0


__all__ = ["register", "run_replay", "run_export"]
