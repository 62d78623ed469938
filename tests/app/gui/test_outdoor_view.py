"""The outdoor view: large numbers on black, sensor bars, one record button.

On its own: poses of a walk with a stiff right knee through the gait sink give a cadence,
two knee ranges and an asymmetry shown in warning orange; a silent sensor shows no signal
and a red name; the record button asks to record. The skeleton is flat and side on by
default: the camera turns with the walker's heading, a body that does not move is not
drawn again, and the 3D view is a click away (and remembered by the window). End to end: `imucap demo --view
outdoor` (a simulated suit in its own process, the window under Xvfb) calibrates and lands
on the outdoor view, whose screenshot holds the yellow numbers on black. Set
IMUCAP_SCREENSHOT=docs/window_outdoor.png to refresh the picture in docs/window.md.

Run under Xvfb: ``xvfb-run -a .venv/bin/pytest -m gui tests/app/gui/test_outdoor_view.py``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.gui

if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    pytest.skip("no display (run under xvfb-run)", allow_module_level=True)

pytest.importorskip("pytestqt")

from PySide6 import QtCore  # noqa: E402

from app.gui.live_session import DeviceRow  # noqa: E402
from app.gui.outdoor_view import ACCENT, BAD, WARN, OutdoorView  # noqa: E402
from app.live import LivePose  # noqa: E402
from app.live.gait import GaitSink  # noqa: E402
from inference.body.body import Body  # noqa: E402
from inference.body.conventions import rot_z  # noqa: E402
from inference.body.motion import Motion  # noqa: E402
from inference.body.skeleton import SEGMENT_INDEX  # noqa: E402
from inference.poser.poser import PoseFrame  # noqa: E402
from inference.signals.synthesis import contact_labels  # noqa: E402
from sim_devices.motions import generate  # noqa: E402
from tests.app.gui.helpers import image_array  # noqa: E402

CLI = [sys.executable, "-m", "app.cli.main"]


def walk_poses(stiff_right: bool, heading_deg: float = 0.0) -> list[LivePose]:
    m = generate("walk", seconds=12, seed=2).resample(20.0)
    if heading_deg:  # the whole walk turned about the vertical
        turn = rot_z(np.radians(heading_deg))
        m = Motion(turn @ m.rot, m.root @ turn.T, m.fps, m.body, m.name)
    rot = m.rot.copy()
    if stiff_right:
        rot[:, SEGMENT_INDEX["r_shank"]] = rot[:, SEGMENT_INDEX["r_thigh"]]
    contacts = contact_labels(m.contacts(), m.fps)
    joints = m.joints()
    out = []
    for i in range(len(rot)):
        frame = PoseFrame(index=i, rot=rot[i], root=joints[i, 0], joints=joints[i], contacts=contacts[i],
                          contact_prob=contacts[i].astype(float), features=np.zeros(190), observed=np.zeros(190))
        out.append(LivePose(frame, t=i / 20.0, t_newest=i / 20.0, index=i, observed_sites=np.ones(13, bool),
                            insoles=False, latency_ms=None, compute_ms=0.0))
    return out


def test_numbers_bars_and_record_button(qtbot):
    view = OutdoorView()
    qtbot.addWidget(view)
    view.resize(1200, 800)
    view.show()
    sink = GaitSink()
    poses = walk_poses(stiff_right=True)
    for lp in poses:
        sink.on_pose(lp)
    body = Body.from_height(1.75)
    assert view.show_pose(poses[-1], body) and not view.show_pose(poses[-1], body)  # a pose is drawn once
    n = sink.numbers()
    view.show_numbers(n)
    assert 90 < float(view.cadence.value.text()) < 140
    left, right = (float(x) for x in view.knees.value.text().split("/"))
    assert left > 40 and right < 2
    assert float(view.asymmetry.value.text()) > 100 and WARN in view.asymmetry.value.styleSheet()

    view.show_numbers(GaitSink().numbers())  # nothing yet: dashes, not made-up numbers
    assert view.cadence.value.text() == "--" and ACCENT in view.cadence.value.styleSheet()

    rows = [DeviceRow("l_shank", "x", "ok", 100.0, 2.0, 80.0, 0.01, 500, 0),
            DeviceRow("r_shank", "x", "silent", None, None, None, 4.0, 10, 0)]
    view.show_devices(rows)
    name, batt, sig = view.sensors.rows["l_shank"]
    assert batt.value() == 80 and sig.value() == 98
    name, batt, sig = view.sensors.rows["r_shank"]
    assert sig.value() == 0 and BAD in name.styleSheet() and not batt.isEnabled()

    asked = []
    view.recordToggled.connect(asked.append)
    assert not view.record_button.isEnabled()  # no capture yet
    view.set_record_enabled(True)
    qtbot.mouseClick(view.record_button, QtCore.Qt.MouseButton.LeftButton)
    assert asked == [True] and "STOP" in view.record_button.text()
    view.set_recording(False, "saved")  # the session's state, without asking again
    assert asked == [True] and "REC" in view.record_button.text()


def test_the_flat_skeleton_stays_side_on_and_a_still_body_is_not_redrawn(qtbot):
    from app.gui.view2d import Skeleton2DView
    from tests.app.gui.helpers import SKELETON_RGB

    view = OutdoorView()
    qtbot.addWidget(view)
    view.resize(1200, 800)
    view.show()
    qtbot.waitExposed(view)
    body = Body.from_height(1.75)
    assert view.skeleton == "2d" and isinstance(view.view, Skeleton2DView) and view.view.side_on
    for heading in (0.0, 120.0):  # the walk as generated (along +X), then turned by 120 deg
        view.set_skeleton("3d")
        view.set_skeleton("2d")  # a fresh camera
        poses = walk_poses(stiff_right=False, heading_deg=heading)
        for lp in poses[:60]:
            view.show_pose(lp, body)
        # the camera on the walker's right: 90 deg behind their heading (the pelvis sways a few degrees)
        off = (view.view.azimuth - (heading - 90.0) + 180.0) % 360.0 - 180.0
        assert abs(off) < 15.0, (heading, view.view.azimuth)
    shown = view.frames_shown
    lp = poses[59]
    still = [LivePose(lp.pose, t=lp.t + k / 20.0, t_newest=lp.t + k / 20.0, index=lp.index + k,
                      observed_sites=lp.observed_sites, insoles=False, latency_ms=None, compute_ms=0.0)
             for k in range(1, 11)]
    assert not any(view.show_pose(s, body) for s in still)  # the same pose again: nothing to redraw
    assert view.frames_shown == shown and view.frames_still == 10
    assert view.show_pose(poses[61], body)  # it moves: drawn
    qtbot.wait(50)
    rgb = image_array(view.view.grab().toImage())
    lit = np.zeros(rgb.shape[:2], bool)
    for colour in SKELETON_RGB:
        lit |= np.all(np.abs(rgb.astype(int) - np.array(colour)) < 30, axis=-1)
    rows, cols = np.nonzero(lit)
    assert lit.mean() > 0.003, f"no skeleton drawn ({lit.mean():.4f})"
    # side on, a standing figure: taller than it is wide on screen
    assert np.ptp(rows) > 1.5 * np.ptp(cols), (np.ptp(rows), np.ptp(cols))


def test_the_3d_skeleton_is_a_click_away_and_the_window_remembers_it(qtbot, tmp_path):
    from tests.app.gui.helpers import shown_window

    win = shown_window(qtbot, tmp_path)
    assert win.outdoor.skeleton == "2d"
    chosen = []
    win.outdoor.skeletonChosen.connect(chosen.append)
    qtbot.mouseClick(win.outdoor.skeleton_button, QtCore.Qt.MouseButton.LeftButton)
    assert chosen == ["3d"] and win.outdoor.skeleton == "3d" and "side" in win.outdoor.skeleton_button.text()
    assert win.settings.value("outdoor/skeleton") == "3d"
    with pytest.raises(ValueError, match="2d, 3d"):
        win.outdoor.set_skeleton("4d")


@pytest.mark.slow
def test_demo_opens_on_the_outdoor_view(tmp_path):
    shot = Path(os.environ.get("IMUCAP_SCREENSHOT", tmp_path / "outdoor.png")).resolve()
    stats = tmp_path / "window.json"
    out = subprocess.run([*CLI, "demo", "--view", "outdoor", "--seconds", "60", "--screenshot", str(shot),
                          "--quit-after", "45", "--window-stats", str(stats)], cwd=tmp_path, capture_output=True,
                         text=True, timeout=240)
    assert out.returncode == 0, out.stderr[-2000:]
    # what the window itself cost, as benchmarks/window_live.py reads it
    cost = json.loads(stats.read_text())
    assert cost["frames_shown"] > 20 and cost["draws_per_s"] > 0 and cost["draw_p50_ms"] > 0, (
        cost["calibration"], cost["hub"], out.stderr[-3000:])
    assert 0 < cost["gui_thread_cores"] <= cost["process_cores"] and cost["wall_s"] > 0
    assert cost["pipeline"]["frames"] > 0
    from PySide6 import QtGui

    rgb = image_array(QtGui.QImage(str(shot)))
    right = rgb[:, rgb.shape[1] * 2 // 3:]
    yellow = np.all(np.abs(right.astype(int) - np.array([255, 212, 0])) < 40, axis=-1).mean()
    black = np.all(right < 20, axis=-1).mean()
    assert yellow > 0.01, f"no numbers drawn ({yellow:.4f} of the right third is yellow)"
    assert black > 0.5, f"not the outdoor view's black ({black:.2f})"
