"""Which device URLs a simulator can serve, and a setup's simulated twin.

Why: ``imucap devices simulate --setup`` makes a setup's devices appear at the setup's own
URLs, so the same file drives the simulator and ``imucap capture``. That works for URLs a
process can bring into being on this machine (a pseudo-terminal linked at a path, the HID
seam's socket, a CAN bus served on loopback, datagrams to a loopback port, a BLE seam socket
for a DOT), not for a real device's (``/dev/ttyUSB0``, ``dualsense://`` through hidapi, a
socketcan adapter, a DOT over Bluetooth, an x-IMU3 over TCP or serial) nor for
anything that would put traffic on the network. ``simulation_problem`` says which and why;
``twin_setup`` turns a setup of real URLs into the same setup over simulated ones, which
``imucap devices simulate --twin-setup`` writes for a user who has no hardware at hand.
"""

from __future__ import annotations

import dataclasses
import socket
import tempfile
from pathlib import Path

from app.capture.setup_file import DEFAULT_MODEL, SensorEntry, Setup, Subject
from drivers.urls import parse_url
from sim_devices.devices.can_loopback import (
    REMOTE_INTERFACE,
    free_loopback_port,
    is_loopback,
    loopback_channel,
    split_host_port,
)

WIRE_PROTOCOLS = ("xbus", "bno08x-rvc", "xsens-can", "dualsense")
WIRELESS_PROTOCOLS = ("movella-dot", "ximu3")  # not in the "mixed" rotation, which stays as it was
EXAMPLE = "examples/simulated_suit.toml"


def free_udp_port() -> int:
    return free_loopback_port(socket.SOCK_DGRAM)


def simulation_problem(url: str) -> str | None:
    """Why a simulator cannot serve ``url`` (a real device's, or one whose traffic would
    leave this machine), or ``None`` when it can."""
    try:
        u = parse_url(url)
    except ValueError as exc:
        return str(exc)
    if u.scheme in ("xbus", "bno08x-rvc"):
        if not u.path:
            return "a serial URL needs the path of its port"
        if u.path.startswith("/dev/"):
            return f"{u.path} is a real serial port (a simulated one is a link elsewhere: /tmp/imucap-sim/pelvis-tty)"
        return None
    if u.scheme == "xsens-can":
        if u.netloc != REMOTE_INTERFACE:
            why = {"virtual": "python-can's virtual bus does not cross processes",
                   "udp_multicast": "a multicast bus leaves this machine"}.get(u.netloc, "a real CAN bus")
            return f"{u.netloc}/{u.path.lstrip('/')} is {why} (a simulated bus is xsens-can://remote/127.0.0.1:PORT)"
        try:
            host, _ = split_host_port(u.path.lstrip("/"))
        except ValueError as exc:
            return str(exc)
        return None if is_loopback(host) else f"{host} is not a loopback address"
    if u.scheme == "dualsense":
        return None if u.netloc == "unix" else "a real DualSense (a simulated one is dualsense://unix/PATH)"
    if u.scheme == "moticon-udp":
        host, _, port = u.netloc.rpartition(":")
        if not port.isdigit():
            return "a Moticon URL needs host:port"
        return None if is_loopback(host) else f"{host} is not a loopback address"
    if u.scheme == "movella-dot":
        return None if u.get("ble") else "a real DOT over Bluetooth (a simulated one is movella-dot://ADDRESS?ble=DIR)"
    if u.scheme == "vmc-in":
        from drivers.vmc.device import split_netloc

        try:
            host, port = split_netloc(u.netloc)
        except ValueError as exc:
            return str(exc)
        if not is_loopback(host):
            return (f"{host} is not a loopback address: a simulated VR rig sends to this machine only "
                    f"(vmc-in://127.0.0.1:{port}?...)")
        return None
    if u.scheme == "ximu3":
        if u.netloc != "udp":
            return f"an x-IMU3 over {u.netloc} (a simulated one is ximu3://udp/PORT, on loopback)"
        if not u.path.lstrip("/").isdigit():
            return "an x-IMU3 UDP URL needs the port: ximu3://udp/PORT"
        ip = u.get("ip", "127.0.0.1") or "127.0.0.1"
        return None if is_loopback(ip) else f"{ip} is not a loopback address"
    return f"no simulated twin for {u.scheme!r}"


def simulated_url(site: str, protocol: str, folder: Path, k: int, can_channel: str | None = None) -> str:
    """Where a simulated device of ``protocol`` for ``site`` appears (the k-th of the suit);
    CAN devices on the bus the simulator serves at ``can_channel`` (127.0.0.1:PORT, one bus
    across processes, on loopback)."""
    if protocol == "xbus":
        return f"xbus://{folder}/{site}-tty?baud=115200"
    if protocol == "bno08x-rvc":
        return f"bno08x-rvc://{folder}/{site}-tty"
    if protocol == "xsens-can":
        return f"xsens-can://remote/{can_channel or loopback_channel()}?id_offset=0x{0x100 * (k + 1):x}"
    if protocol == "dualsense":
        return f"dualsense://unix/{folder}/{site}.sock"
    if protocol == "movella-dot":
        from sim_devices.devices.wireless_twins import dot_address

        return f"movella-dot://{dot_address(site)}?ble={folder}/ble"
    if protocol == "ximu3":
        return f"ximu3://udp/{free_udp_port()}?ip=127.0.0.1&send_port={free_udp_port()}"
    raise ValueError(f"no simulated device for protocol {protocol!r}; "
                     f"choose {', '.join(WIRE_PROTOCOLS + WIRELESS_PROTOCOLS)} or mixed")


def simulated_setup(sites: tuple[str, ...], protocol: str = "xbus", insoles: bool = False,
                    folder: Path | None = None, subject: Subject | None = None, model: str = DEFAULT_MODEL,
                    steps: str | None = None, recordings: Path | None = None) -> Setup:
    """A setup whose devices are simulated: ``protocol`` for all, or ``mixed`` (in turn)."""
    folder = Path(folder or tempfile.mkdtemp(prefix="imucap-sim-"))
    can_channel = loopback_channel()
    sensors = {}
    for k, site in enumerate(sites):
        proto = WIRE_PROTOCOLS[k % len(WIRE_PROTOCOLS)] if protocol == "mixed" else protocol
        sensors[site] = SensorEntry(site, simulated_url(site, proto, folder, k, can_channel), label="simulated")
    setup = Setup(subject=subject or Subject("sim-01", 1.75, "simulated subject"), sensors=sensors,
                  insoles=f"moticon-udp://127.0.0.1:{free_udp_port()}" if insoles else None, model=model,
                  steps=steps, calibration="walk")
    if recordings is not None:
        setup.recordings = recordings
    return setup


def twin_setup(setup: Setup, folder: Path) -> Setup:
    """``setup`` with every device a simulated twin of the same protocol (URLs a simulator
    can serve kept as they are): same sites, subject, model and calibration. Serial links
    and HID sockets go in ``folder``; CAN devices share one bus on loopback and keep their
    identifier blocks."""
    can_channel = loopback_channel()
    sensors = {}
    for k, (site, entry) in enumerate(setup.sensors.items()):
        url = entry.url
        if simulation_problem(url) is not None:
            u = parse_url(url)
            url = simulated_url(site, u.scheme, folder, k, can_channel)
            if u.scheme == "xsens-can" and u.get("id_offset"):
                url = url.split("?")[0] + f"?id_offset={u.get('id_offset')}"
        sensors[site] = dataclasses.replace(entry, url=url)
    insoles = setup.insoles
    if insoles is not None and simulation_problem(insoles) is not None:
        insoles = f"moticon-udp://127.0.0.1:{free_udp_port()}"
    tracked = {}
    for name, entry in setup.tracked.items():
        url = entry.url
        if simulation_problem(url) is not None:  # a rig on another PC: the same serials, on loopback
            url = "vmc-in://127.0.0.1:{}?{}".format(free_udp_port(), url.partition("?")[2])
        tracked[name] = dataclasses.replace(entry, url=url)
    return dataclasses.replace(setup, sensors=sensors, insoles=insoles, tracked=tracked, path=None)
