"""`imucap demo` with a window: the main window on a simulated suit.

The suit is ``imucap devices simulate --setup`` in a process of its own (the chosen sites
over the chosen wire protocol, worn by a simulated subject), so the demo walks through
what a real capture does: the calibration wizard, the live view, recording, replay.
"""

from __future__ import annotations

from app.capture.demo import DemoConfig, demo_spec
from app.gui.main import MainWindow, run_window


def start_demo(win: MainWindow, cfg: DemoConfig) -> None:
    """Show the demo's setup and start its capture: the same spec as the headless demo
    (``app.capture.demo.demo_spec``), run by the window's live session."""
    spec = demo_spec(cfg)
    win.model.load(spec.setup)
    for url in spec.setup.urls().values():
        win.model.add_device(url, f"simulated {cfg.protocol}", "simulated")
    win.tabs.setCurrentIndex(2)  # the calibration wizard first, then the live view by itself
    # the simulator starts on the worker that builds the session (synthesis takes seconds)
    win._start(spec.setup, None, None, options=spec.options, make_simulation=spec.simulator.start)


def run_gui(cfg: DemoConfig) -> int:
    """`imucap demo` with the window (``cfg.extra["args"]``: the CLI's arguments, for
    ``--screenshot`` and ``--quit-after``)."""
    return run_window(lambda win: start_demo(win, cfg), cfg.extra.get("args"))
