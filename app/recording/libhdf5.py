"""The one setting of libhdf5 that h5py does not expose, set through ctypes on the very
library h5py runs on: how often a SWMR read re-reads metadata that fails its checksum."""

from __future__ import annotations

import ctypes
import functools
import os
import re
from pathlib import Path

import h5py

# HDF5 re-reads metadata that fails its checksum up to 100 times in SWMR mode, doubling a
# sleep each time, in case a live writer is half way through it: on a damaged or cut file
# that is a hang of hours. This many tries still give a live writer ~20 ms.
SWMR_READ_ATTEMPTS = 24


@functools.cache
def hdf5_library() -> ctypes.CDLL | None:
    """The HDF5 library h5py already runs on (the very instance: property lists are ids
    into it), for the one setting h5py does not expose; None when it cannot be found.
    Looked up once: scanning the process's memory map cost ~8 ms per damaged file opened."""
    candidates: list[str] = []
    try:
        with open("/proc/self/maps") as fh:
            candidates += sorted({line.split()[-1] for line in fh
                                  if re.search(r"/libhdf5[-.][^/]*$", line.strip())})
    except OSError:
        pass
    base = Path(h5py.__file__).parent
    for folder in (base.parent / "h5py.libs", base / ".dylibs"):
        candidates += sorted(str(c) for c in folder.glob("libhdf5[-.]*"))
    for c in candidates:
        try:
            lib = ctypes.CDLL(c, mode=getattr(os, "RTLD_NOLOAD", 0))
        except OSError:
            continue
        if hasattr(lib, "H5Pset_metadata_read_attempts"):
            return lib
    return None


def open_swmr(path: Path) -> h5py.File:
    """SWMR read (a writer killed or still at work, or a file cut short), with few retries."""
    lib = hdf5_library()
    if lib is None:
        return h5py.File(path, "r", libver="latest", swmr=True)
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fclose_degree(h5py.h5f.CLOSE_STRONG)
    lib.H5Pset_metadata_read_attempts.argtypes = (ctypes.c_int64, ctypes.c_uint)
    if lib.H5Pset_metadata_read_attempts(fapl.id, SWMR_READ_ATTEMPTS) < 0:
        return h5py.File(path, "r", libver="latest", swmr=True)
    fid = h5py.h5f.open(os.fsencode(path), h5py.h5f.ACC_RDONLY | h5py.h5f.ACC_SWMR_READ, fapl=fapl)
    return h5py.File(fid)
