"""`imucap batch --report`: one gait report per recording, of the batch's own replay; a recording with no
walking gets a report that says so; a second run finds the reports done and writes nothing."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from app.capture.offline_session import write_session
from app.report.analysis import analyse
from app.report.events import truth_contact_values
from app.report.html import SECTIONS
from inference.signals.synthesis import kinematics
from sim_devices.motions import generate

pytestmark = [pytest.mark.slow, pytest.mark.xdist_group("batch_report")]
CLI = [sys.executable, "-m", "app.cli.main"]
WALK_SEED = 3


def batch(study: Path, out: Path, *extra: str) -> dict:
    res = subprocess.run([*CLI, "batch", str(study), "--out", str(out), "--report", "--model", "regressor",
                          "--workers", "1", "--no-held-out", "--json", "--no-progress", *extra],
                         capture_output=True, text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def reported(tmp_path_factory):
    study = tmp_path_factory.mktemp("study")
    write_session(study / "walk.h5", seconds=8.0, seed=WALK_SEED)
    write_session(study / "stand.h5", seconds=5.0, seed=4, motion="stand")
    out = study.parent / (study.name + "_out")
    return study, out, batch(study, out)


def test_each_recording_gets_a_report_of_the_batch_replay(reported):
    _, out, summary = reported
    assert summary["done"] == 2 and summary["failed"] == []
    walk = json.loads((out / "walk" / "report.json").read_text())
    assert walk["html"] == "report.html"
    assert "(imucap batch)" in walk["session"]["model"] and walk["session"]["model"].startswith("regressor")
    assert walk["sensors"] == ["pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank"]
    # the walk the session was synthesized from, analysed from its own truth: the same cadence
    m = generate("walk", seconds=8.0, seed=WALK_SEED)
    kin = kinematics(m.resample(60.0), 60.0)
    t = np.arange(len(kin.rot)) / 60.0
    truth = analyse(t, kin.rot, kin.root, t, truth_contact_values(kin.contact_pos, 60.0), "truth", threshold=0.0)
    assert walk["strides"]["l"] >= 4 and walk["strides"]["r"] >= 4
    assert walk["cadence_spm"] == pytest.approx(truth.summary.cadence_spm, rel=0.05)
    html = (out / "walk" / "report.html").read_text()
    for sec in SECTIONS:
        assert (f'<section id="{sec}"' in html) == (sec != "compare")
    result = json.loads((out / "walk" / "result.json").read_text())
    assert {"report.html", "report.json"} <= set(result["files"])


def test_a_recording_without_walking_says_so(reported):
    _, out, _ = reported
    stand = json.loads((out / "stand" / "report.json").read_text())
    assert stand["strides"] == {"l": 0, "r": 0} and stand["cadence_spm"] is None and stand["speed_mps"] is None
    assert "No walking found" in (out / "stand" / "report.html").read_text()


def test_a_second_run_finds_the_reports_done(reported):
    study, out, _ = reported
    before = {p: p.stat().st_mtime_ns for p in out.rglob("report.*")}
    again = batch(study, out)
    assert again["done"] == 0 and again["skipped"] == 2
    assert {p: p.stat().st_mtime_ns for p in out.rglob("report.*")} == before
    (out / "walk" / "report.html").unlink()  # a report lost: that recording is done again, with its report
    third = batch(study, out)
    assert third["done"] == 1 and (out / "walk" / "report.html").is_file()
