"""The x-IMU3 driver over TCP (x-io's package connects): a device that goes away and comes
back on the same port is a lost link, then a reconnect, counted."""

from __future__ import annotations

import socket
import threading
import time

import drivers
from drivers.ximu3 import protocol as x3


def _serve_once(port: int, seconds: float, ready: threading.Event) -> None:
    """A device on ``port`` for ``seconds``: binary inertial + quaternion at 100 Hz, then gone."""
    srv = socket.socket()
    srv.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    srv.bind(("127.0.0.1", port))
    srv.listen(1)
    ready.set()
    srv.settimeout(5.0)
    try:
        c, _ = srv.accept()
    except OSError:
        srv.close()
        return
    srv.close()  # one host; the port refuses others while the device is away
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        ts = int(time.monotonic() * 1e6)
        try:
            c.sendall(x3.encode(x3.Message(x3.INERTIAL, ts, (0.0, 0.0, 10.0, 0.0, 0.0, 1.0)))
                      + x3.encode(x3.Message(x3.QUATERNION, ts, (1.0, 0.0, 0.0, 0.0))))
        except OSError:
            break
        time.sleep(0.01)
    c.close()


def _read(dev: drivers.Device, seconds: float) -> list[drivers.Sample]:
    out: list[drivers.Sample] = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        out += dev.read_many(0.1)
    return out


def test_tcp_device_away_and_back_reconnects():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    ready = threading.Event()
    threading.Thread(target=_serve_once, args=(port, 1.0, ready), daemon=True).start()
    assert ready.wait(5.0)
    dev = drivers.open_device(f"ximu3://tcp/127.0.0.1:{port}?stale=0.5")
    try:
        first = len(_read(dev, 2.0))  # 1 s of data, then silence: lost, reconnect refused meanwhile
        kinds = [e.kind for e in dev.events]
        assert first > 50 and dev.stats.disconnects == 1 and "reconnect_failed" in kinds, (first, kinds)
        ready.clear()
        threading.Thread(target=_serve_once, args=(port, 1.0, ready), daemon=True).start()
        second = _read(dev, 2.5)
        assert len(second) > 50 and dev.stats.reconnects >= 1, (len(second), dev.stats.as_dict())
        for x in second:  # 1 g up, 10 deg/s about z, as sent
            assert abs(x.acc[2] - 9.80665) < 1e-6 and abs(x.gyro[2] - 0.17453293) < 1e-6
    finally:
        dev.close()
