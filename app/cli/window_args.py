"""The window's options shared by the commands that open one on a live session (``demo``,
``capture``): one definition, so the two cannot drift apart. No Qt import here: a capture
install without the GUI extra still parses its command line."""

from __future__ import annotations

import argparse

OUTDOOR_SKELETONS = ("2d", "3d")  # app.gui.outdoor_view.SKELETONS


def add_window_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--screenshot", help="with the window: save it to this PNG after --quit-after seconds")
    p.add_argument("--quit-after", type=float, default=0.0, help="with the window: close it after this many seconds")
    p.add_argument("--window-stats", metavar="FILE.json", default=None,
                   help="with --quit-after: write what the window itself cost (GUI thread CPU, draws/s, draw and "
                        "status times, timer lag; app/gui/gui_cost.py)")
    p.add_argument("--view", choices=("desk", "outdoor"), default="desk",
                   help="with a window: outdoor = large numbers on black for a runner glancing from a distance")
    p.add_argument("--outdoor-skeleton", choices=OUTDOOR_SKELETONS, default=None,
                   help="the outdoor view's skeleton for this run: 2d (side on, the default; a fraction of the "
                        "CPU) or 3d (the desk view's GL skeleton); the window remembers the last one chosen in it")
