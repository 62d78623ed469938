"""The confidence on the command line: `imucap bench --json` times the loop with it under
``confidence``; `imucap evaluate --confidence` scores it and writes the calibration tables;
`imucap replay --confidence` reports the mean spread."""

from __future__ import annotations

import json

import pytest

from app.cli.main import main
from app.export.bvh import write_motion_bvh
from inference.evaluation.runner import synthetic_motion
from inference.poser.models import DEFAULT_WEIGHTS

needs_weights = pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")


def test_bench_reports_the_loop_with_confidence(capsys):
    code = main(["bench", "--json", "--random-weights", "--frames", "3", "--warmup", "1", "--threads", "1",
                 "--steps", "2", "--no-paper", "--no-onnx"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0
    c = res["confidence"]
    assert 0 < c["p50_ms"] <= c["p99_ms"] and c["draws"] >= 1 and c["pool"] >= 1 and c["steps"] == 2
    code = main(["bench", "--json", "--random-weights", "--frames", "3", "--warmup", "1", "--threads", "1",
                 "--steps", "2", "--no-paper", "--no-onnx", "--no-confidence"])
    assert "confidence" not in json.loads(capsys.readouterr().out)


@needs_weights
def test_evaluate_scores_the_spread_and_writes_the_tables(tmp_path, capsys):
    write_motion_bvh(tmp_path / "walk.bvh", synthetic_motion(seconds=2.0, seed=1))
    md = tmp_path / "conf.md"
    code = main(["evaluate", "--data", str(tmp_path / "walk.bvh"), "--sensors", "pelvis,l_wrist,r_wrist",
                 "--confidence", "--confidence-report", str(md), "--json", "--no-progress"])
    res = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0
    c = res["confidence"]
    assert -1 <= c["spearman_pooled"] <= 1 and 0 <= c["inside_90"] <= 1 and c["frames"] == res["frames"]
    assert c["segments"]["l_forearm"]["spread"] == 0.0 and c["segments"]["l_upperarm"]["spread"] > 0
    text = md.read_text()
    assert "| 6 sites |" in text and "| 2 sites (shanks) |" in text and "imucap evaluate" in text


def test_evaluate_confidence_report_needs_confidence(tmp_path, capsys):
    write_motion_bvh(tmp_path / "walk.bvh", synthetic_motion(seconds=1.0, seed=1))
    code = main(["evaluate", "--data", str(tmp_path / "walk.bvh"), "--model", "floor", "--fit-bands", "--json"])
    assert code == 2 and "--confidence" in capsys.readouterr().err


@needs_weights
def test_replay_reports_the_mean_spread(recorded, tmp_path, capsys):
    out = tmp_path / "r.csv"
    code = main(["replay", str(recorded.path), "--model", "diffusion", "--confidence", "--sensors",
                 "pelvis,l_wrist,r_wrist", "--json",
                 "--no-progress", "--out", str(out)])
    res = json.loads(capsys.readouterr().out)
    assert code == 0
    spread = res["spread_mean_deg"]
    assert spread["l_forearm"] == 0.0 and spread["l_upperarm"] > 0.0
    assert "l_upperarm_spread_deg" in out.read_text().splitlines()[0]
