"""`imucap demo` with a window: the main window on a simulated suit.

The suit is ``imucap devices simulate --setup`` in a process of its own (the chosen sites
over the chosen wire protocol, worn by a simulated subject), so the demo walks through
what a real capture does: the calibration wizard, the live view, recording, replay.
"""

from __future__ import annotations

from pathlib import Path

from app.capture.session import CaptureOptions
from app.demo_session import DemoConfig
from app.gui.main import MainWindow, run_window


def start_demo(win: MainWindow, cfg: DemoConfig) -> None:
    """Show the demo suit's setup and start it: model, simulated devices, capture."""
    from app.capture.twins import simulated_setup

    setup = simulated_setup(tuple(cfg.sensors), cfg.protocol, cfg.insoles, model=cfg.model, steps=cfg.steps,
                            recordings=Path("recordings").resolve())
    win.model.load(setup)
    for url in setup.urls().values():
        win.model.add_device(url, f"simulated {cfg.protocol}", "simulated")
    options = CaptureOptions(record=Path(cfg.record) if cfg.record else None, sinks=list(cfg.streams),
                             threads=cfg.threads, latency=cfg.latency, confidence=cfg.confidence)

    def make_simulation():
        from app.gui.simulated import start_simulation

        return start_simulation(setup, cfg.file or cfg.motion, seconds=cfg.seconds, seed=cfg.seed, noise=cfg.noise)

    win.tabs.setCurrentIndex(2)  # the calibration wizard first, then the live view by itself
    win._start(setup, None, None, options=options, make_simulation=make_simulation)


def run_gui(cfg: DemoConfig) -> int:
    """`imucap demo` with the window (``cfg.extra["args"]``: the CLI's arguments, for
    ``--screenshot`` and ``--quit-after``)."""
    return run_window(lambda win: start_demo(win, cfg), cfg.extra.get("args"))
