"""One recording of a batch, in a worker: replay per sensor subset, exports, summary rows.

Safe to lose at any point and to run twice:
- every output is written under a temporary name in its folder and renamed into place,
  so a file under its final name is always whole;
- after each subset's outputs are in place, one line goes to the folder's journal
  (``.journal.jsonl``: the subset, its row, its files, the options' fingerprint); a task
  that runs again (a worker was lost, Ctrl-C, a crash) takes those subsets from the
  journal and writes none of their files again;
- ``result.json``, written last, marks the recording done for these options (imucap's
  version and the model file's content among them) and this input: a later run skips it
  while they stay the same, unless told to ``force`` it (then journal and result go first);
- ``.running`` (the worker's pid and host) is in the folder while a worker re-runs it.

A recording that cannot be re-run (damaged, never calibrated, unreadable) is one failed
result with its reason in one line; it writes no result, so the next run tries it again.
A worker that dies under a recording (a native crash, killed) fails that recording alone
(``crashed``: the executor says so on the worker's behalf).
"""

from __future__ import annotations

import glob
import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.batch.plan import Options, subset_label

RESULT = "result.json"
JOURNAL = ".journal.jsonl"
RUNNING = ".running"
REPORT = "report.html"  # with ``report.json``, its figures (``imucap report --json``)

_MODELS: dict[str, Any] = {}  # per worker process: a model is loaded once, not per recording


@dataclass(frozen=True)
class Task:
    recording: str
    folder: str
    options: Options
    fingerprint: str
    meta: dict[str, str] = field(default_factory=dict)
    truth: str | None = None
    force: bool = False  # redo it even when an earlier result or journal holds


def input_stamp(path: str | Path) -> list[int]:
    st = Path(path).stat()
    return [st.st_size, st.st_mtime_ns]


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def up_to_date(task: Task) -> dict[str, Any] | None:
    """The earlier result of ``task`` when it still holds: done (a failure is tried again),
    same options, same input (size and modification time), every file it lists present and
    no older than the input; never for a task told to ``force``."""
    folder = Path(task.folder)
    res = None if task.force else _read_json(folder / RESULT)
    if not res or res.get("fingerprint") != task.fingerprint or res.get("status") != "done":
        return None
    try:
        if res.get("stamp") != input_stamp(task.recording):
            return None
        made = Path(folder / RESULT).stat().st_mtime_ns
    except OSError:
        return None
    if made < input_stamp(task.recording)[1]:
        return None
    if not all((folder / f).is_file() for f in res.get("files", [])):
        return None
    return res


def _journal(folder: Path, fingerprint: str, stamp: list[int]) -> dict[str, dict[str, Any]]:
    """Subsets already done for these options and this input (a line cut short by a lost
    worker is ignored: its subset is simply done again)."""
    done: dict[str, dict[str, Any]] = {}
    try:
        lines = (folder / JOURNAL).read_text(encoding="utf-8").splitlines()
    except OSError:
        return done
    for line in lines:
        try:
            e = json.loads(line)
        except ValueError:
            continue
        if e.get("fingerprint") == fingerprint and e.get("stamp") == stamp and \
                all((folder / f).is_file() for f in e.get("files", [])):
            done[e["subset"]] = e
    return done


def _append(folder: Path, entry: dict[str, Any]) -> None:
    with open(folder / JOURNAL, "a", encoding="utf-8") as f:
        f.write(json.dumps(entry) + "\n")
        f.flush()
        os.fsync(f.fileno())


def write_atomic(path: Path, write) -> Path:
    """``write(tmp)`` to a temporary name beside ``path`` (same extension, so a writer that
    picks its format by extension still does), then rename it into place. Files the writer
    puts beside it (``tmp.json``: a BVH's time origin) follow it to ``path``'s name first,
    so the main file, renamed last, is never there without them."""
    tmp = path.with_name(f".{path.stem}.tmp-{os.getpid()}{path.suffix}")
    try:
        write(tmp)
        for side in tmp.parent.glob(f"{glob.escape(tmp.name)}.*"):
            os.replace(side, path.with_name(path.name + side.name[len(tmp.name):]))
        os.replace(tmp, path)
    finally:
        for left in [tmp, *tmp.parent.glob(f"{glob.escape(tmp.name)}.*")]:
            if left.exists():
                left.unlink()
    return path


def _json_atomic(path: Path, obj: dict[str, Any]) -> None:
    def write(tmp: Path) -> None:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(obj, f, indent=1)
            f.flush()
            os.fsync(f.fileno())

    write_atomic(path, write)


def _model(spec: str, latency: str) -> Any:
    """The model for ``spec`` in latency mode ``latency``, loaded once per worker."""
    from app.live.latency import model_spec_for
    from app.live.model_choice import load_model

    spec = model_spec_for(latency, spec)
    if spec not in _MODELS:
        _MODELS[spec] = load_model(spec)[0]
    return _MODELS[spec]


def _replay_poser(rec: Any, settings: Any, body: Any, latency: str, subset: Any) -> Any:
    """The replay poser of ``rec`` wearing ``subset`` (None: every recorded sensor), its model
    loaded once per worker (the live default, "auto", chooses its file by the subset)."""
    from dataclasses import replace

    from app.replay import build_replay_poser, replay_model, resolve_sensors

    sites = None if subset is None else resolve_sensors(rec, subset)
    spec = replay_model(rec, settings, sites)
    return build_replay_poser(rec, replace(settings, model=spec), body, model=_model(spec, latency))


def one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if text else type(exc).__name__


def run_task(task: Task) -> dict[str, Any]:
    """Do ``task`` (or find it done); never raises for a bad recording: the result says."""
    from app.live.model_choice import set_torch_threads

    set_torch_threads(1)  # one core per worker: the pool is the parallelism
    t0, c0 = time.perf_counter(), time.process_time()
    base = {"recording": task.recording, "folder": task.folder, "meta": task.meta}
    try:
        done = up_to_date(task)
        if done is not None:
            return skipped(task, done)
        result = _run(task)
    except Exception as exc:  # a bad recording is a failed row, not a stopped study
        # not kept: the next run tries it again (the fault may have been the disk's, or the network's)
        result = failed(task, one_line(exc))
    finally:
        _unmark(Path(task.folder))
    result.update(base, seconds=round(time.perf_counter() - t0, 3), cpu_s=round(time.process_time() - c0, 3))
    if result["status"] == "done":
        _json_atomic(Path(task.folder) / RESULT, result)
    return result


def skipped(task: Task, earlier: dict[str, Any]) -> dict[str, Any]:
    """An earlier result that still holds: "skipped", its rows in the table again, no work done."""
    return {**earlier, "recording": task.recording, "folder": task.folder, "meta": task.meta, "status": "skipped",
            "seconds": 0.0, "cpu_s": 0.0}


def failed(task: Task, reason: str) -> dict[str, Any]:
    return {"recording": task.recording, "folder": task.folder, "meta": task.meta, "status": "failed",
            "reason": reason, "rows": [], "files": [], "fingerprint": task.fingerprint, "seconds": 0.0, "cpu_s": 0.0}


def crashed(task: Task, how: str, pid: int | None = None) -> dict[str, Any]:
    """The failed result of a task whose worker process died under it (``how``: "SIGSEGV",
    "exit code 1", "KilledWorker ..."); its temporaries and mark (the dead worker's ``pid``) go."""
    folder = Path(task.folder)
    if pid is not None:
        for left in [*folder.glob(f".*.tmp-{pid}"), *folder.glob(f".*.tmp-{pid}.*")]:
            left.unlink(missing_ok=True)
    _unmark(folder, pid)
    return failed(task, f"the worker process died ({how}) while re-running this recording")


def _mark(folder: Path) -> None:
    import socket

    _json_atomic(folder / RUNNING, {"pid": os.getpid(), "host": socket.gethostname(), "since": time.time()})


def _unmark(folder: Path, pid: int | None = None) -> None:
    """Remove ``.running`` when it is this process's (or ``pid``'s) mark."""
    mark = _read_json(folder / RUNNING)
    if mark is not None and mark.get("pid") == (os.getpid() if pid is None else pid):
        (folder / RUNNING).unlink(missing_ok=True)


def _run(task: Task) -> dict[str, Any]:
    from app.capture.simulate import read_truth
    from app.export.formats import body_for_recording, export_motion, motion_from_poses
    from app.recording import read_recording
    from app.replay import compare_to_recorded, held_out_errors, replay_recording, truth_errors

    folder = Path(task.folder)
    stamp = input_stamp(task.recording)
    rec = read_recording(task.recording)  # before any folder is made: a file that is no recording leaves none
    folder.mkdir(parents=True, exist_ok=True)
    for left in folder.glob(".*.tmp-*"):  # a worker lost under this recording before left them (one task a folder)
        left.unlink(missing_ok=True)
    _mark(folder)
    if task.force:
        for old in (RESULT, JOURNAL):
            (folder / old).unlink(missing_ok=True)
    journal = _journal(folder, task.fingerprint, stamp)
    body, note = body_for_recording(rec.metadata)
    opts = task.options
    latency = opts.settings.latency or rec.metadata.get("latency") or "centred"
    truth = read_truth(task.truth) if task.truth else None
    warnings = list(rec.damage) + ([note] if note else [])
    full = None  # every recorded sensor's replay, once, for the held-out error of each subset
    first = None  # the first subset's replay and its poser's label and steps, for the report
    rows, files = [], []
    for subset in opts.subsets:
        label = subset_label(subset)
        if label in journal:
            rows.append(journal[label]["row"])
            files += journal[label]["files"]
            continue
        built = _replay_poser(rec, opts.settings, body, latency, subset)
        res = replay_recording(rec, built.poser, sensors=subset, causal=built.causal)
        if subset is None:
            full = res
        if subset == opts.subsets[0]:
            first = (res, built.label, built.steps)
        n = len(res.poses)
        span = (res.poses[-1].t - res.poses[0].t + 0.05) if n else 0.0
        row: dict[str, Any] = {
            "subset": label, "sensors": ",".join(res.sensors), "frames": n, "duration_s": round(span, 3),
            "ga_vs_recorded_deg": compare_to_recorded(rec, res.poses)["vs_recorded_ga_deg"],
            "held_out_deg": None, "ga_truth_deg": None,
            "dropped_frames": int(res.stats.get("dropped", 0) or 0),
            "frames_filled": int(res.stats.get("frames_filled", 0) or 0),
            "model": built.label, "steps": built.steps,
            "warnings": "; ".join(warnings + ([built.warning] if built.warning else [])),
        }
        left_out = [s for s in rec.sites if s not in res.sensors]
        if opts.held_out and left_out:
            if full is None:
                full = replay_recording(rec, built.fresh(), sensors=None, causal=built.causal)
            row["held_out_deg"] = held_out_errors(res.poses, full.poses, left_out)["mean_deg"]
        if truth is not None and n:
            import numpy as np

            got = truth_errors(np.array([p.t for p in res.poses]), np.stack([p.pose.rot for p in res.poses]), truth)
            row["ga_truth_deg"] = None if got["ga_deg"] is None else round(got["ga_deg"], 3)
        made = []
        if opts.exports and n:
            motion = motion_from_poses(res.poses, body, rec, meta={
                "model": built.label, "steps": built.steps, "sensors": list(res.sensors), "insoles": res.insoles,
                "what": f"imucap batch (seed {opts.settings.seed})"})
            for ext in opts.exports:
                name = f"{label}.{ext}"
                write_atomic(folder / name, lambda tmp, m=motion: export_motion(tmp, m))
                made.append(name)
        _append(folder, {"fingerprint": task.fingerprint, "stamp": stamp, "subset": label, "row": row,
                         "files": made})
        rows.append(row)
        files += made
    if opts.report:
        if "report" in journal:
            files += journal["report"]["files"]
        else:
            if first is None:  # the first subset came from the journal: its replay again
                built = _replay_poser(rec, opts.settings, body, latency, opts.subsets[0])
                first = (replay_recording(rec, built.poser, sensors=opts.subsets[0], causal=built.causal),
                         built.label, built.steps)
            made = write_report(rec, folder, *first)
            _append(folder, {"fingerprint": task.fingerprint, "stamp": stamp, "subset": "report", "row": None,
                             "files": made})
            files += made
    return {"recording": task.recording, "fingerprint": task.fingerprint, "stamp": stamp, "status": "done",
            "rows": rows, "files": files, "motion_s": max((r["duration_s"] for r in rows), default=0.0)}


def write_report(rec, folder: Path, res, label: str, steps) -> list[str]:
    """The gait report (``report.html``, self-contained) and its figures (``report.json``) of a replay
    ``res`` of ``rec``; a replay without walking gives a report that says so, not a failure."""
    from app.report.build import make_report, with_poses

    replayed = with_poses(rec, res.poses, model=f"{label} (imucap batch)", steps=steps, sensors=list(res.sensors),
                          insoles=bool(res.insoles))
    summary: dict[str, Any] = {}

    def html(tmp: Path) -> None:
        summary.update(make_report(replayed, tmp).summary)

    write_atomic(folder / REPORT, html)
    summary["html"] = REPORT
    _json_atomic(folder / "report.json", summary)
    return [REPORT, "report.json"]
