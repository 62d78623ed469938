"""The simulated suit through the real drivers and the hub; reconnect over a real pty."""

from __future__ import annotations

import time

import numpy as np

import drivers
from drivers.hub import Hub
from sim_devices.devices import make_sim_device, spinning_signals
from sim_devices.suit import SimulatedSuit


def test_suit_through_hub_mixed_protocols():
    sig = spinning_signals(("pelvis", "l_wrist", "r_wrist", "head", "l_foot", "r_foot"), seconds=30)
    assignment = {
        "pelvis": "xbus",
        "l_wrist": "xsens-can",
        "r_wrist": "xsens-can",
        "head": "bno08x-rvc",
        "l_foot": "dualsense",
        "insoles": "moticon-udp",
    }
    with SimulatedSuit(sig, assignment) as suit:
        devs = {site: drivers.make_device(url) for site, url in suit.urls().items()}
        with Hub(devs, latency=0.05) as hub:
            frames = list(hub.frames(duration=2.0))
    assert len(frames) > 60
    assert frames[0].sites == ("pelvis", "l_wrist", "r_wrist", "head", "l_foot")
    late = frames[len(frames) // 2 :]
    present = np.array([f.present for f in late])
    # (seen once in a full CI-like run: one pty site absent all through; the message says what its track saw)
    why = {n: (tr.clock.offset, tr.device.stats.as_dict(), [e.kind for e in tr.device.events])
           for n, tr in hub.tracks.items()}
    print("present", present.mean(axis=0), "tracks", why)  # shown by pytest when the assertion fails
    assert present.mean(axis=0).min() > 0.9, present.mean(axis=0)
    assert np.mean([f.insole_present for f in late]) > 0.9
    # every device ran its own clock (100 s apart); the hub mapped them all onto one. The
    # offsets are host-clock minus device-clock, so only their spread is fixed: their size
    # follows the host's uptime (an absolute bound failed on a freshly booted machine)
    offsets = [tr.clock.offset for tr in hub.tracks.values() if tr.name != "insoles"]
    assert None not in offsets
    assert np.diff(sorted(offsets)).min() > 50, offsets
    # two MTi on one CAN bus stay apart
    assert not np.allclose(late[-1].gyro[1], late[-1].gyro[2])


def test_xbus_reconnect_over_pty():
    sig = spinning_signals(("pelvis",), seconds=20)
    sim = make_sim_device("xbus", sig, "pelvis").start()
    try:
        with drivers.open_device(sim.url) as dev:
            before = [dev.read(1.0) for _ in range(20)]
            assert all(s is not None for s in before)
            sim.disconnect(0.4)  # unplug: the pty goes away, the same path returns later
            after = []
            deadline = time.monotonic() + 8.0
            while len(after) < 20 and time.monotonic() < deadline:
                s = dev.read(0.2)
                if s is not None and dev.stats.reconnects:
                    after.append(s)
            kinds = [e.kind for e in dev.events]
            assert "disconnected" in kinds and "reconnected" in kinds
            assert len(after) == 20 and dev.stats.reconnects >= 1
            # the driver configured the re-plugged device again
            assert sim.commands.count(0x30) >= 2 and sim.commands.count(0x10) >= 2
    finally:
        sim.stop()
