#!/usr/bin/env bash
# Set up and run the whole test suite, GUI tests under a virtual X server.
# Real-data tests read $IMUCAP_DATA (default ../shared/data) and skip when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
if ! command -v xvfb-run >/dev/null || ! command -v strace >/dev/null || ! command -v chromium >/dev/null; then
  # Xvfb and the libraries Qt's xcb platform plugin needs; strace for the tests that watch
  # where the simulator and a capture send (tests/socket_watch.py); chromium for the gait report's
  # PDF and its browser test (tests/app/report/test_report.py)
  export DEBIAN_FRONTEND=noninteractive
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq xvfb xauth libgl1-mesa-dri libegl1 libxkbcommon-x11-0 libxcb-cursor0 \
    libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxcb-xinerama0 libxcb-randr0 \
    libxcb-shape0 libxcb-xkb1 libdbus-1-3 libfontconfig1 strace chromium >/dev/null
fi
.venv/bin/ruff check .
# let Python keep compiled modules (in the __pycache__ folders git ignores): with
# PYTHONDONTWRITEBYTECODE set, as some shells have it, each xdist worker rewrote the asserts of
# every test module again (half of a collection's CPU) and each CLI subprocess compiled the
# package anew
unset PYTHONDONTWRITEBYTECODE
XVFB=(xvfb-run -a -s "-screen 0 1280x1024x24")
# two passes: everything else on both cores, then the real-time cross-process tests alone
# (tests/conftest.py, SOLO_MODULES); pytest's 5 means "nothing collected" for a pass
# each pass has a ceiling too (pytest-timeout covers a test, not a worker that never exits)
rc=0
timeout -k 30 2400 "${XVFB[@]}" .venv/bin/python -m pytest -n 2 --dist loadgroup -q -m "not solo" "$@" || rc=$?
[ "$rc" = 5 ] && rc=0
rc2=0
timeout -k 30 1200 "${XVFB[@]}" .venv/bin/python -m pytest -q -m solo "$@" || rc2=$?
[ "$rc2" = 5 ] && rc2=0
[ "$rc" = 0 ] && [ "$rc2" = 0 ]
