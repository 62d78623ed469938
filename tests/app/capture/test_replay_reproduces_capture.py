"""A replay with no options gives back the live reconstruction of a capture, frame for frame.

Simulated devices in another process (`imucap devices simulate --setup`), `imucap capture
--record` with confidence on, headless and with its window (under the test run's X server),
in the centred and the low-latency mode. The
recording's metadata says how its poser ran (steps, seed, mirror, root, filter), written
from the poser that was built; `imucap replay REC` with no options and the window's
Re-run (``app.gui.replay_panel.rerun``, the code behind the button) read it back and get
the same frames, within float noise of ONNX Runtime (live) against torch (replay).

Each mode and each front is captured once, as two pairs: the centred mode in the window, the
low-latency mode headless (``CASES``). All four pairs would cost the suite's solo run ~210 s of
CPU where these two cost ~105, and what a pair checks (the file says how its poser ran; replay
and Re-run give back its frames) does not depend on the other half of the pair: the front
writes the recording through the same session, and the mode is in the poser the file names.
The headless capture ends on a condition (a calibration and ENOUGH_POSES recorded,
HEADLESS_CEILING_S the ceiling) rather than after a fixed time, and nothing here measures how
good the calibration is, only that there is one and that the replays give back what live made
of the recording. The window capture quits after a fixed --quit-after. The replays and Re-runs,
which take a core each, come after the captures.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from app.capture.twins import free_udp_port
from app.recording import read_recording
from inference.metrics.errors import global_angle_error
from tests.app.capture.live_capture import cli, finish, recorded, run_capture

pytestmark = pytest.mark.slow
SITES = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
CASES = (("centred", "window"), ("low", "headless"))  # (latency, front): each mode once, each front once
LEAD_IN = 5.0  # s of N-pose before the protocol: the capture waits for the devices (live_capture.py)
ENOUGH_POSES = 140  # the test wants over 100 live poses; the rest is margin for the last flush
# the headless capture's --seconds, a ceiling only: it ends once ENOUGH_POSES are recorded,
# ~8 s after the calibration on a quiet machine; a busy one makes fewer poses a second
HEADLESS_CEILING_S = 60


def capture(tmp: Path, latency: str, window: bool = False) -> Path:
    """A capture of the walk protocol and a walk, recorded with confidence on. Headless, it
    ends (Ctrl-C, as a user ends it) as soon as its recording holds a calibration and
    ENOUGH_POSES poses (its --seconds the ceiling); the window quits after --quit-after."""
    setup = tmp / "setup.toml"
    setup.write_text("\n".join([
        "[subject]", 'id = "sim-replay"', "height = 1.72", "", "[sensors]",
        *[f'{s} = "xbus://{tmp}/{s}-tty?baud=115200"' for s in SITES],
        "", "[insoles]", f'url = "moticon-udp://127.0.0.1:{free_udp_port()}"',
        "", "[model]", 'name = "diffusion"', "confidence = true", "", "[calibration]", 'protocol = "walk"', ""]))
    rec = tmp / f"{latency}.h5"
    front = ["--quit-after", "28"] if window else ["--headless", "--seconds", str(HEADLESS_CEILING_S), "--json"]
    cap, _ = run_capture(["--setup", str(setup), "--record", str(rec), "--latency", latency, "--countdown", "1",
                          *front],
                         ["--setup", str(setup), "--motion", "walk", "--lead-in", str(LEAD_IN), "--activity-seconds",
                          "12", "--seed", "5", "--while-stdin-open"],
                         done=None if window else lambda sim: recorded(rec, ENOUGH_POSES), ceiling=180)
    assert cap.returncode == 0, cap.stderr[-3000:]
    if not window:
        assert json.loads(cap.stdout.strip().splitlines()[-1])["calibrated"], cap.stderr[-2000:]
    assert read_recording(rec).calibrations, cap.stderr[-2000:]
    return rec


@pytest.mark.parametrize(("latency", "front"), CASES)
def test_replay_with_no_options_and_the_windows_rerun_give_back_the_live_poses(tmp_path, latency, front):
    if front == "window" and not os.environ.get("DISPLAY"):
        pytest.skip("the window needs a display: scripts/test.sh runs the tests under xvfb-run")
    path = capture(tmp_path, latency, window=front == "window")
    rec = read_recording(path)
    meta = rec.metadata
    # the file says how it ran, from the poser that was built
    assert meta["latency"] == latency and meta["confidence"] is True and meta["app_version"]
    assert meta["step_list"] and meta["mirror"] is not None and meta["stride_scale"] is not None
    assert meta["pelvis_odometry"] is not None and meta["seed"] == 0
    live_t, live_R = rec.recon["t"], rec.recon["R"]
    assert len(live_t) > 100

    replaying = cli(["replay", str(path), "--json", "--no-progress"])  # beside the window's Re-run below

    from app.gui.replay_panel import rerun
    from app.gui.workers import Job

    job = Job("rerun", lambda: None, (), None, None)  # only receives the progress reports
    track = rerun(job, rec, SITES, True, "diffusion", None, confidence=False)
    rep = finish(replaying)
    assert rep.returncode == 0, rep.stderr[-2000:]
    res = json.loads(rep.stdout)
    assert res["latency_mode"] == latency and res["step_list"] == meta["step_list"]
    assert res["vs_recorded_frames"] == len(live_t) == res["frames"]  # the same frames
    assert res["vs_recorded_ga_deg"] < 0.01, res

    assert np.allclose(track.t, live_t)
    ga = global_angle_error(track.R, live_R)
    assert float(np.mean(ga)) < 0.01, float(np.mean(ga))
