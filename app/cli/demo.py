"""`imucap demo`: the product's main job with no hardware.

The demo is a capture like any other (``app.capture.demo``): a setup whose devices are
simulated, in a process of their own, worn by a simulated subject who follows the walk
calibration and then the activity; imucap opens their URLs through the real drivers and
transports (pty, CAN on loopback, HID socket, UDP), calibrates with the guided steps and
reconstructs the body at 20 Hz. The window and ``--headless`` build the very same session
from one spec; headless, it also scores the poses against the motion the simulator played.

    imucap demo [--motion walk|jog|squat|lunge|jump|arm_raises|stand | --file MOTIONFILE]
                [--sensors SITE,...] [--insoles] [--protocol xbus|bno08x-rvc|xsens-can|dualsense|mixed|...]
                [--seconds N] [--record FILE.h5] [--model SPEC] [--steps K] [--latency centred|low] [--headless --json]
                [--stream lsl,vmc,vrchat [--stream-host HOST]]

``--seconds N``: the activity after the calibration (default 20): the simulated subject's
clip, looped. Headless, the run ends N s after the calibration took effect (the guided
walk takes 10-15 s before it).

``--frames N`` (headless): after the N s, run on until N poses were made, for at most
20 times the seconds, so a script that needs N poses gets them on a busy machine too.

``--headless --json`` prints one JSON object: frames, fps, latency_p50_ms/p99_ms, per-site
packets/errors/gaps (``sites``), calibration_residual_deg, calibration_error_deg (the
recovered straps against the drawn ones; ``calibration_error_by_site`` the same per sensor),
ga_deg against the simulated motion, model, steps, the session's ``spec`` (and more, see
``DemoRun.result``; with ``--stream``, what each stream sent). Without weights for the default
model the floor baseline runs instead and the output says so loudly. The exit code is 1 when
the calibration failed or ``--frames`` was not reached.

``--stream lsl,vmc,vrchat`` also sends the live body to other programs (a lab recorder,
an avatar app, VRChat), to this machine unless ``--stream-host`` names another: see
docs/streams.md.
"""

from __future__ import annotations

import argparse
import json
import os
import sys

from app.capture.demo import DEFAULT_SENSORS, FRAMES_PATIENCE, PROTOCOL_CHOICES, DemoConfig, DemoRun
from app.capture.setup_file import DEFAULT_MODEL
from app.cli.window_args import add_window_arguments
from app.streams import add_stream_arguments, parse_stream_spec, sinks_from_args


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("demo", help="live reconstruction of a simulated suit (no hardware needed)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = p.add_mutually_exclusive_group()
    src.add_argument("--motion", default="walk",
                     help="generated activity: walk, jog, squat, lunge, jump, arm_raises, stand (default walk)")
    src.add_argument("--file", default=None, help="a motion file (BVH, ASF/AMC, AMASS .npz) as the activity")
    p.add_argument("--sensors", default=",".join(DEFAULT_SENSORS),
                   help=f"comma separated sites (default the paper's six: {','.join(DEFAULT_SENSORS)})")
    p.add_argument("--insoles", action="store_true", help="add pressure insoles (contacts)")
    p.add_argument("--protocol", default="xbus", choices=PROTOCOL_CHOICES, help="wire protocol of the sensors")
    p.add_argument("--seconds", type=float, default=20.0,
                   help="the activity after the calibration, in s (default 20; the clip loops in the window)")
    p.add_argument("--frames", type=int, default=0,
                   help="headless: after --seconds, run on until this many poses were made (a busy machine makes "
                        "fewer a second), for at most 20x --seconds; exit 1 if they were not reached")
    p.add_argument("--record", default=None, help="record the session to FILE.h5")
    p.add_argument("--model", default=DEFAULT_MODEL,
                   help="auto (default: the 21-frame file at a third of the compute, the full model where a thigh "
                        "is worn without its shank) | diffusion (the full model) | fast | regressor | floor | PATH.pt")
    p.add_argument("--steps", default=None, help="diffusion steps (default: the model's own)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-noise", action="store_true", help="ideal sensors (no noise, mounting or heading errors)")
    p.add_argument("--threads", type=int, default=1, help="torch threads for inference (0 = torch's default)")
    p.add_argument("--latency", default="centred", choices=("centred", "low"),
                   help="low: wait for no future sample (trailing acceleration filter, the hub holds the latest "
                        "sample; docs/latency.md); default centred, as the shipped model was trained")
    p.add_argument("--confidence", action="store_true",
                   help="each pose with a spread per segment (deg) and for the root (m): 0 where a sensor measured "
                        "it, larger where the model guessed; coloured in the window, in the recording, on LSL "
                        "(docs/confidence.md); costs ~40 %% more per frame")
    add_stream_arguments(p)
    p.add_argument("--headless", action="store_true", help="no window")
    p.add_argument("--json", action="store_true", help="headless: print one JSON object")
    add_window_arguments(p)
    p.set_defaults(func=run)


def config_from_args(args: argparse.Namespace) -> DemoConfig:
    from inference.body.skeleton import parse_sites

    parse_stream_spec(args.stream)  # a bad --stream fails here; the sinks open when the session starts
    return DemoConfig(
        motion=args.motion, file=args.file, sensors=tuple(parse_sites(args.sensors)), insoles=args.insoles,
        protocol=args.protocol, seconds=args.seconds, model=args.model, steps=args.steps, seed=args.seed,
        record=args.record, noise=not args.no_noise, headless=args.headless, threads=args.threads,
        latency=args.latency, confidence=args.confidence, frames=args.frames,
    )


def run(args: argparse.Namespace) -> int:
    from app.capture.demo import check_config

    if args.json and not args.headless:
        raise ValueError("--json needs --headless")
    if args.frames and not args.headless:
        raise ValueError("--frames needs --headless")
    if args.frames < 0:
        raise ValueError("--frames must be positive")
    cfg = config_from_args(args)
    check_config(cfg)
    if not cfg.headless:
        if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or os.environ.get("QT_QPA_PLATFORM")):
            # Qt would abort the process with a page about platform plugins; say what to do instead
            raise OSError("no display to open the window on: run `imucap demo --headless --json`, "
                          "or under a virtual display: `xvfb-run -a imucap demo`")
        from app.gui.main_window import run_gui

        cfg.streams = sinks_from_args(args)
        cfg.extra["args"] = args
        return run_gui(cfg)
    cfg.streams = sinks_from_args(args)
    try:
        demo = DemoRun(cfg)
    except BaseException:
        for s in cfg.streams:
            s.close()
        raise
    if demo.warning:
        print(demo.warning, file=sys.stderr)
    if not args.json:
        print(f"imucap demo: {cfg.motion if not cfg.file else cfg.file}, sensors {','.join(cfg.sensors)}"
              f"{' + insoles' if cfg.insoles else ''} over {cfg.protocol}, model {demo.model_label}, "
              f"{cfg.seconds:g} s after the walk calibration", file=sys.stderr)
    try:
        demo.start()
        reached = demo.run_for(cfg.seconds, cfg.frames)
    except RuntimeError as exc:  # the simulator or the pipeline stopped: one line, not a traceback
        print(f"imucap demo: {exc}", file=sys.stderr)
        return 1
    finally:
        demo.stop()
    res = demo.result()
    if not res["calibrated"]:
        print(f"imucap demo: the calibration did not finish: {res['calibration_status']}", file=sys.stderr)
    elif not reached:
        print(f"imucap demo: {res['frames']} of the {cfg.frames} poses asked were made in "
              f"{FRAMES_PATIENCE * cfg.seconds:g} s: the machine is too busy", file=sys.stderr)
    if args.json:
        print(json.dumps(res, default=str))
    else:
        for k, v in res.items():
            if k not in ("sites", "events", "spec"):
                print(f"{k}: {v}")
        for site, st in res["sites"].items():
            print(f"  {site}: {st}")
        if demo.warning:
            print(demo.warning)
    sys.stdout.flush()
    return 0 if reached and res["calibrated"] else 1


__all__ = ["register", "run"]
