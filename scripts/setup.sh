#!/usr/bin/env bash
# Create .venv and install imucap with every extra and the tests' packages. torch is pinned to the CPU build
# that lies on this machine's disk (an unpinned torch would pull several GB of CUDA).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/pip install -q --upgrade pip
.venv/bin/pip install -q "torch==2.13.0"
.venv/bin/pip install -q -e ".[test,all]"  # every optional part: the tests cover them all
# pylsl's Linux x86_64 wheel (glibc >= 2.35) carries liblsl; elsewhere pylsl needs one it can find
# (PYLSL_LIB, or the system's). Only `--stream lsl` needs it, so a missing one is a note, not a failure.
.venv/bin/python -c "import pylsl" 2>/dev/null || echo "setup: pylsl finds no liblsl; for --stream lsl install it" \
    "(conda install -c conda-forge liblsl, or a release from github.com/sccn/liblsl) and set PYLSL_LIB" >&2
