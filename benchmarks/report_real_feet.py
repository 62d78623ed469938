"""The report's strides on real logs against the foot sensors' stillness (app/report/feet.py).

    imucap import ../shared/data/ximu3/logged_lower_body --out ximu3.h5
    imucap import ../shared/data/opensense/xsens_mtw_walk --out opensense.h5 --map 00B42268=torso ...  (OPENSENSE_MAP)
    .venv/bin/python benchmarks/report_real_feet.py ximu3.h5 opensense.h5 [--events model "foot sensors"]

Per recording and foot: the steps the foot sensor saw (still periods between two moves), how many of
them a stance the report found covers, the stances found, those with no still foot in them, and the
found foot strike's lead before the foot goes still / foot off's lag after it moves (median, ms), and the
walking strides. ``--events`` gives the event sources to table (default: what the report chooses).
"""

from __future__ import annotations

import argparse
import sys

from app.recording import read_recording
from app.report.analysis import analyse_recording
from app.report.feet import feet_check


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("recordings", nargs="+")
    ap.add_argument("--events", nargs="+", default=[None], choices=[None, "model", "foot sensors", "insoles"])
    args = ap.parse_args(argv)
    print("| recording | events from | foot | steps (foot sensor) | covered by a stance found | stances found | "
          "found with no still foot | strike before still (ms) | off after still (ms) | walking strides |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for p in args.recordings:
        rec = read_recording(p)
        for source in args.events:
            an = analyse_recording(rec, source)
            check = feet_check(rec, an.events) or {}
            for side, c in check.items():
                print(f"| {rec.path.name} | {an.source} | {side} | {c['still_steps']} | {c['covered']} | "
                      f"{c['found_stances']} | {c['found_without_still']} | {c['strike_lead_ms']} | "
                      f"{c['off_lag_ms']} | {an.summary.count(side)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
