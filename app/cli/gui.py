"""`imucap gui`: the window, with the last setup file (or the one given) loaded.

    imucap gui [--setup FILE] [--tab TAB] [--view outdoor [--outdoor-skeleton 2d|3d]] [--screenshot PNG --quit-after S]
"""

from __future__ import annotations

import argparse
import os

from app.cli.window_args import add_window_arguments


def run(args: argparse.Namespace) -> int:
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") or os.environ.get("QT_QPA_PLATFORM")):
        raise OSError("no display to open the window on: run it on a desktop, or under a virtual display: "
                      "`xvfb-run -a imucap gui`")
    from app.gui.main import TABS, run_window

    def setup(win) -> None:
        if args.setup:
            win.setup_panel.open(args.setup)
        else:
            win.open_last_setup()
        if args.tab:
            win.tabs.setCurrentIndex(TABS.index(args.tab))

    return run_window(setup, args)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("gui", help="the window: set up, calibrate, watch live, record, replay, export")
    p.add_argument("--setup", help="open this setup file (default: the last one opened or saved)")
    p.add_argument("--tab", choices=("Setup", "Devices", "Calibration", "Live", "Recordings", "Replay"),
                   help="start on this tab")
    add_window_arguments(p)
    p.set_defaults(func=run)
