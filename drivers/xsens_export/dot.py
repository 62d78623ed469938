"""Xsens (Movella) DOT CSV exports, from the DOT app or the DOT SDK's logger: one file per sensor.

Layout, as checked against public exports and documentation:
- DOT app exports in the repository Allwillcome/XsensDot2Mtw4OpenSense:
  bei_D4CA6EF17860_20210830_170505.csv (Euler + Acc + Gyr, recording mode, 120 Hz) and
  Original_XsensDot_Data_Realtime/Pelvis_20210820_202113_836.csv (Quat + FreeAcc +
  Status, real-time streaming, 60 Hz, lost packets);
- the column sets and preamble of the DOT SDK's CSV logger (XsensDotLogger, as found in
  public Android code);
- the Xsens DOT user manual, sections 4.2.2-4.2.5 (units, free acceleration, clocks):
  https://manualshive.com/en/manual/xsens/dot/3652498?page=24 and ?page=25.

What a file holds:

- ``sep=,``, then ``Key:,value`` lines (``DeviceTag:``, ``FirmwareVersion:``,
  ``AppVersion:``, ``SyncStatus:``, ``OutputRate:,60Hz``, ``FilterProfile:``,
  ``Measurement Mode:``, ``StartTime:``; some versions pad them with commas), a
  copyright line, a blank line;
- one line of column names, then one line per sample, comma-separated:
  PacketCounter, SampleTimeFine, then by measurement mode Quat_W..Z or Euler_X..Z (deg,
  roll/pitch/yaw), FreeAcc_X..Z (m/s^2, Earth frame, gravity removed), Acc_X..Z
  (m/s^2, specific force), Gyr_X..Z (deg/s: the DOT's unit, not MT Manager's rad/s),
  Mag_*, Status;
- SampleTimeFine counts microseconds and wraps at 2^32 (about 71.6 min); PacketCounter
  wraps at 2^32. Synchronised sensors share the SampleTimeFine clock (the two public
  files of one session start one sample apart).
- the sensor's Bluetooth address, when the header does not give it, is in the file name:
  ``<tag>_<12 hex digits>_<date>_<time>.csv``.
"""

from __future__ import annotations

import os
import re

from drivers.device_log import DeviceLog
from drivers.xsens_export.samples import Layout, to_device_log
from drivers.xsens_export.table import Table, read_table

DOT = Layout(
    name="dot", title="Xsens DOT export", tick_s=1e-6, counter_wrap=2**32, gyro_to_rad=3.141592653589793 / 180.0,
    rate_keys=("outputrate", "updaterate"), id_keys=("dotaddress", "address", "deviceaddress", "macaddress"),
    name_keys=("devicetag", "tagname", "tag"),
    id_in_stem=re.compile(r"(?:^|_)((?:[0-9A-Fa-f]{2}[:-]?){5}[0-9A-Fa-f]{2})(?=_|$)"),
)
# column names only DOT exports write, for files without a preamble
OWN_COLUMNS = re.compile(r"^(quat[wxyz]|euler[xyz])$")
_PREAMBLE_KEYS = {"devicetag", "tagname", "dotaddress", "outputrate", "syncstatus", "measurementmode", "appversion"}


def is_dot(table: Table) -> bool:
    """Whether the preamble is the DOT app's (``sep=`` or its ``Key:,`` lines)."""
    return table.sep_line or bool(_PREAMBLE_KEYS & set(table.preamble))


def read_dot(path: str | os.PathLike) -> DeviceLog:
    """One DOT export as a DeviceLog (name: the tag, else the address, else the file's
    stem; serial: the address)."""
    return to_device_log(read_table(path), DOT)[0]


__all__ = ["DOT", "OWN_COLUMNS", "is_dot", "read_dot"]
