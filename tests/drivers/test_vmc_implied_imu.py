"""The IMU reading a tracked pose implies (``drivers/vmc/implied_imu.py``), on motions whose
answer is known in closed form, and on a ``vmc-in://`` device fed over a real socket."""

from __future__ import annotations

import math
import socket
import time

import numpy as np
import pytest

from app.capture.twins import free_udp_port
from drivers import open_device
from drivers.vmc import protocol as vmc
from drivers.vmc.implied_imu import ImpliedImu
from inference.body.rotations import quat_exp, quat_multiply, quat_to_matrix

G = 9.80665
UP = np.array([1.0, 0.0, 0.0, 0.0])


def circle(t: np.ndarray, r: float, v: float) -> np.ndarray:
    w = v / r
    return np.stack([r * np.cos(w * t), r * np.sin(w * t), np.full_like(t, 1.2)], -1)


def test_a_circle_at_known_speed_reads_v2_over_r_toward_the_centre():
    r, v, rate = 0.5, 1.5, 72.0  # 4.5 m/s^2, a hand swinging fast
    t = np.arange(200) / rate
    p = circle(t, r, v)
    imu = ImpliedImu()
    out = [imu.update(ti, pi, UP) for ti, pi in zip(t, p, strict=True)]
    assert all(o is None for o in out[:3]) and all(o is not None for o in out[6:])
    lag = 0.075  # the fit's estimate is the window's middle
    for k in range(20, 200, 17):
        a = out[k].free_acc
        assert np.linalg.norm(a) == pytest.approx(v * v / r, rel=0.02)
        centre = np.array([0.0, 0.0, 1.2]) - circle(np.array([t[k] - lag]), r, v)[0]
        cos = a @ centre / (np.linalg.norm(a) * np.linalg.norm(centre))
        assert cos > math.cos(math.radians(3.0))  # toward the centre, within 3 deg
        # unrotated device: the accelerometer reads the free acceleration plus 1 g up
        np.testing.assert_allclose(out[k].acc, a + [0, 0, G], atol=1e-9)


def test_a_constant_rate_turn_reads_the_rate_on_the_body_axis():
    rate_hz, w = 90.0, np.array([0.3, -1.1, 2.0])  # rad/s in the device's frame
    q0 = quat_exp(np.array([0.2, 0.5, -0.4]))
    imu = ImpliedImu()
    got = None
    for k in range(60):
        t = k / rate_hz
        q = quat_multiply(q0, quat_exp(w * t))  # body-frame rate: q' = q (0, w) / 2
        got = imu.update(t, np.zeros(3), q)
    assert got is not None
    np.testing.assert_allclose(got.gyro, w, atol=1e-6)
    # still position: the specific force is 1 g up, seen in the device's frame
    R = quat_to_matrix(q)
    np.testing.assert_allclose(got.acc, R.T @ [0, 0, G], atol=1e-6)
    np.testing.assert_allclose(got.free_acc, 0.0, atol=1e-6)


def test_uneven_times_noise_and_gaps():
    rng = np.random.default_rng(0)
    r, v = 0.4, 1.2
    # uneven sender times (72 Hz +-3 ms) and 1 mm tracking jitter per axis
    t = np.cumsum(rng.uniform(1 / 72 - 0.003, 1 / 72 + 0.003, 720))
    p = circle(t, r, v) + rng.normal(0.0, 0.001, (t.size, 3))
    imu = ImpliedImu()
    a = np.array([o.free_acc for ti, pi in zip(t, p, strict=True) if (o := imu.update(ti, pi, UP)) is not None])
    mag = np.linalg.norm(a[:, :2], axis=-1)
    assert np.mean(mag) == pytest.approx(v * v / r, rel=0.1)
    assert 0.15 < np.std(a[:, 2]) < 0.6  # ~0.3 m/s^2 per axis of the 1 mm jitter (module docstring)
    # a gap beyond MAX_GAP_S starts over: nothing implied across it
    assert imu.update(t[-1] + 0.5, p[-1], UP) is None
    # poses at one time (arrival stamps of one wake-up) are merged, never divided by zero
    same = ImpliedImu()
    outs = [same.update(0.01 * (k // 2), np.array([0.0, 0.0, 0.5 * 0.01 * (k // 2) ** 2]), UP) for k in range(20)]
    assert np.all(np.isfinite(outs[-1].free_acc))


def test_the_device_sends_the_implied_channels():
    port = free_udp_port()
    dev = open_device(f"vmc-in://127.0.0.1:{port}?head=H&r_hand=R")
    assert dev.site_names == {"head": "head", "r_hand": "r_wrist"}
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        r, v, rate = 0.5, 1.0, 72.0
        for k in range(40):
            t = k / rate
            p = circle(np.array([t]), r, v)[0]
            tx.sendto(vmc.encode_frame([vmc.DevicePose("hmd", "H", np.array([0.0, 0.0, 1.6]), UP),
                                        vmc.DevicePose("con", "R", p, UP)], sender_time=100.0 + t),
                      ("127.0.0.1", port))
        got: list = []
        end = time.monotonic() + 10.0
        while len(got) < 80 and time.monotonic() < end:
            got += dev.read_many(0.1)
        assert len(got) == 80
        hand = [s for s in got if s.extra["site"] == "r_hand"]
        head = [s for s in got if s.extra["site"] == "head"]
        assert hand[0].free_acc is None and hand[-1].free_acc is not None
        assert np.linalg.norm(hand[-1].free_acc) == pytest.approx(v * v / r, rel=0.02)
        np.testing.assert_allclose(head[-1].acc, [0.0, 0.0, G], atol=1e-3)
        np.testing.assert_allclose(head[-1].gyro, 0.0, atol=1e-6)
    finally:
        tx.close()
        dev.close()


def test_no_datagram_is_stamped_before_it_was_sent():
    """A sender in this process keeps sending while the device decodes a backlog: every
    sample's arrival stamp is at or after its send time (the hub's clock model trusts the
    earliest arrivals, so a stamp taken before the datagram came puts the rig early)."""
    import threading

    port = free_udp_port()
    dev = open_device(f"vmc-in://127.0.0.1:{port}?head=H")
    t0 = time.monotonic()
    stop = threading.Event()

    def send() -> None:
        tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            while not stop.is_set():
                st = time.monotonic() - t0  # small: exact in the bundle's float32
                tx.sendto(vmc.encode_frame([vmc.DevicePose("hmd", "H", np.zeros(3), UP)], sender_time=st),
                          ("127.0.0.1", port))
                time.sleep(0.0005)
        finally:
            tx.close()

    th = threading.Thread(target=send, daemon=True)
    th.start()
    delays: list[float] = []
    try:
        end = time.monotonic() + 20.0
        while len(delays) < 3000 and time.monotonic() < end:
            time.sleep(0.03)  # a backlog piles up, then is decoded while the sender goes on
            delays += [s.t - (t0 + s.device_time) for s in dev.read_many(0.0, max_samples=4096)]
    finally:
        stop.set()
        th.join(5.0)
        dev.close()
    assert len(delays) >= 1000
    assert min(delays) >= -1e-4, min(delays)  # float32 of times under 20 s: ~2 us
