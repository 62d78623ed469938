"""A device that is there but not reading yet: its port opens, the configuration write
times out (the other end's buffer is full). ``Device.open`` opens it disconnected and the
reconnect loop configures it once it reads, where a port that is not there at all is
still an error at once (a typo in the URL)."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

import drivers
from sim_devices.devices import make_sim_device, spinning_signals


def _fill(link: str) -> int:
    """Write into the port until the other end's buffer takes no more; bytes written."""
    fd = os.open(link, os.O_WRONLY | os.O_NONBLOCK | os.O_NOCTTY)
    n = 0
    full_since = None
    try:
        while full_since is None or time.monotonic() - full_since < 0.3:
            try:
                n += os.write(fd, b"\x00" * 256)
                full_since = None
            except BlockingIOError:  # the kernel moves its flip buffers on a moment later: until it stays full
                full_since = full_since or time.monotonic()
                time.sleep(0.01)
        return n
    finally:
        os.close(fd)


def _xbus_not_reading(link: str, signals) -> tuple:
    """An Xbus twin at ``link``, started, that does not read what comes in until the event it
    returns is set (its own loop held), and whose port's buffer is full: (twin, event)."""
    sim = make_sim_device("xbus", signals, "pelvis", name="pelvis", link_path=link)
    reading = threading.Event()
    service = sim._service  # noqa: SLF001

    def held_service(timeout: float) -> None:  # the twin's own loop, not reading what comes in
        if reading.is_set():
            service(timeout)
        else:
            time.sleep(timeout)

    sim._service = held_service  # noqa: SLF001
    sim.start()
    try:
        assert _fill(link) > 0
    except BaseException:
        sim.stop()
        raise
    return sim, reading


def test_a_twin_not_reading_yet_opens_disconnected_and_is_configured_once_it_reads(tmp_path):
    link = str(tmp_path / "pelvis-tty")
    sim, reading = _xbus_not_reading(link, spinning_signals(("pelvis",), seconds=20))
    try:
        dev = drivers.make_device(f"xbus://{link}")
        dev.open()  # the configuration's first write times out: open, not connected
        try:
            assert dev.is_open and not dev.connected
            gone = [e.detail for e in dev.events if e.kind == "disconnected"]
            assert gone and "not reading" in gone[0], dev.events
            reading.set()
            deadline = time.monotonic() + 10.0
            sample = None
            while sample is None and time.monotonic() < deadline:
                sample = dev.read(0.2)
            assert sample is not None and dev.connected, dev.events
            assert [e.kind for e in dev.events].count("reconnected") == 1
            assert sim.commands.count(0x10) >= 1  # configured (GoToMeasurement) once it read
        finally:
            dev.close()
    finally:
        sim.stop()


def test_in_a_hub_it_reconnects_on_a_thread_of_its_own(tmp_path):
    """Opened while not ready, the device reconnects on a thread of its own, and keeps it once it
    reads: a serial port (a terminal) is never waited on by the selector (drivers/hub/readers.py)."""
    from drivers.hub import Hub

    link = str(tmp_path / "pelvis-tty")
    sig = spinning_signals(("pelvis", "head"), seconds=30)
    sim, reading = _xbus_not_reading(link, sig)
    head = make_sim_device("bno08x-rvc", sig, "head", name="head")
    try:
        head.start()
        devs = {"pelvis": drivers.make_device(f"xbus://{link}"), "head": drivers.make_device(head.url)}
        with Hub(devs, latency=0.05) as hub:
            pelvis = hub.tracks["pelvis"]
            assert pelvis.device.selectable and not pelvis.device.connected
            assert pelvis in hub.readers._selectable  # noqa: SLF001 (the selector's list)
            reading.set()
            deadline = time.monotonic() + 10.0
            while not pelvis.device.connected and time.monotonic() < deadline:
                list(hub.frames(duration=0.2))
            assert pelvis.device.connected, hub.events
            assert pelvis.thread is not None and pelvis.thread.is_alive()  # its own thread, for good
            present = np.array([f.present for f in hub.frames(duration=1.0)])
            assert present[:, 0].mean() > 0.9 and present[:, 1].mean() > 0.9
    finally:
        sim.stop()
        head.stop()


def test_a_port_that_is_not_there_is_still_an_error(tmp_path):
    with pytest.raises(drivers.DeviceGone) as err:
        drivers.make_device(f"xbus://{tmp_path / 'no-such-tty'}").open()
    assert not isinstance(err.value, drivers.DeviceNotReady)
