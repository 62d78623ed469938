"""The hub's selector thread held up while the grid goes on: the samples that waited in the
socket's buffer still make their frames, because ``poll`` reads the selector's devices first
(``Readers.catch_up``). Beside the test suite a capture's selector got no turn for 0.2-1.1 s at a
time and its UDP sensors went missing together from those frames (docs/testing.md).

Real parts: a Moticon insole twin sending UDP at 100 Hz, the driver reading it, the hub's own
selector thread. The stall is made by holding that thread in its ``select`` call, as a busy
machine holds it. A serial port is not the selector's (a terminal's ``select`` waits in the
kernel): the last test says so."""

from __future__ import annotations

import threading
import time

import numpy as np

import drivers
from drivers.hub import Hub
from drivers.hub import readers as readers_module
from sim_devices.devices import make_sim_device, spinning_signals

STALL_S = 0.4


def _present_through_stalls(monkeypatch, catch_up: bool, late: list | None = None) -> np.ndarray:
    """Insole presence in the frames over three stalls of the selector, ``STALL_S`` each."""
    sig = spinning_signals(("head",), seconds=20)
    sim = make_sim_device("moticon-udp", sig, "head", name="insoles").start()
    stalls = {"left": 0}
    real_select = readers_module.select.select

    class StallingSelect:
        @staticmethod
        def select(r, w, x, timeout=None):
            if stalls["left"] and threading.current_thread().name == "hub-selector":
                stalls["left"] -= 1
                time.sleep(STALL_S)
            return real_select(r, w, x, timeout)

    monkeypatch.setattr(readers_module, "select", StallingSelect)
    try:
        with Hub({"insoles": drivers.make_device(sim.url)}, latency=0.05) as hub:
            assert hub.readers.selector_thread is not None
            if not catch_up:
                hub.readers.catch_up = lambda: None  # the selector alone reads
            list(hub.frames(duration=1.0))  # the clock fit settles
            present = []
            for _ in range(3):
                stalls["left"] = 1
                present += [f.insole_present for f in hub.frames(duration=0.6)]
            if late is not None:
                late.append(hub.status()["insoles"]["late"])
            return np.array(present)
    finally:
        sim.stop()


def test_a_stalled_selector_loses_no_frame_when_the_grid_reads_first(monkeypatch):
    late: list[int] = []
    present = _present_through_stalls(monkeypatch, catch_up=True, late=late)
    assert present.mean() > 0.97, present.mean()
    assert late[0] < 0.2 * 3 * STALL_S * 100, late  # the stalls' samples were read in time


def test_without_reading_first_the_stalls_cost_their_frames(monkeypatch):
    """The same stalls with the selector the only reader: what ``catch_up`` is there for
    (and what makes the test above able to fail)."""
    late: list[int] = []
    present = _present_through_stalls(monkeypatch, catch_up=False, late=late)
    assert present.mean() < 0.8, present.mean()
    # the samples that came too late for their frames are counted for the device's status (and a
    # session's summary): missing from the frames, so from a recording too
    assert late[0] >= 0.5 * (1 - present.mean()) * 3 * 0.6 * 100, (late, present.mean())


def test_a_serial_port_is_read_on_a_thread_of_its_own():
    """A terminal's ``select`` and ``read`` wait for the kernel's work that moves its received bytes
    to the line discipline; a capture's selector and ``poll`` sat there together for seconds on a
    loaded machine, and no frame came. A serial device never joins the selector or ``catch_up``."""
    sig = spinning_signals(("head",), seconds=20)
    serial_twin = make_sim_device("bno08x-rvc", sig, "head", name="head").start()
    udp_twin = make_sim_device("moticon-udp", sig, "head", name="insoles").start()
    try:
        devs = {"head": drivers.make_device(serial_twin.url), "insoles": drivers.make_device(udp_twin.url)}
        with Hub(devs, latency=0.05) as hub:
            head, insoles = hub.tracks["head"], hub.tracks["insoles"]
            assert head.is_terminal(head.device.fileno())
            assert not insoles.is_terminal(insoles.device.fileno())
            assert head.thread is not None and insoles.thread is None
            assert hub.readers._selectable == [insoles]  # noqa: SLF001 (the selector's list)
            frames = list(hub.frames(duration=1.5))
            assert np.mean([f.present[0] for f in frames[30:]]) > 0.9
            assert np.mean([f.insole_present for f in frames[30:]]) > 0.9
    finally:
        serial_twin.stop()
        udp_twin.stop()
