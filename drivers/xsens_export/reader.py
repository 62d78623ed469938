"""Which Xsens layout a file is, and reading one export or a session's worth of them."""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

from drivers.device_log import DeviceLog
from drivers.xsens_export.dot import DOT, is_dot
from drivers.xsens_export.dot import OWN_COLUMNS as DOT_COLUMNS
from drivers.xsens_export.mtmanager import MTMANAGER, is_mtmanager
from drivers.xsens_export.mtmanager import OWN_COLUMNS as MT_COLUMNS
from drivers.xsens_export.samples import EULER_SETS, MATRIX, QUAT_SETS, Layout, recognised, to_device_log
from drivers.xsens_export.table import ExportError, Table, norm_key, read_table

HEAD_LINES = 64  # more than any preamble, so the column names are among them
LAYOUTS: dict[str, Layout] = {MTMANAGER.name: MTMANAGER, DOT.name: DOT}


def layout_of(table: Table) -> str | None:
    """The layout a read table is in: by its preamble, else by the orientation names only
    one layout uses; None when neither tells."""
    if is_mtmanager(table):
        return MTMANAGER.name
    if is_dot(table):
        return DOT.name
    names = [norm_key(c) for c in table.columns]
    mt, dot = any(MT_COLUMNS.match(n) for n in names), any(DOT_COLUMNS.match(n) for n in names)
    if mt != dot:
        return MTMANAGER.name if mt else DOT.name
    return None


def _has_orientation(table: Table) -> bool:
    names = {norm_key(c) for c in table.columns}
    return any(set(g) <= names for g in (*QUAT_SETS, MATRIX, *EULER_SETS))


def detect_layout(path: str | os.PathLike) -> str | None:
    """``"mtmanager"``, ``"dot"``, or None for a file that is not an Xsens export (empty,
    without Xsens column names whatever its preamble, or a table that neither has an Xsens
    preamble nor orientation columns: a lab's own CSV with an ``Acc_X`` column is not an
    export); never raises on content. A file with the preamble but no orientation is an
    export, damaged, and reading it says so."""
    try:
        table = read_table(path, limit=HEAD_LINES)
    except (ExportError, OSError):
        return None
    if not recognised(table.columns):
        return None
    if not (is_mtmanager(table) or is_dot(table) or _has_orientation(table)):
        return None
    return layout_of(table)


def _read(path: str | os.PathLike, layout: str | None) -> tuple[DeviceLog, float]:
    if layout is not None and layout not in LAYOUTS:
        raise ValueError(f"unknown Xsens export layout {layout!r} (known: {', '.join(LAYOUTS)})")
    table = read_table(path)
    seen = layout_of(table)
    if layout and seen and seen != layout:
        raise ExportError(path, table.header_line,
                          f"this is an {LAYOUTS[seen].title}, not an {LAYOUTS[layout].title}; give the right format")
    name = layout or seen
    if name is None:
        raise ExportError(path, table.header_line,
                          "cannot tell an MT Manager export from a DOT export (no preamble, no orientation names "
                          "only one of them uses); give the format")
    return to_device_log(table, LAYOUTS[name])


def read_export(path: str | os.PathLike, layout: str | None = None) -> DeviceLog:
    """One Xsens export file as a DeviceLog, in the given layout or the one its header
    shows (``layout_of``). Raises ExportError (``path:line: problem``) for a file it
    cannot read."""
    return _read(path, layout)[0]


def _same_clock_turn(logs: list[tuple[DeviceLog, float]]) -> None:
    """Devices that share a wrapping clock but started on either side of a wrap: move
    each one's times by whole wrap periods next to the first device's start (in place)."""
    ref = logs[0][0].t[0]
    for d, period in logs[1:]:
        if not np.isfinite(period):
            continue
        k = round((ref - d.t[0]) / period)
        if k and abs(ref - d.t[0] - k * period) < period / 4:
            d.t = d.t + k * period


def read_exports(paths: Sequence[str | os.PathLike], layout: str | None = None) -> list[DeviceLog]:
    """The exports of one session (one file per sensor), in the order given, their clocks
    brought to one wrap period (``_same_clock_turn``)."""
    logs = [_read(p, layout) for p in paths]
    if not logs:
        raise ValueError("no Xsens export files given")
    _same_clock_turn(logs)
    return [d for d, _ in logs]


__all__ = ["LAYOUTS", "detect_layout", "layout_of", "read_export", "read_exports"]
