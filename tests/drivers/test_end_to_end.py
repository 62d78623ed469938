"""Every driver against its simulated twin over the real transport."""

from __future__ import annotations

import itertools
import time

import numpy as np
import pytest

import drivers
from drivers._math import quat_rotate
from sim_devices.devices import DeviceFaults, make_sim_device, spinning_signals

SITES = ("pelvis", "head", "l_foot", "r_foot")


@pytest.fixture(scope="module")
def signals():
    return spinning_signals(SITES, seconds=20.0)


def _collect(dev, n, timeout=10.0):
    out = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        s = dev.read(0.2)
        if s is not None:
            out.append(s)
    return out


def _check_imu(samples, sim):
    """Quaternion unit, gravity consistent with orientation, counters consecutive."""
    assert samples
    for s in samples:
        assert s.quat is not None and abs(np.linalg.norm(s.quat) - 1) < 1e-6
        if s.acc is not None:
            up = quat_rotate(s.quat, s.acc)
            assert np.allclose(up, [0, 0, 9.80665], atol=0.25), up


@pytest.mark.parametrize("protocol", ["xbus", "bno08x-rvc", "xsens-can", "dualsense"])
def test_driver_reads_twin(protocol, signals):
    sim = make_sim_device(protocol, signals, "pelvis", name="pelvis")
    if protocol == "xsens-can":
        sim.channel = f"e2e-{id(sim)}"
    sim.start()
    try:
        with drivers.open_device(sim.url) as dev:
            samples = _collect(dev, 40)
            assert len(samples) == 40
            assert dev.stats.decoded >= 40 and dev.stats.bad_checksum == 0
            _check_imu(samples[5:], sim)
            assert samples[-1].device_time is not None and samples[-1].device_time > samples[0].device_time
            if protocol == "xbus":
                assert sim.configured_outputs is not None  # it received SetOutputConfiguration
                # a command whose acknowledgement is late is sent again (the driver's retry, on a busy machine)
                assert [m for m, _ in itertools.groupby(sim.commands)][:3] == [0x30, 0xC0, 0x10]
                assert dev.acknowledged == [0x30, 0xC0, 0x10]
            if protocol != "dualsense":  # dualsense orientation comes from our AHRS: heading starts at 0
                k = len(samples) - 1
                q_true = sim.source.at(0.0)["quat"]
                assert q_true.shape == (4,)
                assert samples[k].free_acc is not None and np.linalg.norm(samples[k].free_acc) < 0.3
    finally:
        sim.stop()


def test_dualsense_ahrs_follows_rotation(signals):
    sim = make_sim_device("dualsense", signals, "pelvis")
    sim.start()
    try:
        with drivers.open_device(sim.url) as dev:
            samples = _collect(dev, 300)
        # spinning at 45 deg/s about z: yaw advances at that rate according to device time
        s0, s1 = samples[50], samples[-1]
        yaw = [2 * np.arctan2(s.quat[3], s.quat[0]) for s in (s0, s1)]
        dyaw = (np.degrees(yaw[1] - yaw[0]) + 180) % 360 - 180
        dt = s1.device_time - s0.device_time
        assert dyaw == pytest.approx(45.0 * dt, abs=3.0)
        assert dev.calibration is not None and dev.calibration.gyro_bias == (2, -3, 1)
        assert s1.battery == 85.0
    finally:
        sim.stop()


def test_moticon_udp_loopback_and_contacts(signals):
    sim = make_sim_device("moticon-udp", signals, "insoles")
    with drivers.open_device(sim.url) as dev:
        sim.start()
        try:
            samples = _collect(dev, 150)
        finally:
            sim.stop()
    assert len(samples) == 150
    force = np.array([s.extra["force"] for s in samples])
    contacts = np.array([s.extra["contacts"] for s in samples])
    # feet alternate each second: whenever one foot carries the weight, its contact is on
    left_loaded = force[:, 0] > 300
    assert np.all(contacts[left_loaded][5:, 0] | contacts[left_loaded][5:, 1])
    assert not np.any(contacts[left_loaded][5:, 2:])


def test_loss_bursts_and_corruption_are_counted(signals):
    faults = DeviceFaults(loss_rate=0.05, loss_burst=4, corrupt_rate=0.05, seed=3)
    sim = make_sim_device("bno08x-rvc", signals, "head", faults=faults)
    sim.start()
    try:
        with drivers.open_device(sim.url) as dev:
            samples = _collect(dev, 200)
            st = dev.stats
    finally:
        sim.stop()
    assert len(samples) == 200
    assert st.lost_packets > 0 and st.counter_gaps > 0
    assert st.bad_checksum + st.resyncs > 0
    gaps = [s.extra.get("lost_before", 0) for s in samples]
    assert sum(gaps) == st.lost_packets
