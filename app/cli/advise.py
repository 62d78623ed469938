"""`imucap advise`: which sensors to wear for a task, ranked on motions like the user's.

    imucap advise --task whole|legs|arms|back|root [--max-sensors K] [--insoles]
                  [--data MOTIONS...] [--top N] [--json] [--plot PNG] [--exact]
                  [--frame-step S] [--beam B] [--seed S] [--threads N]

Every set of 1-3 sensors is scored, larger ones (up to --max-sensors) by a beam grown from
the best sets of the size below (inference/evaluation/advisor.py says why). The score is
the reconstruction error on the task's body parts: GA of its segments (whole: the 18
scored segments; legs: thighs, shanks, feet; arms: upper arms and forearms; back: spine
and neck) or, for root, the horizontal root error over 2 s (RE2, m), on signals
synthesized from the motions with the sensor noise model, as `imucap evaluate` does.

Without --data: one clip of each of the 11 motion classes of the held-out HDM05 actor dg
(the first take of each, ``DEFAULT_CLASSES``; 22.5 s) if the data is installed, else six generated
motions (walk, jog, squat, lunge, jump, arm raises). --data takes any motion file or folder
the loaders read (BVH, ASF/AMC, AMASS .npz).

Output: a ranked table, one set per line, best first: error, its standard deviation over
clips, number of sensors, the set (--top N lines, 0 = all); --json prints one object
instead. --plot PNG draws the best error against the number of sensors, one line per task
(all five tasks are searched for it). --exact scores with the live poser as shipped
(every frame, all steps, mirror averaging; much slower) instead of the fast per-frame
scoring. Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

# the first take of each motion class of HDM05 actor dg (never trained on)
DEFAULT_CLASSES = ("depositFloorR", "elbowToKnee1RepsLelbowStart", "grabHighR", "hopBothLegs1hops",
                   "jogLeftCircle4StepsRstart", "kickLFront1Reps", "lieDownFloor", "rotateArmsBothBackward1Reps",
                   "sneak2StepsLStart", "squat1Reps", "throwBasketball")
GENERATED = ("walk", "jog", "squat", "lunge", "jump", "arm_raises")


# inference.evaluation.advisor.TASKS (not imported here: every imucap command registers this one)
TASK_NAMES = ("whole", "legs", "arms", "back", "root")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("advise", help="rank sensor sets for a task (whole, legs, arms, back, root)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--task", required=True, choices=TASK_NAMES, help="the body parts that matter")
    p.add_argument("--max-sensors", type=int, default=3, help="largest set to consider (default 3)")
    p.add_argument("--insoles", action="store_true", help="every set also has pressure insoles (foot contacts)")
    p.add_argument("--data", nargs="+", default=None, metavar="MOTIONS",
                   help="motion files or folders (default: one take of each HDM05 dg class, see above)")
    p.add_argument("--limit", type=int, default=None, help="only the first N motion files (sorted)")
    p.add_argument("--top", type=int, default=15, help="lines of the table (default 15; 0 = every set)")
    p.add_argument("--beam", type=int, default=5, help="sets kept per size above 3 (default 5)")
    p.add_argument("--frame-step", type=int, default=4,
                   help="score every n-th frame for the angle tasks (default 4; the root needs every frame)")
    p.add_argument("--exact", action="store_true", help="score with the live poser as shipped (slow)")
    p.add_argument("--model", default="diffusion", help="diffusion (shipped) or a diffusion model file PATH.pt")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensor noise")
    p.add_argument("--threads", type=int, default=1, help="torch threads (0 = torch's default)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    p.add_argument("--plot", type=Path, default=None, metavar="PNG",
                   help="best error against the number of sensors, one line per task")
    p.add_argument("--no-progress", action="store_true", help="no progress lines on stderr")
    p.set_defaults(func=run)


def default_motions() -> tuple[list, str]:
    """The documented default motions and a line saying which they are."""
    from inference.evaluation.runner import load_motions
    from inference.training.data import data_root

    dg = data_root() / "hdm05" / "dg"
    files = [next(iter(sorted(dg.glob(f"HDM_dg_{c}_*"))), None) for c in DEFAULT_CLASSES] if dg.is_dir() else []
    files = [f for f in files if f is not None]
    if files:
        return load_motions(files), f"{len(files)} HDM05 dg clips, one per motion class ({dg})"
    from sim_devices.motions import generate

    motions = [replace(generate(kind, seconds=6.0, seed=k), name=f"generated_{kind}")
               for k, kind in enumerate(GENERATED)]
    return motions, f"{len(motions)} generated motions ({', '.join(GENERATED)}): no HDM05 dg data at {dg}"


def _summary(rows: list, task: str, paper: tuple[str, ...] | None) -> dict:
    """The top five of a ranking and where the paper's set for the task stands in it."""
    out = {"top": [{"sites": list(r.sites), "error": r.error(task), "spread": r.spread(task)} for r in rows[:5]]}
    at = [i for i, r in enumerate(rows) if paper and r.sites == tuple(paper)]
    if at:
        out["paper"] = {"sites": list(paper), "error": rows[at[0]].error(task), "rank": at[0] + 1}
    return out


def run(args: argparse.Namespace) -> int:
    from app.live.model_choice import load_model, set_torch_threads
    from inference.evaluation.advisor import (
        PAPER_SETS,
        TASKS,
        Advisor,
        advisor_clips,
        plot_best,
        progress_printer,
        ranked,
        table,
    )
    from inference.evaluation.runner import load_motions

    set_torch_threads(args.threads)
    if args.max_sensors < 1:
        raise ValueError("--max-sensors must be at least 1")
    t0 = time.time()
    if args.data:
        motions, source = load_motions(args.data, args.limit), f"motions under {', '.join(args.data)}"
    else:
        motions, source = default_motions()
        motions = motions[: args.limit] if args.limit else motions
    say = progress_printer() if not args.no_progress else None
    if say:
        say(f"{len(motions)} motion(s): {source}")
    model = load_model(args.model)[0]
    clips = advisor_clips(motions, insoles=args.insoles, seed=args.seed)
    adv = Advisor(model, clips, frame_step=args.frame_step, exact=args.exact, progress=say)
    rows = adv.search(args.task, args.max_sensors, beam=args.beam)
    curves = {}
    if args.plot is not None:
        for task in TASKS:
            adv.search(task, args.max_sensors, beam=args.beam)
            curves[task] = {k: r.error(task) for k, r in adv.best_by_size(task, args.max_sensors).items()}
        plot_best(curves, args.plot, title=f"best sensor set per size; {source}"[:110])
    seconds = round(time.time() - t0, 1)
    paper = PAPER_SETS.get(args.task)
    paper_row = adv.score([paper], [args.task])[0] if paper and len(paper) <= args.max_sensors else None
    unit = "m" if args.task == "root" else "deg"
    if args.json:
        top = rows[: args.top] if args.top else rows
        out = {
            "task": args.task, "unit": unit, "segments": TASKS[args.task], "max_sensors": args.max_sensors,
            "insoles": args.insoles, "motions": len(motions), "source": source, "exact": args.exact,
            "frame_step": args.frame_step, "sets_scored": len(rows), "seconds": seconds,
            "ranking": [{"sites": list(r.sites), "error": r.error(args.task), "spread": r.spread(args.task),
                         "sensors": len(r.sites)} for r in top],
            "best_by_size": {k: {"sites": list(r.sites), "error": r.error(args.task)}
                             for k, r in adv.best_by_size(args.task, args.max_sensors).items()},
            "paper": None if paper_row is None else {
                "sites": list(paper_row.sites), "error": paper_row.error(args.task),
                "rank": next(i + 1 for i, r in enumerate(rows) if r.sites == paper_row.sites)},
            **({"plot": str(args.plot), "curves": curves} if args.plot is not None else {}),
            # the other angle tasks come free with the sets scored for this one
            "other_tasks": {t: _summary(ranked(adv.scored.values(), t, args.max_sensors), t, PAPER_SETS.get(t))
                            for t in TASKS if t != args.task and TASKS[t] is not None and TASKS[args.task] is not None},
        }
        print(json.dumps(out))
    else:
        print(f"task {args.task} ({unit}; {', '.join(TASKS[args.task] or ('root, RE2',))}), {source}"
              f"{', insoles' if args.insoles else ''}; {len(rows)} sets scored in {seconds} s")
        print(table(rows, args.task, args.top or None))
        if paper_row is not None:
            rank = next(i + 1 for i, r in enumerate(rows) if r.sites == paper_row.sites)
            print(f"the paper's best 3 for {args.task}: {'+'.join(paper_row.sites)} "
                  f"{paper_row.error(args.task):.3g} {unit}, rank {rank}")
        if args.plot is not None:
            print(f"plot: {args.plot}")
    sys.stdout.flush()
    return 0


__all__ = ["register", "run", "DEFAULT_CLASSES", "default_motions"]
