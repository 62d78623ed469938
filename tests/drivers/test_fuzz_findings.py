"""Inputs the coverage-guided fuzzer (benchmarks/fuzz.py) found that made a log reader
raise something other than its own one-line error; each now gets that error, or is read
with the damage counted."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.ximu3.log import LogError, read_log
from drivers.xsens_export.reader import read_export
from drivers.xsens_export.table import ExportError

INERTIAL_HEAD = ("Timestamp (us),Gyroscope X (deg/s),Gyroscope Y (deg/s),Gyroscope Z (deg/s),"
                 "Accelerometer X (g),Accelerometer Y (g),Accelerometer Z (g)\n")


def _ximu3_log(root: Path, inertial: bytes, quaternion: bytes) -> Path:
    dev = root / "x-IMU3 65577B35 (USB)"
    dev.mkdir(parents=True)
    (dev / "Inertial.csv").write_bytes(inertial)
    (dev / "Quaternion.csv").write_bytes(quaternion)
    return root


def test_ximu3_bytes_that_are_not_utf8_spoil_only_their_rows(tmp_path):
    """Was a UnicodeDecodeError naming no file (fuzz target ximu3)."""
    rows = "".join(f"{10000 * k},0.1,-0.2,0.3,0.01,0.02,0.99\n" for k in range(6)).encode()
    rows = rows.replace(b"0.3,0.01", b"0.3,\xd0\x01", 1)  # a damaged byte in the first row
    quats = b"Timestamp (us),W,X,Y,Z\n" + b"".join(b"%d,1,0,0,0\n" % (10000 * k) for k in range(6))
    (log,) = read_log(_ximu3_log(tmp_path, INERTIAL_HEAD.encode() + rows, quats))
    assert len(log.t) == 5 and log.skipped["malformed"] == 1


def test_ximu3_a_binary_file_is_a_log_error(tmp_path):
    junk = bytes(range(256)) * 4
    with pytest.raises(LogError, match="fewer than two samples"):
        read_log(_ximu3_log(tmp_path, junk, junk))


def test_xsens_export_without_a_row_that_has_time_and_orientation(tmp_path):
    """Was an IndexError from an empty diff (fuzz target xsens-export): a matrix export
    whose every row lacks a cell of the orientation."""
    head = ("PacketCounter;SampleTimeFine;Mat[1][1];Mat[2][1];Mat[3][1];Mat[1][2];Mat[2][2];Mat[3][2];"
            "Mat[1][3];Mat[2][3];Mat[3][3];Acc_X;Acc_Y;Acc_Z\n")
    cells = ["1,0", "0,0", "0,0", "0,0", "1,0", "0,0", "0,0", "0,0", "1,0"]
    rows = "".join(f"{k};{1000 * k};" + ";".join("" if c == k else v for c, v in enumerate(cells)) + ";0,1;0,2;9,8\n"
                   for k in range(4))  # row k lacks matrix cell k: no row has a whole orientation
    path = tmp_path / "MT_0123.txt"
    path.write_text(head + rows)
    with pytest.raises(ExportError, match="fewer than two rows with both a time and an orientation"):
        read_export(path)


def test_xsens_export_one_good_row_is_still_too_few(tmp_path):
    head = "PacketCounter;SampleTimeFine;Quat_q0;Quat_q1;Quat_q2;Quat_q3\n"
    path = tmp_path / "MT_0124.txt"
    path.write_text(head + "0;0;1;0;0;0\n" + "1;100;;;;\n")
    with pytest.raises(ExportError) as exc:
        read_export(path)
    assert str(path) in str(exc.value) and np.isfinite(exc.value.line)
