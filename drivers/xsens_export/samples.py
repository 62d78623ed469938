"""From an export's cells to a ``DeviceLog``: what both Xsens layouts share.

The two layouts name their columns alike and differ in a few numbers (the tick of
SampleTimeFine, where PacketCounter wraps, the unit of Gyr_*), in where the rate and the
device's name sit in the header and in how a file is named; a ``Layout`` holds exactly
those, and everything else is done once here:

- time from SampleTimeFine, unwrapped at 2^32 ticks; without it, from PacketCounter
  (unwrapped at its own modulus) and the header's rate; without a counter, from the row
  order and the rate. A file that gives none of these is refused rather than given a
  guessed rate: a wrong time base is a wrong answer, not a failure.
- orientation from quaternion, matrix or Euler columns (``frames``), turned to a Z-up
  Earth frame.
- specific force from Acc_* or, where only FreeAcc_* is exported (the DOT app's default),
  from free acceleration: f_S = R_GS^T (a_free + g up), g = ``G``.
- rows without time or orientation are dropped; a missing Acc/Gyr cell in a row that has
  both is filled from its neighbours in time, so a lost cell does not cost the
  orientation of its row. An Acc of exactly (0, 0, 0), which the DOT app writes in a
  recording's first row, counts as missing.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from drivers._math import quat_conjugate, quat_mul, quat_rotate
from drivers.device_log import DeviceLog
from drivers.xsens_export.frames import EARTH_TO_ENU, from_euler_deg, from_matrix, normalise
from drivers.xsens_export.table import ExportError, Table, norm_key

G = 9.81  # the gravity Xsens subtracts for free acceleration (close enough to local g for a body model)
TIME_WRAP = 2**32

QUAT_SETS = (("quatq0", "quatq1", "quatq2", "quatq3"), ("quatw", "quatx", "quaty", "quatz"), ("q0", "q1", "q2", "q3"))
MATRIX = tuple(f"mat{r}{c}" for r in (1, 2, 3) for c in (1, 2, 3))
EULER_SETS = (("roll", "pitch", "yaw"), ("eulerx", "eulery", "eulerz"))
ACC, FREE_ACC, GYR = (tuple(f"{p}{a}" for a in "xyz") for p in ("acc", "freeacc", "gyr"))
_KNOWN = re.compile(r"^(packetcounter|counter|sampletime(fine|coarse)|quat|q[0-3]$|mat[1-3][1-3]$|roll$|pitch$|yaw$"
                    r"|euler|acc|freeacc|gyr|mag|dq|dv|utc|status|flag|year$|month$|day$|hour$|minute$|second$"
                    r"|temperature|pressure|velinc|oriinc)")


@dataclass(frozen=True)
class Layout:
    """What tells one Xsens export layout from the other (module docstring).

    tick_s: one SampleTimeFine tick; counter_wrap: where PacketCounter wraps; gyro_to_rad:
    Gyr_* unit in rad/s; rate_keys, id_keys, name_keys: header keys (``norm_key``) of the
    output rate, of the device's id and of the name the user gave it; id_in_stem: a file
    name pattern whose group 1 is the device id, for exports whose header lacks it."""

    name: str
    title: str
    tick_s: float
    counter_wrap: int
    gyro_to_rad: float
    rate_keys: tuple[str, ...]
    id_keys: tuple[str, ...]
    name_keys: tuple[str, ...]
    id_in_stem: re.Pattern[str]


def recognised(columns: list[str]) -> list[str]:
    """The columns whose names are Xsens output names."""
    return [c for c in columns if _KNOWN.match(norm_key(c))]


def unwrap(raw: np.ndarray, modulus: float) -> np.ndarray:
    """A counter that wraps at ``modulus`` made monotonic; NaN entries stay NaN. A step
    back by more than half the range is a wrap; a smaller one stays a step back."""
    out = np.full(raw.shape, np.nan)
    ok = np.isfinite(raw)
    v = raw[ok]
    if v.size:
        wraps = np.concatenate([[0.0], np.cumsum(np.where(np.diff(v) < -modulus / 2, modulus, 0.0))])
        out[ok] = v + wraps
    return out


def header_rate(table: Table, layout: Layout) -> float | None:
    """The output rate the header states (Hz), if it states one."""
    for key in layout.rate_keys:
        m = re.match(r"\s*([0-9]*\.?[0-9]+)", table.preamble.get(key, ""))
        if m and float(m.group(1)) > 0:
            return float(m.group(1))
    return None


def _column(table: Table, name: str) -> np.ndarray | None:
    """One named column as numbers, or None if the export has no such column or leaves
    it empty throughout (MT Manager writes empty columns for outputs it did not get)."""
    col = table.index().get(name)
    if col is None:
        return None
    v = table.numbers(col)
    return v if np.isfinite(v).any() else None


def _group(table: Table, names: tuple[str, ...]) -> np.ndarray | None:
    """(N, len(names)) a set of columns, or None unless every one of them has values."""
    cols = [_column(table, n) for n in names]
    return None if any(c is None for c in cols) else np.stack(cols, axis=1)


def _time(table: Table, layout: Layout) -> tuple[np.ndarray, float, str]:
    """(t (N,) s with NaN where a row has none, the clock's wrap period in s, its source)."""
    fine = _column(table, "sampletimefine")
    if fine is not None:
        return unwrap(fine, TIME_WRAP) * layout.tick_s, TIME_WRAP * layout.tick_s, "SampleTimeFine"
    rate = header_rate(table, layout)
    if rate is None:
        raise ExportError(table.path, table.header_line,
                          "no time: no SampleTimeFine values and no output rate in the header")
    counter = _column(table, "packetcounter")
    if counter is None:
        counter = _column(table, "counter")
    if counter is not None:
        return unwrap(counter, layout.counter_wrap) / rate, layout.counter_wrap / rate, f"PacketCounter at {rate:g} Hz"
    return np.arange(len(table.rows)) / rate, float("inf"), f"row order at {rate:g} Hz"


def _orientation(table: Table) -> np.ndarray:
    """(N, 4) R_GS in the export's Earth frame, NaN where a row has none."""
    for names in QUAT_SETS:
        q = _group(table, names)
        if q is not None:
            return q
    R = _group(table, MATRIX)
    if R is not None:
        q = np.full((len(R), 4), np.nan)
        ok = np.all(np.isfinite(R), axis=1)
        q[ok] = from_matrix(R[ok].reshape(-1, 3, 3))
        return q
    for names in EULER_SETS:
        e = _group(table, names)
        if e is not None:
            return from_euler_deg(e[:, 0], e[:, 1], e[:, 2])
    raise ExportError(table.path, table.header_line,
                      "no orientation columns (Quat_q0..q3, Quat_W..Z, Mat[r][c], Roll/Pitch/Yaw or Euler_X/Y/Z)")


def _earth(table: Table) -> str:
    """The export's Earth frame, lower case (MT Manager's ``Coordinate system``; ENU else)."""
    frame = table.preamble.get("coordinatesystem", "ENU").strip().lower() or "enu"
    if frame not in EARTH_TO_ENU:
        raise ExportError(table.path, table.header_line,
                          f"unknown coordinate system {frame.upper()!r} (known: ENU, NED, NWU)")
    return frame


def _fill(t: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(v with NaN rows interpolated in time from the finite ones, which rows were)."""
    bad = ~np.all(np.isfinite(v), axis=1)
    if not bad.any() or bad.all():
        return v, np.zeros(len(v), bool)
    out = v.copy()
    for k in range(v.shape[1]):
        ok = np.isfinite(v[:, k])
        out[~ok, k] = np.interp(t[~ok], t[ok], v[ok, k])
    return out, bad


def _device_names(table: Table, layout: Layout) -> tuple[str, str]:
    """(name, id): the name the user gave the device, else its id, else the file's stem;
    the id from the header, else from the file name."""
    pre = table.preamble
    dev_id = next((pre[k] for k in layout.id_keys if pre.get(k)), "")
    if not dev_id:
        m = layout.id_in_stem.search(table.path.stem)
        dev_id = m.group(1) if m else ""
    name = next((pre[k] for k in layout.name_keys if pre.get(k)), "") or dev_id or table.path.stem
    return name, dev_id


def _unmeasured(acc: np.ndarray, gyr: np.ndarray | None) -> None:
    """Blank (in place) rows whose Acc is exactly zero, and their Gyr if it is zero too: no
    accelerometer reads exactly nothing, but a DOT recording's first row is written so."""
    zero = np.all(acc == 0.0, axis=1)
    acc[zero] = np.nan
    if gyr is not None:
        gyr[zero & np.all(gyr == 0.0, axis=1)] = np.nan


def _vectors(table: Table, layout: Layout, rows: np.ndarray, t: np.ndarray, quat: np.ndarray,
             frame: str) -> tuple[np.ndarray, np.ndarray, dict[str, str], int]:
    """(specific force (n, 3), gyro (n, 3) rad/s, where each came from, rows filled) of
    the kept ``rows`` (module docstring); NaN throughout for a channel not exported."""
    nan3 = np.full((len(rows), 3), np.nan)
    acc, free, gyr = _group(table, ACC), _group(table, FREE_ACC), _group(table, GYR)
    if acc is not None:
        _unmeasured(acc, gyr)
    filled = np.zeros(len(rows), bool)
    source = {"acc_from": "none", "gyro_from": "none"}
    if acc is not None:
        acc, filled = _fill(t, acc[rows])
        source["acc_from"] = "Acc"
    elif free is not None:
        free, filled = _fill(t, quat_rotate(EARTH_TO_ENU[frame][None], free[rows]))
        acc = quat_rotate(quat_conjugate(quat), free + np.array([0.0, 0.0, G]))
        source["acc_from"] = "FreeAcc"
    if gyr is not None:
        gyr, filled_gyr = _fill(t, gyr[rows] * layout.gyro_to_rad)
        filled = filled | filled_gyr
        source["gyro_from"] = "Gyr"
    return (nan3 if acc is None else acc), (nan3 if gyr is None else gyr), source, int(filled.sum())


def _kept_rows(table: Table, t: np.ndarray, q_ok: np.ndarray) -> tuple[np.ndarray, dict[str, int]]:
    """(the rows with a time and an orientation, in time order, the first of equal times;
    how many were dropped, by reason)."""
    keep = np.isfinite(t) & q_ok
    skipped = {"no_time": int((~np.isfinite(t)).sum()), "no_orientation": int((np.isfinite(t) & ~q_ok).sum())}
    idx = np.flatnonzero(keep)
    order = idx[np.argsort(t[idx], kind="stable")]
    later = np.ones(order.size, bool)  # also when no row has both (an empty diff)
    later[1:] = np.diff(t[order]) > 0
    skipped["duplicate"] = int((~later).sum())
    rows = order[later]
    if rows.size < 2:
        raise ExportError(table.path, table.header_line, "fewer than two rows with both a time and an orientation")
    return rows, skipped


def to_device_log(table: Table, layout: Layout) -> tuple[DeviceLog, float]:
    """(the export as a DeviceLog, its clock's wrap period in s; module docstring)."""
    if not recognised(table.columns):
        shown = ", ".join(c for c in table.columns[:6] if c) or "none"
        raise ExportError(table.path, table.header_line,
                          f"no recognised columns (found: {shown}); expected Xsens names such as "
                          "PacketCounter, SampleTimeFine, Acc_X, Quat_q0")
    if not table.rows:
        raise ExportError(table.path, table.header_line, "no data rows after the column header")
    quat = _orientation(table)
    t, period, time_from = _time(table, layout)
    frame = _earth(table)
    quat, q_ok = normalise(quat_mul(EARTH_TO_ENU[frame], quat))
    rows, skipped = _kept_rows(table, t, q_ok)
    t, quat = t[rows], quat[rows]
    acc, gyro, source, skipped["filled"] = _vectors(table, layout, rows, t, quat, frame)
    name, dev_id = _device_names(table, layout)
    info = {**table.preamble, "layout": layout.name, "time_from": time_from, "earth_frame": frame.upper(), **source}
    return DeviceLog(name=name, serial=dev_id, t=t, quat=quat, acc=acc, gyro=gyro, skipped=skipped, info=info), period


__all__ = ["G", "Layout", "header_rate", "recognised", "to_device_log", "unwrap"]
