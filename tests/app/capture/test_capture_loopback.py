"""Simulated devices and a capture send only to this machine.

The simulator (`imucap devices simulate --setup`) serves every protocol it can serve
across processes (Xbus and BNO08x on pseudo-terminals, two MTi-600 on a CAN bus, a
DualSense behind the HID seam, Moticon insoles on UDP), and `imucap capture` in a second
process reads them, each under strace. Every internet destination either process (or
any of its threads, compiled libraries included) connects or sends to must be a
loopback address: no multicast, no name lookups. The CAN devices must have delivered,
so the bus that crosses the processes is the one watched.

Tracing slows the processes, so nothing here judges real-time behaviour: the capture's
figures are the end-to-end test's (test_capture_e2e.py).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from app.capture.twins import free_udp_port
from sim_devices.devices.can_loopback import loopback_channel
from tests.socket_watch import STRACE, destinations, off_machine, watched

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(STRACE is None, reason="strace not installed (scripts/test.sh installs it)")]
CLI = [sys.executable, "-m", "app.cli.main"]



def write_setup(tmp: Path) -> Path:
    can_bus = loopback_channel()
    text = f"""[subject]
id = "sim-net"
height = 1.75

[sensors]
pelvis  = "xbus://{tmp}/pelvis-tty?baud=115200"
head    = "bno08x-rvc://{tmp}/head-tty"
l_wrist = "xsens-can://remote/{can_bus}?id_offset=0x100"
r_wrist = "xsens-can://remote/{can_bus}?id_offset=0x200"
l_shank = "dualsense://unix/{tmp}/l_shank.sock"
r_shank = "xbus://{tmp}/r_shank-tty?baud=115200"

[insoles]
url = "moticon-udp://127.0.0.1:{free_udp_port()}"

[model]
name = "diffusion"

[calibration]
protocol = "walk"
"""
    path = tmp / "setup.toml"
    path.write_text(text)
    return path


def test_simulator_and_capture_send_only_to_loopback(tmp_path):
    setup = write_setup(tmp_path)
    sim_log, cap_log = tmp_path / "simulate.strace", tmp_path / "capture.strace"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    sim = subprocess.Popen(watched([*CLI, "devices", "simulate", "--setup", str(setup), "--motion", "walk",
                                    "--lead-in", "30", "--seed", "2", "--seconds", "180", "--while-stdin-open"],
                                   sim_log),
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        for line in sim.stdout:
            if line.startswith("simulating"):
                break
        else:
            pytest.fail(f"the simulator did not start: {sim.stderr.read()[-2000:]}")
        cap = subprocess.run(watched([*CLI, "capture", "--setup", str(setup), "--headless", "--seconds", "8",
                                      "--json", "--countdown", "1"], cap_log),
                             stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=240, env=env)
    finally:
        sim.stdin.close()  # the simulator's signal to stop (a signal would reach strace, not the simulator)
        try:
            sim.wait(60)
        except subprocess.TimeoutExpired:
            sim.kill()
            sim.wait()
    assert cap.returncode == 0, cap.stderr[-3000:]
    result = json.loads(cap.stdout.strip().splitlines()[-1])
    devices = result["devices"]
    for name in ("l_wrist", "r_wrist", "l_shank", "insoles"):  # CAN, the HID seam and UDP all delivered
        assert devices[name]["packets"] > 50, (name, devices[name])
    sim_text, cap_text = sim_log.read_text(), cap_log.read_text()
    # the watch saw the traffic: the CAN bus and the insoles' datagrams are on 127.0.0.1
    assert any(d.address == "127.0.0.1" for d in destinations(cap_text)), cap_text[-2000:]
    assert any(d.address == "127.0.0.1" for d in destinations(sim_text)), sim_text[-2000:]
    away = [f"simulator: {d}" for d in off_machine(sim_text)] + [f"capture: {d}" for d in off_machine(cap_text)]
    assert not away, away
