"""Per-frame latency of the live poser loop: the same measurement as `imucap bench`
(app.cli_bench.run_bench), runnable from a checkout without installing.

    .venv/bin/python benchmarks/bench_poser.py --json [--threads N] [--random-weights]
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.cli.main import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main(["bench", *sys.argv[1:]]))
