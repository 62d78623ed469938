"""The simulated suit in its own process: the devices a demo opens are the child's, over
their real transports (pty, CAN on a bus served on 127.0.0.1, UDP), and the child ends with
its parent."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import numpy as np
import pytest

import drivers
from drivers.hub import Hub
from sim_devices.devices import spinning_signals
from sim_devices.suit_process import SuitProcess


def test_a_suit_in_a_child_process_reaches_the_hub_over_every_transport():
    sig = spinning_signals(("pelvis", "l_wrist", "r_wrist", "head", "l_foot", "r_foot"), seconds=30)
    assignment = {"pelvis": "xbus", "l_wrist": "xsens-can", "r_wrist": "xsens-can", "head": "bno08x-rvc",
                  "l_foot": "dualsense", "insoles": "moticon-udp"}
    suit = SuitProcess(sig, assignment, seed=3).start()
    try:
        assert suit.alive() and suit.proc is not None and suit.proc.pid != os.getpid()
        urls = suit.urls()
        assert set(urls) == set(assignment)
        assert urls["l_wrist"].startswith("xsens-can://remote/127.0.0.1:")  # a per-process virtual bus cannot cross
        # every twin started its clock in the child, on the machine's one monotonic clock
        assert all(abs(t - time.monotonic()) < 60 for t in suit.t0s.values())
        devs = {site: drivers.make_device(url) for site, url in urls.items()}
        with Hub(devs, latency=0.05) as hub:
            frames = list(hub.frames(duration=2.0))
    finally:
        suit.stop()
    assert not suit.alive()
    late = frames[len(frames) // 2:]
    assert len(frames) > 60
    assert np.array([f.present for f in late]).mean(axis=0).min() > 0.9
    assert np.mean([f.insole_present for f in late]) > 0.9
    assert not np.allclose(late[-1].gyro[1], late[-1].gyro[2])  # two MTi on one CAN bus stay apart
    # the child's own packet counts come back when it stops
    assert set(suit.stats) == set(assignment)
    assert all(st["sent"] > 100 for st in suit.stats.values()), suit.stats


def test_a_suit_that_cannot_start_says_why():
    sig = spinning_signals(("pelvis",), seconds=5)
    with pytest.raises(RuntimeError, match=r"the simulated suit did not start: .*unknown protocol 'morse'"):
        SuitProcess(sig, {"pelvis": "morse"}).start()


PARENT = """
import os, sys, json
from sim_devices.devices import spinning_signals
from sim_devices.suit_process import SuitProcess
suit = SuitProcess(spinning_signals(("pelvis",), seconds=30), {"pelvis": "xbus"}).start()
print(suit.proc.pid, flush=True)
os._exit(0)  # dies without stopping it, as a crashed or killed demo would
"""


def test_the_suit_ends_when_its_parent_dies():
    out = subprocess.run([sys.executable, "-c", PARENT], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    pid = int(out.stdout.split()[0])
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            break
        # a zombie (exited, not yet reaped by init) has ended too
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().split(")")[-1].split()[0] == "Z":
                    break
        except FileNotFoundError:
            break
        time.sleep(0.1)
    else:
        os.kill(pid, 9)
        pytest.fail(f"the suit process {pid} outlived its parent by 15 s")
