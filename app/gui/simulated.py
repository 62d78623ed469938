"""Simulated devices started from inside the window: the demo's suit, and "Simulate devices"
for someone trying the window with no sensors at hand (their setups: ``app.capture.twins``).

Why ``imucap devices simulate --setup`` in a process of its own
(``app/capture/simulator_process.py``): the window then goes through exactly what it does
with real sensors (open URLs, calibrate with the guided steps, reconstruct, record), and the
devices' threads do not share the window's interpreter, as real sensors do not.
"""

from __future__ import annotations

from app.capture.setup_file import Setup
from app.capture.simulator_process import SimulatorProcess


def start_simulation(setup: Setup, motion: str = "walk", seconds: float = 60.0, seed: int = 0,
                     noise: bool = True, lead_in: float = 4.0) -> SimulatorProcess:
    """Start the devices in their own process, the subject at the start of the protocol,
    then ``motion`` (a kind or a motion file) for ``seconds``, looped (synthesis takes
    seconds: call it off the GUI thread)."""
    return SimulatorProcess(setup, motion, seconds=seconds, seed=seed, noise=noise, lead_in=lead_in).start()
