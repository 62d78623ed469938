"""Opening a file as a recording: the checks that make anything else a one-line
``RecordingError``, the wait for a writer still laying out its file, and the root's
attributes read so that a damaged file cannot hang the caller (HDF5 can loop forever in a
damaged global heap)."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.recording.format import FORMAT, VERSION, fault_text
from app.recording.libhdf5 import open_swmr


class RecordingError(ValueError):
    """A file imucap cannot take for a recording; the message is one line naming the file
    and the problem, which the CLI prints as it is."""

    def __init__(self, path: str | os.PathLike, problem: str) -> None:
        super().__init__(f"{path}: {problem}")
        self.path = Path(path)
        self.problem = problem


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def open_recording(path: str | os.PathLike) -> h5py.File:
    """Open a recording read-only, also one whose writer was killed or is still writing
    (SWMR read) or one cut short: HDF5 refuses a file shorter than its superblock says,
    but what it still holds is worth reading. Anything that is not a recording this
    version can read is a ``RecordingError``."""
    return open_recording_header(path)[0]


# A Recorder holds a new file locked while it lays out its datasets, until it switches to
# SWMR mode (milliseconds); a reader that comes in between waits this long for it
LOCKED_WAIT_S = 2.0


def _is_locked(exc: OSError) -> bool:
    return getattr(exc, "errno", None) in (errno.EAGAIN, errno.EWOULDBLOCK) or \
        "Resource temporarily unavailable" in str(exc) or "unable to lock file" in str(exc)


def open_recording_header(path: str | os.PathLike) -> tuple[h5py.File, dict[str, Any]]:
    """``open_recording``, and the root's attributes read safely (``root_attributes``)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"recording {path} not found")
    if path.is_dir():
        raise RecordingError(path, "a folder, not a recording")
    try:
        with open(path, "rb") as fh:
            fh.read(8)
    except OSError as exc:
        raise RecordingError(path, f"cannot be read ({fault_text(exc)})") from None
    try:
        f = h5py.File(path, "r")
    except OSError:
        if not h5py.is_hdf5(path):
            raise RecordingError(path, "truncated or not an HDF5 file") from None
        deadline = time.monotonic() + LOCKED_WAIT_S
        while True:
            try:
                f = open_swmr(path)
                break
            except OSError as exc:
                if not _is_locked(exc):
                    raise RecordingError(path, f"truncated or not an HDF5 file ({fault_text(exc)})") from None
                if time.monotonic() > deadline:
                    raise RecordingError(path, "locked by the program writing it, which has not made it readable "
                                               "yet; try again in a moment") from None
                time.sleep(0.05)
    try:
        attrs = root_attributes(f, path)
        check_header(attrs, path)
    except BaseException:
        f.close()
        raise
    return f, attrs



# HDF5 (2.0) can loop forever deserializing a damaged global heap, where variable-length
# strings live (a fuzzed recording hung it in H5HG__cache_heap_deserialize): such values are
# read by a child process that is given this long
HEAP_READ_TIMEOUT_S = 10.0

_ATTRS_CHILD = r"""
import json, sys
import h5py, numpy as np
path = sys.argv[1]
try:
    f = h5py.File(path, "r")
except OSError:
    f = h5py.File(path, "r", libver="latest", swmr=True)
def plain(v):
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.ndarray):
        return [plain(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        return plain(v.item())
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v if isinstance(v, (str, int, float, bool)) or v is None else str(v)
print(json.dumps({k: plain(v) for k, v in f.attrs.items()}))
"""


def in_heap(t: Any) -> bool:
    """Whether values of HDF5 type ``t`` are stored in the global heap."""
    if isinstance(t, h5py.h5t.TypeStringID):
        return bool(t.is_variable_str())
    if isinstance(t, h5py.h5t.TypeVlenID):
        return True
    if isinstance(t, h5py.h5t.TypeCompoundID):
        return any(in_heap(t.get_member_type(i)) for i in range(t.get_nmembers()))
    if isinstance(t, h5py.h5t.TypeArrayID):
        return in_heap(t.get_super())
    return False


def fixed_dataset(f: h5py.File, name: str, path: str | os.PathLike) -> h5py.Dataset:
    """``f[name]``, refused when its values would be read from the global heap (see
    ``root_attributes``): not what the Recorder writes, and a damaged heap can hang HDF5."""
    ds = f[name]
    if not isinstance(ds, h5py.Dataset) or in_heap(ds.id.get_type()):
        raise RecordingError(Path(path), f"damaged: {name} is not the dataset a recording holds")
    return ds


def _decoded(v: Any) -> Any:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    if isinstance(v, np.generic):
        return _decoded(v.item())
    return v


def root_attributes(f: h5py.File, path: str | os.PathLike) -> dict[str, Any]:
    """The root's attributes, strings decoded. The Recorder writes fixed-length strings;
    recordings from before that (and foreign files) hold variable-length ones in the global
    heap, read by a child process with ``HEAP_READ_TIMEOUT_S``: a damaged heap costs that
    wait and a one-line error, never a hang of the caller (the window lists recordings)."""
    path = Path(path)
    try:
        names = list(f.attrs)
        heap = any(in_heap(h5py.h5a.open(f.id, n.encode()).get_type()) for n in names)
        if not heap:
            return {n: _decoded(f.attrs[n]) for n in names}
    except (OSError, RuntimeError, KeyError, ValueError, TypeError):
        raise RecordingError(path, "truncated or not an HDF5 file (its header cannot be read)") from None
    try:
        out = subprocess.run([sys.executable, "-c", _ATTRS_CHILD, os.fspath(path)], capture_output=True, text=True,
                             timeout=HEAP_READ_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        raise RecordingError(path, f"damaged: its header cannot be read (HDF5 did not return within "
                                   f"{HEAP_READ_TIMEOUT_S:g} s)") from None
    if out.returncode != 0:
        last = (out.stderr.strip().splitlines() or ["no reason given"])[-1]
        raise RecordingError(path, f"truncated or not an HDF5 file (its header cannot be read: {last})")
    try:
        attrs = json.loads(out.stdout)
    except ValueError:
        raise RecordingError(path, "damaged: its header cannot be read") from None
    return attrs if isinstance(attrs, dict) else {}


def check_header(attrs: dict[str, Any], path: Path) -> None:
    fmt = attrs.get("format")
    version = attrs.get("version")
    if fmt != FORMAT:
        if fmt == "imucap-motion":
            raise RecordingError(path, "an exported motion (imucap export/replay --out), not a session recording")
        what = f"format {fmt!r}" if fmt is not None else "no 'format' attribute"
        raise RecordingError(path, f"an HDF5 file but not an imucap session recording ({what})")
    try:
        v = int(version)
    except (TypeError, ValueError):
        raise RecordingError(path, f"damaged: format version {version!r} is not a number") from None
    if v > VERSION:
        raise RecordingError(path, f"written by a newer imucap (format version {v}); update imucap")
