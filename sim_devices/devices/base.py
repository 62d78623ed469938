"""Common machinery of the simulated devices.

A simulated device replays one site's synthesized signals in real time through
the protocol's ``encode`` and a real transport, with device-side faults on
request. Signal-side imperfections (noise, bias, mounting, heading) come from
``inference.synthesis.NoiseModel`` before the signals reach us; here live only
the faults a transport or a device adds: loss bursts, corrupted bytes,
disconnects, and the device's own clock (offset and drift), which the hub must
estimate.
"""

from __future__ import annotations

import math
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from inference.body.rotations import quat_continuous
from inference.signals.site_signals import SiteSignals


@dataclass
class DeviceFaults:
    """Device-side imperfections.

    loss_rate: probability per packet of entering a loss burst; loss_burst: mean
        burst length in packets (Gilbert-Elliott: bursty, as radio loss is).
    corrupt_rate: probability per packet that one byte is flipped on the wire.
    disconnects: (session time s, duration s) pairs at which the transport goes away.
    clock_offset: device clock reading at session start, s; drift_ppm: clock rate error.
    """

    loss_rate: float = 0.0
    loss_burst: float = 3.0
    corrupt_rate: float = 0.0
    disconnects: list[tuple[float, float]] = field(default_factory=list)
    clock_offset: float = 0.0
    drift_ppm: float = 0.0
    seed: int | None = None


LOOP_BLEND_S = 0.5  # s at a clip's end spent turning each sensor back to its first orientation


class SignalSource:
    """One site's signals as functions of time, looping over the clip.

    Linear interpolation between 60 Hz frames for vectors and normalised linear
    interpolation for quaternions (at 100-250 Hz the frames are a few degrees
    apart at most, where nlerp and slerp agree to well under the noise). Free
    acceleration is the unsmoothed one (``meta['free_acc_raw']``) when synthesis
    provides it, because a real sensor streams raw values and the live resampler
    smooths.
    """

    def __init__(self, signals: SiteSignals, site: str) -> None:
        k = signals.sites.index(site)
        self.site = site
        self.fps = float(signals.fps)
        self.n = len(signals)
        self.duration = self.n / self.fps
        raw = signals.meta.get("free_acc_raw") if signals.meta else None
        # a continuous sign, so interpolation never crosses the double cover
        self.quat = np.ascontiguousarray(quat_continuous(signals.quat[:, k]))
        self.free_acc = np.array(raw[:, k] if raw is not None else signals.free_acc[:, k], dtype=float)
        self.specific_force = np.array(signals.specific_force[:, k], dtype=float)
        self.gyro = np.array(signals.gyro[:, k], dtype=float)
        self._close_the_loop()

    def _close_the_loop(self) -> None:
        """The clip loops (the window's demo, the soak): its last frames turn the sensor onto
        its first orientation and the gyro measures that turn, as a subject taking the sensor
        off and laying it down would. Without it the orientation jumps where the clip wraps
        while the gyro sees nothing, and a device whose orientation is the driver's own AHRS
        (the DualSense) keeps the old heading: the next loop's table step found it 19 deg off.
        The sensor is held still otherwise (gravity only) over those frames."""
        from inference.body.rotations import quat_conjugate, quat_log, quat_multiply, quat_slerp, quat_to_matrix

        nb = int(round(LOOP_BLEND_S * self.fps))
        if self.n < 4 * nb or nb < 2:
            return
        a = self.n - nb - 1  # the last frame kept as it is
        q0, q1 = self.quat[a], self.quat[0]
        if float(np.dot(q0, q1)) < 0:
            q1 = -q1
        w = np.arange(1, nb + 1) / (nb + 1)
        self.quat[a + 1:] = quat_slerp(q0, q1, w)
        seq = np.concatenate([self.quat[a:], q1[None]])  # through the wrap
        step = quat_multiply(quat_conjugate(seq[:-1]), seq[1:])  # body-frame turn per frame
        self.gyro[a:] = quat_log(step) * self.fps
        R = quat_to_matrix(self.quat[a + 1:])
        self.specific_force[a + 1:] = np.swapaxes(R, -1, -2) @ np.array([0.0, 0.0, 9.80665])
        self.free_acc[a + 1:] = 0.0

    def _idx(self, t: float) -> tuple[int, int, float]:
        x = (t % self.duration) * self.fps
        i0 = int(x)
        w = x - i0
        return i0 % self.n, (i0 + 1) % self.n, w

    def at(self, t: float) -> dict[str, np.ndarray]:
        i0, i1, w = self._idx(t)
        q0, q1 = self.quat[i0], self.quat[i1]
        if float(np.dot(q0, q1)) < 0:
            q1 = -q1
        q = (1 - w) * q0 + w * q1
        q /= math.sqrt(float(np.dot(q, q)))
        if q[0] < 0:
            q = -q

        def lerp(a: np.ndarray) -> np.ndarray:
            return (1 - w) * a[i0] + w * a[i1]

        return {
            "quat": q,
            "free_acc": lerp(self.free_acc),
            "specific_force": lerp(self.specific_force),
            "gyro": lerp(self.gyro),
        }


class InsoleSource:
    """Both insoles' signals: force, contacts, and the feet's IMU channels if the
    signals have foot sites."""

    def __init__(self, signals: SiteSignals) -> None:
        self.fps = float(signals.fps)
        self.n = len(signals)
        self.duration = self.n / self.fps
        self.force = np.asarray(signals.insole_force, dtype=float)
        self.contacts = np.asarray(signals.contacts, dtype=bool)
        self.feet = [SignalSource(signals, s) if s in signals.sites else None for s in ("l_foot", "r_foot")]

    def at(self, t: float) -> dict[str, Any]:
        x = (t % self.duration) * self.fps
        i0 = int(x) % self.n
        i1 = (i0 + 1) % self.n
        w = x - int(x)
        force = (1 - w) * self.force[i0] + w * self.force[i1]
        acc = np.tile([0.0, 0.0, 9.80665], (2, 1))
        gyro = np.zeros((2, 3))
        for k, src in enumerate(self.feet):
            if src is not None:
                s = src.at(t)
                acc[k], gyro[k] = s["specific_force"], s["gyro"]
        return {"force": force, "contacts": self.contacts[i0], "acc": acc, "gyro": gyro}


class SimDevice(ABC):
    """A device thread: every 1/rate s it builds a packet and sends it, unless a
    fault says otherwise. Subclasses implement the transport and the encoding."""

    protocol: ClassVar[str] = ""

    def __init__(self, source: Any, rate: float, faults: DeviceFaults | None = None, name: str = "") -> None:
        self.source = source
        self.rate = rate
        self.faults = faults or DeviceFaults()
        self.name = name or getattr(source, "site", self.protocol)
        self.rng = np.random.default_rng(self.faults.seed)
        self.counter = 0
        self.stats = dict.fromkeys(("packets", "sent", "dropped", "corrupted", "disconnects", "overruns", "skipped"), 0)
        self._in_burst = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._down_until = -1.0
        self._t0 = 0.0
        self._lock = threading.Lock()
        self.connected = False
        # (packet counter, monotonic time the packet left) of every packet sent, when asked
        # for (``log_sends``): the start of an end-to-end latency measurement, taken where
        # only the device knows it
        self.send_log: list[tuple[int, float]] | None = None

    @property
    def started_at(self) -> float:
        """When this twin's clock started (time.monotonic, one clock for every process of the machine)."""
        return self._t0

    def log_sends(self) -> SimDevice:
        """Keep the send time of every packet from now on (``send_log``)."""
        self.send_log = []
        return self

    # --- lifecycle ----------------------------------------------------------------------------------------
    def start(self) -> SimDevice:
        self._open_transport()
        self.connected = True
        self._t0 = time.monotonic()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=f"sim-{self.protocol}-{self.name}", daemon=True)
        self._thread.start()
        return self

    def request_stop(self) -> None:
        """Ask the loop to end without waiting for it: a setup of many devices asks them all first,
        then waits for each (``stop``), so their waits overlap instead of adding up."""
        self._stop.set()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        with self._lock:
            if self.connected:
                self._close_transport()
                self.connected = False
        self._cleanup()

    def __enter__(self) -> SimDevice:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    @abstractmethod
    def url(self) -> str:
        """The URL ``drivers.open_device`` opens to talk to this device."""

    def device_time(self, t_session: float) -> float:
        return self.faults.clock_offset + t_session * (1.0 + self.faults.drift_ppm * 1e-6)

    def disconnect(self, duration: float) -> None:
        """Pull the plug now; plug back in after ``duration`` seconds."""
        with self._lock:
            if self.connected:
                self._close_transport()
                self.connected = False
                self.stats["disconnects"] += 1
            self._down_until = time.monotonic() + duration

    # --- the loop -----------------------------------------------------------------------------------------
    def _run(self) -> None:
        period = 1.0 / self.rate
        next_tick = time.monotonic()
        pending = sorted(self.faults.disconnects)
        while not self._stop.is_set():
            now = time.monotonic()
            t = now - self._t0
            if pending and t >= pending[0][0]:
                self.disconnect(pending.pop(0)[1])
            if not self.connected and now >= self._down_until:
                with self._lock:
                    try:
                        self._open_transport()
                        self.connected = True
                    except OSError:
                        self._down_until = now + 0.1
            if now >= next_tick:
                self._tick(t)
                next_tick += period
                if next_tick < now - 10 * period:  # fell far behind (machine busy): skip, do not burst
                    missed = int((now - next_tick) / period)
                    self._skip_ticks(missed)
                    next_tick += missed * period
            self._service(max(0.0, min(next_tick - time.monotonic(), 0.05)))

    def _skip_ticks(self, n: int) -> None:
        """Ticks this process was too busy to send. A real sensor's oscillator does
        not wait for the host: its counter (the only clock a BNO08x RVC stream has)
        runs on, and the host sees the missed packets as a counter gap. Holding the
        counter instead made the device clock run slow by the stall, and the hub's
        clock fit then placed every later sample that much too early (seen once in
        CI: a head stream judged stale for a whole test)."""
        self.counter += n
        self.stats["skipped"] += n

    def _tick(self, t: float) -> None:
        counter = self.counter
        self.counter += 1
        self.stats["packets"] += 1
        if self._lost():
            self.stats["dropped"] += 1
            return
        if not self.connected or not self._streaming():
            return
        packet = self._make_packet(t, self.device_time(t), counter)
        if packet is None:
            return
        if self.faults.corrupt_rate and self.rng.random() < self.faults.corrupt_rate:
            packet = self._corrupt(packet)
            self.stats["corrupted"] += 1
        with self._lock:
            if not self.connected:
                return
            try:
                self._send(packet)
                if self.send_log is not None:
                    self.send_log.append((counter, time.monotonic()))
                self.stats["sent"] += 1
            except BlockingIOError:
                self.stats["overruns"] += 1
            except OSError:
                pass

    def _lost(self) -> bool:
        f = self.faults
        if f.loss_rate <= 0:
            return False
        if self._in_burst:
            if self.rng.random() < 1.0 / max(1.0, f.loss_burst):
                self._in_burst = False
            return True
        if self.rng.random() < f.loss_rate:
            self._in_burst = True
            return True
        return False

    def _corrupt(self, packet: Any) -> Any:
        b = bytearray(packet)
        if b:
            i = int(self.rng.integers(len(b)))
            b[i] ^= int(self.rng.integers(1, 256))
        return bytes(b)

    # --- subclass hooks -----------------------------------------------------------------------------------
    def _streaming(self) -> bool:
        return True

    def _service(self, timeout: float) -> None:
        """Wait up to ``timeout`` s; devices that receive commands read them here."""
        self._stop.wait(timeout)

    def _cleanup(self) -> None:  # noqa: B027 - optional hook, most devices leave nothing behind
        """Remove what the transport left behind (a symlink, a socket file)."""

    @abstractmethod
    def _open_transport(self) -> None: ...

    @abstractmethod
    def _close_transport(self) -> None: ...

    @abstractmethod
    def _send(self, packet: Any) -> None: ...

    @abstractmethod
    def _make_packet(self, t: float, device_t: float, counter: int) -> Any: ...
