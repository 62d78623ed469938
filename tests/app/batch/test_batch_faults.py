"""`imucap batch` when things go wrong, in real processes: a worker SIGKILLed in the middle of
a recording and a recording that crashes its worker natively each fail that recording alone,
the others are done; two Ctrl-C a second apart end the run with exit 130 and a summary.csv of
every recording finished; a failure is tried again by the next run; an upgrade of imucap, or
``--force``, redoes what was up to date."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.batch.task import RESULT, RUNNING
from app.capture.offline_session import write_session

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("batch_faults")]
HOOKED = [sys.executable, str(Path(__file__).with_name("hooked_batch.py"))]
N = 5


@pytest.fixture(scope="module")
def study(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("faults")
    for k in range(N):
        write_session(root / f"trial{k:02d}.h5", seconds=1.2 + 0.2 * k, seed=40 + k)
    return root


def command(study: Path, out: Path, *extra: str) -> list[str]:
    return [*HOOKED, "batch", str(study), "--out", str(out), "--export", "bvh", "--no-held-out", "--json",
            "--no-progress", *extra]


def run(study: Path, out: Path, *extra: str, env: dict[str, str] | None = None, code: int = 0) -> dict:
    res = subprocess.run(command(study, out, *extra), capture_output=True, text=True, timeout=600,
                         env={**os.environ, **(env or {})})
    assert res.returncode == code, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def rows(out: Path) -> list[dict[str, str]]:
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


def leftovers(out: Path) -> list[Path]:
    return [p for p in out.rglob("*") if ".tmp-" in p.name]


def parent_of(pid: int) -> int:
    stat = Path(f"/proc/{pid}/stat").read_text()
    return int(stat.rsplit(")", 1)[1].split()[1])


def test_a_worker_killed_mid_recording_fails_that_recording_alone(study, tmp_path):
    out = tmp_path / "killed"
    proc = subprocess.Popen(command(study, out, "--workers", "2"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    victim = None
    deadline = time.monotonic() + 300
    while proc.poll() is None and victim is None and time.monotonic() < deadline:
        for mark in out.rglob(RUNNING) if out.exists() else []:
            try:
                pid = json.loads(mark.read_text())["pid"]
            except (OSError, ValueError):
                continue  # being written or just removed
            try:
                ours = proc.pid in (parent_of(pid), parent_of(parent_of(pid)))  # forked by the batch's fork server
            except OSError:
                continue  # it has just ended
            if not ours:
                continue  # not one of this batch's workers
            # its mark says this worker is in the middle of this recording (a worker removes it as the task ends)
            os.kill(pid, signal.SIGKILL)
            victim = mark.parent.name + ".h5"
            break
        time.sleep(0.05)
    stdout, stderr = proc.communicate(timeout=600)
    assert victim is not None, "no worker was caught in the middle of a recording"
    assert proc.returncode == 0, stderr[-3000:]
    res = json.loads(stdout.strip().splitlines()[-1])
    assert [Path(f["recording"]).name for f in res["failed"]] == [victim]
    assert "SIGKILL" in res["failed"][0]["reason"] and "\n" not in res["failed"][0]["reason"]
    assert res["done"] == N - 1 and res["not_run"] == 0
    table = rows(out)
    assert {Path(r["recording"]).name for r in table if r["status"] == "ok"} == \
        {f"trial{k:02d}.h5" for k in range(N)} - {victim}
    assert [r["reason"] for r in table if r["status"] == "failed"] == [res["failed"][0]["reason"]]
    assert not leftovers(out) and not list(out.rglob(RUNNING))
    # the next run does the failed recording, and only it
    again = run(study, out, "--workers", "2")
    assert again["done"] == 1 and again["skipped"] == N - 1 and not again["failed"]


def test_a_native_crash_fails_that_recording_alone(study, tmp_path):
    out = tmp_path / "segfault"
    res = run(study, out, "--workers", "2", env={"IMUCAP_TEST_SEGFAULT": "trial01.h5"})
    assert [Path(f["recording"]).name for f in res["failed"]] == ["trial01.h5"]
    assert "SIGSEGV" in res["failed"][0]["reason"]
    assert res["done"] == N - 1
    assert sum(r["status"] == "ok" for r in rows(out)) == N - 1 and not leftovers(out)


def test_two_ctrl_c_end_with_130_and_the_table_of_what_is_finished(study, tmp_path):
    out = tmp_path / "stopped"
    proc = subprocess.Popen(command(study, out, "--workers", "1"), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and proc.poll() is None and not (out.exists() and list(out.rglob(RESULT))):
        time.sleep(0.05)
    while time.monotonic() < deadline and proc.poll() is None and not list(out.rglob(RUNNING)):
        time.sleep(0.05)  # the next recording under way
    proc.send_signal(signal.SIGINT)
    time.sleep(1.0)
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr[-3000:]
    assert "Traceback" not in stderr
    res = json.loads(stdout.strip().splitlines()[-1])
    finished = {p.parent.name + ".h5" for p in out.rglob(RESULT)}
    assert finished and res["done"] == len(finished) and not res["failed"]
    assert res["not_run"] == N - len(finished) > 0
    table = rows(out)
    assert {Path(r["recording"]).name for r in table} == finished and all(r["status"] == "ok" for r in table)
    assert not leftovers(out)


def test_failures_are_retried_and_an_upgrade_or_force_redoes_the_rest(study, tmp_path):
    out = tmp_path / "again"
    first = run(study, out, "--workers", "2", env={"IMUCAP_TEST_FAIL": "trial02.h5", "IMUCAP_TEST_VERSION": "1.0"})
    assert [Path(f["recording"]).name for f in first["failed"]] == ["trial02.h5"] and first["done"] == N - 1
    assert "file server did not answer" in first["failed"][0]["reason"]
    second = run(study, out, "--workers", "2", env={"IMUCAP_TEST_VERSION": "1.0"})
    assert second["done"] == 1 and second["skipped"] == N - 1 and not second["failed"]
    forced = run(study, out, "--workers", "2", "--force", "trial03*", env={"IMUCAP_TEST_VERSION": "1.0"})
    assert forced["done"] == 1 and forced["skipped"] == N - 1
    stamp = (out / "trial00" / "all.bvh").stat().st_mtime_ns
    upgraded = run(study, out, "--workers", "2", env={"IMUCAP_TEST_VERSION": "1.1"})
    assert upgraded["done"] == N and upgraded["skipped"] == 0
    assert (out / "trial00" / "all.bvh").stat().st_mtime_ns != stamp  # written again, not taken from the journal


def test_a_missing_model_is_one_line(study, tmp_path):
    res = subprocess.run(command(study, tmp_path / "x", "--model", str(tmp_path / "none.pt")), capture_output=True,
                         text=True, timeout=120)
    assert res.returncode == 2 and res.stderr.strip().count("\n") == 0 and "none.pt" in res.stderr
