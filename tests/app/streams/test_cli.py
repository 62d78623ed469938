"""``--stream`` on `imucap demo` (live, through the simulated suit) and `imucap replay`
(paced to real time times ``--stream-speed``), received by OSC servers in the test."""

from __future__ import annotations

import json
import time

import numpy as np
import pytest
import torch

from app.cli.main import main
from app.recording import read_recording
from inference.features.layout import N_FEATURES
from inference.model.config import ModelConfig
from inference.model.files import build_model, save_model

from .conftest import OscInbox


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("model") / "tiny.pt"
    save_model(path, build_model("diffusion", ModelConfig.tiny()).eval(), "diffusion",
               np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32),
               meta={"default_steps": [1000, 500, 0]})
    return path


@pytest.fixture
def two_inboxes():
    a, b = OscInbox(), OscInbox()
    yield a, b
    a.close()
    b.close()


def test_demo_streams_the_live_body(tiny_model, two_inboxes, capsys):
    vmc, vrc = two_inboxes
    rc = main(["demo", "--headless", "--json", "--seconds", "5", "--model", str(tiny_model), "--threads", "1",
               "--sensors", "pelvis,l_wrist,r_shank", "--stream", f"vmc:{vmc.port},vrchat:{vrc.port},lsl"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    by = {s["kind"]: s for s in out["streams"]}
    assert by["vmc"]["target"] == f"127.0.0.1:{vmc.port}" and by["vmc"]["errors"] == 0
    assert by["vmc"]["bundles"] == by["vrchat"]["bundles"] == by["lsl"]["samples"]["body"] == out["frames"] > 10
    assert by["lsl"]["streams"]["body"] == "imucap body" and by["lsl"]["samples"]["sensors"] > 2 * out["frames"]
    vmc.wait_for("/VMC/Ext/OK", out["frames"])
    vrc.wait_for("/tracking/trackers/head/rotation", out["frames"])
    assert vmc.count("/VMC/Ext/Bone/Pos") == 22 * out["frames"]


def test_demo_rejects_a_bad_stream(capsys):
    assert main(["demo", "--headless", "--stream", "lsl,osc"]) == 2
    err = capsys.readouterr().err
    assert "unknown stream 'osc'; valid: lsl, vmc, vrchat" in err and err.count("\n") == 1


def test_replay_streams_at_the_recorded_pace(recorded, two_inboxes, capsys, monkeypatch):
    """Paced, the replay holds frames back to the recording's pace; at speed 0 it never waits.
    The waits are counted, not timed: a busy machine makes any replay slow, and a wall-clock
    bound on the unpaced run failed beside other work."""
    import app.cli.replay as cli_replay
    from app.streams.pacing import Pacer

    slept: list[float] = []

    def sleep(seconds: float) -> None:
        slept.append(seconds)
        time.sleep(seconds)

    class CountingPacer(Pacer):
        def __init__(self, speed: float = 1.0) -> None:
            super().__init__(speed, sleep=sleep)

    monkeypatch.setattr(cli_replay, "Pacer", CountingPacer)
    vrc, _ = two_inboxes
    rec = read_recording(recorded.path)
    span = float(rec.raw["t"][-1] - rec.raw["t"][0])
    t0 = time.monotonic()
    rc = main(["replay", str(recorded.path), "--model", "floor", "--json", "--no-progress",
               "--stream", f"vrchat:{vrc.port}", "--stream-speed", "4"])
    elapsed = time.monotonic() - t0
    assert rc == 0
    res = json.loads(capsys.readouterr().out)
    assert slept and elapsed > 0.9 * span / 4  # it waited for the pace (a lower bound: holds however busy)
    (s,) = res["streams"]
    assert s["kind"] == "vrchat" and s["bundles"] == res["frames"] > 40 and s["errors"] == 0
    vrc.wait_for("/tracking/trackers/head/rotation", res["frames"])

    slept.clear()
    assert main(["replay", str(recorded.path), "--model", "floor", "--json", "--no-progress",
                 "--stream", f"vrchat:{vrc.port}", "--stream-speed", "0"]) == 0
    assert slept == []  # as fast as it goes
    capsys.readouterr()


@pytest.mark.parametrize("argv, message", [
    (["--stream", "vmc:x"], "the port must be a number"),
    (["--stream", "vmc", "--stream-speed", "-1"], "--stream-speed must be >= 0"),
])
def test_replay_stream_errors(recorded, capsys, argv, message):
    assert main(["replay", str(recorded.path), "--model", "floor", *argv]) == 2
    cap = capsys.readouterr()
    assert message in cap.err and cap.err.count("\n") == 1 and cap.out == ""
