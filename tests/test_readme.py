"""The README's capture without hardware, run as written: its lines, in order, in an
empty folder, as a user pastes them into a shell (the simulator in the background, as
the README's `&` puts it)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import REPO

pytestmark = pytest.mark.slow
HEADING = "### The same capture without hardware"


def readme_block(heading: str) -> list[str]:
    """The first indented code block after ``heading`` in README.md, one command per line."""
    lines = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    i = lines.index(heading)
    while not lines[i].startswith("    "):
        i += 1
    block = []
    while i < len(lines) and lines[i].startswith("    "):
        block.append(lines[i][4:])
        i += 1
    return block


def test_the_block_is_what_this_test_expects():
    """If the README's block changes shape, this says so before the long run does."""
    block = readme_block(HEADING)
    assert [c.split()[:3] for c in block] == [["imucap", "setup", "example"], ["imucap", "devices", "simulate"],
                                              ["imucap", "capture", "--setup"], ["imucap", "replay", "walk.h5"]]
    assert block[1].split("#")[0].rstrip().endswith("&")


def test_readme_capture_without_hardware_runs_as_written(tmp_path):
    script = "set -e\n" + "\n".join(readme_block(HEADING)) + "\n"
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
           "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen(["bash", "-c", script], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, process_group=0)
    # a process group of its own (to end the simulator with it), not a session of its own: a
    # new session is a new scheduling group under Linux's autogroup, outside the priorities
    # scripts/test.sh gives its runs
    try:
        out, err = proc.communicate(timeout=600)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGTERM)  # the simulator, if it outlived the script
        except ProcessLookupError:
            pass
    assert proc.returncode == 0, err[-3000:]
    assert {"suit.toml", "truth.npz", "walk.h5"} <= {p.name for p in tmp_path.iterdir()}
    replay = json.loads([line for line in out.splitlines() if line.startswith("{")][-1])
    assert replay["recorded_ga_deg"] is not None and replay["ga_deg"] < 15.0, replay
    assert replay["truth_frames"] > 200  # scored over the walk, not a few frames
