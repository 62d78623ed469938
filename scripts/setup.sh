#!/usr/bin/env bash
# Create .venv and install imucap with every extra and the tests' packages. torch is pinned to the CPU build
# that lies on this machine's disk (an unpinned torch would pull several GB of CUDA).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null || PY=python3
[ -x .venv/bin/python ] || "$PY" -m venv .venv
.venv/bin/pip install -q --upgrade pip
# One resolve for torch and the rest, and no byte-compiling of every installed file: pip's compile step
# was half of the set-up (62 s -> 28 s in a fresh venv here), for the ~20,000 files of torch and the
# others that are never imported; Python compiles what is imported, once, into the same __pycache__.
.venv/bin/pip install -q --no-compile "torch==2.13.0" -e ".[test,all]"  # every optional part: the tests cover them all
# pylsl's Linux x86_64 wheel (glibc >= 2.35) carries liblsl; elsewhere pylsl needs one it can find
# (PYLSL_LIB, or the system's). Only `--stream lsl` needs it, so a missing one is a note, not a failure.
.venv/bin/python -c "import pylsl" 2>/dev/null || echo "setup: pylsl finds no liblsl; for --stream lsl install it" \
    "(conda install -c conda-forge liblsl, or a release from github.com/sccn/liblsl) and set PYLSL_LIB" >&2
