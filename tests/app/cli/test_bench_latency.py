"""`imucap bench --end-to-end --json`: sensor-to-pose keys per latency mode (the low mode's
containing "low", a DESIGN.md contract) from one run of the real suit, drivers, hub and
pipeline; `imucap bench --json` times the ONNX Runtime call next to torch's. No wall-clock
assertions (the machine is shared)."""

from __future__ import annotations

import json

import pytest

import app.capture.end_to_end_bench as e2e
from app.cli.main import main
from inference.model.onnx_runtime import onnxruntime_available

MODE_KEYS = ("p50_ms", "p99_ms", "age_p50_ms", "age_p99_ms", "model_p50_ms", "poses", "hub_wait_ms", "acc_filter")


@pytest.mark.slow
def test_end_to_end_json_has_both_modes_from_one_run(capsys):
    code = main(["bench", "--end-to-end", "--json", "--seconds", "1.5", "--rounds", "1", "--threads", "1"])
    assert code == 0
    res = json.loads(capsys.readouterr().out)
    assert res["suit"] == "process"  # the demo's devices, in their own process
    for mode in ("centred", "low"):
        for k in MODE_KEYS:
            assert f"{mode}_{k}" in res
    assert {k for k in res if k.startswith("low_")} and all("low" in k for k in res if k.startswith("low_"))
    assert {"model_p50_ms", "model_p99_ms", "runtime", "load_avg_1min"} <= set(res)
    assert res["low_acc_filter"] == "causal" and res["centred_acc_filter"] == "centred"
    assert res["low_hub_wait_ms"] < res["centred_hub_wait_ms"]
    for mode in ("centred", "low"):
        p50, p99 = res[f"{mode}_p50_ms"], res[f"{mode}_p99_ms"]
        assert (p50 is None) == (res[f"{mode}_poses"] == 0)
        assert p50 is None or (0 < p50 <= p99)  # ordered and positive, whatever the load
    # the send logs crossed the process boundary and matched
    assert res["centred_poses"] > 0 and res["low_poses"] > 0


def test_end_to_end_rounds_alternate_the_modes(monkeypatch):
    order = []

    def fake(mode, seconds, model, **kw):
        order.append(mode)
        return {"mode": mode, "e2e_ms": [10.0, 20.0] if mode == "low" else [80.0], "age_ms": [12.0],
                "model_ms": [5.0], "poses": 3, "timed": 2, "unmatched": 0, "dropped": 0, "hub_frames_skipped": 0,
                "hub_wait_ms": 10.0, "acc_filter": "causal", "model": "m", "runtime": "torch", "warning": None}

    monkeypatch.setattr(e2e, "measure_mode", fake)
    res = e2e.run_end_to_end(seconds=1.0, rounds=3)
    assert order == ["centred", "low"] * 3
    assert res["low_p50_ms"] == 15.0 and res["centred_p50_ms"] == 80.0 and res["low_poses"] == 6


def test_send_times_are_found_through_wrapping_counters():
    log = [(n, 100.0 + n * 0.01) for n in range(600)]  # an 8-bit counter wraps twice in this log
    assert e2e._send_time(log, 300 % 256, 256, before=103.005) == pytest.approx(103.0)
    assert e2e._send_time(log, 43, 256, before=103.005) == pytest.approx(102.99)
    assert e2e._send_time(log, 45, 256, before=103.005) == pytest.approx(100.45)  # the one a wrap earlier
    assert e2e._send_time(log, 7, None, before=100.05) is None  # not sent yet


@pytest.mark.skipif(not onnxruntime_available(), reason="onnx or onnxruntime is not installed")
def test_bench_times_onnx_runtime_next_to_torch(capsys):
    code = main(["bench", "--json", "--random-weights", "--frames", "3", "--warmup", "1", "--threads", "1",
                 "--steps", "2", "--no-paper"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["runtime"] == "torch"
    assert 0 < res["onnx_p50_ms"] <= res["onnx_p99_ms"]
    o = res["onnx"]  # torch timed frame for frame in turn with it
    assert o["interleaved"] and o["onnx_p50_ms"] == res["onnx_p50_ms"] and 0 < o["torch_p50_ms"] <= o["torch_p99_ms"]
    code = main(["bench", "--json", "--random-weights", "--frames", "3", "--warmup", "1", "--threads", "1",
                 "--steps", "2", "--no-paper", "--no-onnx"])
    assert "onnx_p50_ms" not in json.loads(capsys.readouterr().out)
