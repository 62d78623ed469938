"""`imucap report` end to end on recordings the real Recorder wrote (tests/app/report/walks.py): the JSON
contract, a walk's figures against the motion's own, a stand that says there is no walk, a comparison,
and the HTML as headless Chromium shows it."""

from __future__ import annotations

import json
import re
import shutil

import numpy as np
import pytest

from app.cli.main import main
from app.report.browser import dump_dom, find_chromium, screenshot
from app.report.html import SECTIONS

from .walks import stand_recording, walk_recording

KEYS = ("sensors", "strides", "cadence_spm", "stride_time_s", "stance_pct", "knee_range_deg", "speed_mps")


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("report")
    return {"walk": walk_recording(d / "walk.h5", speed=1.3, seconds=10.0),
            "slow": walk_recording(d / "slow.h5", speed=0.8, seconds=12.0, seed=2),
            "stand": stand_recording(d / "stand.h5"), "dir": d}


def run_report(capsys, *args) -> dict:
    assert main(["report", *map(str, args), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_a_walk_gives_its_strides_and_figures(recordings, capsys):
    out = recordings["dir"] / "walk.html"
    s = run_report(capsys, recordings["walk"], "--out", out)
    for k in KEYS:
        assert k in s
    assert s["sensors"] == ["pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank"]
    assert s["strides"]["l"] >= 3 and s["strides"]["r"] >= 3
    assert 90 < s["cadence_spm"] < 130 and s["speed_mps"] == pytest.approx(1.3, abs=0.1)
    for side in ("l", "r"):
        assert 0.9 < s["stride_time_s"][side]["mean"] < 1.4
        assert 30 < s["stance_pct"][side] < 70
        assert 40 < s["knee_range_deg"][side] < 80
    c = s["confidence"]["joints"]
    assert c["l_knee_flexion"]["status"] == "inferred" and c["l_knee_flexion"]["inferred"] == ["l_thigh"]
    assert c["l_knee_flexion"]["expected_deg"] > 0  # from the real logs' pelvis + shanks
    html = out.read_text()
    assert "data:image/png;base64," in html and "<script" not in html  # self-contained, nothing to run
    assert "not clinical normative data" in html


def test_a_stand_says_there_is_no_walk(recordings, capsys):
    out = recordings["dir"] / "stand.html"
    s = run_report(capsys, recordings["stand"], "--out", out)
    assert s["strides"] == {"l": 0, "r": 0}
    for k in ("cadence_spm", "speed_mps"):
        assert s[k] is None
    assert s["stride_time_s"] == {"l": {"mean": None, "sd": None}, "r": {"mean": None, "sd": None}}
    assert s["stance_pct"] == {"l": None, "r": None} and s["knee_range_deg"] == {"l": None, "r": None}
    assert "No walking found" in out.read_text()


def test_a_slower_walk_is_marked_changed(recordings, capsys):
    out = recordings["dir"] / "compare.html"
    s = run_report(capsys, recordings["slow"], "--compare", recordings["walk"], "--out", out)
    rows = {r["figure"]: r for r in s["compare"]["rows"]}
    speed = rows["Walking speed"]
    assert speed["difference"] == pytest.approx(0.8 - 1.3, abs=0.12)
    assert rows["Cadence"]["after"] == pytest.approx(s["cadence_spm"], abs=0.01)
    assert speed["marked"] == (speed["expected_error"] is not None)
    same = run_report(capsys, recordings["walk"], "--compare", recordings["walk"], "--out", out)
    assert same["compare"]["marked"] == 0 and all(r["difference"] == 0 for r in same["compare"]["rows"]
                                                  if r["difference"] is not None)
    # the comparison's cadence is the one page one gives (120 s over the mean stride time; the mean of the
    # strides' own cadences is 0.7 steps/min more on this walk)
    cadence = next(r for r in same["compare"]["rows"] if r["figure"] == "Cadence")
    assert cadence["before"] == cadence["after"] == pytest.approx(same["cadence_spm"], abs=0.01)


@pytest.mark.skipif(find_chromium() is None, reason="chromium is not installed (scripts/test.sh installs it)")
def test_the_report_in_a_real_browser(recordings, capsys, tmp_path):
    out = tmp_path / "walk.html"
    run_report(capsys, recordings["walk"], "--compare", recordings["slow"], "--out", out, "--pdf")
    assert out.with_suffix(".pdf").read_bytes()[:5] == b"%PDF-"
    png = screenshot(out, tmp_path / "page.png", width=1100, height=3000)
    from PIL import Image

    img = np.asarray(Image.open(png).convert("L"), dtype=np.float64)
    assert img.shape == (3000, 1100) and img.std() > 20  # drawn: text, tables and plots, not a blank page
    dom = dump_dom(out)
    for sec in SECTIONS:
        m = re.search(rf'<section id="{sec}"[^>]*>(.*?)</section>', dom, re.S)
        assert m, f"section {sec} missing"
        text = re.sub(r"<[^>]+>", " ", m.group(1))
        assert re.search(r"\d+\.\d", text), f"section {sec} shows no number"
    assert dom.count("data:image/png;base64,") >= 3  # timeline, cycles, the comparison's cycles


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium is not installed")
def test_no_walk_in_the_browser(recordings, capsys, tmp_path):
    out = tmp_path / "stand.html"
    run_report(capsys, recordings["stand"], "--out", out)
    dom = dump_dom(out)
    assert "No walking found: 0 walking strides" in dom


def test_a_recording_posed_again_late(tmp_path, capsys):
    """``--answer-lag``: the report reads a replay's poses, each the window four frames later's, and says so;
    the recording's own poses (here the truth's) are read only with ``--answer-lag 0``. That the lag moves the
    inferred segments is tests/inference/poser/test_lag.py's."""
    rec = walk_recording(tmp_path / "walk.h5", speed=1.2, seconds=8.0, sites=("pelvis", "l_shank", "r_shank"),
                         raw=True, seed=4)
    truth = run_report(capsys, rec, "--out", tmp_path / "truth.html", "--answer-lag", "0")
    late = run_report(capsys, rec, "--out", tmp_path / "late.html", "--answer-lag", "4")
    assert "posed again 4 frames late" in late["session"]["model"] and truth["session"]["model"] == "truth (test)"
    assert (truth["posed"], late["posed"]) == ("its own poses", "posed again 4 frames late")
    # with no --answer-lag a live capture's report is posed again by the full model, as an import poses
    default = run_report(capsys, rec, "--out", tmp_path / "default.html")
    assert default["posed"] == "posed again 4 frames late" and "diffusionposer.pt" in default["session"]["model"]
    assert default["knee_range_deg"] == late["knee_range_deg"]
    assert "posed again 4 frames late" in (tmp_path / "late.html").read_text()
    assert late["strides"]["l"] >= 2 and late["strides"]["r"] >= 2
    knees = [[s["knee_range_deg"][side] for side in "lr"] for s in (truth, late)]
    assert all(k is not None and 20 < k < 90 for ks in knees for k in ks) and knees[0] != knees[1]
    # late poses are expected nearer the truth: the expected errors of the late sections (expected_error.json)
    knee = [s["confidence"]["joints"]["l_knee_flexion"]["expected_deg"] for s in (truth, late)]
    assert knee[1] < knee[0]
