"""`CaptureSession.start`: the model's first call (its runtime's build, seconds on a busy
machine with the interpreter held) is made before the devices open and the guided steps'
clock starts. Made after, it left the serial readers without a turn for a second while the
subject held the N-pose, and three of six sensors came out uncalibrated."""

from __future__ import annotations

import pytest

from app.capture import session as session_module
from app.capture.session import CaptureOptions, CaptureSession
from app.capture.setup_file import parse_setup

SETUP = """\
[subject]
id = "S1"
height = 1.75

[sensors]
pelvis = "xbus:///tmp/imucap-no-such-tty?baud=115200"
"""


class Stop(Exception):
    """Raised by the intercepted hub start: the test needs nothing after it."""


def test_the_model_is_warm_before_the_devices_open(monkeypatch):
    setup = parse_setup(SETUP)
    session = CaptureSession(setup, CaptureOptions(threads=1))
    order: list[str] = []
    warm_up = session.poser.warm_up
    monkeypatch.setattr(session.poser, "warm_up", lambda: (order.append("warm up"), warm_up())[-1])

    def hub_start(hub):
        order.append("devices open")
        raise Stop

    monkeypatch.setattr(session_module.Hub, "start", hub_start)
    with pytest.raises(Stop):
        session.start()
    assert order == ["warm up", "devices open"]
    assert session.started_at is not None  # the guided steps' clock: set just before the devices open


def test_the_demo_warms_up_before_its_simulated_subject_starts_and_once(monkeypatch, tmp_path):
    """The demo's simulated subject stands in its N-pose from the moment its process is up:
    a warm-up after that (seconds on a busy machine) ate the lead-in, and the guided N-pose
    ran into the walk ("N-pose: not still"). The session's start then finds it done."""
    from app.capture.demo import DemoConfig, DemoRun, demo_spec

    run = DemoRun(DemoConfig(seconds=5.0, threads=1), demo_spec(DemoConfig(seconds=5.0, threads=1), tmp_path))
    order: list[str] = []
    warm_up = run.session.poser.warm_up
    monkeypatch.setattr(run.session.poser, "warm_up", lambda: (order.append("warm up"), warm_up())[-1])

    def sim_start(*args, **kwargs):
        order.append("simulator")
        raise Stop

    monkeypatch.setattr(run.spec.simulator, "start", sim_start)
    with pytest.raises(Stop):
        run.start()
    assert order == ["warm up", "simulator"]
    run.session.pipeline.warm_up()  # as CaptureSession.start calls it: already done
    assert order == ["warm up", "simulator"]


def test_a_setup_without_a_model_runs_the_live_default_chosen_by_its_sensors():
    """No [model] table: the live default. Its file follows the worn sensors (the 21-frame file with the shanks
    worn, the full model with the thighs and no shanks), and the recording names the spec a replay runs again."""
    from inference.poser.models import DEFAULT_WEIGHTS

    if not (DEFAULT_WEIGHTS["fast"].exists() and DEFAULT_WEIGHTS["diffusion"].exists()):
        pytest.skip("shipped weights not installed")
    made = {}
    for name, legs in (("shanks", ("l_shank", "r_shank")), ("thighs", ("l_thigh", "r_thigh"))):
        lines = [f'{site} = "xbus:///tmp/imucap-no-such-tty-{site}?baud=115200"' for site in legs]
        setup = parse_setup(SETUP + "\n".join(lines) + "\n")
        assert setup.model == "auto" and set(setup.sites()) == {"pelvis", *legs}
        made[name] = CaptureSession(setup, CaptureOptions(threads=1))
    assert made["shanks"].model_spec == "fast" and made["shanks"].model_label.endswith("(diffusionposer_fast.pt)")
    assert made["thighs"].model_spec == "diffusion" and made["thighs"].model_label.endswith("(diffusionposer.pt)")
    assert made["shanks"].metadata()["model_spec"] == "fast" and made["shanks"].poser.int8
