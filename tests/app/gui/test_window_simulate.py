"""The Devices tab's "Simulate devices", as someone trying imucap without hardware reaches it:
sites chosen on the Setup tab, then one click makes a simulated device for each site (in
turn over every wire protocol: "mixed"), running in a process of their own. Start capture
restarts that process so the simulated subject begins with the calibration steps, the
session calibrates and poses, and closing the window ends the process.
"""

from __future__ import annotations

import os
import time

import pytest

pytestmark = [pytest.mark.gui, pytest.mark.slow]

if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    pytest.skip("no display (run under xvfb-run)", allow_module_level=True)

pytest.importorskip("pytestqt")
pytest.importorskip("OpenGL")

from PySide6 import QtCore  # noqa: E402

from tests.app.gui.helpers import choose_preset, shown_window, wait, window_state  # noqa: E402

SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")


def _ended(proc, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if proc.poll() is not None:
            return True
        time.sleep(0.1)
    return proc.poll() is not None


def test_simulate_devices_then_capture(qtbot, tmp_path):

    win = shown_window(qtbot, tmp_path)
    state = lambda: window_state(win)  # noqa: E731
    children = []
    try:
        dp = win.devices_panel
        win.tabs.setCurrentWidget(dp)
        # no sites yet: the window says what to do first, and starts nothing
        win.model.set_sites(())
        qtbot.mouseClick(dp.sim_button, QtCore.Qt.MouseButton.LeftButton)
        assert "choose the sites first" in win.messages.label.text()
        assert win.simulation is None and not win.jobs.busy("simulate")

        choose_preset(win, "classic 6")
        assert win.model.draft.sites == SITES
        dp.sim_protocol.setCurrentText("mixed")
        qtbot.mouseClick(dp.sim_button, QtCore.Qt.MouseButton.LeftButton)
        wait(qtbot, lambda: win.simulation is not None, 180, "the simulated devices to run", state)
        sim = win.simulation
        first = sim.proc
        children.append(first)
        assert sim.running and first.pid != os.getpid()
        assigned = win.model.assigned()
        assert tuple(assigned) == SITES
        schemes = {url.split("://")[0] for url in assigned.values()}
        assert schemes == {"xbus", "bno08x-rvc", "xsens-can", "dualsense"}, schemes
        assert set(sim.urls) == set(SITES), sim.urls
        assert "6 simulated devices running" in win.messages.label.text()

        win.start_action.trigger()
        wait(qtbot, lambda: win.session is not None, 180, "the capture to start", state)
        live = win.session
        assert live.simulation is sim, "the window's simulator goes with the session"
        # restarted, so the subject begins with the protocol's first step
        assert sim.proc is not None and sim.proc is not first and sim.running
        children.append(sim.proc)
        assert _ended(first, 15), "the first simulator process did not end when restarted"
        wait(qtbot, lambda: live.calibrated, 180, "calibration from the simulated subject", state)
        wait(qtbot, lambda: live.perf()["frames"] >= 20, 120, "poses from the simulated devices", state)
        rows = {r.name: r for r in live.device_rows()}
        assert set(rows) == set(SITES) and all(r.packets > 0 for r in rows.values()), state()
    finally:
        win.close()
    assert children and all(_ended(p, 20) for p in children), "a simulator process outlived the window"
