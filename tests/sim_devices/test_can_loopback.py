"""Simulated MTi-600s reach a driver over a CAN bus served on 127.0.0.1 (python-can's
``remote`` interface), as imucap reaches a simulator in another process."""

from __future__ import annotations

import time

import pytest

import drivers
from sim_devices.devices import DeviceFaults, make_sim_device, spinning_signals
from sim_devices.devices.can_loopback import SERVERS, loopback_channel, split_host_port

pytestmark = pytest.mark.xdist_group("realtime_or_heavy")  # streams in real time


@pytest.fixture(scope="module")
def signals():
    return spinning_signals(("pelvis",), seconds=20.0)


def collect(dev, n: int, timeout: float = 8.0) -> list:
    out: list = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        out.extend(dev.read_many(0.1))
    return out


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
