"""How long a motion file takes to load (parse, retarget, check), per dataset.

    .venv/bin/python benchmarks/load_speed.py [--files 300] [--json]

The first --files files of each dataset under $IMUCAP_DATA (Bandai BVH, HDM05 and CMU ASF/AMC), each loaded
with ``inference.loaders.load_motion`` as training and the real-data tests load them: ms per file. Training
reads every file once per data preparation and the suite's real-data tests read all ~2,700 of Bandai and HDM05.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from inference.loaders import find_motion_files, load_motion  # noqa: E402
from inference.training.data import data_root  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--files", type=int, default=300)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    out = {}
    for name, share in (("bandai", 1), ("hdm05", 4), ("cmu", 8)):  # the slower formats, fewer files
        files = find_motion_files(data_root() / name)[: max(1, args.files // share)]
        t = time.perf_counter()
        for f in files:
            load_motion(f)
        out[name] = {"files": len(files), "ms_per_file": round((time.perf_counter() - t) / max(len(files), 1) * 1e3, 1)}
    print(json.dumps(out) if args.json else "\n".join(f"{k:7s} {v['ms_per_file']:7.1f} ms a file ({v['files']} files)"
                                                       for k, v in out.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
