"""`imucap devices` contract: probe prints samples, rate_hz, errors, first."""

from __future__ import annotations

import json

from app.cli.main import main
from sim_devices.devices import make_sim_device, spinning_signals


def test_probe_json_contract(capsys):
    sim = make_sim_device("bno08x-rvc", spinning_signals(("head",), seconds=10), "head").start()
    try:
        assert main(["devices", "probe", sim.url, "--seconds", "0.5", "--json"]) == 0
    finally:
        sim.stop()
    out = json.loads(capsys.readouterr().out)
    assert out["samples"] > 10 and out["rate_hz"] > 0 and out["errors"] == 0
    assert {"quat", "free_acc", "t"} <= set(out["first"])


def test_list_json_never_fails(capsys):
    assert main(["devices", "list", "--json"]) == 0
    assert "devices" in json.loads(capsys.readouterr().out)


def test_bad_url_is_a_clean_error(capsys):
    assert main(["devices", "probe", "nosuch://x", "--seconds", "0.1"]) == 2
    assert "unknown device scheme" in capsys.readouterr().err
