"""`imucap validate`: a recording's reconstruction against a lab's reference system.

    imucap validate REC.h5 --reference FILE [--static FILE] [--sensors SET ...] [--json] [--report DIR]
                    [--model M] [--steps K] [--seed S] [--offset S] [--heading DEG]
                    [--height M] [--threads N]

The reference: an MVN BVH or MVNX take, a BVH from another system (mapped onto our
skeleton by joint names; the mapping is printed), C3D or TRC markers or joint centres,
an OpenSim .mot/.sto (Rajagopal coordinate names), or imucap's truth .npz. The recording
is re-run once per ``--sensors`` set (default: every recorded sensor); the time offset
comes from correlating joint angles (a warning names the candidates when the best peak
is low or another is nearly as high, e.g. one stride away on a steady walk), the heading
is one yaw for the trial, and both can be given (``--offset``, ``--heading``). ``--json``
prints one object (time_offset_s, heading_deg, subsets, baseline, warnings); ``--report
DIR`` writes report.md with plots and validation.json. docs/validation.md.
"""

from __future__ import annotations

import argparse
import json
import shlex
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("validate", help="score a recording against a lab's reference (BVH, MVNX, C3D, TRC, "
                                               ".mot, truth .npz)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", metavar="REC.h5", help="a session recording")
    p.add_argument("--reference", required=True, metavar="FILE",
                   help="the other system's answer: .bvh, .mvnx, .c3d, .trc, .mot/.sto or a truth .npz")
    p.add_argument("--static", default=None, metavar="FILE",
                   help="a static trial (C3D/TRC) of the reference's marker set, for landmarks the trial lacks "
                        "(e.g. medial knee and ankle markers removed after calibration)")
    p.add_argument("--sensors", action="append", default=[], metavar="SET",
                   help="comma separated recorded sites to re-run with (repeatable; default: all recorded)")
    p.add_argument("--model", default="diffusion",
                   help="diffusion | fast | regressor | floor | PATH.pt (default diffusion)")
    p.add_argument("--steps", default=None, help="diffusion steps (default: as recorded)")
    p.add_argument("--seed", type=int, default=None, help="inpainting seed (default: the session's)")
    p.add_argument("--offset", "--time-offset", dest="time_offset", type=float, default=None, metavar="S",
                   help="reference clock minus the recording's (s): skip the search (e.g. one of the candidates "
                        "a warning names)")
    p.add_argument("--heading", type=float, default=None, metavar="DEG",
                   help="yaw turning the recording's world onto the reference's: skip the search")
    p.add_argument("--height", type=float, default=None, help="subject height in m (default: from the recording)")
    p.add_argument("--threads", type=int, default=1, help="torch threads (0 = torch's default)")
    p.add_argument("--report", default=None, metavar="DIR", help="write report.md, plots and validation.json here")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.set_defaults(func=run_validate)


def run_validate(args: argparse.Namespace) -> int:
    from app.live.model_choice import set_torch_threads
    from app.validate.run import validate

    set_torch_threads(args.threads)

    def progress(msg: str) -> None:
        print(f"validate: {msg}", file=sys.stderr, flush=True)

    v = validate(args.recording, args.reference, args.sensors or [None], model=args.model, steps=args.steps,
                 seed=args.seed, time_offset=args.time_offset, heading_deg=args.heading, height=args.height,
                 progress=progress, static=args.static)
    for line in v.reference.mapping:
        print(f"validate: mapping {line}", file=sys.stderr)
    for w in v.alignment.warnings:
        print(f"validate: warning: {w}", file=sys.stderr)
    s = v.summary()
    if args.report:
        from app.validate.report import write_report

        md = write_report(v, args.report, "imucap " + " ".join(shlex.quote(a) for a in sys.argv[1:]))
        s["report"] = str(md)
        progress(f"wrote {md}")
    if args.json:
        print(json.dumps(s))
    else:
        print(f"time offset {s['time_offset_s']:+.4f} s"
              + ("" if s["time_offset_correlation"] is None else f" (correlation {s['time_offset_correlation']:.3f})")
              + f", heading {s['heading_deg']:.2f} deg")
        for r in [*s["subsets"], s["baseline"]]:
            name = ",".join(r["sensors"]) or "baseline (standing)"
            joints = ", ".join(f"{j} {d['rms_deg']:.1f}" for j, d in r["joints"].items())
            mean = "n/a" if r["mean_deg"] is None else f"{r['mean_deg']:.2f}"
            print(f"{name}: segments {mean} deg; joint RMS (deg): {joints}")
    sys.stdout.flush()
    return 0


__all__ = ["register", "run_validate"]
