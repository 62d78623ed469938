#!/usr/bin/env bash
# Set up and run the whole test suite, GUI tests under a virtual X server.
# Real-data tests read $IMUCAP_DATA (default ../shared/data) and skip when it is absent.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
# Xvfb and the libraries Qt's xcb platform plugin needs; strace for the tests that watch
# where the simulator and a capture send (tests/socket_watch.py); chromium for the gait report's
# PDF and its browser test (tests/app/report/test_report.py). Checked package by package: with
# xvfb-run, strace and chromium present but an xcb library missing, Qt aborts in every window test.
PACKAGES="xvfb xauth libgl1-mesa-dri libegl1 libxkbcommon-x11-0 libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1
  libxcb-image0 libxcb-render-util0 libxcb-xinerama0 libxcb-randr0 libxcb-shape0 libxcb-xkb1 libdbus-1-3
  libfontconfig1 strace chromium"
if command -v dpkg >/dev/null; then
  # shellcheck disable=SC2086
  dpkg -s $PACKAGES >/dev/null 2>&1 && missing="" || missing=yes
else
  command -v xvfb-run >/dev/null && command -v strace >/dev/null && command -v chromium >/dev/null && missing="" \
    || missing=yes
fi
if [ -n "$missing" ]; then
  export DEBIAN_FRONTEND=noninteractive
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  # shellcheck disable=SC2086
  $SUDO apt-get install -y -qq $PACKAGES >/dev/null
fi
.venv/bin/ruff check .
# let Python keep compiled modules (in the __pycache__ folders git ignores): with
# PYTHONDONTWRITEBYTECODE set, as some shells have it, each xdist worker rewrote the asserts of
# every test module again (half of a collection's CPU) and each CLI subprocess compiled the
# package anew
unset PYTHONDONTWRITEBYTECODE
# Five runs, each at its priority (tests/conftest.py sorts the tests; docs/testing.md):
# - realtime and windows, nice 0, one worker each, side by side: the tests that must keep up in real time
#   (devices streaming, the demo; the windows in a lane of their own); they mostly wait on the clock;
# - solo and solo2, nice 0, one worker each, side by side once both realtime lanes are done: the captures in
#   a process of their own whose figures (a calibration, a score against the truth) need the cores, one
#   capture per lane and never beside a realtime lane. Beside the realtime run, on a machine where a live
#   step costs 25 ms, the live runs' posers, simulators and windows asked for more than the two cores and a
#   capture made 10-13 poses a second: three live tests of a run failed there and passed alone
#   (docs/testing.md, "On a slower machine"); a failed live test gets its second run below;
# - rest, nice 10, two workers, beside them: everything else, on the cores the live runs leave (the
#   scheduler weighs nice 0 / 10 as 1024 / 110).
# Each run has its own X server (-n), temporary folder and log; the logs are printed at the end. Each
# collects only its own modules (IMUCAP_TEST_RUN, tests/conftest.py).
# pytest's 5 means "nothing collected" (a -k that leaves a run empty); each run has a ceiling too
# (pytest-timeout covers a test, not a worker that never exits).
LOGS=$(mktemp -d)
# the windows at half scale: Xvfb's software GL renders every pixel on the CPU, and a quarter of the
# pixels took a quarter of the window tests' CPU off (test_outdoor_view 34.6 -> 26.1 s, the workflow and
# unplug windows 53.3 -> 40.8 s); the tests check what is drawn, not its size
export QT_SCALE_FACTOR=${QT_SCALE_FACTOR:-0.5}
run() {  # run NAME NICE DISPLAY WORKERS MARKERS [pytest args]
  local name=$1 prio=$2 display=$3 workers=$4 markers=$5; shift 5
  local rc=0
  IMUCAP_TEST_RUN=$name IMUCAP_STALL_TRACE="$LOGS/$name.stall" nice -n "$prio" timeout -k 30 1500 xvfb-run -a -n "$display" -s "-screen 0 1280x1024x24" \
    .venv/bin/python -m pytest -n "$workers" --dist loadgroup -q -p no:cacheprovider --basetemp "$LOGS/$name" \
    -m "$markers" "$@" >"$LOGS/$name.log" 2>&1 || rc=$?
  [ "$rc" = 5 ] && rc=0
  echo "$rc" >"$LOGS/$name.rc"
}
DISPLAY_BASE=$((100 + RANDOM % 300))
# what the kernel says each thread of a stalled capture is doing (scripts/stall_watch.py; NOTES.md "Tests")
.venv/bin/python scripts/stall_watch.py "$LOGS/realtime.stall" "$LOGS/solo.stall" "$LOGS/rest.stall" \
  "$LOGS/windows.stall" "$LOGS/solo2.stall" "$LOGS/again.stall" >/dev/null 2>&1 &
watch_pid=$!
{
  run windows 0 $((DISPLAY_BASE + 150)) 1 "realtime" "$@" &
  run realtime 0 "$DISPLAY_BASE" 1 "realtime" "$@"
  wait
  run solo2 0 $((DISPLAY_BASE + 750)) 1 "solo" "$@" &
  run solo 0 $((DISPLAY_BASE + 600)) 1 "solo" "$@"
  wait
} &
live_pid=$!
run rest 10 $((DISPLAY_BASE + 300)) 2 "not solo and not realtime" "$@" &
rest_pid=$!
wait "$live_pid"
# A live test (realtime or solo) that failed gets one more run once the live runs are done, beside only the rest
# run, which yields the cores at nice 10: their figures and timing need the cores (docs/testing.md, "A second run
# alone"). It runs while the rest finishes, so it costs the suite little time. It passes only if it passes there;
# the first failure stays in the log, named again at the end. A failure of the rest, a live run that failed without
# naming its tests (a crash, its ceiling) or a second failure fails the suite.
again=()
for name in realtime windows solo solo2; do
  [ "$(cat "$LOGS/$name.rc" 2>/dev/null)" = 0 ] && continue
  mapfile -t ids < <(sed -n -E 's/^(FAILED|ERROR) ([^ ]+).*/\2/p' "$LOGS/$name.log" | sort -u)
  if [ "${#ids[@]}" = 0 ]; then again=(); echo none >"$LOGS/again.rc"; break; fi
  again+=("${ids[@]}")
done
if [ "${#again[@]}" -gt 0 ] && [ ! -f "$LOGS/again.rc" ]; then
  run again 0 $((DISPLAY_BASE + 900)) 1 "realtime or solo" "${again[@]}"
fi
wait "$rest_pid"
kill "$watch_pid" 2>/dev/null || true
ok=0
for name in realtime windows rest solo solo2 again; do
  [ -f "$LOGS/$name.rc" ] || continue
  echo "=== $name ($(cat "$LOGS/$name.rc" 2>/dev/null || echo none))"
  [ -f "$LOGS/$name.log" ] && cat "$LOGS/$name.log"
  # a failed run's live pipelines that went 1.5 s without a hub frame: every thread's stack then
  # (IMUCAP_STALL_TRACE, app/live/runner.py, one file per process), and the kernel's view of its threads
  # then (scripts/stall_watch.py; what held a capture that stalled, NOTES.md "Tests")
  if [ "$(cat "$LOGS/$name.rc" 2>/dev/null)" != 0 ]; then
    for f in $(grep -l Timeout "$LOGS/$name".stall.* 2>/dev/null | grep -v '\.proc$'); do
      echo "=== $name: stalls of ${f##*.stall.} (each thread's stack once a hub gave no frame for 1.5 s; the last 200 lines)"
      grep -v '^hub frames at' "$f" | tail -n 200
      if [ -f "$f.proc" ]; then cat "$f.proc"; fi
    done
  fi
done
[ "$(cat "$LOGS/rest.rc")" = 0 ] || ok=1
for name in realtime windows solo solo2; do
  if [ "$(cat "$LOGS/$name.rc")" != 0 ] && [ "$(cat "$LOGS/again.rc" 2>/dev/null)" != 0 ]; then ok=1; fi
done
if [ "${#again[@]}" -gt 0 ] && [ "$(cat "$LOGS/again.rc" 2>/dev/null)" = 0 ]; then
  echo "=== passed on a second run (beside the rest run only), failed beside the other live run:"
  printf '  %s\n' "${again[@]}"
fi
exit $ok
