"""Where each table header and key of a setup file's TOML text is (``Locator``), so that
an error in it names the line: ``tomllib`` reports values, not lines."""

from __future__ import annotations

import json
import re

_KEY_PART = r'(?:[A-Za-z0-9_-]+|"(?:[^"\\]|\\.)*"|\'[^\']*\')'
_KEY_PATH = re.compile(rf"\s*({_KEY_PART}(?:\s*\.\s*{_KEY_PART})*)\s*")
_PART = re.compile(_KEY_PART)


def _key_parts(path: str) -> tuple[str, ...]:
    parts = []
    for token in _PART.findall(path):
        if token.startswith('"'):
            try:
                token = json.loads(token)
            except ValueError:
                token = token[1:-1]
        elif token.startswith("'"):
            token = token[1:-1]
        parts.append(token)
    return tuple(parts)


class Locator:
    """Where each table header and key of a TOML text is: tomllib reports values, not
    lines. A line scanner that knows just enough TOML (quoted keys, dotted keys, comments,
    strings, arrays spanning lines, multi-line strings) to never take a value for a key."""

    def __init__(self, text: str) -> None:
        self.headers: dict[tuple[str, ...], list[int]] = {}
        self.keys: dict[tuple[tuple[str, ...], str], list[int]] = {}
        self.first: dict[tuple[tuple[str, ...], str], int] = {}
        table: tuple[str, ...] = ()
        scan = _ValueScanner()
        for n, raw in enumerate(text.splitlines(), 1):
            if scan.inside():
                scan.feed(raw)
                continue
            header = self._header(raw)
            if header is not None:
                table, is_array, rest = header
                if not is_array:
                    self.headers.setdefault(table, []).append(n)
                scan.feed(rest)
                continue
            m = _KEY_PATH.match(raw)
            if m and raw[m.end():].startswith("="):
                parts = _key_parts(m.group(1))
                for i in range(len(parts)):
                    self.first.setdefault((table + parts[:i], parts[i]), n)
                self.keys.setdefault((table + parts[:-1], parts[-1]), []).append(n)
                scan.feed(raw[m.end() + 1:])
            else:
                scan.feed(raw)

    @staticmethod
    def _header(raw: str) -> tuple[tuple[str, ...], bool, str] | None:
        s = raw.lstrip()
        if not s.startswith("["):
            return None
        is_array = s.startswith("[[")
        m = _KEY_PATH.match(s, 2 if is_array else 1)
        close = "]]" if is_array else "]"
        if not m or not s[m.end():].startswith(close):
            return None
        return _key_parts(m.group(1)), is_array, s[m.end() + len(close):]

    def line_of(self, table: tuple[str, ...], key: str | None = None, sub: str | None = None) -> int | None:
        """The line of ``key`` in ``table`` (of the table header when key is None), falling
        back to the nearest enclosing thing that has a line. ``sub`` (a key inside an
        inline table) shares its key's line, since inline tables are one line in TOML."""
        if key is not None:
            line = self.first.get((table, key))
            if line is None and self.headers.get(table + (key,)):
                line = self.headers[table + (key,)][0]
            if line is not None:
                return line
        headers = self.headers.get(table)
        if headers:
            return headers[0]
        if len(table) == 1:
            return self.first.get(((), table[0]))
        return None

    def duplicates(self) -> list[tuple[tuple[str, ...], str | None, list[int]]]:
        found: list[tuple[tuple[str, ...], str | None, list[int]]] = [
            (t, None, lines) for t, lines in self.headers.items() if len(lines) > 1]
        found += [(t, k, lines) for (t, k), lines in self.keys.items() if len(lines) > 1]
        return sorted(found, key=lambda d: d[2][1])

    def duplicate_at(self, line: int) -> tuple[tuple[str, ...], str | None, list[int]] | None:
        for d in self.duplicates():
            if line in d[2][1:]:
                return d
        return None

    def first_duplicate(self) -> tuple[tuple[str, ...], str | None, list[int]] | None:
        dups = self.duplicates()
        return dups[0] if dups else None


class _ValueScanner:
    """Follows strings, comments and brackets across lines, so the locator knows when a
    line starts inside a multi-line string or array (where nothing is a key)."""

    def __init__(self) -> None:
        self.multiline: str | None = None
        self.depth = 0

    def inside(self) -> bool:
        return self.multiline is not None or self.depth > 0

    def feed(self, s: str) -> None:
        i = 0
        while i < len(s):
            if self.multiline is not None:
                j = s.find(self.multiline, i)
                if j < 0:
                    return
                i, self.multiline = j + 3, None
                continue
            c = s[i]
            if c == "#":
                return
            if s.startswith('"""', i) or s.startswith("'''", i):
                self.multiline, i = s[i:i + 3], i + 3
                continue
            if c in "\"'":
                i = self._string_end(s, i)
                continue
            if c in "[{":
                self.depth += 1
            elif c in "]}":
                self.depth = max(0, self.depth - 1)
            i += 1

    @staticmethod
    def _string_end(s: str, i: int) -> int:
        quote, j = s[i], i + 1
        while j < len(s):
            if s[j] == "\\" and quote == '"':
                j += 2
                continue
            if s[j] == quote:
                return j + 1
            j += 1
        return j
