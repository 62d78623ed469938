"""A VR rig in a setup file (``[tracked]``): its sites as the model names them, a site given
once, one-line errors, read back the same, and which rig URLs a simulator can serve."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.capture.setup_file import SetupError, dump_setup, load_setup, parse_setup
from app.capture.twins import simulation_problem, twin_setup

RIG = "vmc-in://127.0.0.1:39540?head=HMD&l_hand=CL&r_hand=CR"
GOOD = f"""\
[subject]
id = "P020"
height = 1.70

[sensors]
l_shank = "bno08x-rvc:///dev/ttyUSB1"
r_shank = "xbus:///dev/ttyUSB0?baud=115200"

[tracked]
vr = "{RIG}"
"""


def error_of(text: str, tmp_path: Path) -> SetupError:
    f = tmp_path / "vr.toml"
    f.write_text(text)
    with pytest.raises(SetupError) as info:
        load_setup(f)
    assert "\n" not in str(info.value) and str(info.value).startswith(f"{f}:")
    return info.value


def line_of(text: str, needle: str) -> int:
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


def test_a_rig_gives_its_sites_under_the_models_names():
    s = parse_setup(GOOD)
    assert s.tracked["vr"].sites == ("head", "l_wrist", "r_wrist")
    assert s.sites() == ("l_shank", "r_shank", "head", "l_wrist", "r_wrist")
    assert s.urls() == {"l_shank": "bno08x-rvc:///dev/ttyUSB1", "r_shank": "xbus:///dev/ttyUSB0?baud=115200",
                        "vr": RIG}
    back = parse_setup(dump_setup(s))
    assert back.tracked == s.tracked and back.sites() == s.sites()


def test_a_rig_alone_is_a_setup():
    text = GOOD.replace('l_shank = "bno08x-rvc:///dev/ttyUSB1"\nr_shank = "xbus:///dev/ttyUSB0?baud=115200"\n', "")
    s = parse_setup(text)
    assert s.sensors == {} and s.sites() == ("head", "l_wrist", "r_wrist")


def test_a_site_under_sensors_and_tracked_is_refused(tmp_path):
    text = GOOD.replace("[sensors]\n", '[sensors]\nr_wrist = "bno08x-rvc:///dev/ttyUSB2"\n')
    err = error_of(text, tmp_path)
    assert "site r_wrist is given twice: under [sensors] and by [tracked] vr" in str(err)
    assert err.line == line_of(text, "vr = ")


@pytest.mark.parametrize("line, words", [
    ('head = "vmc-in://127.0.0.1:39540?head=H"', "named for itself, not for a site"),
    ('vr = "xbus:///dev/ttyUSB3"', "is not a VR rig"),
    ('vr = "vmc-in://127.0.0.1:39540?neck=H"', "unknown parameter(s) neck"),
    ('vr = "vmc-in://localhost:39540?head=H"', "not an IP address"),
    ("vr = 5", "must be text"),
])
def test_bad_tracked_entries(tmp_path, line, words):
    text = GOOD.replace(f'vr = "{RIG}"', line)
    err = error_of(text, tmp_path)
    assert words in str(err) and err.line == line_of(text, line)


def test_a_rig_under_sensors_is_sent_to_tracked(tmp_path):
    text = GOOD.replace('l_shank = "bno08x', f'l_shank = "{RIG}"\nl_foot = "bno08x')
    text = text.replace(f'[tracked]\nvr = "{RIG}"\n', "")
    err = error_of(text, tmp_path)
    assert "is a VR rig (tracked points), not an IMU" in str(err) and "[tracked]" in str(err)


def test_which_rig_urls_a_simulator_serves(tmp_path):
    assert simulation_problem(RIG) is None
    assert simulation_problem("vmc-in://[::1]:39540?head=H") is None
    why = simulation_problem("vmc-in://0.0.0.0:39540?head=H")
    assert why is not None and "not a loopback address" in why
    far = parse_setup(GOOD.replace("127.0.0.1", "192.168.1.20"))
    twin = twin_setup(far, tmp_path)
    url = twin.tracked["vr"].url
    assert simulation_problem(url) is None and url.endswith("?head=HMD&l_hand=CL&r_hand=CR")
    assert twin.tracked["vr"].sites == far.tracked["vr"].sites


def test_the_arms_reach_unless_the_setup_says_not(tmp_path):
    assert parse_setup(GOOD).reach is True and "reach = true" in dump_setup(parse_setup(GOOD))
    off = GOOD + '\n[model]\nname = "diffusion"\nreach = false\n'
    s = parse_setup(off)
    assert s.reach is False and parse_setup(dump_setup(s)).reach is False
    bad = GOOD + '\n[model]\nreach = "no"\n'
    err = error_of(bad, tmp_path)
    assert err.line == line_of(bad, "reach =") and "reach = true (or false)" in err.fix
    # a setup without a rig has nothing to reach for, and its file does not mention it
    assert "reach" not in dump_setup(parse_setup(GOOD.split("[tracked]")[0]))
