"""The DOT twin (behind the BLE seam's socket) and the x-IMU3 twin (UDP on loopback)
through the real drivers: values as played, a scan, the hub, and a 5 s drop rejoined."""

from __future__ import annotations

import time

import numpy as np
import pytest

import drivers
from drivers.hub import Hub
from drivers.movella_dot.ble_seam import SocketSeam
from drivers.movella_dot.driver import list_dots
from inference.body.rotations import quat_to_matrix
from inference.signals.synthesis import synthesize
from sim_devices.devices import DeviceFaults, make_sim_device, spinning_signals
from sim_devices.motions import generate
from sim_devices.suit import SimulatedSuit

G = 9.80665


@pytest.fixture(scope="module")
def walk():
    return synthesize(generate("walk", seconds=8.0, seed=2), rng=0, sites=("pelvis", "l_wrist"))


def _angle_deg(q1: np.ndarray, q2: np.ndarray) -> float:
    return float(np.degrees(2 * np.arccos(min(1.0, abs(float(np.dot(q1, q2)))))))


def _read(dev: drivers.Device, seconds: float) -> list[drivers.Sample]:
    out: list[drivers.Sample] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += dev.read_many(0.1)
    return out


@pytest.mark.parametrize("protocol", ["movella-dot", "ximu3"])
def test_twin_to_driver_values_as_played(walk, protocol):
    sim = make_sim_device(protocol, walk, "l_wrist").start()
    try:
        with drivers.open_device(sim.url) as dev:
            samples = _read(dev, 1.5)
            stats = dev.stats.as_dict()
    finally:
        sim.stop()
    rate = 60 if protocol == "movella-dot" else 100
    assert len(samples) > 0.5 * 1.5 * rate, stats
    assert stats["bad_frame"] == 0 and stats["disconnects"] == 0
    moving = 0
    for s in samples:  # the device clock is the twin's session clock here (no offset)
        truth = sim.source.at(s.device_time)
        assert _angle_deg(s.quat, truth["quat"]) < 0.01
        moving += float(np.linalg.norm(truth["free_acc"])) > 0.5
        if protocol == "movella-dot":
            np.testing.assert_allclose(s.free_acc, truth["free_acc"], atol=2e-3)
        else:  # the x-IMU3 sends specific force; free acceleration is the driver's R(q) f - g
            np.testing.assert_allclose(s.acc, truth["specific_force"], atol=1e-3)  # float32, µs stamps
            np.testing.assert_allclose(s.gyro, truth["gyro"], atol=1e-4)
            expect = quat_to_matrix(truth["quat"]) @ truth["specific_force"] - [0.0, 0.0, G]
            np.testing.assert_allclose(s.free_acc, expect, atol=2e-3)
    assert moving > 10  # a walk, not a still sensor
    assert samples[-1].battery == (87.0 if protocol == "movella-dot" else 76.0)
    dt = np.diff([s.device_time for s in samples])
    assert abs(np.median(dt) - 1 / rate) < 1e-4  # the sensor's own timestamps


def test_dot_scan_lists_name_address_battery(walk, tmp_path):
    sims = [make_sim_device("movella-dot", walk, site, folder=str(tmp_path)).start() for site in walk.sites]
    try:
        found = list_dots(SocketSeam(tmp_path), 1.0)
    finally:
        for s in sims:
            s.stop()
    assert sorted(d["path"] for d in found) == sorted(s.address for s in sims)
    for d in found:
        assert d["what"] == "Movella DOT" and d["battery"] == 87.0
        assert drivers.make_device(d["url"]).describe() == d["url"]


def test_dot_and_ximu3_through_the_hub_with_a_wired_sensor():
    sig = spinning_signals(("pelvis", "l_wrist", "r_wrist", "head"), seconds=30)
    assignment = {"pelvis": "xbus", "l_wrist": "movella-dot", "r_wrist": "movella-dot", "head": "ximu3"}
    with SimulatedSuit(sig, assignment) as suit:
        urls = suit.urls()
        assert drivers.parse_url(urls["l_wrist"]).get("ble") == drivers.parse_url(urls["r_wrist"]).get("ble")
        devs = {site: drivers.make_device(url) for site, url in urls.items()}
        with Hub(devs, latency=0.05) as hub:
            frames = list(hub.frames(duration=2.5))
    late = frames[len(frames) // 2:]
    present = np.array([f.present for f in late])
    assert present.mean(axis=0).min() > 0.9, present.mean(axis=0)
    offsets = [tr.clock.offset for tr in hub.tracks.values()]
    assert None not in offsets and np.diff(sorted(offsets)).min() > 50, offsets  # four device clocks, mapped


@pytest.mark.parametrize("protocol", ["movella-dot", "ximu3"])
def test_a_5_s_drop_rejoins_within_2_s_with_the_gap_in_the_data(walk, protocol):
    drop_at, drop_s = 1.0, 5.0
    sim = make_sim_device(protocol, walk, "pelvis", faults=DeviceFaults(disconnects=[(drop_at, drop_s)])).start()
    try:
        with drivers.open_device(sim.url) as dev:
            samples = _read(dev, drop_at + drop_s + 3.0)
            events = list(dev.events)
            stats = dev.stats.as_dict()
    finally:
        sim.stop()
    assert stats["disconnects"] == 1 and stats["reconnects"] == 1, (stats, events)
    back_at = sim.started_at + drop_at + drop_s  # when the twin came back (monotonic, as the events)
    rejoined = [e.t for e in events if e.kind == "reconnected"]
    assert rejoined and rejoined[0] - back_at < 2.0, (rejoined, back_at)
    t = np.array([s.device_time for s in samples])
    k = int(np.argmax(np.diff(t)))
    assert drop_s - 0.2 < t[k + 1] - t[k] < drop_s + 2.0  # the gap is in the data, on the sensor's clock
    assert t[-1] - t[k + 1] > 0.5  # and it streams again
