"""The recording format: its name and version, the datasets each group holds (name, shape
of a row, type), and the few rules every writer and reader of it shares (how strings are
cut to their fields, what a row nobody wrote reads as, how a disk fault reads in one line).
``docs/recording_format.md`` is the format for people; this is it for the code."""

from __future__ import annotations

import re
from typing import Any

import h5py
import numpy as np

from inference.body.skeleton import N_CONTACTS, N_SEGMENTS, N_SITES

FORMAT = "imucap-session"
VERSION = 1
CAL_META = "S8192"
EVENT_KIND = "S32"
EVENT_DETAIL = "S512"

# (name, per-row shape, dtype) of every dataset; the reader needs them to stand in for one
# it cannot open
SITE_FIELDS = (("quat", (4,), "f4"), ("free_acc", (3,), "f4"), ("acc", (3,), "f4"), ("gyro", (3,), "f4"),
               ("present", (), "?"))
# a tracked device's site (a VR rig's) also keeps its position (m, in the rig's own frame);
# only those sites have it, and recordings from before positions were kept have none
POSITION_FIELD = ("position", (3,), "f4")
INSOLE_FIELDS = (("force", (2,), "f4"), ("contacts", (N_CONTACTS,), "?"), ("present", (), "?"))
RECON_FIELDS = (("t", (), "f8"), ("index", (), "i8"), ("rot", (N_SEGMENTS, 4), "f4"), ("root", (3,), "f4"),
                ("joints", (N_SEGMENTS, 3), "f4"), ("contacts", (N_CONTACTS,), "?"),
                ("contact_prob", (N_CONTACTS,), "f4"), ("observed_sites", (N_SITES,), "?"), ("insoles", (), "?"),
                ("latency_ms", (), "f4"), ("spread_deg", (N_SEGMENTS,), "f4"), ("root_spread_m", (), "f4"))
# recon fields recordings from before they existed lack (read back as NaN)
RECON_NEWER = ("spread_deg", "root_spread_m")
EVENT_FIELDS = (("t", (), "f8"), ("kind", (), EVENT_KIND), ("detail", (), EVENT_DETAIL))


def calibration_fields(n_sites: int) -> tuple[tuple[str, tuple[int, ...], str], ...]:
    S = n_sites
    return (("t", (), "f8"), ("R_WG", (S, 3, 3), "f8"), ("R_SB", (S, 3, 3), "f8"), ("acc_offset", (S, 3), "f8"),
            ("valid", (S,), "?"), ("residual_world_deg", (S,), "f8"), ("residual_tpose_deg", (S,), "f8"),
            ("meta", (), CAL_META))


def fit_text(text: str, dtype: str) -> bytes:
    """UTF-8 bytes cut to the field's size (on a character boundary)."""
    limit = int(dtype[1:])
    raw = text.encode("utf-8")
    return raw if len(raw) <= limit else raw[:limit].decode("utf-8", "ignore").encode("utf-8")


def fill_value(dtype: Any) -> Any:
    """What a row nobody wrote reads as: NaN times and values, index -1, False flags, so a
    reader can tell a row that never reached the disk from a real one (HDF5's default,
    zero, would pass for time 0 and a motionless sensor)."""
    kind = np.dtype(dtype).kind
    return np.nan if kind == "f" else -1 if kind in "iu" else False if kind == "b" else b""


_ERRNO_WORDS = {28: "the disk is full", 27: "the file size limit is reached",
                122: "the disk quota is used up", 30: "the disk became read-only", 13: "permission denied",
                5: "the disk failed (input/output error)", 2: "the file or its folder is gone"}


def fault_text(exc: BaseException) -> str:
    """One short line out of an OSError or HDF5's multi-part message (which carries the
    system's errno and text buried in a paragraph)."""
    text = str(exc.args[0]) if isinstance(exc, KeyError) and exc.args else str(exc)
    num = exc.errno if isinstance(exc, OSError) and exc.errno else None
    m = re.search(r"errno = (\d+)", text)
    if num is None and m:
        num = int(m.group(1))
    m = re.search(r"error message = '([^']*)'", text)
    detail = m.group(1) if m else (exc.strerror if isinstance(exc, OSError) and exc.strerror else None)
    if detail is None:
        detail = " ".join(text.split("\n")[0].split())[:200] or type(exc).__name__
    word = _ERRNO_WORDS.get(num) if num is not None else None
    return f"{word} ({detail})" if word and word.lower() not in detail.lower() else detail



def fixed_attr(f: h5py.File, name: str, text: str) -> None:
    """A string attribute of fixed length (UTF-8): it lives in the object header, where a
    variable-length one lives in HDF5's global heap (see ``root_attributes``)."""
    b = text.encode("utf-8")
    f.attrs.create(name, np.array(b, dtype=h5py.string_dtype("utf-8", max(len(b), 1))))



HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
