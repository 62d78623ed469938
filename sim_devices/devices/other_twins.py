"""Simulated MTi-600 on CAN, DualSense behind the HID seam, Moticon insoles on UDP."""

from __future__ import annotations

import os
import socket
import tempfile
import threading

import can
import numpy as np

from drivers.dualsense import protocol as ds
from drivers.moticon import protocol as mot
from drivers.urls import build_url
from drivers.xsens_can import protocol as xcan
from drivers.xsens_can.shared_bus import BusRegistry, Tap

from .base import DeviceFaults, InsoleSource, SignalSource, SimDevice
from .can_loopback import REMOTE_INTERFACE, SERVERS

G = 9.80665

# The simulated MTis of a process send through one bus per channel: on python-can's
# virtual interface every bus on a channel gets a deep copy of every frame sent, so one
# sending bus per sensor meant N-1 copies per frame into queues nobody reads (growing
# without bound). A registry apart from the drivers', because a bus never receives its
# own frames and the drivers' bus must receive ours.
SIM_CAN_BUSES = BusRegistry()


class SimXsensCan(SimDevice):
    """An MTi-600 on a python-can bus (``virtual`` by default: in-process, real
    python-can message path). A corrupted packet becomes a frame with a wrong
    length, which is what a CAN receiver can see (the CRC catches bit flips).
    The MTis on one channel share one sending bus (``SIM_CAN_BUSES``); an MTi
    receives nothing, so its tap routes no identifiers to it.

    On ``interface="remote"`` with ``channel="127.0.0.1:PORT"`` the twin is for another
    process: it sends on an in-process virtual channel that a loopback server
    (``can_loopback``) carries to python-can's ``remote`` clients at that address, and its
    URL is the one those clients open."""

    protocol = "xsens-can"

    def __init__(
        self,
        source: SignalSource,
        rate: float = 100.0,
        faults: DeviceFaults | None = None,
        name: str = "",
        interface: str = "virtual",
        channel: str = "imucap",
        id_offset: int = 0,
    ) -> None:
        super().__init__(source, rate, faults, name)
        self.interface, self.channel, self.id_offset = interface, channel, id_offset
        self._bus: Tap | None = None
        self._served: str | None = None  # the virtual channel a loopback server carries (remote only)

    @property
    def url(self) -> str:
        return build_url("xsens-can", self.interface, f"/{self.channel}", id_offset=hex(self.id_offset), id=self.name)

    def start(self) -> SimXsensCan:
        if self.interface == REMOTE_INTERFACE and self._served is None:
            self._served = SERVERS.acquire(self.channel)
        try:
            super().start()
        except BaseException:
            self._release_server()
            raise
        return self

    def stop(self) -> None:
        super().stop()
        self._release_server()

    def _release_server(self) -> None:
        if self._served is not None:
            self._served = None
            SERVERS.release(self.channel)

    def _open_transport(self) -> None:
        if self._served is not None:
            self._bus = SIM_CAN_BUSES.attach("virtual", self._served, {"receive_own_messages": False})
        else:
            self._bus = SIM_CAN_BUSES.attach(self.interface, self.channel, {"receive_own_messages": False})

    def _close_transport(self) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()

    def _make_packet(self, t: float, device_t: float, counter: int) -> list[tuple[int, bytes]]:
        s = self.source.at(t)
        g = xcan.CanGroup(
            sample_time_us=int(device_t * 1e6) % (1 << 32),
            counter=counter & 0xFFFF,
            status=3,
            quat=tuple(s["quat"]),
            gyro=tuple(s["gyro"]),
            acc=tuple(s["specific_force"]),
            free_acc=tuple(s["free_acc"]),
        )
        return xcan.encode(g, self.id_offset)

    def _corrupt(self, packet: list[tuple[int, bytes]]) -> list[tuple[int, bytes]]:
        k = int(self.rng.integers(len(packet)))
        fid, data = packet[k]
        return packet[:k] + [(fid, data[:-1])] + packet[k + 1 :]

    def _send(self, packet: list[tuple[int, bytes]]) -> None:
        bus = self._bus
        if bus is None:
            raise OSError("bus closed")
        for fid, data in packet:
            bus.send(can.Message(arbitration_id=fid, data=data, is_extended_id=False))


class SimDualSense(SimDevice):
    """A DualSense behind the HID seam: a local SOCK_SEQPACKET endpoint that sends
    USB input reports 0x01 and answers feature report 0x05 with a calibration
    that is deliberately not the identity, so the driver's calibration path is
    exercised. 250 Hz like the real controller over USB."""

    protocol = "dualsense"

    def __init__(
        self,
        source: SignalSource,
        rate: float = 250.0,
        faults: DeviceFaults | None = None,
        name: str = "",
        socket_path: str | None = None,
        calibration: ds.DsCalibration | None = None,
    ) -> None:
        super().__init__(source, rate, faults, name)
        if socket_path is None:
            socket_path = os.path.join(tempfile.mkdtemp(prefix="imucap-hid-"), "dualsense.sock")
        self.socket_path = socket_path
        self.calibration = calibration or ds.DsCalibration(
            gyro_bias=(2, -3, 1),
            gyro_plus=(8200, 8150, 8300),
            gyro_minus=(-8180, -8170, -8250),
            gyro_speed_plus=540,
            gyro_speed_minus=540,
            acc_plus=(8250, 8120, 8190),
            acc_minus=(-8100, -8230, -8210),
        )
        self._gscale = np.array(self.calibration.gyro_scale())
        self._gbias = np.array(self.calibration.gyro_bias, dtype=float)
        sc, bi = self.calibration.acc_scale_bias()
        self._ascale, self._abias = np.array(sc), np.array(bi)
        self._server: socket.socket | None = None
        self._clients: list[socket.socket] = []
        self._accept_thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        return build_url("dualsense", "unix", self.socket_path, id=self.name)

    def _open_transport(self) -> None:
        if os.path.exists(self.socket_path):
            os.unlink(self.socket_path)
        srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        srv.bind(self.socket_path)
        srv.listen(4)
        srv.settimeout(0.05)
        self._server = srv
        self._accept_thread = threading.Thread(target=self._accept_loop, args=(srv,), daemon=True)
        self._accept_thread.start()

    def _accept_loop(self, srv: socket.socket) -> None:
        while self._server is srv:
            try:
                c, _ = srv.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            c.setblocking(True)
            self._clients.append(c)
            threading.Thread(target=self._serve, args=(c,), daemon=True).start()

    def _serve(self, c: socket.socket) -> None:
        """Answer feature report requests from one host."""
        while True:
            try:
                msg = c.recv(64)
            except OSError:
                return
            if not msg:
                return
            if msg[:1] == b"F" and len(msg) >= 2 and msg[1] == ds.CALIBRATION_REPORT_ID:
                with self._lock:
                    try:
                        c.send(b"f" + ds.encode_calibration(self.calibration))
                    except OSError:
                        return

    def _close_transport(self) -> None:
        srv, self._server = self._server, None
        for c in self._clients:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        self._clients = []
        if srv is not None:
            srv.close()
        try:
            os.unlink(self.socket_path)
        except OSError:
            pass

    def _make_packet(self, t: float, device_t: float, counter: int) -> bytes:
        s = self.source.at(t)
        graw = s["gyro"] / self._gscale + self._gbias
        araw = s["specific_force"] / self._ascale + self._abias
        rep = ds.DsInput(
            counter & 0xFF,
            tuple(int(round(v)) for v in graw),  # type: ignore[arg-type]
            tuple(int(round(v)) for v in araw),  # type: ignore[arg-type]
            int(device_t * ds.TIMESTAMP_HZ) % ds.TIMESTAMP_MOD,
            85.0,
            False,
        )
        return ds.encode_input_report(rep)

    def _send(self, packet: bytes) -> None:
        dead = []
        for c in list(self._clients):
            try:
                c.send(b"I" + packet, socket.MSG_DONTWAIT)
            except BlockingIOError:
                self.stats["overruns"] += 1
            except OSError:
                dead.append(c)
        for c in dead:
            self._clients.remove(c)
            c.close()


class SimMoticon(SimDevice):
    """Both OpenGo insoles sending their UDP stream to ``host:port``."""

    protocol = "moticon-udp"

    def __init__(
        self,
        source: InsoleSource,
        rate: float = 100.0,
        faults: DeviceFaults | None = None,
        name: str = "insoles",
        host: str = "127.0.0.1",
        port: int | None = None,
        weight_kg: float = 75.0,
    ) -> None:
        super().__init__(source, rate, faults, name)
        self.host = host
        if port is None:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.bind((host, 0))
                port = probe.getsockname()[1]
        self.port = port
        self.weight_kg = weight_kg
        self._sock: socket.socket | None = None

    @property
    def url(self) -> str:
        return build_url("moticon-udp", f"{self.host}:{self.port}", weight_kg=self.weight_kg, rate=int(self.rate))

    def _open_transport(self) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def _close_transport(self) -> None:
        s, self._sock = self._sock, None
        if s is not None:
            s.close()

    def _make_packet(self, t: float, device_t: float, counter: int) -> bytes:
        s = self.source.at(t)
        force = np.maximum(s["force"], 0.0)
        c = s["contacts"]
        cop = np.zeros((2, 2))
        pressure = np.zeros((2, mot.N_PRESSURE))
        for k in range(2):
            heel, toe = bool(c[2 * k]), bool(c[2 * k + 1])
            cop[k, 1] = -0.3 if heel and not toe else 0.3 if toe and not heel else 0.0
            # spread the force over the sensors of the loaded region (each ~6 cm^2)
            region = slice(0, 8) if heel and not toe else slice(8, 16) if toe and not heel else slice(0, 16)
            n = region.stop - region.start
            pressure[k, region] = force[k] / n / 6.0
        f = mot.InsoleFrame(round(device_t, 4), s["acc"] / G, np.degrees(s["gyro"]), cop, pressure, force)
        return mot.encode(f)

    def _corrupt(self, packet: bytes) -> bytes:
        b = bytearray(packet)
        b[int(self.rng.integers(len(b)))] = ord("x")
        return bytes(b)

    def _send(self, packet: bytes) -> None:
        if self._sock is None:
            raise OSError("socket closed")
        self._sock.sendto(packet, (self.host, self.port))
