"""Simulated devices made from inside the window: the demo's suit, and "Simulate devices"
for someone trying the window with no sensors at hand.

Why ``imucap devices simulate --setup`` in a process of its own
(``app/capture/simulator_process.py``): the window then goes through exactly what it does
with real sensors (open URLs, calibrate with the guided steps, reconstruct, record), and the
devices' threads do not share the window's interpreter, as real sensors do not.
"""

from __future__ import annotations

import socket
import tempfile
from pathlib import Path

from app.capture.setup_file import SensorEntry, Setup, Subject
from app.capture.simulator_process import SimulatorProcess
from sim_devices.suit_process import random_can_group

WIRE_PROTOCOLS = ("xbus", "bno08x-rvc", "xsens-can", "dualsense")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def simulated_url(site: str, protocol: str, folder: Path, k: int, can_group: str | None = None) -> str:
    """Where a simulated device of ``protocol`` for ``site`` appears (the k-th of the suit);
    CAN devices on the UDP multicast group ``can_group`` (one bus across processes)."""
    if protocol == "xbus":
        return f"xbus://{folder}/{site}-tty?baud=115200"
    if protocol == "bno08x-rvc":
        return f"bno08x-rvc://{folder}/{site}-tty"
    if protocol == "xsens-can":
        group = can_group or random_can_group()
        return f"xsens-can://udp_multicast/{group}?id_offset=0x{0x100 * (k + 1):x}"
    if protocol == "dualsense":
        return f"dualsense://unix/{folder}/{site}.sock"
    raise ValueError(f"no simulated device for protocol {protocol!r}; choose {', '.join(WIRE_PROTOCOLS)} or mixed")


def simulated_setup(sites: tuple[str, ...], protocol: str = "xbus", insoles: bool = False,
                    folder: Path | None = None, subject: Subject | None = None, model: str = "diffusion",
                    steps: str | None = None, recordings: Path | None = None) -> Setup:
    """A setup whose devices are simulated: ``protocol`` for all, or ``mixed`` (in turn)."""
    folder = Path(folder or tempfile.mkdtemp(prefix="imucap-sim-"))
    group = random_can_group()
    sensors = {}
    for k, site in enumerate(sites):
        proto = WIRE_PROTOCOLS[k % len(WIRE_PROTOCOLS)] if protocol == "mixed" else protocol
        sensors[site] = SensorEntry(site, simulated_url(site, proto, folder, k, group), label="simulated")
    setup = Setup(subject=subject or Subject("sim-01", 1.75, "simulated subject"), sensors=sensors,
                  insoles=f"moticon-udp://127.0.0.1:{_free_udp_port()}" if insoles else None, model=model,
                  steps=steps, calibration="walk")
    if recordings is not None:
        setup.recordings = recordings
    return setup


def start_simulation(setup: Setup, motion: str = "walk", seconds: float = 60.0, seed: int = 0,
                     noise: bool = True, lead_in: float = 4.0) -> SimulatorProcess:
    """Start the devices in their own process, the subject at the start of the protocol,
    then ``motion`` (a kind or a motion file) for ``seconds``, looped (synthesis takes
    seconds: call it off the GUI thread)."""
    return SimulatorProcess(setup, motion, seconds=seconds, seed=seed, noise=noise, lead_in=lead_in).start()
