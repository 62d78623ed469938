"""Reading motion text files that may be gzipped and may not be UTF-8 (HDM05's AMC header
holds a Latin-1 byte): every loader goes through here so they agree on it."""

from __future__ import annotations

import gzip
from pathlib import Path

from inference.body.motion import MotionFormatError


def read_text_lines(path: str | Path) -> list[str]:
    path = Path(path)
    try:
        raw = gzip.open(path, "rb").read() if path.name.endswith(".gz") else path.read_bytes()
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such motion file") from None
    except (OSError, EOFError) as exc:  # truncated gzip stream, bad gzip header
        raise MotionFormatError(str(path), f"cannot read compressed data ({exc})") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.splitlines()
