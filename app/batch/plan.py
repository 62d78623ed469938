"""Which recordings a batch reads, with what, and where each one's outputs go.

Inputs are named the way a study's files are at hand: a folder (every ``.h5`` under it),
a glob (``'study/*/walk*.h5'``), single recordings, or a manifest: a CSV with a
``recording`` column (relative paths are relative to the manifest) and any others
(``subject``, ``condition``, ...), which are carried into the summary; an optional
``truth`` column names a simulator's truth file to score against.

Outputs go under ``--out``, one folder per recording, named by the recording's path below
the inputs' common folder (``P014/walk`` for ``study/P014/walk.h5``), so recordings of the
same name in different folders never share one.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import json
import os
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from app.replay import ReplaySettings

MANIFEST_COLUMN = "recording"
RESERVED = {"recording", "truth"}


@dataclass(frozen=True)
class Input:
    recording: Path
    meta: dict[str, str] = field(default_factory=dict)
    truth: Path | None = None


def _manifest(path: Path) -> list[Input]:
    with path.open(newline="", encoding="utf-8-sig") as f:
        reader = csv.DictReader(f)
        if not reader.fieldnames or MANIFEST_COLUMN not in reader.fieldnames:
            raise ValueError(f"{path}: a manifest needs a {MANIFEST_COLUMN!r} column (has: "
                             f"{', '.join(reader.fieldnames or []) or 'none'})")
        out = []
        for line, row in enumerate(reader, start=2):
            rec = (row.get(MANIFEST_COLUMN) or "").strip()
            if not rec:
                raise ValueError(f"{path}:{line}: no recording named")
            truth = (row.get("truth") or "").strip()
            meta = {k: (v or "").strip() for k, v in row.items() if k not in RESERVED and k is not None}
            out.append(Input((path.parent / rec).resolve(), meta, (path.parent / truth).resolve() if truth else None))
        return out


def find_inputs(names: list[str]) -> list[Input]:
    """Every recording the names stand for, each once, in the order given (a folder's and a
    glob's sorted). A name that matches nothing is an error: a typo must not pass as an
    empty study."""
    seen: dict[Path, Input] = {}
    for name in names:
        p = Path(name)
        if p.suffix.lower() == ".csv" and p.is_file():
            found = _manifest(p)
        elif p.is_dir():
            found = [Input(q.resolve()) for q in sorted(p.rglob("*.h5"))]
        elif p.is_file():
            found = [Input(p.resolve())]
        else:
            found = [Input(Path(q).resolve()) for q in sorted(glob.glob(name, recursive=True)) if Path(q).is_file()]
        if not found:
            raise ValueError(f"{name}: no recordings (a folder of .h5 files, a glob, a recording or a manifest .csv)")
        for inp in found:
            seen.setdefault(inp.recording, inp)
    return list(seen.values())


def output_folder(out: Path, inp: Input, root: Path) -> Path:
    """``out/<the recording's path below root, without .h5>``."""
    try:
        rel = inp.recording.relative_to(root)
    except ValueError:
        rel = Path(inp.recording.name)
    return out / rel.with_suffix("")


def common_root(inputs: list[Input]) -> Path:
    if not inputs:
        return Path(".")
    return Path(os.path.commonpath([str(i.recording.parent) for i in inputs]))


def subset_label(sensors: tuple[str, ...] | None) -> str:
    return "all" if sensors is None else "+".join(sensors)


@dataclass(frozen=True)
class Options:
    """What every recording of the batch is re-run with."""

    settings: ReplaySettings = ReplaySettings()
    subsets: tuple[tuple[str, ...] | None, ...] = (None,)
    exports: tuple[str, ...] = ()
    held_out: bool = True
    report: bool = False  # a gait report per recording (``app.report``), of the first subset's replay

    def fingerprint(self) -> str:
        """Changes whenever an option, imucap's version or the content of a model file the
        options may load changes: outputs made otherwise are not up to date. (Without a report
        the fingerprint is what it was before the option existed: earlier batches stay done.)"""
        import app

        d: dict[str, Any] = asdict(self)
        if not self.report:
            d.pop("report")
        d["imucap"] = app.APP_VERSION
        d["model_files"] = {str(p): file_digest(p) for p in model_files(self.settings.model)}
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=str).encode()).hexdigest()[:16]


def model_files(spec: str) -> list[Path]:
    """The weights files ``--model spec`` may load: the file named, or a shipped model's file
    and, for the diffusion model, the one the low-latency mode swaps in."""
    from app.live.latency import model_spec_for
    from inference.poser.models import DEFAULT_WEIGHTS

    out = []
    for latency in ("centred", "low"):
        chosen = model_spec_for(latency, spec)
        path = Path(DEFAULT_WEIGHTS.get(chosen, chosen))
        if path.is_file() and path not in out:
            out.append(path)
    return out


_DIGESTS: dict[tuple[str, int, int], str] = {}


def file_digest(path: Path) -> str:
    """SHA-256 of a file's content (kept per size and modification time in this process)."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _DIGESTS:
        h = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
        _DIGESTS[key] = h.hexdigest()
    return _DIGESTS[key]
