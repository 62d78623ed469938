"""The gait report's expected errors on real recordings, from the real logs' held-out scoring.

    imucap evaluate --data @real --json > late.json
    imucap evaluate --data @real --answer-lag 0 --model auto --json > live.json   # live poses: the live default
    .venv/bin/python benchmarks/report_expected_real.py late.json [--write]
    .venv/bin/python benchmarks/report_expected_real.py live.json --live [--write]

Writes the ``real_late`` section of app/report/expected_error.json (``--live``: ``real``; with ``--write``,
else prints it): per standard sensor set, each left-out segment's orientation error (deg) in each real log's
walking phase (``held_out.<log>.<set>.phases.walking.deg``), posed as the JSON was made: late as an import
poses (``imucap evaluate --data @real``'s default) or live. A report shows the section that matches its
poses beside each inferred joint (``app.report.confidence.expected_section``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from app.report.confidence import EXPECTED_FILE

ABOUT = ("Orientation error (deg) of each segment left out of the sensor set, on the real logs' walking phases, "
         "posed {how}: imucap evaluate --data @real{arg} --json, "
         "held_out.<log>.<set>.phases.walking.deg, model {model}; written by "
         "benchmarks/report_expected_real.py; docs/real_signals.md, 'Per phase, constant and dynamic'. The truth is "
         "the left-out sensor itself, so its own mounting error counts in.")


def real_section(result: dict, live: bool = False) -> dict:
    held = result["held_out"]
    logs = list(held)
    sets: dict[str, dict] = {}
    for log in logs:
        for label, r in held[log].items():
            entry = sets.setdefault(label, {"sites": list(r["sensors"]), "segments": {}})
            walking = (r.get("phases") or {}).get("walking", {}).get("deg", {})
            for seg in r["deg"]:
                entry["segments"].setdefault(seg, [None] * len(logs))
                v = walking.get(seg)
                entry["segments"][seg][logs.index(log)] = None if v is None else round(float(v), 1)
    for entry in sets.values():
        entry["segments"] = dict(sorted(entry["segments"].items()))
    model = str(result.get("model") or "diffusion")
    named = {"diffusion": "diffusion (inference/weights/diffusionposer.pt)",
             "auto": "auto (the live default: diffusionposer_fast.pt, diffusionposer.pt with pelvis + thighs)"}
    about = ABOUT.format(how="live" if live else "as imports pose them (four frames late)",
                         arg=(" --answer-lag 0" if live else "")
                         + ("" if model == "diffusion" else f" --model {model}"),
                         model=named.get(model, model))
    return {"about": about, "logs": logs, "sets": sets}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("result", help="the JSON of imucap evaluate --data @real --json")
    ap.add_argument("--live", action="store_true", help="the JSON was made with --answer-lag 0: the live section")
    ap.add_argument("--write", action="store_true", help=f"write it into {EXPECTED_FILE}")
    args = ap.parse_args(argv)
    section = real_section(json.loads(Path(args.result).read_text()), args.live)
    if args.write:
        d = json.loads(EXPECTED_FILE.read_text())
        d["real" if args.live else "real_late"] = section
        EXPECTED_FILE.write_text(json.dumps(d, indent=1) + "\n")
    else:
        json.dump(section, sys.stdout, indent=1)
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
