"""`imucap capture --setup FILE` with a display: the main window on that setup's session."""

from __future__ import annotations

from typing import Any

from app.capture.session import CaptureSession
from app.gui.main import run_window


def run_capture_window(session: CaptureSession, args: Any) -> int:
    """Open the window, start ``session`` in it (its devices, its calibration), run until
    the window closes; ``--screenshot PNG --quit-after S`` saves the window after S s."""
    return run_window(lambda win: win.adopt_session(session), args)
