"""`imucap demo --headless --json`: the contract (DESIGN.md), a few seconds of a simulated
suit through the real drivers, hub, calibration and poser. A tiny random model stands in
for the shipped weights so the test does not depend on training."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from app.cli.main import main
from app.demo_session import assignment_for
from app.recording import read_recording
from inference.features.layout import N_FEATURES
from inference.model.config import ModelConfig
from inference.model.files import build_model, save_model


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    path = tmp_path_factory.mktemp("model") / "tiny.pt"
    save_model(path, build_model("diffusion", cfg).eval(), "diffusion", np.zeros(N_FEATURES, np.float32),
               np.ones(N_FEATURES, np.float32), meta={"default_steps": [1000, 500, 0]})
    return path


def test_the_suit_can_run_inside_the_demo_process_too(tiny_model, capsys):
    rc = main(["demo", "--headless", "--json", "--seconds", "5", "--frames", "11", "--model", str(tiny_model),
               "--threads", "1", "--sensors", "pelvis,r_shank", "--protocol", "mixed", "--suit", "thread"])
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert rc == 0 and out["suit"] == "thread" and out["calibration_status"] == "calibrated"
    assert out["frames"] > 10 and all(st["packets"] > 100 for st in out["sites"].values())


def test_headless_json_contract(tiny_model, tmp_path, capsys):
    rec = tmp_path / "demo.h5"
    # a frame budget, not the clock: a busy machine makes fewer poses in the 6 s, and the demo runs on for them
    rc = main(["demo", "--headless", "--json", "--seconds", "6", "--frames", "30", "--model", str(tiny_model),
               "--threads", "1", "--sensors", "pelvis,l_wrist,r_shank", "--protocol", "mixed", "--record", str(rec)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    for key in ("frames", "fps", "latency_p50_ms", "latency_p99_ms", "sites", "calibration_residual_deg", "ga_deg",
                "model", "steps"):
        assert key in out, key
    assert out["frames"] >= 30 and out["steps"] == 3 and out["model"].startswith("diffusion 1/32/64")
    assert out["calibration_status"] == "calibrated"
    assert out["suit"] == "process"  # the simulated devices in a child process, as real ones are outside
    assert out["calibration_residual_deg"] < 2.0
    assert out["calibration_error_deg"] < 2.0  # recovered strap rotations vs the drawn ones, through 3 drivers
    assert out["ga_deg"] is not None and np.isfinite(out["ga_deg"])
    assert out["latency_p99_ms"] >= out["latency_p50_ms"] > 0
    assert set(out["sites"]) == {"pelvis", "l_wrist", "r_shank"}
    for site, st in out["sites"].items():
        assert st["packets"] > 100 and st["errors"] >= 0 and st["gaps"] >= 0, site
    assert [out["sites"][s]["protocol"] for s in ("pelvis", "l_wrist", "r_shank")] == ["xbus", "xsens-can",
                                                                                      "bno08x-rvc"]
    r = read_recording(rec)
    assert r.metadata["steps"] == 3 and r.metadata["sensors"] == ["pelvis", "l_wrist", "r_shank"]
    assert r.metadata["mirror"] is False  # the tiny file says nothing; replays need to know
    assert r.metadata["stride_scale"] is True  # on by default; replays do as recorded
    # one shank worn: no strides from the shanks; the pelvis odometry walks the root
    assert out["stride"] == {"enabled": True, "shanks": False, "scale": None, "strides": 0, "odometry": True}
    assert r.metadata["pelvis_odometry"] is True
    assert len(r.calibrations) >= 1 and len(r.recon["t"]) >= out["frames"] - 25
    assert r.n_frames > 200


def test_assignment_and_bad_arguments(capsys):
    a = assignment_for(("pelvis", "head", "l_wrist", "r_wrist", "l_foot"), "mixed", True)
    assert a == {"pelvis": "xbus", "head": "xsens-can", "l_wrist": "bno08x-rvc", "r_wrist": "dualsense",
                 "l_foot": "xbus", "insoles": "moticon-udp"}
    assert main(["demo", "--headless", "--json", "--sensors", "pelvis,elbow"]) == 2
    assert "unknown sensor site" in capsys.readouterr().err
    assert main(["demo", "--headless", "--motion", "moonwalk"]) == 2
    capsys.readouterr()
    assert main(["demo", "--suit", "thread"]) == 2  # the window's devices always run in their own process
    assert "--suit thread needs --headless" in capsys.readouterr().err


def test_headless_demo_with_confidence(tiny_model, tmp_path, capsys):
    """--confidence: the live poses carry a spread, 0 on the measured segments, in the
    JSON and the recording."""
    rec = tmp_path / "conf.h5"
    rc = main(["demo", "--headless", "--json", "--seconds", "6", "--model", str(tiny_model), "--threads", "1",
               "--sensors", "pelvis,l_wrist,r_shank", "--protocol", "xbus", "--confidence", "--record", str(rec)])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    spread = out["spread_mean_deg"]
    measured = [spread[s] for s in ("pelvis", "l_forearm", "r_shank")]
    open_ = [v for s, v in spread.items() if s not in ("pelvis", "l_forearm", "r_shank")]
    assert max(measured) < 0.5 * np.mean(open_), spread
    r = read_recording(rec)
    s = np.asarray(r.recon["spread_deg"])
    assert s.shape[1] == 24 and np.isfinite(s).all(axis=1).mean() > 0.9


def test_a_frame_budget_the_machine_cannot_meet_fails_loudly(tiny_model, capsys):
    from app.demo_session import DemoConfig, DemoSession

    # the wait is a parameter of run_for, so the refusal is checked without 80 s of waiting
    session = DemoSession(DemoConfig(seconds=4.0, headless=True, model=str(tiny_model), sensors=("pelvis",),
                                     threads=1, suit="thread"))
    try:
        session.start()
        assert session.run_for(4.0, poses=100_000, timeout=6.0) is False
        assert session.session_time() >= 4.0 and 0 < session.pipeline.stats.poses < 100_000
    finally:
        session.stop()
    capsys.readouterr()
    assert main(["demo", "--frames", "10"]) == 2
    assert "--frames needs --headless" in capsys.readouterr().err
