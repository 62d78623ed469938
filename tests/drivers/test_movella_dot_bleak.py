"""The DOT driver through the real ``BleakSeam`` (its asyncio loop thread, bleak's
``BleakClient`` and ``BleakScanner``) against a stand-in of bleak's backend that reaches a
simulated DOT (``tests/drivers/dot_bleak_backend.py``): a scan from advertisements, the
battery on demand, connect, control writes, notifications decoded to the values played,
a link the DOT drops reported through bleak's disconnected callback, the rejoin, and
samples again."""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bleak", reason="bleak (the [ble] extra) is not installed: the BleakSeam path cannot run")

import drivers  # noqa: E402
from drivers.movella_dot import protocol as dot  # noqa: E402
from drivers.movella_dot.ble_seam import BleakLink, BleakSeam, read_battery  # noqa: E402
from drivers.movella_dot.driver import list_dots  # noqa: E402
from sim_devices.devices import make_sim_device, spinning_signals  # noqa: E402
from tests.drivers.dot_bleak_backend import dot_backends  # noqa: E402

PATIENCE = 60.0  # s: an upper bound for waiting on a busy machine, never a figure that is checked


def _angle_deg(q1: np.ndarray, q2: np.ndarray) -> float:
    return float(np.degrees(2 * np.arccos(min(1.0, abs(float(np.dot(q1, q2)))))))


def _read_until(dev: drivers.Device, done, out: list[drivers.Sample]) -> None:
    end = time.monotonic() + PATIENCE
    while not done():
        assert time.monotonic() < end, (dev.stats.as_dict(), list(dev.events))
        out += dev.read_many(0.1)


def _as_played(sim, samples: list[drivers.Sample]) -> None:
    for s in samples:  # the sensor's clock is the twin's session clock (no offset)
        truth = sim.source.at(s.device_time)
        assert _angle_deg(s.quat, truth["quat"]) < 0.01
        np.testing.assert_allclose(s.free_acc, truth["free_acc"], atol=2e-3)


@pytest.fixture
def short_dir():
    """A folder for the twin's socket: AF_UNIX paths are limited to ~107 bytes, which pytest's
    per-worker tmp_path can pass once a UUID is in the socket's name."""
    d = tempfile.mkdtemp(prefix="dot", dir="/tmp")
    yield Path(d)
    shutil.rmtree(d, ignore_errors=True)


def test_dot_through_bleak_seam_scan_stream_drop_and_rejoin(short_dir):
    tmp_path = short_dir
    drop_s = 1.0
    signals = spinning_signals(("pelvis",), seconds=10.0)
    sim = make_sim_device("movella-dot", signals, "pelvis", folder=str(tmp_path)).start()
    client_backend, scanner_backend = dot_backends(tmp_path)
    seam = BleakSeam(client_backend=client_backend, scanner_backend=scanner_backend)
    try:
        # a scan: bleak's scanner over the backend's advertisements, no connection, no battery
        found = list_dots(seam, 0.2)
        assert [(d["path"], d["what"], d["battery"], d["url"]) for d in found] == [
            (sim.address, "Movella DOT", None, f"movella-dot://{sim.address}")]
        assert read_battery(seam, sim.address) == 87.0  # on demand: one short connection

        with drivers.open_device(found[0]["url"], seam=seam) as dev:
            assert isinstance(dev._link, BleakLink)  # the bleak path, not the socket seam
            assert sim.control == dot.DotControl(action=1, payload_mode=dot.MODE_COMPLETE_QUATERNION)
            before: list[drivers.Sample] = []
            _read_until(dev, lambda: len(before) >= 30, before)

            sim.disconnect(drop_s)  # the DOT drops the link and comes back after drop_s
            after: list[drivers.Sample] = []
            _read_until(dev, lambda: any(e.kind == "reconnected" for e in dev.events) and len(after) >= 30, after)
            stats = dev.stats.as_dict()
            events = [(e.kind, e.detail) for e in dev.events]
        assert sim.control.action == 0  # closing wrote the stop through bleak
    finally:
        sim.stop()

    assert client_backend.dropped == [sim.address]  # the twin's drop came up as bleak's disconnected callback
    kinds = [k for k, _ in events]
    assert kinds[:1] == ["opened"] and "disconnected" in kinds, events
    assert kinds.index("reconnected") > kinds.index("disconnected"), events
    assert stats["disconnects"] == 1 and stats["reconnects"] == 1, stats
    assert stats["bad_frame"] == 0, stats
    _as_played(sim, before)
    _as_played(sim, after)
    assert {s.battery for s in before + after} == {87.0}
    t = np.array([s.device_time for s in before + after])
    assert np.all(np.diff(t) > 0)
    k = int(np.argmax(np.diff(t)))
    assert t[k + 1] - t[k] >= drop_s - 1e-3  # the drop is in the data, on the sensor's clock
    assert sum(s.device_time > t[k] for s in after) >= 30  # and it streams again after the rejoin


def test_dot_by_corebluetooth_uuid_through_bleak_seam(short_dir):
    """On macOS bleak names a sensor by the UUID CoreBluetooth gives it: the same path takes it."""
    uuid = "6E400001-B5A3-F393-E0A9-E50E24DCCA9E"
    tmp_path = short_dir
    sim = make_sim_device("movella-dot", spinning_signals(("pelvis",), seconds=10.0), "pelvis", folder=str(tmp_path),
                          address=uuid).start()
    client_backend, scanner_backend = dot_backends(tmp_path)
    seam = BleakSeam(client_backend=client_backend, scanner_backend=scanner_backend)
    try:
        assert [d["url"] for d in list_dots(seam, 0.2)] == [f"movella-dot://{uuid}"]
        with drivers.open_device(f"movella-dot://{uuid.lower()}", seam=seam) as dev:
            samples: list[drivers.Sample] = []
            _read_until(dev, lambda: len(samples) >= 10, samples)
    finally:
        sim.stop()
    assert {s.device_id for s in samples} == {uuid}
    _as_played(sim, samples)
