"""Which DOT and x-IMU3 URLs a simulator can serve, and setup twins of real ones."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.capture.setup_file import SensorEntry, Setup, Subject
from app.capture.twins import simulated_url, simulation_problem, twin_setup
from drivers import make_device, parse_url


@pytest.mark.parametrize("url,why", [
    ("movella-dot://D4:22:CD:00:01:27", "a real DOT over Bluetooth"),
    ("ximu3://tcp/192.168.1.5:7000", "an x-IMU3 over tcp"),
    ("ximu3://serial/dev/ttyACM0", "an x-IMU3 over serial"),
    ("ximu3://udp/8000?ip=192.168.1.5", "192.168.1.5 is not a loopback address"),
    ("ximu3://udp/x", "needs the port"),
])
def test_real_or_outside_urls_are_refused_with_the_reason(url, why):
    assert why in (simulation_problem(url) or "")


def test_simulated_urls_open_as_drivers(tmp_path: Path):
    for proto in ("movella-dot", "ximu3"):
        url = simulated_url("l_shank", proto, tmp_path, 0)
        assert simulation_problem(url) is None, url
        dev = make_device(url)
        assert dev.scheme == proto
    assert parse_url(simulated_url("head", "movella-dot", tmp_path, 0)).get("ble") == f"{tmp_path}/ble"


def test_twin_setup_of_real_wireless_sensors(tmp_path: Path):
    setup = Setup(subject=Subject("s", 1.8, ""), sensors={
        "head": SensorEntry("head", "movella-dot://D4:22:CD:00:01:27"),
        "pelvis": SensorEntry("pelvis", "ximu3://tcp/192.168.1.5:7000"),
    })
    twin = twin_setup(setup, tmp_path)
    for site, scheme in (("head", "movella-dot"), ("pelvis", "ximu3")):
        url = twin.sensors[site].url
        assert parse_url(url).scheme == scheme and simulation_problem(url) is None, url
