"""The OpenSense walk mirrored left for right: a second real log whose turns go the other way.

    .venv/bin/python benchmarks/mirror_real_log.py OUT_DATA_DIR
    IMUCAP_DATA=OUT_DATA_DIR imucap evaluate --data @real --model fast --against diffusion --json

Why: the OpenSense walk turns left three times and right once, and a model's loss on one foot may be that
foot's role in the turns (the inner, pivoting one) or a left/right bias of the model. The mirror image of
the whole recording answers it: each sensor's orientation R (an MT Manager export's Mat[i][j], world and
sensor frames both) becomes M R M and its acceleration M a, with M = diag(1, -1, 1) (a reflection through
the vertical x-z plane), and each left sensor's file takes its right twin's id, so the log's own map
(app/evaluation/real.py) puts the mirrored right thigh on the left thigh. A mirror-equivariant model (the
default: whole-chain mirror averaging) scores the mirrored log exactly as the original with left and right
swapped, which checks the transform (docs/model.md, "The fast model").

Writes OUT_DATA_DIR/opensense/xsens_mtw_walk/ from $IMUCAP_DATA (default ../shared/data); nothing else.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from inference.training.data import data_root

LOG = Path("opensense") / "xsens_mtw_walk"
# the walk's sensor ids, left <-> right (app/evaluation/real.py's map: thighs, shanks, feet)
TWINS = {"00B4227C": "00B421EE", "00B4227D": "00B421ED", "00B421EF": "00B421E6"}
SWAP = {**TWINS, **{v: k for k, v in TWINS.items()}}


def mirrored_columns(columns: list[str]) -> list[int]:
    """Indices of the columns whose sign the reflection flips: Acc_Y and the matrix entries with
    exactly one index along y (Mat[2][j], Mat[i][2], not Mat[2][2])."""
    def flips(c: str) -> bool:
        if c == "Acc_Y":
            return True
        if c.startswith("Mat[") and len(c) == 9:
            return (c[4] == "2") != (c[7] == "2")
        return False
    return [i for i, c in enumerate(columns) if flips(c)]


def mirror_text(text: str) -> str:
    """An MT Manager export (comment lines, a tab-separated header, rows) with the rows mirrored."""
    out, flip = [], None
    for line in text.splitlines():
        if line.startswith("//") or not line.strip():
            out.append(line)
        elif flip is None:
            columns = line.split("\t")
            flip = mirrored_columns(columns)
            if not any(columns[i].startswith("Mat[") for i in flip):
                raise ValueError("no orientation matrix columns (Mat[i][j]) in this export")
            out.append(line)
        else:
            v = line.split("\t")
            for i in flip:
                if i < len(v) and v[i].strip():
                    v[i] = v[i][1:] if v[i].startswith("-") else "-" + v[i]
            out.append("\t".join(v))
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path, help="a data folder to write the mirrored log into")
    args = ap.parse_args(argv)
    src, dst = data_root() / LOG, args.out / LOG
    dst.mkdir(parents=True, exist_ok=True)
    for f in sorted(src.glob("*.txt")):
        sid = f.stem.split("_")[-1]
        (dst / f.name.replace(sid, SWAP.get(sid, sid))).write_text(mirror_text(f.read_text()))
    print(dst)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
