"""The simulated MTi-600s of one CAN channel send through one shared bus."""

from __future__ import annotations

import threading
import time
import uuid

import pytest
from can.interfaces import virtual

import drivers
from sim_devices.devices import DeviceFaults, make_sim_device, spinning_signals
from sim_devices.devices.other_twins import SIM_CAN_BUSES

pytestmark = pytest.mark.xdist_group("realtime_or_heavy")  # streams in real time

OFFSETS = (0x100, 0x200, 0x300)


@pytest.fixture(scope="module")
def signals():
    return spinning_signals(("pelvis",), seconds=20.0)


def sim_buses(channel: str) -> list:
    return [b for b in SIM_CAN_BUSES.open_buses() if b.key[1] == channel]


def collect(dev, n: int, timeout: float = 8.0) -> list:
    out: list = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out.extend(dev.read_many(0.1))
    return out


def test_sims_on_a_channel_share_one_sending_bus(signals):
    channel = f"twins-{uuid.uuid4().hex[:8]}"
    sims = [make_sim_device("xsens-can", signals, "pelvis", interface="virtual", channel=channel, id_offset=o,
                            faults=DeviceFaults(seed=k)) for k, o in enumerate(OFFSETS)]
    devs = [drivers.open_device(s.url) for s in sims]
    try:
        for s in sims:
            s.start()
        assert len(sim_buses(channel)) == 1 and len(sim_buses(channel)[0].taps) == len(OFFSETS)
        # one queue for the sims' bus, one for the drivers': no per-sensor copies nobody reads
        assert len(virtual.channels[channel]) == 2
        sims[0].stop()
        got = [[], []]
        readers = [threading.Thread(target=lambda d=d, g=g: g.extend(collect(d, 50)), daemon=True)
                   for d, g in zip(devs[1:], got, strict=True)]
        for th in readers:
            th.start()
        for th in readers:
            th.join(10.0)
        assert not any(th.is_alive() for th in readers)
        assert all(len(g) >= 50 for g in got), "the others keep sending after one sim left"
    finally:
        for s in sims:
            s.stop()
        for d in devs:
            d.close()
    assert sim_buses(channel) == []
    assert channel not in virtual.channels  # every bus on the channel was shut down


def test_a_sim_unplugged_and_back_rejoins_the_shared_bus(signals):
    channel = f"twins-{uuid.uuid4().hex[:8]}"
    sims = [make_sim_device("xsens-can", signals, "pelvis", interface="virtual", channel=channel, id_offset=o)
            for o in OFFSETS[:2]]
    try:
        for s in sims:
            s.start()
        shared = sim_buses(channel)[0]
        sims[0].disconnect(0.05)
        assert sim_buses(channel) == [shared] and len(shared.taps) == 1
        deadline = time.monotonic() + 8.0
        while not sims[0].connected and time.monotonic() < deadline:
            time.sleep(0.01)
        assert sims[0].connected and sim_buses(channel) == [shared] and len(shared.taps) == 2
    finally:
        for s in sims:
            s.stop()
