"""The hub over a VR rig: one ``vmc-in://`` device (a real UDP socket on loopback) standing
for several sites, its samples routed by site onto the grid like IMU sites, with the IMU
channels their poses imply."""

from __future__ import annotations

import math
import socket
import threading
import time

import numpy as np
import pytest

from app.capture.twins import free_udp_port
from drivers import make_device
from drivers._math import quat_from_euler_zyx
from drivers.hub import Hub, Interpolation
from drivers.vmc import protocol as vmc
from inference.signals.resample import slerp_unit

G = 9.80665
R_CIRCLE, V_CIRCLE = 0.4, 1.2  # the right hand's circle: 3.6 m/s^2 toward its centre
YAW_RATE = 1.5  # rad/s: the head turns about the vertical


def poses(t: float) -> list[vmc.DevicePose]:
    w = V_CIRCLE / R_CIRCLE
    hand = np.array([0.3 + R_CIRCLE * math.cos(w * t), -0.3 + R_CIRCLE * math.sin(w * t), 1.0])
    yaw = YAW_RATE * t
    head_q = quat_from_euler_zyx(yaw, 0.0, 0.0)
    return [vmc.DevicePose("hmd", "HMD", np.array([0.0, 0.0, 1.64]), head_q),
            vmc.DevicePose("con", "CON-L", np.array([0.1, 0.25, 0.9]), np.array([1.0, 0, 0, 0])),
            vmc.DevicePose("con", "CON-R", hand, np.array([1.0, 0, 0, 0]))]


class Sender:
    """A bridge on loopback: a bundle every 1/72 s with its own clock, until stopped."""

    def __init__(self, port: int, rate: float = 72.0) -> None:
        self.port, self.rate = port, rate
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.sent = 0

    def _run(self) -> None:
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        t0 = time.monotonic()
        try:
            while not self.stop_event.is_set():
                t = self.sent / self.rate
                tx.sendto(vmc.encode_frame(poses(t), sender_time=20.0 + t), ("127.0.0.1", self.port))
                self.sent += 1
                self.stop_event.wait(max(0.0, t0 + self.sent / self.rate - time.monotonic()))
        finally:
            tx.close()

    def __enter__(self) -> Sender:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_event.set()
        self.thread.join(5.0)


@pytest.mark.parametrize("interpolate", [False, True], ids=["hold", "interpolate"])
def test_a_rig_is_one_device_and_three_sites(interpolate):
    port = free_udp_port()
    dev = make_device(f"vmc-in://127.0.0.1:{port}?head=HMD&l_hand=CON-L&r_hand=CON-R&id=vr")
    hub = Hub({"vr": dev}, latency=0.08, interpolation=Interpolation(slerp_unit) if interpolate else None)
    assert hub.sites == ("head", "l_wrist", "r_wrist")
    frames = []
    with Sender(port) as sender:
        hub.start()
        try:
            end = time.monotonic() + 30.0  # a deadline far beyond the ~2 s wanted, for a busy machine
            while time.monotonic() < end and (len(frames) < 120 or sender.sent < 150):
                frames += hub.poll()
                time.sleep(0.01)
        finally:
            hub.stop()
    assert len(frames) >= 120 and all(f.sites == ("head", "l_wrist", "r_wrist") for f in frames)
    present = np.array([f.present for f in frames])
    assert present[30:].mean(axis=0).min() > 0.8, present.mean(axis=0)  # a busy machine delays some samples
    late = [f for f in frames[30:] if f.present.all() and np.isfinite(f.free_acc).all()]
    assert len(late) > 40
    free = np.array([f.free_acc for f in late])
    acc = np.array([f.acc for f in late])
    gyro = np.array([f.gyro for f in late])
    np.testing.assert_allclose(np.linalg.norm(free[:, 2], axis=-1), V_CIRCLE ** 2 / R_CIRCLE, rtol=0.05)
    np.testing.assert_allclose(free[:, :2], 0.0, atol=0.05)  # head and left hand are still
    np.testing.assert_allclose(acc[:, 1], np.tile([0.0, 0.0, G], (len(late), 1)), atol=0.05)
    np.testing.assert_allclose(gyro[:, 0], np.tile([0.0, 0.0, YAW_RATE], (len(late), 1)), atol=1e-3)
    q = np.array([f.quat[1] for f in late])
    np.testing.assert_allclose(np.abs(q[:, 0]), 1.0, atol=1e-6)
    st = hub.status()
    assert set(st) == {"vr"} and st["vr"]["packets"] >= 3 * 120 and st["vr"]["errors"] == 0
    assert hub.tracks["vr"].ring.last_t() is not None  # a silent-device check reads the device's ring


def test_a_site_given_by_two_devices_is_refused():
    a = make_device(f"vmc-in://127.0.0.1:{free_udp_port()}?head=HMD&r_hand=CON-R")
    b = make_device(f"vmc-in://127.0.0.1:{free_udp_port()}?r_hand=OTHER")
    with pytest.raises(ValueError, match="site r_wrist is given twice"):
        Hub({"vr": a, "vr2": b})
    imu = make_device(f"ximu3://udp/{free_udp_port()}?ip=127.0.0.1")  # built, not opened
    with pytest.raises(ValueError, match="site head is given twice: by device head and by device vr"):
        Hub({"head": imu, "vr": a})


def test_a_rigs_latency_dates_its_samples_earlier():
    """Two receivers of the same bundles, one told the runtime's latency: its samples are
    dated that much earlier, the other's as they came."""
    pa, pb = free_udp_port(), free_udp_port()
    a = make_device(f"vmc-in://127.0.0.1:{pa}?head=HMD")
    b = make_device(f"vmc-in://127.0.0.1:{pb}?r_hand=CON-R&latency_ms=30")
    assert b.pose_age == 0.03 and "latency_ms=30" in b.describe()
    hub = Hub({"a": a, "b": b}, latency=0.08)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    hub.start()
    try:
        t0 = time.monotonic()
        for k in range(150):
            bundle = vmc.encode_frame(poses(k / 72.0), sender_time=5.0 + k / 72.0)
            tx.sendto(bundle, ("127.0.0.1", pa))
            tx.sendto(bundle, ("127.0.0.1", pb))
            time.sleep(max(0.0, t0 + (k + 1) / 72.0 - time.monotonic()))
        end = time.monotonic() + 10.0
        while time.monotonic() < end and min(len(hub.tracks[n].ring) for n in "ab") < 150:
            hub.poll()
            time.sleep(0.02)
        hub.poll()
    finally:
        hub.stop()
        tx.close()
    ta = hub.tracks["a"].site_rings["head"].last(100)[:, 0]
    tb = hub.tracks["b"].site_rings["r_wrist"].last(100)[:, 0]
    assert np.isfinite(ta).all() and np.isfinite(tb).all()
    assert np.median(ta - tb) == pytest.approx(0.030, abs=0.004)
    with pytest.raises(ValueError, match="latency_ms"):
        make_device(f"vmc-in://127.0.0.1:{pa}?head=H&latency_ms=fast")
