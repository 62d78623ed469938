"""The simulated MTi-600s of one CAN channel send through one shared bus; for another
process, that bus is served on 127.0.0.1 (python-can's ``remote`` interface)."""

from __future__ import annotations

import threading
import time
import uuid

import pytest
from can.interfaces import virtual

import drivers
from sim_devices.devices import DeviceFaults, make_sim_device, spinning_signals
from sim_devices.devices.can_loopback import SERVERS, loopback_channel, split_host_port
from sim_devices.devices.other_twins import SIM_CAN_BUSES

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


# --- across processes: a bus served on 127.0.0.1 (python-can's remote interface)


def test_two_twins_share_one_served_bus_which_outlives_an_unplugged_one(signals):
    channel = loopback_channel()
    sims = [make_sim_device("xsens-can", signals, "pelvis", interface="remote", channel=channel, id_offset=o,
                            faults=DeviceFaults(seed=k), name=f"mti{k}") for k, o in enumerate((0x100, 0x200))]
    for s in sims:
        s.start()
    devs = []
    try:
        assert sims[0].url.startswith(f"xsens-can://remote/{channel}?id_offset=0x100")
        assert len(SERVERS._served) >= 1 and split_host_port(channel) in SERVERS._served  # one server, both twins
        assert SERVERS._served[split_host_port(channel)].users == 2
        devs = [drivers.open_device(s.url) for s in sims]
        got = [collect(d, 50) for d in devs]
        assert all(len(g) >= 50 for g in got), [len(g) for g in got]
        assert [{x.device_id for x in g} for g in got] == [{"mti0"}, {"mti1"}]  # each its own frames
        sims[0].disconnect(1.0)  # pulled off the bus: it stops sending, the bus stays
        time.sleep(0.2)
        assert len(collect(devs[1], 30)) >= 30
    finally:
        for s in sims:
            s.stop()
    assert split_host_port(channel) not in SERVERS._served  # the last twin stopped: the bus is gone
    # the bus went with its server: the device says so (and would reconnect when it is back)
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and not any(e.kind == "disconnected" for e in devs[1].events):
        devs[1].read(0.2)
    assert any(e.kind == "disconnected" for e in devs[1].events), devs[1].events
    for d in devs:
        d.close()


def test_a_bus_is_served_on_loopback_only(signals):
    sim = make_sim_device("xsens-can", signals, "pelvis", interface="remote", channel="192.0.2.1:54701")
    with pytest.raises(ValueError, match="loopback"):
        sim.start()
    with pytest.raises(ValueError, match="HOST:PORT"):
        split_host_port("localhost")
