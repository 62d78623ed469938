"""Simulated wireless sensors: a Movella DOT behind the BLE seam's socket, an x-IMU3
sending its data messages over UDP on loopback."""

from __future__ import annotations

import json
import os
import select
import socket
import tempfile
import threading
import uuid as uuidlib
import zlib

from drivers.movella_dot import protocol as dot
from drivers.movella_dot.ble_seam import socket_name
from drivers.urls import build_url
from drivers.ximu3 import protocol as x3

from .base import DeviceFaults, SignalSource, SimDevice

G = 9.80665


def dot_address(name: str) -> str:
    """A stable Bluetooth address for a simulated DOT named ``name`` (Xsens' D4:22:CD prefix)."""
    h = zlib.crc32(name.encode()) & 0xFFFFFF
    return "D4:22:CD:" + ":".join(f"{(h >> s) & 0xFF:02X}" for s in (16, 8, 0))


class SimMovellaDot(SimDevice):
    """A DOT in 'radio range': a SOCK_SEQPACKET endpoint named after its address in
    ``folder``, serving the GATT characteristics the driver uses (measurement control,
    device control with the output rate, battery) and notifying the payload
    characteristic of the mode a host started, padded as the sensor pads it. A dropped
    link (fault) closes every connection and the socket, and stops the measurement, as a
    DOT does when its central goes away. A corrupted packet is one the BLE link layer's CRC
    would have dropped: it is not sent."""

    protocol = "movella-dot"

    def __init__(self, source: SignalSource, rate: float = 60.0, faults: DeviceFaults | None = None, name: str = "",
                 folder: str | None = None, address: str | None = None, battery: int = 87) -> None:
        super().__init__(source, rate, faults, name)
        self.folder = folder or tempfile.mkdtemp(prefix="imucap-ble-")
        self.address = (address or dot_address(self.name)).upper()
        self.socket_path = os.path.join(self.folder, socket_name(self.address))
        self.battery = dot.DotBattery(battery, False)
        self.control = dot.DotControl(action=0, payload_mode=dot.MODE_COMPLETE_QUATERNION)
        tag = b"Movella DOT"
        dc = bytearray(32)
        dc[7] = len(tag)
        dc[8 : 8 + len(tag)] = tag
        dc[24:26] = int(rate).to_bytes(2, "little")
        self.device_control = bytes(dc)
        self._server: socket.socket | None = None
        self._clients: dict[socket.socket, set[bytes]] = {}

    @property
    def url(self) -> str:
        return build_url("movella-dot", self.address, ble=self.folder, id=self.name)

    # --- transport --------------------------------------------------------------------------------
    def _open_transport(self) -> None:
        os.makedirs(self.folder, exist_ok=True)
        if os.path.exists(self.socket_path):
            os.unlink(self.socket_path)
        srv = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        srv.bind(self.socket_path)
        srv.listen(4)
        srv.settimeout(0.05)
        self._server = srv
        threading.Thread(target=self._accept_loop, args=(srv,), name=f"sim-dot-{self.name}", daemon=True).start()

    def _accept_loop(self, srv: socket.socket) -> None:
        while self._server is srv:
            try:
                c, _ = srv.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            c.setblocking(True)
            with self._lock:
                self._clients[c] = set()
            threading.Thread(target=self._serve, args=(c,), daemon=True).start()

    def _serve(self, c: socket.socket) -> None:
        """Answer one central's GATT requests."""
        while True:
            try:
                msg = c.recv(512)
            except OSError:
                return
            if not msg:
                with self._lock:
                    self._clients.pop(c, None)
                return
            try:
                answer = self._request(c, msg)
            except (ValueError, dot.DotError) as exc:
                answer = b"e" + str(exc).encode()
            with self._lock:
                try:
                    c.send(answer)
                except OSError:
                    return

    def _request(self, c: socket.socket, msg: bytes) -> bytes:
        kind, key, value = msg[:1], msg[1:17], msg[17:]
        if kind == b"A":
            # the advertisement's data: what a scan learns without connecting
            return b"a" + json.dumps({"name": "Movella DOT", "address": self.address, "rssi": -55,
                                      "battery": self.battery.level}).encode()
        char = str(uuidlib.UUID(bytes=key)) if len(key) == 16 else ""
        if kind == b"R":
            values = {dot.BATTERY: dot.encode_battery(self.battery), dot.CONTROL: dot.encode_control(self.control),
                      dot.DEVICE_CONTROL: self.device_control}
            if char not in values:
                raise ValueError(f"characteristic {char} cannot be read")
            return b"r" + key + values[char]
        if kind == b"W":
            if char == dot.CONTROL:
                ctl = dot.decode_control(value)
                if ctl.action == 1:
                    dot.characteristic_for(ctl.payload_mode)  # refuses modes the twin does not stream
                self.control = ctl
            elif char == dot.DEVICE_CONTROL:
                if len(value) < 26:
                    raise ValueError("device control write is 32 bytes")
                rate = int.from_bytes(value[24:26], "little")
                if value[0] & 0x10 and rate in dot.OUTPUT_RATES:
                    self.rate = float(rate)
                    dc = bytearray(self.device_control)
                    dc[24:26] = value[24:26]
                    self.device_control = bytes(dc)
            else:
                raise ValueError(f"characteristic {char} cannot be written")
            return b"w" + key
        if kind == b"N":
            with self._lock:
                if c in self._clients:
                    self._clients[c].add(key)
            return b"n" + key
        raise ValueError(f"unknown request {kind!r}")

    def _close_transport(self) -> None:
        srv, self._server = self._server, None
        for c in list(self._clients):
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        self._clients = {}
        self.control = dot.DotControl(action=0, payload_mode=self.control.payload_mode)
        if srv is not None:
            srv.close()
        try:
            os.unlink(self.socket_path)
        except OSError:
            pass

    def _streaming(self) -> bool:
        return self.control.streaming

    def _make_packet(self, t: float, device_t: float, counter: int) -> bytes:
        s = self.source.at(t)
        m = dot.DotMeasurement(int(device_t * 1e6) % dot.TIMESTAMP_MOD, tuple(s["quat"]), tuple(s["free_acc"]),
                               status=0, clip_acc=0, clip_gyr=0)
        return dot.encode(m, self.control.payload_mode)

    def _corrupt(self, packet: bytes) -> bytes:
        return b""

    def _send(self, packet: bytes) -> None:
        if not packet:
            return
        key = uuidlib.UUID(dot.characteristic_for(self.control.payload_mode)).bytes
        dead = []
        for c, subs in list(self._clients.items()):
            if key not in subs:
                continue
            try:
                c.send(b"V" + key + packet, socket.MSG_DONTWAIT)
            except BlockingIOError:
                self.stats["overruns"] += 1
            except OSError:
                dead.append(c)
        for c in dead:
            self._clients.pop(c, None)
            c.close()


class SimXimu3(SimDevice):
    """An x-IMU3 in UDP mode: binary inertial and quaternion messages every tick (one
    datagram), a battery message every second, sent to ``host:port``; it listens for
    commands on ``host:send_port`` and answers them (a ping with its name and serial
    number) on the data port, as the device does. Unplugged, it neither sends nor answers."""

    protocol = "ximu3"

    def __init__(self, source: SignalSource, rate: float = 100.0, faults: DeviceFaults | None = None, name: str = "",
                 host: str = "127.0.0.1", port: int | None = None, send_port: int | None = None,
                 binary: bool = True, battery: float = 76.0) -> None:
        super().__init__(source, rate, faults, name)
        self.host, self.binary, self.battery = host, binary, battery
        self.port = port or _free_udp_port(host)
        self.send_port = send_port or _free_udp_port(host)
        self.serial = f"{zlib.crc32(self.name.encode()) & 0xFFFFFFFF:08X}"
        self._sock: socket.socket | None = None

    @property
    def url(self) -> str:
        return build_url("ximu3", "udp", f"/{self.port}", ip=self.host, send_port=self.send_port,
                         rate=int(self.rate), id=self.name)

    def _open_transport(self) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((self.host, self.send_port))
        except OSError:
            s.close()
            raise
        self._sock = s

    def _close_transport(self) -> None:
        s, self._sock = self._sock, None
        if s is not None:
            s.close()

    def _service(self, timeout: float) -> None:
        s = self._sock
        if s is None:
            self._stop.wait(timeout)
            return
        try:
            r, _, _ = select.select([s], [], [], timeout)
            if not r:
                return
            data = s.recv(4096)
        except (OSError, ValueError):
            self._stop.wait(timeout)
            return
        for line in data.splitlines():
            try:
                cmd = json.loads(line)
                key = next(iter(cmd))
            except (ValueError, StopIteration, TypeError):
                continue
            value = ({"interface": "UDP", "device_name": "x-IMU3", "serial_number": self.serial}
                     if key == "ping" else cmd[key])
            with self._lock:
                if self._sock is not None:
                    try:
                        self._sock.sendto(json.dumps({key: value}).encode() + b"\r\n", (self.host, self.port))
                    except OSError:
                        pass

    def _make_packet(self, t: float, device_t: float, counter: int) -> bytes:
        # sampled and stamped on the device's own tick, as the x-IMU3 does: a send late by the
        # host's scheduling does not move its timestamp (the counter's tick, the loop's schedule)
        t = counter / self.rate
        s = self.source.at(t)
        ts = max(0, int(self.device_time(t) * 1e6))
        out = x3.encode(x3.Message(x3.INERTIAL, ts, (*(s["gyro"] * 180.0 / 3.141592653589793),
                                                      *(s["specific_force"] / G))), self.binary)
        out += x3.encode(x3.Message(x3.QUATERNION, ts, tuple(s["quat"])), self.binary)
        if counter % max(1, int(self.rate)) == 0:
            out += x3.encode(x3.Message(x3.BATTERY, ts, (self.battery, 3.9, 0.0)), self.binary)
        return out

    def _corrupt(self, packet: bytes) -> bytes:
        """A damaged datagram that still arrived: the first message cut short (the UDP
        checksum drops flipped bits; a truncation is what a receiver can still see)."""
        first, _, rest = packet.partition(b"\n")
        return first[: max(1, len(first) // 2)] + b"\n" + rest

    def _send(self, packet: bytes) -> None:
        s = self._sock
        if s is None:
            raise OSError("socket closed")
        s.sendto(packet, (self.host, self.port))


def _free_udp_port(host: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.bind((host, 0))
        return int(probe.getsockname()[1])
