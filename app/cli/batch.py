"""`imucap batch`: re-process a whole study and get one table.

    imucap batch INPUTS... --out DIR [--sensors SET ...] [--model M] [--steps K] [--seed S]
                 [--export EXT ...] [--report] [--workers N | --cluster tcp://HOST:PORT] [--json] [--no-progress]

INPUTS: folders (every .h5 below), globs, recordings, or a manifest CSV with a
``recording`` column (and any others: subject, condition; ``truth`` scores against a
simulator's truth file). Per recording: a replay with all its sensors and with each
``--sensors`` subset, exports of each (``--export bvh csv``), with ``--report`` a gait report of the
replay with all its sensors (``report.html`` and its figures in ``report.json``, as ``imucap report``),
and the table's rows; in ``DIR/<recording>/`` and ``DIR/summary.csv`` (+ ``summary.parquet``).

Running it again does only what is missing, failed or out of date (inputs, options,
imucap's version or the model file changed); ``--force`` redoes every recording, or those
matching a glob. A worker that dies under a recording fails that recording alone. Ctrl-C
stops handing out recordings (again: ends the running ones), writes the table of what is
done and exits 130; the next run finishes the job. The default runs one worker per core
here; ``--cluster`` sends the same tasks to a Dask scheduler (docs/batch.md). Needs the
``batch`` extra (``pip install 'imucap[batch]'``).
"""

from __future__ import annotations

import argparse
import fnmatch
import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

from app.cli.replay import ANSWER_LAG_HELP, KNEE_TWIST_HELP


def export_choices() -> tuple[str, ...]:
    """Every format `imucap export` writes, by extension without the dot (new exporters join by themselves)."""
    from app.export.formats import WRITERS

    return tuple(dict.fromkeys(ext.lstrip(".") for ext in WRITERS))


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("batch", help="re-process many recordings (subsets, model, exports) into one table",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", metavar="INPUT", help="folder, glob, recording (.h5) or manifest (.csv)")
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="where outputs and summary.csv go")
    p.add_argument("--sensors", action="append", default=[], metavar="SITE,SITE,...",
                   help="also replay with only these recorded sites (repeatable); all sensors always run")
    p.add_argument("--model", default="diffusion", help="diffusion | fast | regressor | floor | PATH.pt")
    p.add_argument("--steps", default=None, help="diffusion steps (default: the model's)")
    p.add_argument("--seed", type=int, default=None, help="inpainting noise seed (default: each session's)")
    p.add_argument("--latency", default=None, choices=("centred", "low"), help="default: as recorded")
    p.add_argument("--answer-lag", type=int, default=None, metavar="K",
                   help=ANSWER_LAG_HELP)
    p.add_argument("--knee-twist", type=float, default=None, metavar="S", help=KNEE_TWIST_HELP)
    p.add_argument("--export", action="append", default=[], metavar="EXT",
                   help="write each replay in this format too, by extension as imucap export: bvh, csv, h5, mot, ... "
                        "(repeatable)")
    p.add_argument("--no-held-out", action="store_true",
                   help="skip the held-out error of subsets (saves one full replay per recording)")
    p.add_argument("--report", action="store_true",
                   help="also a gait report per recording (DIR/<recording>/report.html and report.json, as imucap "
                        "report), of the replay with all the recorded sensors")
    p.add_argument("--workers", type=int, default=0, help="local worker processes (default: one per core)")
    p.add_argument("--cluster", default=None, metavar="tcp://HOST:PORT", help="a Dask distributed scheduler")
    p.add_argument("--force", nargs="?", const="*", default=None, metavar="GLOB",
                   help="redo recordings even when up to date: all, or those whose path (or path below the "
                        "inputs' common folder, or name) matches GLOB")
    p.add_argument("--json", action="store_true", help="print one JSON object at the end")
    p.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    p.set_defaults(func=run_batch)


def _options(args: argparse.Namespace):
    from app.batch.plan import Options
    from app.replay import ReplaySettings
    from inference.body.skeleton import parse_sites

    exports = []
    choices = export_choices()
    for e in args.export:
        for ext in e.split(","):
            ext = ext.strip().lower().lstrip(".")
            if ext not in choices:
                raise ValueError(f"--export {ext!r}: one of {', '.join(choices)}")
            if ext not in exports:
                exports.append(ext)
    subsets: list[tuple[str, ...] | None] = [None]
    for s in args.sensors:
        try:
            sites = tuple(parse_sites(s))
        except ValueError as exc:
            raise ValueError(f"--sensors {s!r}: {exc}") from None
        if sites not in subsets:
            subsets.append(sites)
    settings = ReplaySettings(model=args.model, steps=args.steps, seed=args.seed, latency=args.latency,
                              answer_lag=args.answer_lag, knee_twist=args.knee_twist)
    return Options(settings=settings, subsets=tuple(subsets), exports=tuple(exports), held_out=not args.no_held_out,
                   report=args.report)


class _Progress:
    """Recordings done, hours of motion per hour of wall time, time left (tqdm, stderr)."""

    def __init__(self, total: int, enabled: bool) -> None:
        from tqdm import tqdm

        self.bar = tqdm(total=total, unit="rec", disable=not enabled, file=sys.stderr, dynamic_ncols=True)
        self.t0 = time.perf_counter()
        self.motion_s = 0.0
        self.failed = 0

    def update(self, result: dict[str, Any]) -> None:
        if result["status"] == "done":
            self.motion_s += float(result.get("motion_s") or 0.0)
        self.failed += result["status"] == "failed"
        wall = time.perf_counter() - self.t0
        self.bar.set_postfix_str(f"{self.motion_s / max(wall, 1e-9):.1f} h motion/h, {self.failed} failed")
        self.bar.update(1)

    def close(self) -> None:
        self.bar.close()


def forced(pattern: str | None, recording: Path, root: Path) -> bool:
    """Whether ``--force pattern`` names ``recording`` (its path, its path below ``root``, or its name)."""
    if pattern is None:
        return False
    try:
        rel = recording.relative_to(root).as_posix()
    except ValueError:
        rel = recording.name
    return any(fnmatch.fnmatchcase(name, pattern) for name in (recording.as_posix(), rel, recording.name))


def run_batch(args: argparse.Namespace) -> int:
    from drivers.extras import need

    need("pyarrow", "imucap batch (its summary.parquet)")
    from app.batch.executors import DaskCluster, LocalPool
    from app.batch.plan import common_root, find_inputs, output_folder
    from app.batch.task import Task, skipped, up_to_date

    options = _options(args)
    inputs = find_inputs(args.inputs)
    from inference.poser.models import MODEL_NAMES

    if options.settings.model not in MODEL_NAMES and not Path(options.settings.model).is_file():
        raise FileNotFoundError(f"--model {options.settings.model}: no such file")
    args.out.mkdir(parents=True, exist_ok=True)
    root = common_root(inputs)
    fp = options.fingerprint()
    tasks = [Task(str(i.recording), str(output_folder(args.out, i, root)), options, fp, dict(i.meta),
                  str(i.truth) if i.truth else None, forced(args.force, i.recording, root)) for i in inputs]
    # what is already done for these options is known here, without starting a worker
    finished = {t.recording: skipped(t, done) for t in tasks if (done := up_to_date(t)) is not None}
    todo = [t for t in tasks if t.recording not in finished]
    runner = DaskCluster(args.cluster).connect() if args.cluster else LocalPool(args.workers or None)
    if not args.no_progress:
        print(f"batch: {len(tasks)} recording(s) ({len(finished)} up to date), {len(options.subsets)} sensor "
              f"set(s) each, on {runner.description}", file=sys.stderr, flush=True)
    interrupts = 0

    def on_sigint(signum, frame):  # noqa: ARG001
        nonlocal interrupts
        interrupts += 1
        runner.stop(abandon=interrupts > 1)
        print("\nbatch: stopping: no new recordings" + (", running ones ended" if interrupts > 1 else
              " (Ctrl-C again to end the running ones); run the same command to finish"), file=sys.stderr)

    # the handler stays until the end: a second Ctrl-C while the summary is written is counted,
    # and does not lose the summary to a KeyboardInterrupt
    old = signal.signal(signal.SIGINT, on_sigint)
    try:
        progress = _Progress(len(todo), not args.no_progress)
        results: dict[str, dict[str, Any]] = dict(finished)
        t0 = time.perf_counter()
        broke: str | None = None
        try:
            for res in runner.run(todo) if todo else ():
                results[res["recording"]] = res
                progress.update(res)
        except Exception as exc:  # noqa: BLE001 - the executor itself failed (a cluster gone): keep what is done
            broke = f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        finally:
            progress.close()
            runner.close()
        ordered = [results[t.recording] for t in tasks if t.recording in results]
        return _report(args, ordered, len(tasks), time.perf_counter() - t0, broke, interrupted=interrupts > 0)
    finally:
        # once stopped by Ctrl-C there is nothing left to stop: one more, pressed while the interpreter
        # shuts down (torch and the pool take ~0.3 s; Python puts SIGINT back to its default there), would
        # end the process by the signal instead of the 130 it returns
        signal.signal(signal.SIGINT, signal.SIG_IGN if interrupts else old)


def _report(args: argparse.Namespace, ordered: list[dict[str, Any]], n_tasks: int, wall: float, broke: str | None,
            interrupted: bool) -> int:
    """Write the summary of the recordings finished (in input order), print it, and give the exit code."""
    from app.batch.summary import write_summary

    written = write_summary(args.out, ordered)
    done = [r for r in ordered if r["status"] == "done"]
    motion_s = sum(float(r.get("motion_s") or 0.0) for r in done)
    summary = {
        "done": len(done), "skipped": sum(r["status"] == "skipped" for r in ordered),
        "failed": [{"recording": r["recording"], "reason": r["reason"]} for r in ordered if r["status"] == "failed"],
        "not_run": n_tasks - len(ordered), "recordings": n_tasks,
        "summary": [str(p) for p in written], "wall_s": round(wall, 2), "motion_s": round(motion_s, 2),
        "motion_hours_per_hour": round(motion_s / wall, 2) if done and wall > 0 else None,
        "cpu_s": round(sum(float(r.get("cpu_s") or 0.0) for r in done), 2),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{summary['done']} done, {summary['skipped']} up to date, {len(summary['failed'])} failed"
              + (f", {summary['not_run']} not run (stopped)" if summary["not_run"] else "")
              + f"; {written[0]}")
        for f in summary["failed"]:
            print(f"  failed: {f['recording']}: {f['reason']}")
    if broke is not None and not interrupted:
        print(f"imucap batch: error: stopped by {broke}; {written[0]} holds the {len(ordered)} recording(s) "
              "finished; run the same command to finish", file=sys.stderr)
        return 1
    return 130 if interrupted else 0
