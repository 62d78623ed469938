"""`imucap batch` over a small study: 10 recordings of different lengths (1.2-2.0 s of walk each,
as short as a replay with a few dozen poses), one damaged.

The default process pool and a Dask cluster of two worker processes on 127.0.0.1 give
byte-identical outputs; the damaged file is one failed row with its reason; a second run
does no work but try the failed one again; a Dask worker killed in the middle of a recording
loses nothing and writes nothing twice; Ctrl-C stops cleanly and the same command finishes
the job. Dead local workers, a second Ctrl-C, upgrades: test_batch_faults.py.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import pytest

from app.batch.plan import find_inputs
from app.batch.task import JOURNAL, RESULT, RUNNING
from app.capture.offline_session import write_session
from inference.loaders import load_motion

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("batch")]
CLI = [sys.executable, "-m", "app.cli.main"]
N = 10
SUBSET = "pelvis,l_shank,r_shank"


# session-scoped: built once per worker even if the worker's order tears module fixtures down
# between two of this module's tests (the suite once built ``pooled`` twice)
@pytest.fixture(scope="session")
def study(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("study")
    for k in range(N - 1):
        (root / f"P{k % 4:02d}").mkdir(exist_ok=True)
        write_session(root / f"P{k % 4:02d}" / f"trial{k:02d}.h5", seconds=1.2 + 0.1 * k, seed=k)
    whole = (root / "P00" / "trial00.h5").read_bytes()
    (root / "P03" / "damaged.h5").write_bytes(whole[:1500])  # a copy cut short in transfer
    return root


def batch(study: Path, out: Path, *extra: str, timeout: float = 600) -> dict:
    res = subprocess.run([*CLI, "batch", str(study), "--out", str(out), "--sensors", SUBSET, "--export", "bvh",
                          "--export", "csv", "--no-held-out", "--json", "--no-progress", *extra],
                         capture_output=True, text=True, timeout=timeout)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


def outputs(out: Path) -> dict[str, bytes]:
    return {p.relative_to(out).as_posix(): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.suffix in (".bvh", ".csv") and p.name != "summary.csv"}


def summary_rows(out: Path) -> list[dict[str, str]]:
    with open(out / "summary.csv", newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="session")
def pooled(study, tmp_path_factory) -> tuple[Path, dict]:
    out = tmp_path_factory.mktemp("pooled")
    return out, batch(study, out, "--workers", "2")


def test_pool_does_every_recording_and_names_the_damaged_one(pooled):
    out, res = pooled
    assert res["done"] == N - 1 and res["skipped"] == 0 and res["recordings"] == N
    assert [Path(f["recording"]).name for f in res["failed"]] == ["damaged.h5"]
    assert "not an HDF5 file" in res["failed"][0]["reason"] and "\n" not in res["failed"][0]["reason"]
    rows = summary_rows(out)
    assert len(rows) == 2 * (N - 1) + 1  # recording x subset, and the failed one
    failed = [r for r in rows if r["status"] == "failed"]
    assert len(failed) == 1 and failed[0]["reason"] == res["failed"][0]["reason"]
    ok = [r for r in rows if r["status"] == "ok"]
    assert {r["subset"] for r in ok} == {"all", "pelvis+l_shank+r_shank"}
    assert all(int(r["frames"]) > 10 for r in ok)
    assert all(float(r["ga_vs_recorded_deg"]) >= 0 for r in ok)
    assert len(outputs(out)) == 4 * (N - 1)
    # every BVH reads back as motion of the right length
    for name in outputs(out):
        if name.endswith(".bvh"):
            row = next(r for r in ok if Path(r["recording"]).stem == Path(name).parent.name
                       and r["subset"] == Path(name).stem)
            assert load_motion(out / name).n_frames == int(row["frames"])
    import pyarrow.parquet as pq

    assert pq.read_table(out / "summary.parquet").num_rows == len(rows)


def test_a_second_run_does_no_work_but_try_the_failed_one_again(pooled, study):
    out, _ = pooled
    before = {p: p.stat().st_mtime_ns for p in out.rglob("*") if p.is_file() and p.name != "summary.csv"
              and p.suffix != ".parquet"}
    res = batch(study, out, "--workers", "2")
    assert res["done"] == 0 and res["skipped"] == N - 1 and res["cpu_s"] == 0
    assert [Path(f["recording"]).name for f in res["failed"]] == ["damaged.h5"]  # tried again, failed again
    after = {p: p.stat().st_mtime_ns for p in before}
    assert after == before  # not one output, journal or result rewritten


def test_a_dask_cluster_gives_the_same_outputs_and_survives_a_lost_worker(pooled, study, tmp_path):
    from distributed import Client, LocalCluster

    out_pool, _ = pooled
    out = tmp_path / "dask"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                      scheduler_port=0, silence_logs=50) as cluster, Client(cluster) as client:
        proc = subprocess.Popen([*CLI, "batch", str(study), "--out", str(out), "--sensors", SUBSET, "--export", "bvh",
                                 "--export", "csv", "--no-held-out", "--json", "--no-progress", "--cluster",
                                 cluster.scheduler_address], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        killed = None
        deadline = time.monotonic() + 300
        while proc.poll() is None and time.monotonic() < deadline:
            done = list(out.rglob(RESULT)) if out.exists() else []
            if killed is None and len(done) >= 3:  # mid-run: some recordings done, most not
                workers = set(client.run(os.getpid).values())
                for mark in out.rglob(RUNNING):  # a worker in the middle of a recording says so there
                    try:
                        pid = json.loads(mark.read_text())["pid"]
                    except (OSError, ValueError):
                        continue
                    if pid not in workers:
                        continue
                    os.kill(pid, signal.SIGKILL)
                    # a worker removes its mark when the recording ends: still there (or the rerun's, elsewhere,
                    # which only an unfinished recording gets), the kill landed mid-recording
                    if mark.is_file():
                        killed = pid
                        break
            time.sleep(0.05)
        stdout, stderr = proc.communicate(timeout=60)
    assert killed is not None, "no Dask worker was caught in the middle of a recording"
    assert proc.returncode == 0, stderr[-3000:]
    res = json.loads(stdout.strip().splitlines()[-1])
    assert res["done"] == N - 1 and len(res["failed"]) == 1
    assert outputs(out) == outputs(out_pool)  # every output complete, and the pool's to the byte
    written = Counter()
    for journal in out.rglob(JOURNAL):
        for line in journal.read_text().splitlines():
            for f in json.loads(line)["files"]:
                written[(journal.parent, f)] += 1
    assert len(written) == 4 * (N - 1) and max(written.values()) == 1  # none written twice
    assert not [p for p in out.rglob("*") if ".tmp-" in p.name]  # no temporary left behind


def test_ctrl_c_stops_cleanly_and_the_same_command_finishes(study, tmp_path):
    out = tmp_path / "stopped"
    cmd = [*CLI, "batch", str(study), "--out", str(out), "--export", "bvh", "--no-held-out", "--json",
           "--no-progress", "--workers", "1"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and not (out.exists() and len(list(out.rglob(RESULT))) >= 2):
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 130, stderr[-2000:]
    first = json.loads(stdout.strip().splitlines()[-1])
    assert first["not_run"] > 0 and "stopping" in stderr
    assert not [p for p in out.rglob("*") if ".tmp-" in p.name]
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr[-2000:]
    second = json.loads(again.stdout.strip().splitlines()[-1])
    assert second["skipped"] == first["done"] and second["done"] + second["skipped"] == N - 1


def test_a_manifest_carries_its_columns_and_held_out_errors(study, tmp_path):
    manifest = tmp_path / "study.csv"
    manifest.write_text("recording,subject,condition\n"
                        f"{study / 'P01' / 'trial01.h5'},S1,brace\n{study / 'P02' / 'trial02.h5'},S2,none\n")
    assert [i.meta for i in find_inputs([str(manifest)])] == [{"subject": "S1", "condition": "brace"},
                                                              {"subject": "S2", "condition": "none"}]
    out = tmp_path / "out"
    res = subprocess.run([*CLI, "batch", str(manifest), "--out", str(out), "--sensors", SUBSET, "--json",
                          "--no-progress", "--workers", "1"], capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-2000:]
    rows = summary_rows(out)
    assert list(rows[0])[:4] == ["recording", "subject", "condition", "status"]
    sub = [r for r in rows if r["subset"] != "all"]
    assert [r["subject"] for r in sub] == ["S1", "S2"] and all(float(r["held_out_deg"]) > 0 for r in sub)


def test_inputs_that_are_not_there_are_an_error(tmp_path):
    bad = tmp_path / "m.csv"
    bad.write_text("file,subject\nx.h5,S1\n")
    with pytest.raises(ValueError, match="needs a 'recording' column"):
        find_inputs([str(bad)])
    with pytest.raises(ValueError, match="no recordings"):
        find_inputs([str(tmp_path / "nothing" / "*.h5")])
