"""benchmarks/fuzz.py, run for a few inputs per target in its own process, as it runs for
a million: every target starts, fuzzes, reports a JSON line, and the modules that parse
its input are instrumented. A parser imported outside atheris' instrumentation (the motion
loaders import theirs on first call) gives libFuzzer no coverage from its branches, and
the fuzzer then mutates blind while its counts look the same."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("atheris")

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
import fuzz  # noqa: E402

NEEDS_DATA = {"asf-amc": Path("hdm05") / "dg" / "HDM_dg.asf"}


@pytest.mark.parametrize("name", sorted(fuzz.TARGETS))
def test_target_fuzzes_with_its_parser_instrumented(name: str, tmp_path: Path) -> None:
    need = NEEDS_DATA.get(name)
    if need is not None and not (fuzz._data_root() / need).exists():
        pytest.skip(f"needs {need} under IMUCAP_DATA for its seed")
    out = subprocess.run([sys.executable, str(REPO / "benchmarks" / "fuzz.py"), name, "--runs", "30",
                          "--workdir", str(tmp_path)], capture_output=True, text=True, timeout=300, cwd=REPO)
    summary = json.loads(out.stdout.strip().splitlines()[-1])
    assert out.returncode == 0, summary
    assert summary["runs"] >= 30 and summary["findings"] == []
    instrumented = set((tmp_path / name / "instrumented.txt").read_text().split())
    assert set(fuzz.TARGETS[name].surface) <= instrumented
    assert fuzz.TARGETS[name].surface, "each target names the modules that parse its input"


def test_memory_mode_runs_the_reader_uninstrumented(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, str(REPO / "benchmarks" / "fuzz.py"), "moticon", "--memory", "120",
                          "--workdir", str(tmp_path)], capture_output=True, text=True, timeout=300, cwd=REPO)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["inputs"] == 120 and len(report["rss_mb"]) == 7 and report["escaped"] == 0
    assert "Instrumenting" not in out.stderr
