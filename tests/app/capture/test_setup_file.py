"""The setup file: every mistake a person makes in it is one line naming the file, the
line, and what to do; what is written reads back the same."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from app.capture.setup_file import (
    SensorEntry,
    Setup,
    SetupError,
    Subject,
    dump_setup,
    load_setup,
    parse_setup,
    save_setup,
)
from inference.body.skeleton import SITES

REPO = Path(__file__).resolve().parents[3]
GOOD = """\
# imucap setup
[subject]
id = "P014"
height = 1.72          # metres
notes = "left knee brace"

[sensors]              # site = device URL, or a table with url / serial / label
pelvis  = "xbus:///dev/ttyUSB0?baud=115200"
l_wrist = { url = "bno08x-rvc:///dev/ttyUSB1", label = "blue strap" }
r_wrist = "dualsense://"

[insoles]
url = "moticon-udp://127.0.0.1:9999"

[model]
name = "diffusion"
steps = "10D:3"

[calibration]
protocol = "walk"

[recording]
folder = "recordings"
"""


def error_of(text: str, tmp_path: Path) -> SetupError:
    f = tmp_path / "lab.toml"
    f.write_text(text)
    with pytest.raises(SetupError) as info:
        load_setup(f)
    err = info.value
    assert "\n" not in str(err)
    assert str(err).startswith(f"{f}:")
    assert err.path == f
    return err


def line_of(text: str, needle: str) -> int:
    return next(n for n, line in enumerate(text.splitlines(), 1) if needle in line)


def test_good_file_parses(tmp_path):
    f = tmp_path / "lab.toml"
    f.write_text(GOOD)
    s = load_setup(f)
    assert s.subject == Subject("P014", 1.72, "left knee brace")
    assert s.sites() == ("pelvis", "l_wrist", "r_wrist")  # SITES order
    assert s.sensors["l_wrist"] == SensorEntry("l_wrist", "bno08x-rvc:///dev/ttyUSB1", label="blue strap")
    assert s.sensors["l_wrist"].line == line_of(GOOD, "l_wrist =")
    assert s.insoles == "moticon-udp://127.0.0.1:9999"
    assert s.urls()["insoles"] == s.insoles and s.urls()["pelvis"] == "xbus:///dev/ttyUSB0?baud=115200"
    assert (s.model, s.steps, s.calibration) == ("diffusion", "10D:3", "walk")
    assert s.recordings == tmp_path / "recordings" and s.path == f


def test_defaults_when_optional_tables_are_left_out():
    s = parse_setup('[subject]\nid = "A"\nheight = 1.8\n[sensors]\nhead = "dualsense://"\n')
    assert (s.insoles, s.model, s.steps, s.calibration, s.recordings) == (None, "auto", None, "walk",
                                                                          Path("recordings"))
    assert s.path is None


def test_example_file_parses():
    s = load_setup(REPO / "examples" / "setup_example.toml")
    assert set(s.sites()) <= set(SITES) and len(s.sites()) >= 6
    assert s.insoles is not None and s.subject.height_m == 1.72


def test_round_trip(tmp_path):
    f = tmp_path / "lab.toml"
    f.write_text(GOOD)
    s = load_setup(f)
    s.sensors["pelvis"].serial = 'SN "7"\\x'  # quotes and backslashes must survive
    s.subject.notes = "line one\nline two\ttab"
    again = parse_setup(dump_setup(s), f)
    assert again == s
    assert [e.line for e in again.sensors.values()] != [None] * 3  # lines come from the new text


def test_round_trip_of_a_minimal_setup_and_comments(tmp_path):
    s = Setup(Subject("S1", 1.6), {"head": SensorEntry("head", "dualsense://")}, calibration="table",
              path=tmp_path / "x.toml")
    text = dump_setup(s)
    assert "# [insoles]" in text and '# steps = "10D:3"' in text and "[calibration]" in text
    back = parse_setup(text, s.path)
    assert (back.subject, back.sensors, back.insoles, back.calibration, back.steps) == (
        s.subject, s.sensors, None, "table", None)
    assert back.recordings == tmp_path / "recordings"


def test_save_is_atomic_and_leaves_no_temp_file(tmp_path):
    f = tmp_path / "lab.toml"
    f.write_text(GOOD)
    s = load_setup(f)
    s.subject.id = "P015"
    save_setup(s, f)
    assert load_setup(f).subject.id == "P015"
    assert os.listdir(tmp_path) == ["lab.toml"]
    assert load_setup(f).recordings == tmp_path / "recordings"  # written relative, read back the same


def test_toml_syntax_error_keeps_the_line(tmp_path):
    text = GOOD.replace('r_wrist = "dualsense://"', "r_wrist = dualsense://")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "r_wrist =")
    assert "TOML syntax error" in str(err) and "quotes" in err.fix


def test_unknown_site_suggests_the_closest(tmp_path):
    text = GOOD.replace("l_wrist =", "l_wirst =")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "l_wirst")
    assert "unknown site 'l_wirst'" in str(err) and "did you mean l_wrist?" in str(err)
    assert "r_foot" in str(err)  # the valid ones are listed


def test_site_given_twice_names_both_lines(tmp_path):
    text = GOOD.replace('r_wrist = "dualsense://"', 'r_wrist = "dualsense://"\n"l_wrist" = "dualsense://unix/x"')
    err = error_of(text, tmp_path)
    first, second = line_of(text, "l_wrist = {"), line_of(text, '"l_wrist" =')
    assert err.line == second
    assert f"site l_wrist given twice (lines {first} and {second})" in str(err) and "keep one" in str(err)


def test_table_given_twice(tmp_path):
    text = GOOD + '\n[sensors]\nhead = "dualsense://unix/x"\n'
    err = error_of(text, tmp_path)
    assert err.line == len(text.splitlines()) - 1 and "[sensors] appears twice" in str(err)


def test_one_device_for_two_sites_names_both(tmp_path):
    text = GOOD.replace('r_wrist = "dualsense://"', 'r_wrist = "bno08x-rvc:///dev/ttyUSB1?id=x"')
    err = error_of(text, tmp_path)
    a, b = line_of(text, "l_wrist ="), line_of(text, "r_wrist =")
    assert err.line == b
    assert f"l_wrist (line {a})" in str(err) and f"r_wrist (line {b})" in str(err)
    assert "own sensor" in str(err)


def test_can_sensors_on_one_bus_are_different_devices(tmp_path):
    text = GOOD.replace('r_wrist = "dualsense://"', 'r_wrist = "xsens-can://socketcan/can0?id_offset=0x100"\n'
                                                   'head = "xsens-can://socketcan/can0?id_offset=0x200"')
    assert len(parse_setup(text).sensors) == 4
    err = error_of(text.replace("0x200", "256"), tmp_path)  # 0x100 written another way
    assert "head" in str(err) and "r_wrist" in str(err)


@pytest.mark.parametrize(
    ("url", "words"),
    [
        ("xbuss:///dev/ttyUSB2", ["unknown device scheme 'xbuss'", "xbus, bno08x-rvc, xsens-can, dualsense, "
                                  "moticon-udp", "did you mean xbus?"]),
        ("bno08x-rvc://", ["names no serial port", "bno08x-rvc:///dev/ttyUSB1"]),
        ("xsens-can://socketcan", ["names no CAN interface and channel"]),
        ("/dev/ttyUSB2", ["is not a device URL", "scheme://"]),
        ("xbus:///dev/ttyUSB2?baud=fast", ["baud='fast' is not an integer"]),
        ("moticon-udp://127.0.0.1:9998", ["names insoles, not an IMU", "[insoles]"]),
    ],
)
def test_bad_url(tmp_path, url, words):
    text = GOOD.replace('"dualsense://"', f'"{url}"')
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "r_wrist =")
    assert str(err).split(": ", 1)[1].startswith("r_wrist: ")
    for w in words:
        assert w in str(err)


def test_insoles_must_be_insoles(tmp_path):
    text = GOOD.replace("moticon-udp://127.0.0.1:9999", "xbus:///dev/ttyUSB5")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, 'url = "xbus') and "is an IMU, not insoles" in str(err)


def test_height_missing(tmp_path):
    text = GOOD.replace("height = 1.72          # metres\n", "")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "[subject]")
    assert "height is missing" in str(err) and "height = 1.75" in str(err)


@pytest.mark.parametrize(("value", "words"), [("172", ["172 m is not a body height", "height = 1.72"]),
                                              ("0.2", ["0.2 m is not a body height", "between 0.5 and 2.5"]),
                                              ('"1.72"', ["is not a number", "without quotes"])])
def test_height_absurd(tmp_path, value, words):
    text = GOOD.replace("height = 1.72", f"height = {value}")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "height =")
    for w in words:
        assert w in str(err)


def test_no_sensors(tmp_path):
    start = GOOD.index("pelvis  =")
    text = GOOD[:start] + GOOD[GOOD.index("[insoles]"):]
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "[sensors]") and "no sensors" in str(err) and "site = device URL" in str(err)
    no_table = text.replace("[sensors]", "")
    err = error_of(no_table, tmp_path)
    assert err.line is None and "no sensors" in str(err)


def test_unknown_table(tmp_path):
    text = GOOD.replace("[sensors]", "[sensor]")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "[sensor]")
    assert "unknown table [sensor]" in str(err) and "did you mean [sensors]?" in str(err)


def test_unknown_keys(tmp_path):
    text = GOOD.replace("notes =", "note =")
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "note =") and "unknown key 'note' in [subject]" in str(err)
    assert "did you mean notes?" in str(err)
    text = GOOD.replace('label = "blue strap"', 'lable = "blue strap"')
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "lable") and "did you mean label?" in str(err)


def test_bad_calibration_protocol(tmp_path):
    text = GOOD.replace('protocol = "walk"', 'protocol = "tpose"')
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "protocol =")
    assert "unknown calibration protocol 'tpose'" in str(err) and '"walk"' in str(err) and '"table"' in str(err)


def test_bad_steps(tmp_path):
    text = GOOD.replace('steps = "10D:3"', 'steps = "fast"')
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "steps =") and "10D:3" in err.fix


def test_lines_are_found_past_multiline_strings_and_arrays():
    text = ('[subject]\nid = "P1"\nnotes = """\n[sensors]\nhead = "x"\n"""\nheight = 1.7\n'
            "[sensors]\n'pelvis' = \"xbus:///dev/ttyUSB0\"  # a [comment]\nhead = \"nope://x\"\n")
    with pytest.raises(SetupError) as info:
        parse_setup(text)
    assert info.value.line == 10 and str(info.value).startswith("<setup>:10: head:")


def test_sub_table_sensor_lines(tmp_path):
    text = GOOD + '\n[sensors.head]\nurl = "bno08x-rvc:///dev/ttyUSB1"\n'
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "[sensors.head]") and "head" in str(err) and "l_wrist" in str(err)


def test_missing_file_is_one_line(tmp_path):
    with pytest.raises(SetupError) as info:
        load_setup(tmp_path / "nope.toml")
    assert "no such file" in str(info.value) and "imucap setup new" in str(info.value)


def test_confidence_reads_back_and_must_be_true_or_false(tmp_path):
    f = tmp_path / "lab.toml"
    f.write_text(GOOD.replace('steps = "10D:3"', 'steps = "10D:3"\nconfidence = true'))
    s = load_setup(f)
    assert s.confidence is True and parse_setup(dump_setup(s), f).confidence is True
    assert load_setup_text(GOOD, tmp_path).confidence is False  # left out: off
    text = GOOD.replace('steps = "10D:3"', 'steps = "10D:3"\nconfidence = "yes"')
    err = error_of(text, tmp_path)
    assert err.line == line_of(text, "confidence =") and "true" in err.fix


def load_setup_text(text: str, tmp_path: Path) -> Setup:
    f = tmp_path / "other.toml"
    f.write_text(text)
    return load_setup(f)
