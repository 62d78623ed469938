"""The window's parts without devices: presets, the body figure, the setup file round
trip, settings kept between runs, errors in the window, the skeleton's colours, the 2D
view when OpenGL is missing, the recordings list, the replay's frame matching, and
``imucap gui --screenshot``.

Run under Xvfb: ``xvfb-run -a .venv/bin/pytest -m gui tests/app/gui``."""

from __future__ import annotations

import os
import subprocess

import numpy as np
import pytest

pytestmark = pytest.mark.gui

if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
    pytest.skip("no display (run under xvfb-run)", allow_module_level=True)

pytest.importorskip("pytestqt")

from PySide6 import QtCore  # noqa: E402

from app.capture.setup_file import load_setup  # noqa: E402
from tests.app.gui.helpers import (  # noqa: E402
    CLI,
    grab_view,
    settings,
    shown_window,
    skeleton_pixels,
    suit_urls,
    write_setup,
)


@pytest.fixture
def window(qtbot, tmp_path):
    win = shown_window(qtbot, tmp_path)
    yield win
    win.close()


def test_presets_are_the_papers_table_1():
    from app.gui.presets import CLASSIC_6, PRESETS, preset, sites_of

    assert preset("classic 6").sites == CLASSIC_6
    best = {p.name.split(":")[0]: set(p.sites) for p in PRESETS}
    assert best["whole body, 4"] == {"pelvis", "head", "l_wrist", "r_wrist"}
    assert best["whole body, 3"] == {"pelvis", "l_wrist", "r_wrist"}
    assert best["whole body, 2"] == {"l_upperarm", "r_upperarm"}
    assert best["legs, 4"] == {"pelvis", "head", "l_thigh", "r_thigh"}
    assert best["legs, 3"] == {"pelvis", "l_thigh", "r_thigh"}
    assert best["legs, 2"] == {"pelvis", "r_shank"}
    assert best["back, 4"] == {"pelvis", "head", "l_upperarm", "r_upperarm"}
    assert best["back, 3"] == {"pelvis", "l_upperarm", "r_upperarm"}
    assert best["back, 2"] == {"l_upperarm", "r_upperarm"}
    assert best["root translation, 4"] == {"l_thigh", "r_thigh", "l_shank", "r_shank"}
    assert best["root translation, 3"] == {"pelvis", "l_shank", "r_shank"}
    assert best["root translation, 2"] == {"l_shank", "r_shank"}
    mine = preset("all I have")
    assert sites_of(mine, {"head": "xbus:///dev/a", "l_foot": "xbus:///dev/b"}) == ("head", "l_foot")
    assert len(sites_of(mine, {})) == 13


def test_setup_chosen_on_the_figure_is_the_file_capture_reads(window, qtbot, tmp_path):
    """A clinician picks a preset, clicks a site on and off, types the subject, tries to
    save before every site has a device (refused, in the window), assigns devices from
    the list, saves; the file loads as the same setup and is remembered."""
    win, panel = window, window.setup_panel
    i = panel.preset.findData(next(p for p in (panel.preset.itemData(k) for k in range(panel.preset.count()))
                                   if p and p.startswith("classic 6")))
    panel.preset.setCurrentIndex(i)
    panel.preset.activated.emit(i)
    assert win.model.draft.sites == ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
    fig = panel.figure
    qtbot.mouseClick(fig, QtCore.Qt.MouseButton.LeftButton, pos=fig.spot_center("torso"))
    assert "torso" in win.model.draft.sites
    qtbot.mouseClick(fig, QtCore.Qt.MouseButton.LeftButton, pos=fig.spot_center("torso"))
    assert "torso" not in win.model.draft.sites
    panel.subject_id.setText("P07")
    panel.subject_id.editingFinished.emit()
    panel.height.setValue(1.62)
    assert win.model.draft.subject_id == "P07" and win.model.draft.height_m == pytest.approx(1.62)

    target = tmp_path / "p07.toml"
    assert not panel.save_to(target)
    assert win.messages.isVisible() and win.messages.level == "error"
    assert "no device for pelvis" in win.messages.label.text() and not target.exists()

    dev = win.devices_panel
    urls = suit_urls(tmp_path)
    for site, url in urls.items():
        qtbot.keyClicks(dev.url_edit, url)
        qtbot.keyClick(dev.url_edit, QtCore.Qt.Key.Key_Return)
        dev.select_url(url)
        dev.site_combo.setCurrentText(site)
        qtbot.mouseClick(dev.assign_button, QtCore.Qt.MouseButton.LeftButton)
    assert win.model.assigned() == urls
    assert dev.table.rowCount() == 6 and dev.table.item(0, 2).text() == "pelvis"
    assert panel.save_to(target)
    s = load_setup(target)
    assert s.subject.id == "P07" and s.subject.height_m == pytest.approx(1.62)
    assert {k: e.url for k, e in s.sensors.items()} == urls
    assert win.settings.value("setup/last_file") == str(target.resolve())
    assert win.recordings_panel.folder == target.parent / "recordings"

    # the next run opens it again, on the tab and with the geometry it was left
    win.tabs.setCurrentIndex(3)
    win.resize(1111, 777)
    win.close()
    from app.gui.main import MainWindow

    again = MainWindow(settings(tmp_path))
    qtbot.addWidget(again)
    assert again.open_last_setup()
    assert again.model.assigned() == urls and again.model.draft.subject_id == "P07"
    assert again.tabs.currentIndex() == 3 and again.width() == 1111


def test_errors_are_shown_in_the_window(window, qtbot, tmp_path):
    win = window
    win.start_capture()  # nothing chosen
    assert win.messages.isVisible() and win.messages.level == "error"
    assert "no sensor sites" in win.messages.label.text()
    win.setup_panel.open(tmp_path / "missing.toml")
    assert "no such file" in win.messages.label.text()
    # a setup whose devices are not there: the start fails in the window, not on the console
    path = write_setup(tmp_path / "absent.toml", {"pelvis": f"xbus://{tmp_path}/nothing-tty"}, model="floor")
    assert win.setup_panel.open(path)
    win.start_capture()
    qtbot.waitUntil(lambda: "could not start" in win.messages.label.text(), timeout=60_000)
    assert win.messages.level == "error" and win.session is None and win.start_action.isEnabled()


def test_alarm_stays_until_the_device_is_back(window):
    bar = window.messages
    bar.alarm("DEVICE DROPPED OUT: r_shank")
    bar.show_message("saved something", "ok")
    assert bar.label.text().startswith("DEVICE DROPPED OUT") and bar.isVisible()
    bar.dismiss()
    assert bar.isVisible()
    bar.clear_alarm(then="r_shank is back")
    assert bar.level == "ok" and bar.label.text() == "r_shank is back"


def test_segment_colours_say_what_was_measured():
    from app.gui.colours import INFERRED, MEASURED, segment_colours, spread_colour
    from app.gui.skeleton_geometry import bone_segments
    from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX

    obs = np.zeros(13, bool)
    obs[[SITE_INDEX["pelvis"], SITE_INDEX["l_wrist"]]] = True
    c = segment_colours(obs)
    assert np.allclose(c[SEGMENT_INDEX["pelvis"]], MEASURED) and np.allclose(c[SEGMENT_INDEX["l_forearm"]], MEASURED)
    assert np.allclose(c[SEGMENT_INDEX["head"]], INFERRED)
    spread = np.zeros(24)
    spread[SEGMENT_INDEX["head"]] = 40.0
    c = segment_colours(obs, spread)
    assert np.allclose(c[SEGMENT_INDEX["head"]], spread_colour(40.0)) and c[SEGMENT_INDEX["head"], 0] > 0.9
    assert np.allclose(c[SEGMENT_INDEX["pelvis"]], MEASURED)
    # every drawn line belongs to a segment; the pelvis draws the lines to the hips and spine
    seg, owner = bone_segments(np.random.default_rng(0).normal(size=(24, 3)), np.tile(np.eye(3), (24, 1, 1)))
    assert len(seg) == 2 * len(owner) and set(owner[:3]) == {SEGMENT_INDEX["pelvis"]}


def _standing():
    from inference.body.body import Body, forward_kinematics, npose_rotations

    body = Body.from_height(1.75)
    R = npose_rotations(1)[0]
    joints = forward_kinematics(R, np.array([0.0, 0.0, 0.95]), body.offsets)
    return body, R, joints


def _in_layout(layout, widget) -> int:
    """How many items of ``layout`` and its nested layouts hold ``widget``."""
    n = 0
    for i in range(layout.count()):
        item = layout.itemAt(i)
        n += item.widget() is widget
        if item.layout() is not None:
            n += _in_layout(item.layout(), widget)
    return n


@pytest.mark.parametrize("gl", [True, False], ids=["gl", "no-gl"])
def test_the_skeleton_is_drawn_with_and_without_opengl(qtbot, monkeypatch, gl):
    """Without OpenGL (here: IMUCAP_NO_GL) the live view is the QPainter one; either way
    a standing body puts skeleton-coloured pixels on screen, and they move with it."""
    from app.gui import views
    from app.gui.live_panel import LivePanel

    monkeypatch.setattr(views, "_GL_OK", None)
    if not gl:
        monkeypatch.setenv("IMUCAP_NO_GL", "1")
    panel = LivePanel()
    qtbot.addWidget(panel)
    panel.resize(900, 600)
    panel.show()
    qtbot.waitExposed(panel)
    assert panel.view.is_gl is gl
    # in the layout once, with the panel's height: the GL view once went in twice (the window made again
    # for GL composition showed the panel a second time) and the two items halved it, the body cut off
    qtbot.wait(50)
    assert _in_layout(panel.layout(), panel.view) == 1
    assert panel.view.height() > 0.75 * panel.height(), (panel.view.height(), panel.height())
    body, R, joints = _standing()
    obs = np.ones(13, bool)
    view = panel.view
    view.follow = False
    view.set_segment_colours(np.tile([0.30, 0.70, 1.00, 1.0], (24, 1)))
    view.show_pose(joints, R, np.ones(4, bool), body)
    qtbot.wait(200)
    first = grab_view(view)
    assert skeleton_pixels(first) > 100, "no skeleton drawn"
    view.show_pose(joints + np.array([0.0, 0.4, 0.0]), R, np.ones(4, bool), body)
    qtbot.wait(200)
    second = grab_view(view)
    assert np.mean(np.any(first != second, axis=-1)) > 0.001
    del obs


def test_no_gl_widget_is_in_the_window_until_a_3d_tab_is_shown(qtbot, tmp_path):
    """A GL widget makes Qt compose the whole window through OpenGL (software GL: most of the
    window's CPU, docs/window.md), so the Live and Replay tabs' 3D views join the window only
    when their tab is first shown; a window kept on the outdoor view's flat skeleton has none."""
    from PySide6 import QtOpenGLWidgets

    from app.gui import views
    from tests.app.gui.helpers import shown_window

    if not views.gl_available():
        pytest.skip(f"no GL here: {views.GL_PROBLEM}")
    win = shown_window(qtbot, tmp_path)
    win.show_outdoor()
    qtbot.wait(50)
    assert win.live_panel.view.is_gl and win.replay_panel.view.is_gl
    assert not win.findChildren(QtOpenGLWidgets.QOpenGLWidget)  # the hidden tabs' views are not in it yet
    win.tabs.setCurrentWidget(win.live_panel)
    qtbot.wait(50)
    assert win.findChildren(QtOpenGLWidgets.QOpenGLWidget) == [win.live_panel.view]
    assert win.live_panel.view.isVisible()


def test_recordings_are_listed_from_their_headers(tmp_path):
    from app.gui.recordings_panel import fmt_length, scan_folder
    from app.live import frames_from_signals
    from app.recording import Recorder
    from sim_devices.devices import spinning_signals

    sig = spinning_signals(("pelvis", "head"), seconds=3.0)
    rec = Recorder(tmp_path / "a.h5", ("pelvis", "head"),
                   metadata={"subject": {"id": "P09"}, "sensors": ["pelvis", "head"], "model": "floor"})
    for f in frames_from_signals(sig, t0=100.0):
        rec.on_frame(f)
    rec.on_event(101.0, "marker", "heel strike")
    rec.on_event(101.5, "note", "tired")
    rec.close()
    (tmp_path / "broken.h5").write_bytes(b"not a recording")
    infos = {i.path.name: i for i in scan_folder(tmp_path)}
    a = infos["a.h5"]
    assert a.subject == "P09" and a.sensors == ("pelvis", "head") and a.markers == 1 and a.model == "floor"
    assert a.seconds == pytest.approx(3.0 - 1 / 60, abs=0.02) and fmt_length(a.seconds) == "0:03"
    assert infos["broken.h5"].problem


def test_replay_frames_are_matched_by_time():
    from app.gui.replay_panel import Track, segment_differences
    from app.replay import match_times

    a = np.arange(10) / 20.0
    b = a[[1, 2, 3, 5, 8]]
    idx = match_times(a, b)
    assert list(idx) == [-1, 0, 1, 2, -1, 3, -1, -1, 4, -1]
    # a live run that dropped 60 Hz frames sits one or two samples off the re-run's grid
    assert list(match_times(a[:4] + 1 / 60, a)) == [0, 1, 2, 3]
    assert list(match_times(a[:4] + 2 / 60, a)) == [1, 2, 3, 4]
    assert list(match_times(a[:4] + 0.03, a[:2])) == [1, -1, -1, -1]
    R = np.tile(np.eye(3), (10, 24, 1, 1))
    ref = Track("ref", a, R, np.zeros((10, 24, 3)), np.zeros((10, 4), bool), np.zeros((10, 13), bool))
    other = Track("other", b, R[:5].copy(), np.zeros((5, 24, 3)), np.zeros((5, 4), bool), np.zeros((5, 13), bool))
    other.R[:, 16] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # the left upper arm 90 deg off
    diff, summary = segment_differences(ref, other, idx)
    assert summary["frames"] == 5 and summary["segments"]["l_upperarm"] == pytest.approx(90.0)
    assert np.isnan(diff[0]).all() and summary["ga_deg"] == pytest.approx(90.0 / 18)


@pytest.mark.slow
def test_imucap_gui_saves_a_screenshot(tmp_path):
    setup = write_setup(tmp_path / "s.toml", suit_urls(tmp_path))
    shot = tmp_path / "gui.png"
    env = {**os.environ, "XDG_CONFIG_HOME": str(tmp_path / "config")}
    out = subprocess.run([*CLI, "gui", "--setup", str(setup), "--tab", "Devices", "--screenshot", str(shot),
                          "--quit-after", "2"], capture_output=True, text=True, timeout=120, env=env)
    assert out.returncode == 0, out.stderr[-2000:]
    assert shot.stat().st_size > 10_000
    cfg = (tmp_path / "config" / "imucap" / "imucap.conf").read_text()
    assert str(setup.resolve()) in cfg and "tab=Devices" in cfg  # remembered for the next run


def test_the_live_view_colours_by_spread_when_the_pose_has_one(qtbot):
    """The poser's per-segment spread, when it reports one, colours the inferred segments
    (green sure to red unsure) and the legend shows the ramp; without it, measured/inferred."""
    from app.gui.colours import MEASURED, spread_colour
    from app.gui.live_panel import LivePanel
    from app.live import LivePose
    from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
    from inference.poser.poser import PoseFrame

    body, R, joints = _standing()
    panel = LivePanel()
    qtbot.addWidget(panel)
    obs = np.zeros(13, bool)
    obs[SITE_INDEX["pelvis"]] = True

    def pose(k: int, spread) -> LivePose:
        frame = PoseFrame(index=k, rot=R, root=joints[0], joints=joints, contacts=np.ones(4, bool),
                          contact_prob=np.ones(4), features=np.zeros(190), observed=np.zeros(190, bool),
                          spread_deg=spread)
        return LivePose(frame, t=k / 20, t_newest=k / 20, index=k, observed_sites=obs, insoles=False,
                        latency_ms=None, compute_ms=1.0)

    assert panel.show_pose(pose(1, None), body) and not panel.legend.with_spread
    spread = np.full(24, 25.0)
    assert panel.show_pose(pose(2, spread), body) and panel.legend.with_spread
    colours = panel.view.figures[0].segment_colours
    assert np.allclose(colours[SEGMENT_INDEX["pelvis"]], MEASURED)
    assert np.allclose(colours[SEGMENT_INDEX["head"]], spread_colour(25.0))
    assert not panel.show_pose(pose(2, spread), body)  # the same frame is not drawn twice


def test_a_gait_report_from_the_recordings_tab(window, qtbot, tmp_path, capsys):
    """The Recordings tab's button writes the selected recording's gait report beside it and links it;
    a recording with no reconstruction says why in the window."""
    import json
    import re

    from app.gui.recordings_panel import report_path
    from app.live import frames_from_signals
    from app.recording import Recorder
    from sim_devices.devices import spinning_signals
    from tests.app.report.walks import walk_recording

    folder = tmp_path / "recordings"
    folder.mkdir()
    walk = walk_recording(folder / "walk.h5", speed=1.3, seconds=10.0)
    sig = spinning_signals(("pelvis", "head"), seconds=2.0)  # raw frames only: never reconstructed
    rec = Recorder(folder / "raw_only.h5", ("pelvis", "head"), metadata={"sensors": ["pelvis", "head"]})
    for f in frames_from_signals(sig, t0=100.0):
        rec.on_frame(f)
    rec.close()
    panel = window.recordings_panel
    window.tabs.setCurrentWidget(panel)
    panel.set_folder(folder)
    qtbot.waitUntil(lambda: panel.table.rowCount() == 2, timeout=30_000)

    def pick(name: str) -> None:
        row = [i.path.name for i in panel.infos].index(name)
        panel.table.selectRow(row)

    pick("walk.h5")
    with qtbot.waitSignal(panel.reportWritten, timeout=120_000) as written:
        qtbot.mouseClick(panel.report_button, QtCore.Qt.MouseButton.LeftButton)
        assert not panel.report_button.isEnabled()  # one report at a time
    out = report_path(walk)
    assert written.args == [str(out)] and out.is_file() and panel.report_button.isEnabled()
    html = out.read_text()
    assert '<section id="strides">' in html and "data:image/png;base64," in html
    # the link names the strides the report counted: the same as `imucap report --json` of that file
    from app.cli.main import main

    capsys.readouterr()
    assert main(["report", str(walk), "--out", str(tmp_path / "cli.html"), "--json"]) == 0
    cli = json.loads(capsys.readouterr().out)
    text = panel.report_link.text()
    m = re.search(r"(\d+) \+ (\d+) walking strides", text)
    assert m and (int(m.group(1)), int(m.group(2))) == (cli["strides"]["l"], cli["strides"]["r"])
    assert cli["strides"]["l"] >= 3 and out.resolve().as_uri() in text
    assert window.messages.level == "ok"
    # "pose again 200 ms late" is on, but this recording holds no raw stream to replay: its own poses, said
    assert panel.late_box.isChecked() and "its own poses (" in text and "no calibration" in text

    pick("raw_only.h5")
    qtbot.mouseClick(panel.report_button, QtCore.Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: window.messages.level == "error", timeout=60_000)
    assert "no reconstruction" in window.messages.label.text()
    assert not report_path(folder / "raw_only.h5").exists() and panel.report_button.isEnabled()


def test_the_window_report_poses_a_live_recording_again_late(tmp_path):
    """The Recordings tab's report with "pose again 200 ms late": a replayable live recording is posed again
    four frames late (``app.report.build.posed_again``) and its report says so."""
    from app.gui.recordings_panel import report_path, write_report
    from tests.app.report.walks import walk_recording

    walk = walk_recording(tmp_path / "walk.h5", speed=1.2, seconds=8.0, sites=("pelvis", "l_shank", "r_shank"),
                          raw=True, seed=4)
    late = write_report(walk, late=True)
    assert late["posed"] == "posed again 4 frames late" and "posed again 4 frames late" in late["session"]["model"]
    assert "posed again 4 frames late" in report_path(walk).read_text()
    own = write_report(walk, late=False)
    assert own["posed"] == "its own poses" and own["session"]["model"] == "truth (test)"
