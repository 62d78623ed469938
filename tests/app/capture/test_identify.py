"""Telling sensors apart by moving one: simulated devices over their real transports,
opened through drivers.open_device as the CLI opens them."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest

import drivers
from app.capture.identify import MotionWatcher, watch_devices
from app.cli.main import main
from drivers.base import Sample
from inference.body.conventions import quat_z
from sim_devices.devices import make_sim_device, spinning_signals


def sim(protocol: str, site: str, rate_dps: float):
    """A device replaying a sensor turning at ``rate_dps`` (0: lying still)."""
    return make_sim_device(protocol, spinning_signals((site,), seconds=20.0, rate_dps=rate_dps), site).start()


@pytest.fixture
def still_and_spinning():
    devices = [sim("bno08x-rvc", "pelvis", 0.0), sim("bno08x-rvc", "l_wrist", 180.0)]
    yield devices
    for d in devices:
        d.stop()


def feed(watcher: MotionWatcher, urls: list[str], seconds: float) -> list[str | None]:
    """Read every device for ``seconds`` as the CLI does, asking the watcher as it goes."""
    opened = {u: drivers.open_device(u) for u in urls}
    answers = []
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            for url, dev in opened.items():
                for s in dev.read_many(0.005):  # 0.0 means "select saw data" to the serial drivers
                    watcher.push(url, s)
            answers.append(watcher.moving())
            time.sleep(0.02)
    finally:
        for dev in opened.values():
            dev.close()
    return answers


def test_watcher_picks_the_spinning_device(still_and_spinning):
    still, spinning = still_and_spinning
    urls = [still.url, spinning.url]
    watcher = MotionWatcher(urls)
    answers = feed(watcher, urls, 1.5)
    speeds = watcher.speeds()
    assert speeds[spinning.url] == pytest.approx(180.0, rel=0.1)  # from orientations: RVC has no gyro
    assert speeds[still.url] < 5.0
    assert answers[-1] == spinning.url
    assert set(answers[len(answers) // 2:]) == {spinning.url}
    assert watcher.moving(among=[still.url]) is None  # once taken, the spinning one is not a candidate


def test_watcher_names_nobody_when_all_are_still():
    devices = [sim("bno08x-rvc", "pelvis", 0.0), sim("dualsense", "head", 0.0)]
    try:
        urls = [d.url for d in devices]
        watcher = MotionWatcher(urls)
        answers = feed(watcher, urls, 1.2)
    finally:
        for d in devices:
            d.stop()
    assert set(answers) == {None}
    assert max(watcher.speeds().values()) < 5.0


def test_watch_devices_with_a_gyro_device_spinning():
    """The DualSense reports its gyro: the speed comes from it, and watch_devices opens,
    reads and closes on its own threads."""
    devices = [sim("bno08x-rvc", "pelvis", 0.0), sim("dualsense", "r_wrist", 120.0)]
    updates = []
    try:
        winner = watch_devices([d.url for d in devices], 1.5, lambda s, w: updates.append((s, w)))
    finally:
        for d in devices:
            d.stop()
    assert winner == devices[1].url
    assert updates and updates[-1][0][devices[1].url] == pytest.approx(120.0, rel=0.1)


def test_two_devices_turning_alike_name_nobody():
    watcher = MotionWatcher(["a", "b"], threshold_dps=60.0)
    for k in range(40):
        t = k * 0.01
        for key, rate in (("a", 200.0), ("b", 150.0)):
            watcher.push(key, Sample(t, t, key, gyro=np.array([0.0, 0.0, np.radians(rate)])))
    assert watcher.speeds()["a"] == pytest.approx(200.0)
    assert watcher.moving() is None  # 200 does not lead 150 by 2x
    assert watcher.moving(among=["a"]) == "a"


def test_a_silent_device_counts_as_still():
    watcher = MotionWatcher(["a", "b"])
    yaw = np.radians(300.0)
    for k in range(30):
        t = k * 0.01
        q = quat_z(yaw * t)
        watcher.push("a", Sample(t, t, "a", quat=q))
    assert watcher.moving() == "a"
    watcher.push("b", Sample(2.0, 2.0, "b", quat=np.array([1.0, 0, 0, 0])))  # time goes on; "a" said nothing
    assert watcher.speeds()["a"] == 0.0 and watcher.moving() is None


def test_identify_cli_json(still_and_spinning, capsys):
    still, spinning = still_and_spinning
    assert main(["devices", "identify", still.url, spinning.url, "--seconds", "1.2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["moving"] == spinning.url
    by_url = {d["url"]: d for d in out["devices"]}
    assert by_url[spinning.url]["peak_dps"] > 100 and by_url[still.url]["peak_dps"] < 5


def test_identify_cli_live_lines_and_a_dead_url(still_and_spinning, capsys, tmp_path):
    _, spinning = still_and_spinning
    dead = f"bno08x-rvc://{tmp_path}/nobody"
    assert main(["devices", "identify", spinning.url, dead, "--seconds", "1.0"]) == 0
    cap = capsys.readouterr()
    lines = [line for line in cap.out.splitlines() if "deg/s" in line]
    assert lines and re.search(r"l_wrist +1[5-9]\d deg/s <- moving \| nobody not open", lines[-1])
    assert "cannot open" in cap.err and f"moving: {spinning.url}" in cap.out
