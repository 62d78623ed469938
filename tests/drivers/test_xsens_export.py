"""The Xsens export readers (drivers/xsens_export): MT Manager and DOT files written here
(by sim_devices.xsens_export, or by hand where one line matters), read back in SI units
and our frames; clocks that wrap, packets lost, cells missing, column subsets; and each
refusal as one line that names the file, the line and the problem."""

from __future__ import annotations

import numpy as np
import pytest

from drivers._math import quat_rotate
from drivers.xsens_export import ExportError, detect_layout, read_export, read_exports
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate
from sim_devices.xsens_export import write_dot_exports, write_mtmanager_exports

SITES = ("pelvis", "l_shank")
IDS = {"pelvis": "00B421E6", "l_shank": "00B421ED"}
TAGS = {"pelvis": "Pelvis", "l_shank": "LTibia"}


@pytest.fixture(scope="module")
def sig():
    return synthesize(generate("walk", seconds=4.0), NoiseModel.typical(), rng=3, sites=SITES)


def same_orientation(q, truth, tol=1e-5):
    np.testing.assert_allclose(np.abs(np.sum(q * truth, axis=1)), 1.0, atol=tol)


def kept(n, drop):
    return np.setdiff1d(np.arange(n), drop)


def test_mtmanager_tab_export_reads_back_across_the_clock_wrap(tmp_path, sig):
    paths = write_mtmanager_exports(sig, tmp_path, IDS, drop=[40, 41, 90])
    d = read_export(paths[1])
    keep = kept(len(sig.t), [40, 41, 90])
    assert d.info["layout"] == "mtmanager" and d.info["time_from"] == "SampleTimeFine"
    assert (d.name, d.serial) == ("00B421ED", "00B421ED")  # the short header has no id: the file name's
    # SampleTimeFine started 2 s before 2^32 ticks: one clock across the wrap, 10 kHz ticks
    assert len(d.t) == len(keep) and np.all(np.diff(d.t) > 0)
    np.testing.assert_allclose(d.t - d.t[0], sig.t[keep] - sig.t[0], atol=1e-4)
    assert d.rate_hz == pytest.approx(60.0, rel=0.01)
    np.testing.assert_allclose(d.acc, sig.specific_force[keep, 1], atol=1e-5)
    np.testing.assert_allclose(d.gyro, sig.gyro[keep, 1], atol=1e-5)  # rad/s as written
    same_orientation(d.quat, sig.quat[keep, 1])
    assert d.skipped == {"no_time": 0, "no_orientation": 0, "duplicate": 0, "filled": 0}


def test_mtmanager_csv_with_long_header_euler_and_no_gyro(tmp_path, sig):
    paths = write_mtmanager_exports(sig, tmp_path, IDS, columns=("acc", "euler"), delimiter=",", long_header=True)
    assert paths[0].suffix == ".csv" and detect_layout(paths[0]) == "mtmanager"
    d = read_export(paths[0])
    assert d.serial == "00B421E6" and d.info["deviceid"] == "00B421E6" and d.info["earth_frame"] == "ENU"
    same_orientation(d.quat, sig.quat[:, 0])
    assert np.isnan(d.gyro).all() and d.info["gyro_from"] == "none"  # not exported: not invented


def test_mtmanager_matrix_and_time_from_the_wrapping_packet_counter(tmp_path, sig):
    """No SampleTimeFine (as in the OpenSim example exports): PacketCounter, which wraps
    at 2^16 (here 136 samples in), over the header's update rate."""
    paths = write_mtmanager_exports(sig, tmp_path, IDS, columns=("acc", "gyr", "matrix"), time=False,
                                    counter0=65_400, drop=[150])
    d = read_export(paths[0])
    keep = kept(len(sig.t), [150])
    assert d.info["time_from"] == "PacketCounter at 60 Hz"
    np.testing.assert_allclose(d.t - d.t[0], keep / 60.0, atol=1e-9)
    same_orientation(d.quat, sig.quat[keep, 0])


def test_missing_cells_are_filled_or_drop_their_row(tmp_path, sig):
    paths = write_mtmanager_exports(sig, tmp_path, IDS, blank=[(10, "Acc_Y"), (11, "Gyr_Z"), (20, "Quat_q2")])
    lines = paths[0].read_text().splitlines()
    cells = lines[6 + 30].split("\t")
    cells[3] = "NaN"  # Acc_X as MT Manager 2022 writes a missing value
    lines[6 + 30] = "\t".join(cells)
    paths[0].write_text("\n".join(lines) + "\n")
    d = read_export(paths[0])
    assert d.skipped["no_orientation"] == 1 and d.skipped["filled"] == 3
    assert len(d.t) == len(sig.t) - 1 and np.isfinite(d.acc).all() and np.isfinite(d.gyro).all()
    # a filled cell lies between its neighbours
    assert min(d.acc[9, 1], d.acc[11, 1]) - 1e-9 <= d.acc[10, 1] <= max(d.acc[9, 1], d.acc[11, 1]) + 1e-9


def test_dot_quaternion_and_free_acceleration(tmp_path, sig):
    """The DOT app's default export: free acceleration in Earth turned back into the
    specific force a sensor reads; no Gyr columns, so no angular rate."""
    paths = write_dot_exports(sig, tmp_path, TAGS, drop=[7])
    assert detect_layout(paths[0]) == "dot"
    d = read_export(paths[0])
    keep = kept(len(sig.t), [7])
    assert (d.name, d.serial) == ("Pelvis", "D4CA6EF17200") and d.info["syncstatus"] == "Synced"
    np.testing.assert_allclose(d.t - d.t[0], sig.t[keep] - sig.t[0], atol=2e-6)  # us ticks, across the wrap
    np.testing.assert_allclose(d.acc, sig.specific_force[keep, 0], atol=1e-4)
    same_orientation(d.quat, sig.quat[keep, 0])
    assert d.info["acc_from"] == "FreeAcc" and np.isnan(d.gyro).all()


def test_dot_euler_with_inertial_data_in_degrees(tmp_path, sig):
    paths = write_dot_exports(sig, tmp_path, TAGS, columns=("euler", "acc", "gyr"))
    d = read_export(paths[1])
    same_orientation(d.quat, sig.quat[:, 1])
    np.testing.assert_allclose(d.gyro, sig.gyro[:, 1], atol=1e-6)  # deg/s in the file
    np.testing.assert_allclose(d.acc, sig.specific_force[:, 1], atol=1e-5)


def test_a_dot_recordings_zero_first_row_counts_as_missing(tmp_path, sig):
    path = write_dot_exports(sig, tmp_path, TAGS, columns=("euler", "acc", "gyr"))[0]
    lines = path.read_text().splitlines()
    cells = lines[11].split(",")
    lines[11] = ",".join(cells[:5] + ["0.00000000000000"] * 6)  # as the DOT app writes it
    path.write_text("\n".join(lines) + "\n")
    d = read_export(path)
    assert d.skipped["filled"] == 1 and len(d.t) == len(sig.t)
    np.testing.assert_allclose(d.acc[0], d.acc[1])  # held from the first measured row


def test_sensors_on_either_side_of_the_wrap_are_put_on_one_clock(tmp_path, sig):
    paths = write_dot_exports(sig, tmp_path, TAGS)  # the shared clock wraps 3 s (180 samples) in
    lines = paths[1].read_text().splitlines()
    paths[1].write_text("\n".join(lines[:11] + lines[11 + 200:]) + "\n")  # this one started after the wrap
    a, b = read_exports(paths)
    assert b.t[0] - a.t[0] == pytest.approx(200 / 60.0, abs=1e-3)


def test_ned_exports_come_out_z_up_and_semicolons_with_decimal_commas_read(tmp_path):
    """A still sensor with its axes along north, east, down in an NED export: its
    specific force, (0, 0, -g) in its own frame, points up once turned to Earth."""
    path = tmp_path / "MT_00B40001.csv"
    rows = [f"{i};{i * 100};0;0;-9,81;1;0;0;0" for i in range(5)]
    path.write_text("// Update Rate: 100.0Hz\n// Coordinate system: NED\n"
                    "PacketCounter;SampleTimeFine;Acc_X;Acc_Y;Acc_Z;Quat_q0;Quat_q1;Quat_q2;Quat_q3\n"
                    + "\n".join(rows) + "\n")
    d = read_export(path)
    np.testing.assert_allclose(quat_rotate(d.quat, d.acc), np.tile([0.0, 0.0, 9.81], (5, 1)), atol=1e-9)
    np.testing.assert_allclose(np.diff(d.t), 0.01)
    assert d.serial == "00B40001"


def test_detection_needs_a_preamble_or_orientation_names_of_one_layout(tmp_path):
    plain = tmp_path / "plain.csv"
    plain.write_text("PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z\n1,0,1,0,0,0\n2,16667,1,0,0,0\n")
    assert detect_layout(plain) == "dot" and read_export(plain).rate_hz == pytest.approx(60.0, rel=1e-3)
    other = tmp_path / "other.csv"
    other.write_text("time,x,y\n0,1,2\n")
    notes = tmp_path / "notes.txt"
    notes.write_text("// trial 3: subject fell\nrepeat tomorrow\n")
    assert detect_layout(other) is None and detect_layout(notes) is None
    (tmp_path / "empty.csv").write_text("")
    assert detect_layout(tmp_path / "empty.csv") is None


MT_HEAD = "// Update Rate: 100.0Hz\n"


@pytest.mark.parametrize("text, line, problem", [
    ("", 1, "empty file"),
    ("\n\n", 1, "empty file"),
    (MT_HEAD + "// Firmware Version: 4.0.2\n", 2, "no column header"),
    (MT_HEAD + "Time\tX\tY\n0\t1\t2\n", 2, "no recognised columns (found: Time, X, Y)"),
    (MT_HEAD + "PacketCounter\tAcc_X\tAcc_Y\tAcc_Z\n1\t0\t0\t9.8\n", 2, "no orientation columns"),
    (MT_HEAD + "PacketCounter\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n1\t1\t0\t0\t0\n2\t1\t0\tx1\t0\n", 4,
     "column Quat_q2: 'x1' is not a number"),
    (MT_HEAD + "PacketCounter\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n", 2, "no data rows"),
    ("// Filter Profile: human (46.1)\nPacketCounter\tQuat_q0\tQuat_q1\tQuat_q2\tQuat_q3\n1\t1\t0\t0\t0\n", 2,
     "no time: no SampleTimeFine values and no output rate"),
    ("Acc_X,Acc_Y,Acc_Z\n0,0,9.8\n", 1, "cannot tell an MT Manager export from a DOT export"),
])
def test_refusals_name_the_file_the_line_and_the_problem(tmp_path, text, line, problem):
    path = tmp_path / "sensor.txt"
    path.write_text(text)
    with pytest.raises(ExportError) as err:
        read_export(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}:{line}: ") and problem in msg and "\n" not in msg


def test_a_format_given_against_the_file_is_refused(tmp_path, sig):
    """Read as DOT, an MT Manager file's 10 kHz ticks and rad/s would pass for us and deg/s."""
    path = write_mtmanager_exports(sig, tmp_path, IDS)[0]
    with pytest.raises(ExportError, match=r":6: this is an MT Manager export, not an Xsens DOT export"):
        read_export(path, "dot")
    assert read_export(path, "mtmanager").serial == "00B421E6"
