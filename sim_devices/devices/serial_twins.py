"""Simulated serial devices: an Xsens MTi (Xbus) and a BNO08x in UART-RVC mode."""

from __future__ import annotations

import math
import select
import struct
from typing import Any

import numpy as np

from drivers._math import euler_zyx_from_quat
from drivers.bno08x import protocol as rvc
from drivers.urls import build_url
from drivers.xbus import protocol as xb

from .base import DeviceFaults, SignalSource, SimDevice
from .pty_port import PtyPort


class _PtyDevice(SimDevice):
    def __init__(
        self, source: Any, rate: float, faults: DeviceFaults | None = None, name: str = "", link_path: str | None = None
    ) -> None:
        super().__init__(source, rate, faults, name)
        self.port = PtyPort(link_path)

    def _open_transport(self) -> None:
        self.port.open()

    def _close_transport(self) -> None:
        self.port.close()

    def _send(self, packet: bytes) -> None:
        self.port.write(packet)

    def _cleanup(self) -> None:
        self.port.remove()


class SimXbus(_PtyDevice):
    """An MTi on a pty: streams MTData2 in measurement state and answers
    GoToConfig / SetOutputConfiguration / GoToMeasurement / ReqDID with the
    acknowledgements a real MTi sends. It starts measuring with its factory
    configuration (float32 ENU, 100 Hz), as an MTi does at power-up."""

    protocol = "xbus"

    def __init__(
        self,
        source: SignalSource,
        rate: float = 100.0,
        faults: DeviceFaults | None = None,
        name: str = "",
        link_path: str | None = None,
        device_serial: int = 0x037003F8,
    ) -> None:
        super().__init__(source, rate, faults, name, link_path)
        self.device_serial = device_serial
        self.measuring = True
        self.precision = xb.Precision.FLOAT32
        self.frame = xb.CoordFrame.ENU
        self.outputs: set[int] = {
            xb.XDI.PacketCounter,
            xb.XDI.SampleTimeFine,
            xb.XDI.Quaternion,
            xb.XDI.Acceleration,
            xb.XDI.FreeAcceleration,
            xb.XDI.RateOfTurn,
            xb.XDI.StatusWord,
        }
        self.configured_outputs: list[tuple[int, int]] | None = None
        self.commands: list[int] = []
        self._parser = xb.XbusStreamParser()

    @property
    def url(self) -> str:
        return build_url("xbus", "", self.port.link_path, baud=115200, rate=int(self.rate), id=self.name)

    def _open_transport(self) -> None:
        super()._open_transport()
        self._parser = xb.XbusStreamParser()
        self.measuring = True  # power-up state after a re-plug

    def _streaming(self) -> bool:
        return self.measuring

    def _service(self, timeout: float) -> None:
        fd = self.port.master
        if fd is None:
            self._stop.wait(timeout)
            return
        try:
            r, _, _ = select.select([fd], [], [], timeout)
        except (OSError, ValueError):
            return
        if r:
            for m in self._parser.feed(self.port.read()):
                self._handle(m)

    def _reply(self, mid: int, data: bytes = b"") -> None:
        with self._lock:
            try:
                self.port.write(xb.encode(mid, data))
            except OSError:
                pass

    def _handle(self, m: xb.XbusMessage) -> None:
        self.commands.append(m.mid)
        if m.mid == xb.MID.GoToConfig:
            self.measuring = False
            self._reply(xb.MID.GoToConfigAck)
        elif m.mid == xb.MID.GoToMeasurement:
            self.measuring = True
            self._reply(xb.MID.GoToMeasurementAck)
        elif m.mid == xb.MID.ReqDID:
            self._reply(xb.MID.DeviceID, struct.pack(">I", self.device_serial))
        elif m.mid == xb.MID.SetOutputConfiguration and not self.measuring:
            try:
                items = xb.decode_output_configuration(m.data)
            except xb.XbusError:
                self._reply(xb.MID.Error, b"\x21")  # invalid message
                return
            self.configured_outputs = items
            self.outputs = {did & 0xFFF0 for did, _ in items}
            for did, rate in items:
                if did & 0xFFF0 in (xb.XDI.Quaternion, xb.XDI.Acceleration, xb.XDI.FreeAcceleration, xb.XDI.RateOfTurn):
                    self.precision = xb.Precision(did & 0x3)
                    self.frame = xb.CoordFrame(did & 0xC)
                    if 0 < rate < 0xFFFF:
                        self.rate = float(rate)
            self._reply(xb.MID.SetOutputConfigurationAck, m.data)
        elif m.mid == xb.MID.WakeUpAck:
            pass
        else:
            self._reply(xb.MID.Error, b"\x04")  # message not valid in this state

    def _make_packet(self, t: float, device_t: float, counter: int) -> bytes:
        s = self.source.at(t)
        q, fa, f, g = s["quat"], s["free_acc"], s["specific_force"], s["gyro"]
        if self.frame == xb.CoordFrame.NED:  # the inverse of the driver's Z-up mapping
            flip = np.array([1.0, -1.0, -1.0])
            q = np.array([q[0], q[1], -q[2], -q[3]])
            fa, f, g = fa * flip, f * flip, g * flip
        o = self.outputs

        def pick(xdi: int, v: np.ndarray) -> tuple[float, ...] | None:
            return tuple(float(x) for x in v) if xdi in o else None

        d = xb.MTData2(
            packet_counter=counter & 0xFFFF if xb.XDI.PacketCounter in o else None,
            sample_time_fine=int(device_t * xb.SAMPLE_TIME_FINE_HZ) % xb.SAMPLE_TIME_FINE_MOD
            if xb.XDI.SampleTimeFine in o
            else None,
            quat=pick(xb.XDI.Quaternion, q),
            acc=pick(xb.XDI.Acceleration, f),
            free_acc=pick(xb.XDI.FreeAcceleration, fa),
            gyro=pick(xb.XDI.RateOfTurn, g),
            status=0x00000003 if xb.XDI.StatusWord in o else None,  # self-test ok, filter valid
            precision=self.precision,
            frame=self.frame,
        )
        return xb.encode(xb.MID.MTData2, xb.encode_mtdata2(d))


class SimBno08xRvc(_PtyDevice):
    """A BNO08x in RVC mode: 100 Hz, no commands, 19-byte frames."""

    protocol = "bno08x-rvc"

    def __init__(
        self,
        source: SignalSource,
        rate: float = 100.0,
        faults: DeviceFaults | None = None,
        name: str = "",
        link_path: str | None = None,
    ) -> None:
        super().__init__(source, rate, faults, name, link_path)

    @property
    def url(self) -> str:
        return build_url("bno08x-rvc", "", self.port.link_path, id=self.name)

    def _make_packet(self, t: float, device_t: float, counter: int) -> bytes:
        s = self.source.at(t)
        yaw, pitch, roll = (math.degrees(a) for a in euler_zyx_from_quat(s["quat"]))
        acc_mg = tuple(float(a) * 1000.0 / 9.80665 for a in s["specific_force"])
        return rvc.encode(rvc.RvcFrame(counter & 0xFF, yaw, pitch, roll, acc_mg))  # type: ignore[arg-type]
