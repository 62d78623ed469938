"""The demo window under a (virtual) display: it opens, receives frames from the pipeline
thread, the skeleton item's data changes, the sensor chooser reaches the pipeline, the
record button writes a file. The window is grabbed to a PNG: set IMUCAP_SCREENSHOT=docs/demo.png
to refresh the picture in the docs (a test run must not rewrite tracked files).

Run under Xvfb: ``xvfb-run -a .venv/bin/pytest -m gui tests/app/gui/test_main_window.py``."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.gui

if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    pytest.skip("no display (run under xvfb-run)", allow_module_level=True)

pytest.importorskip("pytestqt")
pytest.importorskip("OpenGL")

from app.demo_session import DemoConfig, DemoSession  # noqa: E402
from app.recording import read_recording  # noqa: E402
from calibration import Protocol  # noqa: E402

SUIT = ("pelvis", "torso", "head", "l_upperarm", "r_upperarm", "l_wrist", "r_wrist", "l_thigh", "r_thigh",
        "l_shank", "r_shank", "l_foot", "r_foot")


def _state(session) -> str:
    """What a stalled session was doing, for the failure message (a bare timeout said
    nothing the time this test stalled in a full run under load)."""
    live, hub = session.live, session.hub
    events = [(e.device_id, e.kind, e.detail) for e in list(hub.events)[-12:]] if hub is not None else []
    return (f"status={session.pipeline.status!r} live_error={getattr(live, 'error', None)!r} "
            f"running={getattr(live, 'running', None)} stats={live.stats() if live else None} "
            f"devices={hub.status() if hub is not None else None} events={events}")


def _wait(qtbot, session, cond, timeout: int) -> None:
    """Wait for the pipeline thread. The generous timeouts are for shared CI machines
    (two test workers plus whatever else): a stall still fails, with the session state."""
    try:
        qtbot.waitUntil(cond, timeout=timeout)
    except qtbot.TimeoutError as exc:
        raise AssertionError(f"timed out after {timeout} ms: {_state(session)}") from exc


def test_demo_window(qtbot, tmp_path):
    from app.gui.main_window import DemoWindow

    cfg = DemoConfig(motion="walk", sensors=SUIT, protocol="xbus", seconds=30.0, model="floor", headless=False,
                     threads=1, calibration_protocol=Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.4,
                                                              margin=0.15))
    session = DemoSession(cfg).start()
    try:
        win = DemoWindow(session)
        qtbot.addWidget(win)
        win.show()
        qtbot.waitExposed(win)
        # frames arrive from the pipeline thread and reach the GL items
        _wait(qtbot, session, lambda: win.frames_shown >= 3, 90_000)  # slow, shared CI machines
        before = np.array(win.view.bones.pos, copy=True)
        shown = win.frames_shown
        _wait(qtbot, session, lambda: win.frames_shown >= shown + 5, 30_000)
        assert not np.allclose(before, win.view.bones.pos)
        assert np.isfinite(win.view.bones.pos).all()
        _wait(qtbot, session, lambda: win.table.rowCount() == len(SUIT), 30_000)
        assert win.table.item(0, 0).text() == "pelvis"
        assert win.stride_label.text().endswith(": off")  # the floor has no root to scale

        # the clinician's sensor configuration goes to the pipeline thread
        win.preset.setCurrentIndex(win.preset.findText("paper 6 (pelvis, head, wrists, shanks)"))
        _wait(qtbot, session, lambda: len(session.pipeline.active_sites) == 6, 30_000)
        _wait(qtbot, session, lambda: session.live.latest().observed_sites.sum() == 6, 30_000)
        win.preset.setCurrentIndex(0)
        _wait(qtbot, session, lambda: len(session.pipeline.active_sites) == len(SUIT), 30_000)

        # recording from the button
        win.record_path = tmp_path / "gui.h5"
        win.record_button.click()
        assert win.record_button.isChecked() and session.recorder is not None
        n0 = session.pipeline.stats.poses
        _wait(qtbot, session, lambda: session.pipeline.stats.poses >= n0 + 20, 30_000)
        # a walking pose for the screenshot
        qtbot.wait(300)
        shot = Path(os.environ.get("IMUCAP_SCREENSHOT", tmp_path / "demo.png"))
        assert win.grab().save(str(shot)) and shot.stat().st_size > 10_000
        win.record_button.click()
        assert session.recorder is None and not win.record_button.isChecked()
        rec = read_recording(tmp_path / "gui.h5")
        assert len(rec.recon["t"]) >= 15 and rec.n_frames >= 45
        assert rec.metadata["model"] == "floor"
        win.close()
    finally:
        session.stop()
