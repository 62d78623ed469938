"""One python-can bus per channel, shared by every XsensCanDevice on it.

Threads are bounded with ``join(timeout)`` (a deadlock fails the test instead of
hanging it); nothing here asserts how long anything took.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable

import can
import pytest

from drivers.base import DeviceGone
from drivers.xsens_can import driver as can_driver
from drivers.xsens_can import protocol as xcan
from drivers.xsens_can.driver import XsensCanDevice, owned_ids
from drivers.xsens_can.shared_bus import BusRegistry, Tap
from sim_devices.devices import DeviceFaults, make_sim_device, spinning_signals

JOIN_S = 10.0  # generous: a deadlock, not a slow machine, is what fails a join


class ProbeBus:
    """A real virtual bus that counts its shutdowns, records its filters and fails
    its next ``recv`` on request (a cable pulled, a controller gone bus-off)."""

    def __init__(self, **kwargs: object) -> None:
        kwargs["interface"] = "virtual"
        self.inner = can.Bus(**kwargs)
        self.shutdowns = 0
        self.receiving = 0
        self.shut_while_receiving = False
        self.filters: list | None = None
        self.fail = threading.Event()

    def recv(self, timeout: float | None = None) -> can.Message | None:
        if self.fail.is_set():
            raise can.CanOperationError("bus-off")
        self.receiving += 1
        try:
            return self.inner.recv(timeout)
        finally:
            self.receiving -= 1

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        self.inner.send(msg, timeout)

    def set_filters(self, filters: list | None = None) -> None:
        self.filters = filters

    def shutdown(self) -> None:
        self.shutdowns += 1
        self.shut_while_receiving |= self.receiving > 0
        self.inner.shutdown()


@pytest.fixture
def opened() -> list[ProbeBus]:
    return []


@pytest.fixture
def registry(monkeypatch, opened) -> BusRegistry:
    """The drivers' registry, replaced by one whose buses are ``ProbeBus``es."""

    def factory(**kwargs: object) -> ProbeBus:
        bus = ProbeBus(**kwargs)
        opened.append(bus)
        return bus

    reg = BusRegistry(factory=factory)
    monkeypatch.setattr(can_driver, "BUSES", reg)
    return reg


@pytest.fixture
def channel() -> str:
    return f"shared-{uuid.uuid4().hex[:8]}"


@pytest.fixture(scope="module")
def signals():
    return spinning_signals(("pelvis",), seconds=20.0)


def group(counter: int, offset: int) -> list[can.Message]:
    """One MTi sample moved to ``offset``; its device time says whose it is."""
    g = xcan.CanGroup(sample_time_us=offset * 1000 + counter, counter=counter, status=3,
                      quat=(1.0, 0.0, 0.0, 0.0), gyro=(0.0, 0.0, 0.0), acc=(0.0, 0.0, 9.81),
                      free_acc=(0.0, 0.0, 0.0))
    return [can.Message(arbitration_id=i, data=d, is_extended_id=False) for i, d in xcan.encode(g, offset)]


def run_threads(targets: list[Callable[[], None]]) -> None:
    threads = [threading.Thread(target=t, daemon=True) for t in targets]
    for th in threads:
        th.start()
    for th in threads:
        th.join(JOIN_S)
    assert not any(th.is_alive() for th in threads), "a reader is stuck (deadlock?)"


def read_until(dev: XsensCanDevice, n: int, out: list, stop: threading.Event | None = None) -> Callable[[], None]:
    """A hub-like reader thread body: ``read_many`` until ``n`` samples or the deadline."""

    def body() -> None:
        deadline = time.monotonic() + JOIN_S - 1.0
        while len(out) < n and time.monotonic() < deadline and not (stop and stop.is_set()):
            out.extend(dev.read_many(0.1))

    return body


def device(channel: str, offset: int, **kw: object) -> XsensCanDevice:
    return XsensCanDevice("virtual", channel, id_offset=offset, device_id=f"0x{offset:X}", **kw)


# --- devices over the real simulated MTis -----------------------------------------------------------------
def test_devices_on_one_channel_get_exactly_their_own_samples(signals, channel):
    offsets = (0x100, 0x200, 0x300, 0x400)
    sims = [make_sim_device("xsens-can", signals, "pelvis", interface="virtual", channel=channel, id_offset=o,
                            faults=DeviceFaults(clock_offset=1000.0 * (k + 1), seed=k))
            for k, o in enumerate(offsets)]
    devs = [device(channel, o).open() for o in offsets]
    got: list[list] = [[] for _ in devs]
    try:
        for s in sims:
            s.start()
        run_threads([read_until(d, 100, out) for d, out in zip(devs, got, strict=True)])
    finally:
        for s in sims:
            s.stop()
        for d in devs:
            d.close()
    assert all(b.key[1] != channel for b in can_driver.BUSES.open_buses())
    for k, (dev, samples, sim) in enumerate(zip(devs, got, sims, strict=True)):
        assert len(samples) >= 100
        # each sim's clock starts 1000 s apart: a sample of another sensor would stand out
        assert all(1000.0 * (k + 1) <= s.device_time < 1000.0 * (k + 1) + 100 for s in samples)
        assert all(s.device_id == dev.device_id for s in samples)
        assert dev.stats.bad_frame == 0 and dev.frames_dropped == 0
        # the only loss allowed is ticks the sim itself skipped because this machine stalled
        assert dev.stats.lost_packets <= sim.stats["skipped"]


# --- routing ----------------------------------------------------------------------------------------------
def test_foreign_frames_are_dropped_without_decoding(registry, channel, monkeypatch):
    decoded: list[int] = []
    real_decode = xcan.decode

    def spy(arbitration_id: int, data: bytes, id_offset: int = 0):
        decoded.append(arbitration_id)
        return real_decode(arbitration_id, data, id_offset)

    monkeypatch.setattr(xcan, "decode", spy)
    a, b = device(channel, 0x100).open(), device(channel, 0x200).open()
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for k in range(20):
            for msg in group(k, 0x100) + group(k, 0x200) + group(k, 0x500):  # 0x500: a node we do not read
                sender.send(msg)
            sender.send(can.Message(arbitration_id=0x7F0, data=b"\x01\x02", is_extended_id=False))
        got_a: list = []
        got_b: list = []
        run_threads([read_until(a, 20, got_a), read_until(b, 20, got_b)])
    finally:
        sender.shutdown()
        a.close()
        b.close()
    assert [s.counter for s in got_a] == list(range(20)) and [s.counter for s in got_b] == list(range(20))
    assert {round(s.device_time * 1e6) // 1000 for s in got_a} == {0x100}
    assert {round(s.device_time * 1e6) // 1000 for s in got_b} == {0x200}
    assert set(decoded) <= owned_ids(0x100) | owned_ids(0x200)
    assert a.stats.bad_frame == b.stats.bad_frame == 0


def test_malformed_and_error_frames_still_count_as_bad(registry, channel):
    dev = device(channel, 0x100).open()
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        sender.send(can.Message(arbitration_id=0x105, data=b"\x00", is_extended_id=False))  # ours, too short
        sender.send(can.Message(is_error_frame=True, arbitration_id=0x20000080, is_extended_id=True, dlc=8,
                                data=bytes(8)))
        for k in range(3):
            for msg in group(k, 0x100):
                sender.send(msg)
        got: list = []
        run_threads([read_until(dev, 3, got)])
    finally:
        sender.shutdown()
        dev.close()
    assert [s.counter for s in got] == [0, 1, 2]
    assert dev.stats.bad_frame == 2


def test_kernel_filters_follow_the_routed_ids(opened, channel):
    """socketcan filters in the kernel: the bus is asked to pass the union of the ids."""
    reg = BusRegistry(factory=lambda **kw: opened.append(ProbeBus(**kw)) or opened[-1])
    a = reg.attach("socketcan", channel, {}, owned_ids(0x100))
    b = reg.attach("socketcan", channel, {}, owned_ids(0x200))
    assert {f["can_id"] for f in opened[0].filters} == owned_ids(0x100) | owned_ids(0x200)
    a.shutdown()
    assert {f["can_id"] for f in opened[0].filters} == owned_ids(0x200)
    b.shutdown()
    plain = BusRegistry(factory=lambda **kw: opened.append(ProbeBus(**kw)) or opened[-1])
    plain.attach("virtual", channel, {}, owned_ids(0x100)).shutdown()
    assert opened[1].filters is None  # filtering in Python would only repeat our routing


def test_a_full_queue_drops_its_oldest_frames_and_counts_them(registry, channel):
    slow = registry.attach("virtual", channel, {}, [0x10], queue_size=10)
    fast = registry.attach("virtual", channel, {}, [0x20])
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        for k in range(25):
            sender.send(can.Message(arbitration_id=0x10, data=bytes([k]), is_extended_id=False))
        sender.send(can.Message(arbitration_id=0x20, data=b"", is_extended_id=False))
        assert fast.recv(JOIN_S) is not None  # its thread reads the bus, routing everything queued before it
        assert slow.dropped == 15
        assert [slow.recv(0.0).data[0] for _ in range(10)] == list(range(15, 25))
    finally:
        sender.shutdown()
        slow.shutdown()
        fast.shutdown()


# --- lifetime ---------------------------------------------------------------------------------------------
def test_closing_one_device_keeps_the_others_and_the_last_close_shuts_the_bus(registry, opened, channel):
    devs = [device(channel, o).open() for o in (0x100, 0x200, 0x300)]
    assert len(opened) == 1 and len(registry.open_buses()) == 1
    sender = can.Bus(interface="virtual", channel=channel)
    try:
        devs[0].close()
        for k in range(5):
            for o in (0x100, 0x200, 0x300):
                for msg in group(k, o):
                    sender.send(msg)
        got = [[], []]
        run_threads([read_until(d, 5, out) for d, out in zip(devs[1:], got, strict=True)])
        assert [[s.counter for s in g] for g in got] == [list(range(5))] * 2
        assert opened[0].shutdowns == 0
        devs[1].close()
        assert opened[0].shutdowns == 0
        devs[2].close()
        assert opened[0].shutdowns == 1 and registry.open_buses() == []
    finally:
        sender.shutdown()
        for d in devs:
            d.close()
    again = device(channel, 0x100).open()
    again.close()
    assert len(opened) == 2  # a later open gets a new bus


def test_a_bus_error_reaches_every_device_and_they_reopen_on_a_fresh_bus(registry, opened, channel):
    offsets = (0x100, 0x200, 0x300)
    devs = [device(channel, o, backoff=(0.01, 0.05)).open() for o in offsets]
    stop = threading.Event()
    sender = can.Bus(interface="virtual", channel=channel)

    def send() -> None:
        k = 0
        while not stop.is_set():
            for o in offsets:
                for msg in group(k, o):
                    sender.send(msg)
            k += 1
            time.sleep(0.01)

    got: list[list] = [[] for _ in devs]
    readers = [read_until(d, 10**9, out, stop) for d, out in zip(devs, got, strict=True)]

    def drive() -> None:
        deadline = time.monotonic() + JOIN_S - 2.0
        while time.monotonic() < deadline and not all(got):
            time.sleep(0.01)
        opened[0].fail.set()
        while time.monotonic() < deadline and not all(d.stats.reconnects and got[k] and got[k][-1].t > d.events[-1].t
                                                      for k, d in enumerate(devs)):
            time.sleep(0.01)
        stop.set()

    try:
        run_threads([send, drive, *readers])
    finally:
        stop.set()
        sender.shutdown()
        for d in devs:
            d.close()
    for d, samples in zip(devs, got, strict=True):
        kinds = [e.kind for e in d.events]
        assert "disconnected" in kinds and "reconnected" in kinds, kinds
        assert d.stats.disconnects == 1 and d.stats.reconnects == 1
        reconnected_at = next(e.t for e in d.events if e.kind == "reconnected")
        assert any(s.t > reconnected_at for s in samples), "no samples after the reopen"
    assert len(opened) == 2 and opened[0].shutdowns == 1  # the broken bus was closed, not reused
    assert opened[1].shutdowns == 1


def test_a_tap_error_is_device_gone_for_every_tap(registry, opened, channel):
    taps = [registry.attach("virtual", channel, {}, [i]) for i in (1, 2, 3)]
    errors: list[BaseException] = []

    def wait_on(tap: Tap) -> Callable[[], None]:
        def body() -> None:
            try:
                while True:
                    tap.recv(None)  # forever: only the error can end this
            except DeviceGone as exc:
                errors.append(exc)

        return body

    def fail_soon() -> None:
        time.sleep(0.1)
        opened[0].fail.set()

    run_threads([fail_soon, *[wait_on(t) for t in taps]])
    assert len(errors) == 3 and all("bus-off" in str(e) for e in errors)
    assert registry.open_buses() == []
    fresh = registry.attach("virtual", channel, {}, [1])
    assert fresh.shared is not taps[0].shared
    for t in (*taps, fresh):
        t.shutdown()
    assert [b.shutdowns for b in opened] == [1, 1]


def test_the_last_close_during_a_receive_waits_for_it(registry, opened, channel):
    """Shutting a bus down under a thread inside ``bus.recv`` is not safe on every
    interface: the reader shuts it down when it comes back."""
    a = registry.attach("virtual", channel, {}, [1])
    shared = a.shared
    errors: list[BaseException] = []

    def read_forever() -> None:
        try:
            a.recv(None)
        except DeviceGone as exc:
            errors.append(exc)

    def close_while_reading() -> None:
        until(lambda: shared.reading)
        a.shutdown()

    run_threads([read_forever, close_while_reading])
    assert len(errors) == 1 and opened[0].shutdowns == 1 and not opened[0].shut_while_receiving


# --- concurrency ------------------------------------------------------------------------------------------
def until(cond: Callable[[], bool]) -> None:
    deadline = time.monotonic() + JOIN_S - 2.0
    while not cond() and time.monotonic() < deadline:
        time.sleep(0.001)
    assert cond()


def test_the_reader_routes_to_waiters_and_hands_its_role_over(registry, channel):
    """Both threads wait forever, so only the leader's routing can wake B, and only the
    hand-over when A leaves can let B read the bus again: either missing hangs B."""
    a = registry.attach("virtual", channel, {}, [0xA])
    b = registry.attach("virtual", channel, {}, [0xB])
    shared = a.shared
    sender = can.Bus(interface="virtual", channel=channel)
    got_b: list[int] = []

    def frame(i: int, k: int) -> can.Message:
        return can.Message(arbitration_id=i, data=bytes([k]), is_extended_id=False)

    def thread_a() -> None:
        assert a.recv(None) is not None

    def thread_b() -> None:
        until(lambda: shared.reading)  # A leads
        for _ in range(2):
            got_b.append(b.recv(None).data[0])

    def script() -> None:
        until(lambda: shared.reading and b in shared.waiting)
        sender.send(frame(0xB, 1))  # A reads it, routes it to B and wakes B
        until(lambda: len(got_b) == 1 and b in shared.waiting)
        sender.send(frame(0xA, 0))  # A returns: B must take over the bus
        until(lambda: b not in shared.waiting)
        sender.send(frame(0xB, 2))

    try:
        run_threads([thread_a, thread_b, script])
    finally:
        sender.shutdown()
        a.shutdown()
        b.shutdown()
    assert got_b == [1, 2]


def test_many_threads_reading_concurrently_neither_deadlock_nor_lose_frames(registry, channel):
    """Two taps, three threads each, with timeouts from zero to forever, while frames
    arrive: every frame reaches exactly one thread of its tap, nobody hangs."""
    ids = (0x10, 0x20)
    taps = {i: registry.attach("virtual", channel, {}, [i]) for i in ids}
    n = 2000
    received: dict[int, list[int]] = {i: [] for i in ids}
    lock = threading.Lock()
    sender = can.Bus(interface="virtual", channel=channel)

    def send() -> None:
        for k in range(n):
            for i in ids:
                sender.send(can.Message(arbitration_id=i, data=k.to_bytes(2, "big"), is_extended_id=False))
            if k % 50 == 0:
                time.sleep(0.001)

    def reader(tap: Tap, timeout: float | None) -> Callable[[], None]:
        def body() -> None:
            try:
                while True:
                    msg = tap.recv(timeout)
                    if msg is not None:
                        with lock:
                            received[msg.arbitration_id].append(int.from_bytes(msg.data, "big"))
            except DeviceGone:
                pass  # shut down at the end

        return body

    def finish() -> None:
        deadline = time.monotonic() + JOIN_S - 2.0
        while time.monotonic() < deadline and sum(map(len, received.values())) < n * len(ids):
            time.sleep(0.01)
        for t in taps.values():
            t.shutdown()  # wakes the threads waiting forever

    try:
        run_threads([send, finish, *[reader(taps[i], t) for i in ids for t in (0.0, 0.02, None)]])
    finally:
        sender.shutdown()
    for i in ids:
        assert sorted(received[i]) == list(range(n)), f"id 0x{i:X}: lost or duplicated frames"
