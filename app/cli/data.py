"""`imucap data ...`: look at motion files, build the training dataset, plot synthesized
signals, and generate procedural motions.

    imucap data inspect PATH... [--json]
    imucap data build --data PATH... --out DIR [--json]
    imucap data plot FILE --out PNG [--sites a,b,c]
    imucap data generate KIND --out FILE.npz [--height H] [--speed V] [--seconds S] [--seed N]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def _format_of(path: Path) -> str:
    name = path.name.lower()
    if name.endswith((".bvh", ".bvh.gz")):
        return "bvh"
    if name.endswith((".amc", ".amc.gz")):
        return "asf/amc"
    if name.endswith(".npz"):
        return "amass"
    return "unknown"


def inspect_motion(path: str | Path) -> dict:
    """Summary of one motion file after loading (retargeted, floor aligned)."""
    from inference.loaders import load_motion

    path = Path(path)
    m = load_motion(path)
    cp = m.contacts()
    return {
        "name": m.name or path.stem,
        "source": str(path),
        "format": _format_of(path),
        "frames": m.n_frames,
        "fps": float(m.fps),
        "duration_s": float(m.duration),
        "height_m": float(m.body.height),
        "root_z_min_m": float(m.root[:, 2].min()),
        "root_z_max_m": float(m.root[:, 2].max()),
        "min_foot_z_m": float(cp[..., 2].min()),
        "root_path_m": float(np.linalg.norm(np.diff(m.root[:, :2], axis=0), axis=-1).sum()),
        "layout": str(m.meta.get("layout", m.meta.get("skeleton", _format_of(path)))),
        **({"declared_fps": float(m.meta["declared_fps"])} if "declared_fps" in m.meta else {}),
    }


def inspect_many(paths: list[str | Path]) -> dict:
    """Every motion file under ``paths`` inspected, the ones that fail kept with their
    error instead of stopping the walk, and totals per skeleton layout: a new dataset is
    checked in one go, and a file no loader can read shows up by name."""
    from inference.loaders import MotionFormatError, find_motion_files

    files: list[dict] = []
    failed: list[dict] = []
    for f in find_motion_files(list(paths)):
        try:
            files.append(inspect_motion(f))
        except (MotionFormatError, ValueError, OSError) as exc:
            failed.append({"source": str(f), "error": str(exc)})
    return {"files": files, "failed": failed, "layouts": _layout_totals(files)}


def _layout_totals(files: list[dict]) -> dict[str, dict]:
    """Per layout: how much there is, at which rates, and the range of body heights."""
    out: dict[str, dict] = {}
    for layout in sorted({f["layout"] for f in files}):
        group = [f for f in files if f["layout"] == layout]
        heights = [f["height_m"] for f in group]
        out[layout] = {
            "files": len(group),
            "frames": sum(f["frames"] for f in group),
            "fps": sorted({round(f["fps"], 3) for f in group}),
            "minutes": sum(f["duration_s"] for f in group) / 60.0,
            "height_m": [min(heights), max(heights)],
        }
    return out


def _print_many(report: dict) -> None:
    """One line per file, then one per layout; failures to stderr, where a script looks."""
    rows = [(f["name"], f["layout"], f["frames"], f"{f['fps']:g}", f"{f['duration_s']:.1f}", f"{f['height_m']:.2f}",
             f"{f['min_foot_z_m'] * 100:.1f}") for f in report["files"]]
    head = ("file", "layout", "frames", "fps", "s", "height_m", "min_foot_cm")
    widths = [max(len(str(r[k])) for r in [head, *rows]) for k in range(len(head))]
    for r in [head, *rows]:
        print("  ".join(str(v).ljust(w) for v, w in zip(r, widths)))
    print()
    for layout, t in report["layouts"].items():
        print(f"{layout}: {t['files']} files, {t['frames']} frames at {', '.join(f'{v:g}' for v in t['fps'])} fps, "
              f"{t['minutes']:.1f} min, height {t['height_m'][0]:.2f}-{t['height_m'][1]:.2f} m")
    for f in report["failed"]:
        print(f"failed: {f['error']}", file=sys.stderr)


def _print_one(info: dict) -> None:
    w = max(len(k) for k in info)
    for k, v in info.items():
        print(f"{k:<{w}}  {v:.4g}" if isinstance(v, float) else f"{k:<{w}}  {v}")


def _cmd_inspect(args: argparse.Namespace) -> int:
    """One file: its summary, as before (a file that fails is an error). Folders or
    several files: a report that carries on past files that fail, exit code 1 if any did."""
    if len(args.paths) == 1 and not Path(args.paths[0]).is_dir():
        info = inspect_motion(args.paths[0])
        if args.json:
            print(json.dumps(info))
        else:
            _print_one(info)
        return 0
    report = inspect_many(args.paths)
    if args.json:
        print(json.dumps(report))
    else:
        _print_many(report)
    return 1 if report["failed"] else 0


def _cmd_build(args: argparse.Namespace) -> int:
    from inference.training.dataset import build_dataset, cache_path

    ds = build_dataset(args.data, args.out, progress=not args.json)
    summary = {
        "clips": len(ds), "frames": ds.n_frames, "seconds": ds.n_frames / 20.0, "skipped": ds.skipped,
        "cache": str(cache_path(args.out, ds.key)),
    }
    if args.json:
        print(json.dumps(summary))
    else:
        print(f"{summary['clips']} clips, {summary['frames']} frames at 20 Hz ({summary['seconds'] / 60:.1f} min)"
              f" -> {summary['cache']}")
        for s in ds.skipped:
            print(f"skipped: {s}", file=sys.stderr)
    return 0


def plot_motion(path: str | Path, out: str | Path, sites: list[str] | None = None, n_snapshots: int = 6) -> Path:
    """Skeleton snapshots (side and front view) and the synthesized signals of a few sites."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from inference.body.skeleton import CONTACTS, PARENTS, parse_sites
    from inference.loaders import load_motion
    from inference.signals.synthesis import synthesize

    sites = parse_sites(sites or ["pelvis", "l_wrist", "r_shank"])
    m = load_motion(path).resample(60.0)
    sig = synthesize(m, sites=tuple(sites))
    j = m.joints()
    T = m.n_frames
    frames = np.linspace(0, T - 1, n_snapshots).round().astype(int)

    fig = plt.figure(figsize=(14, 4 + 2.2 * (len(sites) + 1)))
    gs = fig.add_gridspec(2 + len(sites) + 1, n_snapshots, height_ratios=[2, 2] + [1] * (len(sites) + 1))
    lo, hi = j.min((0, 1)), j.max((0, 1))
    for col, f in enumerate(frames):
        for row, (a, b, label) in enumerate(((0, 2, "side (x-z)"), (1, 2, "front (y-z)"))):
            ax = fig.add_subplot(gs[row, col])
            c = j[f, :, (a, b)].T - [j[f, 0, a], 0]
            for i, p in enumerate(PARENTS):
                if p >= 0:
                    color = "tab:blue" if "l_" in _seg(i) else ("tab:red" if "r_" in _seg(i) else "k")
                    ax.plot([c[p, 0], c[i, 0]], [c[p, 1], c[i, 1]], color=color, lw=1.5)
            ax.axhline(0, color="0.6", lw=0.8)
            ax.set_xlim(-1.0, 1.0)
            ax.set_ylim(min(lo[2], 0) - 0.05, hi[2] + 0.1)
            ax.set_aspect("equal")
            ax.tick_params(labelsize=6)
            ax.set_title(f"t={f / m.fps:.2f}s {label}", fontsize=7)
    t = sig.t
    for r, s in enumerate(sites):
        k = sig.sites.index(s)
        ax = fig.add_subplot(gs[2 + r, : n_snapshots // 2])
        ax.plot(t, sig.free_acc[:, k], lw=0.8)
        ax.set_ylabel(f"{s}\nfree acc m/s²", fontsize=7)
        ax.legend(["x", "y", "z"], fontsize=6, loc="upper right")
        ax.tick_params(labelsize=6)
        ax = fig.add_subplot(gs[2 + r, n_snapshots // 2:])
        ax.plot(t, sig.gyro[:, k], lw=0.8)
        ax.set_ylabel("gyro rad/s", fontsize=7)
        ax.tick_params(labelsize=6)
    ax = fig.add_subplot(gs[-1, :])
    for i, name in enumerate(CONTACTS):
        ax.fill_between(t, i, i + 0.8 * sig.contacts[:, i], step="mid", alpha=0.7, label=name)
    ax.set_yticks(np.arange(4) + 0.4, CONTACTS, fontsize=7)
    ax.set_xlabel("time (s)", fontsize=8)
    ax.set_ylabel("contacts", fontsize=7)
    fig.suptitle(f"{Path(path).name}: {T} frames at 60 Hz, height {m.body.height:.2f} m", fontsize=10)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


def _seg(i: int) -> str:
    from inference.body.skeleton import SEGMENTS

    return SEGMENTS[i]


def _cmd_plot(args: argparse.Namespace) -> int:
    out = plot_motion(args.file, args.out, args.sites.split(",") if args.sites else None)
    print(out)
    return 0


def _cmd_generate(args: argparse.Namespace) -> int:
    from sim_devices.motions import generate, write_amass_npz

    m = generate(args.kind, height=args.height, speed=args.speed, seconds=args.seconds, seed=args.seed,
                 heading_deg=args.heading)
    p = write_amass_npz(m, args.out)
    print(p)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    from sim_devices.motions import KINDS

    data = subparsers.add_parser("data", help="motion files: inspect, build the dataset, plot, generate")
    sub = data.add_subparsers(dest="data_command", required=True)

    p = sub.add_parser("inspect", help="summary of a motion file, or of every one under folders (per layout)")
    p.add_argument("paths", nargs="+", metavar="PATH", help="a motion file, or files and folders")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=_cmd_inspect)

    p = sub.add_parser("build", help="build (or reuse) the cached feature dataset")
    p.add_argument("--data", nargs="+", required=True, metavar="PATH", help="motion files or folders")
    p.add_argument("--out", required=True, metavar="DIR", help="cache directory")
    p.add_argument("--json", action="store_true", help="print one JSON summary (no progress bar)")
    p.set_defaults(func=_cmd_build)

    p = sub.add_parser("plot", help="skeleton snapshots and synthesized signals as a PNG")
    p.add_argument("file")
    p.add_argument("--out", required=True, metavar="PNG")
    p.add_argument("--sites", default=None, help="comma separated sites (default pelvis,l_wrist,r_shank)")
    p.set_defaults(func=_cmd_plot)

    p = sub.add_parser("generate", help="write a procedural motion as AMASS .npz")
    p.add_argument("kind", choices=KINDS)
    p.add_argument("--out", required=True, metavar="FILE.npz")
    p.add_argument("--height", type=float, default=1.75, help="body height, m")
    p.add_argument("--speed", type=float, default=None, help="m/s for walk/jog, tempo factor otherwise")
    p.add_argument("--seconds", type=float, default=6.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--heading", type=float, default=0.0, help="facing direction, degrees about Z from +X")
    p.set_defaults(func=_cmd_generate)
