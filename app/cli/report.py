"""`imucap report`: a recorded walk as a gait report a clinic can file.

    imucap report REC.h5 [--compare EARLIER.h5] --out REPORT.html [--pdf] [--json]

From the recording's reconstruction (a live session's, an import's or a replay's): the gait events
(foot strike, foot off) from the insoles when worn, else the model's foot contacts, debounced; each
stride's time, stance, swing, double support, length and speed, turns and standing left out and
counted; per side mean +- SD and the symmetry index; hip, knee, ankle and pelvis angles over the gait
cycle against a comparison band from motion capture walks (not clinical normative data); which segments
were measured and which inferred, with the model's spread and the sensor set's expected error on real
walks. ``--compare`` puts an earlier session beside it and marks the differences larger than the two
sensor sets' expected errors. The HTML is one self-contained file; ``--pdf`` also prints it to
REPORT.pdf with headless Chromium (Debian's ``chromium``).

``--json`` prints one object: ``sensors``, ``strides`` (l, r: count), ``cadence_spm``,
``stride_time_s`` (l, r: mean, sd), ``stance_pct`` (l, r), ``knee_range_deg`` (l, r), ``speed_mps``,
and more (``parameters``, ``ranges``, ``excluded``, ``confidence``, ``session``, ``compare``). A
recording without walking gives 0 strides and null figures. docs/report.md.

A live capture (and ``--compare``'s) is posed again first with the full model, each pose shown as the
window four frames later answered it, as an import is (a replay with the session's other settings, about
0.4 of the recording's length on two cores): a live capture's poses had to be the newest frame's and came
from the live default, chosen for its compute; a report's need neither. On the synthesized walks of
docs/report.md that takes the knee range's error with pelvis + shanks from 13.1 to 5.9 deg, the ankle's and
the timing's unchanged. ``--answer-lag K`` poses again K frames late (an error if the recording cannot be
replayed), ``--answer-lag 0`` reads the recording's own poses; ``posed`` in the JSON says which it read.
"""

from __future__ import annotations

import argparse
import json
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("report", help="a gait report of a recorded walk (HTML, PDF)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("recording", metavar="REC.h5", help="a session recording with its reconstruction")
    p.add_argument("--compare", default=None, metavar="EARLIER.h5", help="an earlier session to put beside it")
    p.add_argument("--out", required=True, metavar="REPORT.html", help="the report to write")
    p.add_argument("--pdf", action="store_true", help="also REPORT.pdf (headless chromium)")
    p.add_argument("--json", action="store_true", help="print the figures as one JSON object")
    p.add_argument("--answer-lag", type=int, default=None, metavar="K",
                   help="pose the recording again first with the full model, each pose K frames late (0: read "
                        "the recording's own poses); default: a live capture is posed again 4 frames late, as an "
                        "import is, and a recording that cannot be replayed is read on its own poses")
    p.set_defaults(func=run_report)


def run_report(args: argparse.Namespace) -> int:
    from app.report import make_report
    from app.report.build import poses_to_report

    said = lambda m: print(f"report: {m}", file=sys.stderr)  # noqa: E731
    rec, posed = poses_to_report(args.recording, args.answer_lag, said)
    earlier = None if args.compare is None else poses_to_report(args.compare, args.answer_lag, said)[0]
    rep = make_report(rec, args.out, compare_with=earlier, pdf=args.pdf)
    s = rep.summary
    s["posed"] = posed
    if args.json:
        print(json.dumps(s))
    else:
        n = s["strides"]
        if n["l"] + n["r"] == 0:
            print(f"report: no walking found in {args.recording}: 0 strides")
        else:
            print(f"report: {n['l']} + {n['r']} walking strides, cadence {s['cadence_spm']:.1f} steps/min, "
                  f"speed {s['speed_mps']:.2f} m/s")
        print(f"report: wrote {rep.html}" + (f" and {rep.pdf}" if rep.pdf else ""))
    for w in s["session"]["warnings"]:
        print(f"report: warning: {w}", file=sys.stderr)
    return 0
