"""Shared test fixtures: where the real data lies, and a skip when it is not there."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def data_root() -> Path:
    return Path(os.environ.get("IMUCAP_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    root = data_root()
    if not (root / "hdm05").is_dir() or not (root / "bandai").is_dir():
        pytest.skip(f"real motion data not found at {root} (set IMUCAP_DATA)")
    return root


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """The suite runs two xdist workers on two cores: one intra-op thread each (oversubscribed
    OpenMP threads crawl). Set before every test, it also undoes a CLI test's --threads."""
    torch = sys.modules.get("torch")  # only if the test already uses it: driver tests need no torch
    if torch is not None:
        torch.set_num_threads(1)
    yield
