"""The words `imucap setup check` uses for each problem a device can have."""

from __future__ import annotations

from pathlib import Path

from app.capture.check import NO_ANSWER, DeviceCheck, SetupCheck, _check_model, check_setup, judge
from app.capture.setup_file import parse_setup


def healthy(**kw) -> DeviceCheck:
    base = dict(name="l_wrist", url="bno08x-rvc:///dev/ttyUSB1", samples=300, rate_hz=100.0)
    base.update(kw)
    return DeviceCheck(**base)


def test_a_healthy_device_has_no_problem():
    assert judge(healthy()) == []
    assert judge(healthy(kind="insoles", rate_hz=25.0)) == []  # insoles need only the 20 Hz contacts


def test_each_problem_in_plain_words():
    assert judge(healthy(samples=0, rate_hz=0.0)) == [NO_ANSWER]
    assert judge(healthy(samples=0, open_error="could not open port"))[0] == f"{NO_ANSWER}: could not open port"
    assert "is the insoles app streaming" in judge(healthy(kind="insoles", samples=0))[0]
    assert judge(healthy(rate_hz=12.0)) == ["rate 12 Hz, expected >= 50"]
    assert judge(healthy(lost_packets=30, errors=30))[0].startswith("lost 30 packets (9%)")
    assert judge(healthy(lost_packets=1, errors=1)) == []  # one packet in 300 is not worth a word
    assert judge(healthy(errors=12))[0] == "12 corrupted packets: check the cable and the baud rate"
    assert "disconnected 2 time(s)" in judge(healthy(disconnects=2))[0]
    assert judge(healthy(battery_pct=15.0)) == ["battery 15%: charge it before capturing"]


def test_serial_is_compared_only_when_both_sides_name_one():
    assert judge(healthy(serial_expected="A1B2")) == []  # the protocol reports none: nothing to compare
    d = healthy(serial_expected="A1B2", serial_reported="C3D4")
    assert d.serial_match is False
    assert judge(d)[0].startswith("serial A1B2 expected, device says C3D4")
    assert healthy(serial_expected="a1b2", serial_reported="A1B2 ").serial_match is True


def test_a_model_file_that_is_not_there_is_a_setup_problem(tmp_path):
    setup = parse_setup('[subject]\nid = "A"\nheight = 1.7\n[sensors]\nhead = "dualsense://"\n'
                        '[model]\nname = "no/such/model.pt"\n', tmp_path / "s.toml")
    report = SetupCheck(setup, 0.0, [])
    _check_model(setup.model, report)
    assert report.problems and "no/such/model.pt" in report.problems[0] and not report.ok


def test_check_setup_of_a_device_nobody_serves(tmp_path):
    setup = parse_setup(f'[subject]\nid = "A"\nheight = 1.7\n[sensors]\nhead = "bno08x-rvc://{tmp_path}/tty"\n'
                        '[model]\nname = "floor"\n', tmp_path / "s.toml")
    report = check_setup(setup, 0.3)
    (d,) = report.devices
    assert not report.ok and d.problems[0].startswith(NO_ANSWER) and d.open_error
    assert report.as_json()["devices"]["head"]["ok"] is False
    assert Path(report.as_json()["file"]) == tmp_path / "s.toml"
