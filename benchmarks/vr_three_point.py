"""The three-point task on the held-out sets: a VR headset and two controllers, alone, with
two shank IMUs, and the shanks alone, read as the live vmc-in chain reads the points
(``imucap evaluate --points``, app/evaluation/tracked_points.py), with the papers' metrics and paired
bootstrap intervals over clips.

    .venv/bin/python benchmarks/vr_three_point.py --sets dg,cmu-val,sad --json runs/vr/three_point.json \
        [--model diffusion] [--markdown runs/vr/three_point.md]

Each (set, sensor set) result is kept in ``--cache`` (default beside --json) as it finishes,
keyed by the model file's content hash and the seed, so a run that stops resumes where it
was. The comparison the issue asks for: 3 points + 2 shanks against 3 points alone and
against 2 shanks alone, on lower-body PE and GA; a difference whose interval holds 0 is not
settled by the clips. The ", reach" rows are the same answers with each arm reaching its
controller afterwards (``imucap evaluate --reach``, ``inference/body/reach.py``).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import pickle
import sys
import time
from pathlib import Path

METRICS = ("ga_deg", "mpjre_deg", "mpjpe_cm", "mpjve_cms", "jitter_1e2m_s3", "hand_pe_cm", "upper_pe_cm",
           "lower_pe_cm", "root_pe_cm")
POINTS = ("head", "l_hand", "r_hand")
SENSOR_SETS = {  # label -> (IMU sites, tracked points, the arms reach the controllers after the answer)
    "3 points + 2 shanks": (("l_shank", "r_shank"), POINTS, False),
    "3 points": ((), POINTS, False),
    "2 shanks": (("l_shank", "r_shank"), (), False),
    "3 points, reach": ((), POINTS, True),
    "3 points + 2 shanks, reach": (("l_shank", "r_shank"), POINTS, True),
}
COMPARE = (("3 points + 2 shanks", "3 points"), ("3 points + 2 shanks", "2 shanks"),
           ("3 points, reach", "3 points"), ("3 points + 2 shanks, reach", "2 shanks"))
COMPARED = ("ga_deg", "lower_pe_cm", "mpjpe_cm", "hand_pe_cm", "upper_pe_cm")


def run_set(held_out: str, label: str, model_spec: str, seed: int, cache: Path) -> list:
    """Per-clip metrics of one sensor set on one held-out set (cached)."""
    key = cache / f"{held_out}__{label.replace(' ', '_').replace('+', 'and')}__{model_key(model_spec)}__s{seed}.pkl"
    if key.exists():
        return pickle.loads(key.read_bytes())
    from app.evaluation.tracked_points import tracked_points_input, tracked_signals
    from inference.evaluation.runner import evaluate_motions, evaluation_noise, load_motions
    from inference.poser.models import default_steps, resolve_model
    from inference.training.splits import held_out_files

    sites, points, reach = SENSOR_SETS[label]
    model = resolve_model(model_spec)
    reads_points = bool(getattr(model.config, "points", False))  # positions, else the IMUs they imply
    motions = load_motions(held_out_files(held_out))
    t0 = time.time()
    _, clips = evaluate_motions(motions, model, list(sites), steps=default_steps(model) or None,
                                noise=evaluation_noise(), seed=seed, progress=False,
                                given=tracked_signals(points) if points and not reads_points else None,
                                tracked=tracked_points_input(points) if points and reads_points else None,
                                reach=tracked_points_input(points) if reach else None)
    metrics = [c.metrics for c in clips]
    print(f"vr_three_point: {held_out} {label}: {len(metrics)} clips in {time.time() - t0:.0f} s", file=sys.stderr)
    return store(key, metrics)


def model_key(model_spec: str) -> str:
    """The model's name in a cache key: its weights' content hash (two files in one folder, or one file
    retrained in place, never share a key), after its readable name."""
    from inference.poser.models import DEFAULT_WEIGHTS

    if model_spec == "floor":
        return "floor"
    path = Path(DEFAULT_WEIGHTS.get(model_spec, model_spec))
    files = sorted(q for q in path.rglob("*") if q.is_file()) if path.is_dir() else [path]
    h = hashlib.sha256()
    for q in files:
        h.update(q.read_bytes())
    return f"{path.stem}-{h.hexdigest()[:16]}"


def store(key: Path, metrics: list) -> list:
    """Keep per-clip metrics under ``key``, atomically (a run that stops leaves no half file)."""
    key.parent.mkdir(parents=True, exist_ok=True)
    tmp = key.with_suffix(".tmp")
    tmp.write_bytes(pickle.dumps(metrics))
    tmp.replace(key)
    return metrics


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sets", default="dg,cmu-val,sad", help="held-out sets (inference/training/splits.py)")
    ap.add_argument("--model", default="diffusion")
    ap.add_argument("--against", default=None, metavar="MODEL",
                    help="a second model (e.g. one that reads the points' positions): its rows, and --model minus "
                         "it per sensor set")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", type=Path, required=True)
    ap.add_argument("--markdown", type=Path, default=None)
    ap.add_argument("--cache", type=Path, default=None)
    args = ap.parse_args(argv)

    import torch

    from inference.metrics.errors import paired_difference, summarize

    torch.set_num_threads(1)
    cache = args.cache or args.json.parent / "cache"
    out: dict = {"model": args.model, "seed": args.seed, "points": list(POINTS), "sets": {}}
    for held_out in [s.strip() for s in args.sets.split(",") if s.strip()]:
        per = {label: run_set(held_out, label, args.model, args.seed, cache) for label in SENSOR_SETS}
        entry: dict = {"clips": len(next(iter(per.values()))), "rows": {}, "differences": {}}
        for label, metrics in per.items():
            s = summarize(metrics)
            entry["rows"][label] = {m: s.get(m) for m in METRICS}
        for a, b in COMPARE:
            entry["differences"][f"{a} - {b}"] = {
                m: paired_difference(per[a], per[b], m, seed=args.seed).as_dict() for m in COMPARED}
        if args.against:
            theirs = {label: run_set(held_out, label, args.against, args.seed, cache) for label in SENSOR_SETS}
            entry["against"] = {"model": args.against, "rows": {}, "differences": {}}
            for label, metrics in theirs.items():
                s = summarize(metrics)
                entry["against"]["rows"][label] = {m: s.get(m) for m in METRICS}
                entry["against"]["differences"][label] = {
                    m: paired_difference(per[label], metrics, m, seed=args.seed).as_dict()
                    for m in ("ga_deg", "mpjpe_cm", "hand_pe_cm", "lower_pe_cm")}
        out["sets"][held_out] = entry
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
    if args.markdown:
        args.markdown.write_text(markdown(out))
    print(json.dumps(out))
    return 0


def table_lines(rows: dict, head: str = "sensors") -> list[str]:
    """A markdown table of ``rows`` (label -> metric -> value) over ``METRICS``."""
    out = [f"| {head} | " + " | ".join(METRICS) + " |", "|---" * (len(METRICS) + 1) + "|"]
    for label, row in rows.items():
        out.append(f"| {label} | " + " | ".join("n/a" if row[m] is None else f"{row[m]:.2f}" for m in METRICS) + " |")
    return out


def difference_cells(d: dict) -> str:
    """Paired differences (metric -> ``PairedDifference.as_dict``) as one line."""
    return "; ".join(f"{m} {v['difference']:+.2f} [{v['low']:+.2f}, {v['high']:+.2f}]" for m, v in d.items())


def markdown(out: dict) -> str:
    lines = []
    for held_out, e in out["sets"].items():
        lines += [f"**@{held_out}** ({e['clips']} clips)", "", *table_lines(e["rows"]), ""]
        lines += [f"- {name}: {difference_cells(d)}" for name, d in e["differences"].items()]
        lines.append("")
        if "against" in e:
            a = e["against"]
            lines += [f"against {a['model']}:", "", *table_lines(a["rows"]), ""]
            lines += [f"- {out['model']} minus it, {label}: {difference_cells(d)}"
                      for label, d in a["differences"].items()]
            lines.append("")
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
