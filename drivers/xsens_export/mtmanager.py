"""MT Manager text exports (MTi, MTw Awinda): one file per sensor.

Layout, as checked against public exports and documentation:
- the OpenSim example data exported from MT Manager, as kept in the repository
  Allwillcome/XsensDot2Mtw4OpenSense, OpenSenseExampleIMUData/MT_012005D6_009-001_00B421E6.txt
  (short preamble, tab-separated, Acc + Mat, empty SampleTimeFine and UTC columns);
- the MTw Awinda user manual's table of export columns and units,
  https://www.manualshelf.com/manual/xsens-technologies/awnddng/user-manual-english/page-45.html
  (Counter wraps at 65535, Acc m/s^2, Gyr rad/s, Roll/Pitch/Yaw deg, Mat[row][col]);
- the grouped preamble of MT Manager 2022 (``//  DeviceId:``, ``// Coordinate system:``)
  and its ``NaN`` cells, as seen in public code that writes and parses such exports.

What a file holds:

- a preamble of ``//`` lines: ``// Update Rate: 100.0Hz``, ``// Filter Profile: ...``,
  ``// Firmware Version: ...``, in newer versions indented groups with
  ``//  DeviceId: 00B42D4F`` and ``// Coordinate system: ENU``;
- one line of column names, then one line per sample, tab-separated (comma or semicolon
  when exported so); a cell MT Manager has no value for is empty or ``NaN``, and outputs
  it did not get are whole empty columns (the OpenSim files leave SampleTimeFine and
  UTC_* empty and time by PacketCounter);
- PacketCounter wraps at 2^16; SampleTimeFine counts 10 kHz ticks and wraps at 2^32;
  Acc_* m/s^2 (specific force), FreeAcc_* m/s^2 in the Earth frame, Gyr_* rad/s;
  orientation as Quat_q0..q3 (q0 = w), Mat[row][col] or Roll/Pitch/Yaw (deg);
- the device id, when the header lacks it, ends the file name:
  ``MT_012005D6_009-001_00B421E6.txt``.
"""

from __future__ import annotations

import os
import re

from drivers.device_log import DeviceLog
from drivers.xsens_export.samples import Layout, to_device_log
from drivers.xsens_export.table import Table, read_table

MTMANAGER = Layout(
    name="mtmanager", title="MT Manager export", tick_s=1e-4, counter_wrap=2**16, gyro_to_rad=1.0,
    rate_keys=("updaterate", "outputrate"), id_keys=("deviceid", "deviceidentifier"), name_keys=(),
    id_in_stem=re.compile(r"(?:^|_)([0-9A-Fa-f]{8})$"),
)
# column names only MT Manager writes (its orientation names), for files without a preamble
OWN_COLUMNS = re.compile(r"^(quatq[0-3]|q[0-3]|mat[1-3][1-3]|roll|pitch|yaw)$")


def is_mtmanager(table: Table) -> bool:
    """Whether the preamble is MT Manager's (``//`` lines)."""
    return table.comments


def read_mtmanager(path: str | os.PathLike) -> DeviceLog:
    """One MT Manager export as a DeviceLog (name and serial: the device id, else the file's stem)."""
    return to_device_log(read_table(path), MTMANAGER)[0]


__all__ = ["MTMANAGER", "OWN_COLUMNS", "is_mtmanager", "read_mtmanager"]
