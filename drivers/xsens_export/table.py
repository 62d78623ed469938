"""The text of an Xsens export: its preamble, its column header and its cells.

Both Xsens layouts are a few lines about the device, one line of column names, then one
line per sample; they differ in how the preamble is written (``// Key: value`` lines
from MT Manager, ``Key:,value,,,`` lines after a ``sep=,`` line from the DOT app) and in
the separator (tab, comma or semicolon). Reading that much is the same for both, so it is
done once here and the layouts only interpret it (``mtmanager``, ``dot``).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

_MISSING = {"", "nan", "-nan", "n/a", "na", "null"}


class ExportError(ValueError):
    """A file that is not a readable Xsens export; the message is ``path:line: problem``."""

    def __init__(self, path: str | os.PathLike, line: int, problem: str) -> None:
        super().__init__(f"{path}:{line}: {problem}")
        self.path, self.line, self.problem = Path(path), line, problem


def norm_key(text: str) -> str:
    """A header key or column name without case, spaces or punctuation, so that
    ``Device ID``, ``DeviceId`` and ``deviceid`` are one key."""
    return re.sub(r"[^0-9a-z]", "", text.lower())


@dataclass
class Table:
    """path; preamble: the header's ``key: value`` pairs (keys as ``norm_key`` makes them;
    the first of a repeated key wins); comments: whether the preamble used ``//`` lines
    (MT Manager's mark); sep_line: whether it began with ``sep=`` (the DOT app's mark);
    columns: the column names as written; rows: the cells of each
    data line, with lines[i] the 1-based line number of rows[i]; header_line: the line of
    the column names."""

    path: Path
    preamble: dict[str, str]
    comments: bool
    sep_line: bool
    columns: list[str]
    header_line: int
    rows: list[list[str]] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)
    delimiter: str = ","
    decimal_comma: bool = False  # a semicolon or tab export written with a decimal comma

    def index(self) -> dict[str, int]:
        """norm_key(column name) -> column position (the first of equal names)."""
        out: dict[str, int] = {}
        for i, c in enumerate(self.columns):
            out.setdefault(norm_key(c), i)
        return out

    def numbers(self, col: int) -> np.ndarray:
        """(N,) one column as floats, NaN where a cell is empty, NaN or missing from a
        short row; a cell that is none of these nor a number is an ExportError."""
        cells = [row[col] if col < len(row) else "" for row in self.rows]
        if self.decimal_comma:
            cells = [c.replace(",", ".") for c in cells]
        try:  # the common case, every cell a number: at C speed
            return np.fromiter(map(float, cells), dtype=np.float64, count=len(cells))
        except ValueError:
            return self._cell_by_cell(col, cells)

    def _cell_by_cell(self, col: int, cells: list[str]) -> np.ndarray:
        out = np.full(len(cells), np.nan)
        for k, cell in enumerate(cells):
            cell = cell.strip()
            if cell.lower() in _MISSING:
                continue
            try:
                out[k] = float(cell)
            except ValueError:
                raise ExportError(self.path, self.lines[k],
                                  f"column {self.columns[col]}: {cell!r} is not a number") from None
        return out


def _delimiter(line: str) -> str:
    """The separator of a column-name line: tab, then semicolon, then comma."""
    for d in ("\t", ";", ","):
        if d in line:
            return d
    return ","


def _preamble_pair(line: str, delimiter: str) -> tuple[str, str] | None:
    """(key, value) of one preamble line, or None when the line is not one."""
    s = line.strip()
    if s.startswith("//"):
        key, colon, value = s[2:].partition(":")
        return (key.strip(), value.strip()) if colon else None
    cells = [c.strip() for c in s.split(delimiter)]
    if len(cells) >= 2 and cells[0].endswith(":"):
        value = next((c for c in cells[1:] if c), "")
        return cells[0][:-1].strip(), value
    return None


def _is_preamble(line: str, delimiter: str) -> bool:
    """Whether a line belongs to the preamble: a ``//`` comment, ``sep=``, a ``Key:,``
    line, or the DOT app's copyright line."""
    s = line.strip()
    low = s.lower()
    return (s.startswith("//") or low.startswith("sep=") or "\u00a9" in s or "b. v." in low
            or _preamble_pair(s, delimiter) is not None)


def _lines(path: Path, limit: int | None) -> list[str]:
    """The file's lines, or only its first ``limit`` (enough to tell its layout)."""
    with open(path, encoding="utf-8-sig", errors="replace", newline="") as f:
        if limit is None:
            return f.read().splitlines()
        return [line.rstrip("\r\n") for _, line in zip(range(limit), f)]


@dataclass
class _Preamble:
    end: int = 0  # index of the first line after it
    pairs: dict[str, str] = field(default_factory=dict)
    comments: bool = False
    delimiter: str = ","
    sep_line: bool = False


def _scan_preamble(lines: list[str]) -> _Preamble:
    """Where the preamble ends and what it says (``Table`` for the fields)."""
    pre = _Preamble()
    for i, line in enumerate(lines):
        s = line.strip()
        if s.lower().startswith("sep=") and len(s) > 4:
            pre.delimiter, pre.sep_line = s[4], True
        elif s and not _is_preamble(s, pre.delimiter):
            pre.end = i
            return pre
        elif s:
            pre.comments = pre.comments or s.startswith("//")
            pair = _preamble_pair(s, pre.delimiter)
            if pair and pair[0]:
                pre.pairs.setdefault(norm_key(pair[0]), pair[1])
    pre.end = len(lines)
    return pre


def read_table(path: str | os.PathLike, limit: int | None = None) -> Table:
    """Split an export into preamble, column names and data rows (module docstring); with
    ``limit``, from its first ``limit`` lines only. Raises ExportError for an empty file or
    one with no column-name line."""
    path = Path(path)
    lines = _lines(path, limit)
    if not any(s.strip() for s in lines):
        raise ExportError(path, 1, "empty file")
    pre = _scan_preamble(lines)
    i = pre.end
    if i == len(lines):
        raise ExportError(path, len(lines), "no column header after the preamble")
    delimiter = pre.delimiter if pre.sep_line else _delimiter(lines[i])
    table = Table(path, pre.pairs, pre.comments, pre.sep_line, [c.strip() for c in lines[i].split(delimiter)], i + 1,
                  delimiter=delimiter)
    for n, line in enumerate(lines[i + 1:], start=i + 2):
        if line.strip():
            table.rows.append(line.split(delimiter))
            table.lines.append(n)
    table.decimal_comma = delimiter != "," and any("," in line for line in lines[i + 1:i + 11])
    return table


__all__ = ["ExportError", "Table", "norm_key", "read_table"]
