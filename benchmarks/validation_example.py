"""Make the committed example of ``imucap validate`` (docs/validation_example/): a
simulated subject walks a known motion (a lab's walking trial: standing still, then walking
with turns and a change of pace, ``sim_devices.motions`` kind ``walk_trial``; a steady walk
repeats itself every stride and its offset could not be told from one a stride away)
through the simulated suit and the live pipeline
(``imucap demo --headless --record``, 13 sensors, the shipped DiffusionPoser); an Xsens MVN
"lab system" records the same motion as an MVNX take, started by its own clock and facing
its own way; ``imucap validate`` then finds the offset and heading itself and scores the
recording re-run with three sensor sets against the take.

    .venv/bin/python benchmarks/validation_example.py [--out docs/validation_example] [--seconds 40]

Takes about as long as the session (real time) plus three replays.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

SUBSETS = ("pelvis,torso,head,l_upperarm,r_upperarm,l_wrist,r_wrist,l_thigh,r_thigh,l_shank,r_shank,l_foot,r_foot",
           "pelvis,head,l_wrist,r_wrist,l_shank,r_shank", "pelvis,l_shank,r_shank")
MVN_LABELS = {"pelvis": "Pelvis", "l_shank": "LeftLowerLeg", "r_shank": "RightLowerLeg"}
MOTION, SEED = "walk_trial", 21
CLIP_MARGIN_S = 5.0  # the clip outlasts the session, so the simulated suit never loops it back to the stand


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "validation_example")
    ap.add_argument("--seconds", type=float, default=40.0)
    ap.add_argument("--work", type=Path, default=None, help="folder for the recording and the take (default: temp)")
    ap.add_argument("--reuse", action="store_true", help="keep the recording and take already in --work")
    args = ap.parse_args()

    from inference.signals.synthesis import synthesize
    from sim_devices.motions import generate, write_amass_npz
    from sim_devices.xsens_export import write_mvnx

    work = args.work or Path(tempfile.mkdtemp(prefix="imucap-validate-"))
    work.mkdir(parents=True, exist_ok=True)
    clip, take, rec = work / "walk.npz", work / "walk-take.mvnx", work / "walk.h5"
    imucap = [sys.executable, "-m", "app.cli.main"]
    demo = ["demo", "--headless", "--file", str(clip), "--sensors", SUBSETS[0], "--seconds", f"{args.seconds:g}",
            "--record", str(rec), "--json"]
    if not (args.reuse and rec.exists() and take.exists()):
        motion = generate(MOTION, seconds=args.seconds + CLIP_MARGIN_S, seed=SEED)
        write_amass_npz(motion, clip)
        write_mvnx(synthesize(motion, None, rng=2, sites=tuple(MVN_LABELS)), take, MVN_LABELS, motion=motion)
        subprocess.run([*imucap, *demo], cwd=REPO, check=True)
    out = args.out.resolve()
    shown = out.relative_to(REPO) if out.is_relative_to(REPO) else out
    cmd = ["validate", str(rec), "--reference", str(take)]
    for s in SUBSETS:
        cmd += ["--sensors", s]
    subprocess.run([*imucap, *cmd, "--report", str(shown), "--json"], cwd=REPO, check=True, stdout=subprocess.DEVNULL)
    # the report names the command that made it; the work folder's paths mean nothing elsewhere
    made = ("The recording: a simulated subject walks `walk.npz` (sim_devices.motions.generate("
            f"'{MOTION}', seconds={args.seconds + CLIP_MARGIN_S:g}, seed={SEED}): standing still for 3 s, then "
            "walking with 180 deg turns and a brisker second half) through the simulated suit and the live "
            "pipeline with the shipped model; the reference: the same motion as an Xsens MVN take on its own "
            "clock and heading. All of it made by `benchmarks/validation_example.py`; the session:\n\n    imucap "
            + " ".join(demo).replace(str(work) + "/", "") + "\n\n")
    for f in (out / "report.md", out / "validation.json"):
        text = f.read_text().replace(str(work.resolve()) + "/", "").replace(str(work) + "/", "")
        if f.suffix == ".md":
            text = text.replace("Made with:", made + "The report, made with:", 1)
        f.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
