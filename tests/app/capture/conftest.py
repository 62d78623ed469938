"""Fixtures of the capture tests."""

from __future__ import annotations

import subprocess

import pytest

from tests.app.capture.live_capture import CLI


@pytest.fixture(scope="session")
def walk_20s(tmp_path_factory):
    """The activity the real-time captures play (`imucap data generate walk`, 20 s, seed 3),
    made once for all of them."""
    motion = tmp_path_factory.mktemp("motion") / "walk.npz"
    gen = subprocess.run([*CLI, "data", "generate", "walk", "--seconds", "20", "--seed", "3", "--out", str(motion)],
                         capture_output=True, text=True, timeout=120)
    assert gen.returncode == 0, gen.stderr[-2000:]
    return motion
