"""``imucap batch`` with faults put in on purpose, for tests/app/batch/test_batch_faults.py.

Run as a script, it is ``imucap``; its top level also runs in every worker the local pool
spawns (multiprocessing imports the main script there as ``__mp_main__``), so the faults
reach the workers:

- ``IMUCAP_TEST_SEGFAULT=GLOB``: a recording whose name matches crashes its worker natively
  (a read of address 0 through ctypes: SIGSEGV), after it started the replay;
- ``IMUCAP_TEST_FAIL=GLOB``: a recording whose name matches fails with an OSError (a fault
  of the moment: the next run without it must do the recording);
- ``IMUCAP_TEST_VERSION=V``: imucap says it is version V (an upgrade).
"""

from __future__ import annotations

import ctypes
import fnmatch
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[3]))

import app  # noqa: E402
import app.batch.task as task  # noqa: E402

if os.environ.get("IMUCAP_TEST_VERSION"):
    app.APP_VERSION = os.environ["IMUCAP_TEST_VERSION"]

_run = task._run


def _faulty_run(t):
    name = Path(t.recording).name
    if fnmatch.fnmatch(name, os.environ.get("IMUCAP_TEST_FAIL", "\0")):
        raise OSError(f"{name}: the file server did not answer (a fault put in by the test)")
    if fnmatch.fnmatch(name, os.environ.get("IMUCAP_TEST_SEGFAULT", "\0")):
        ctypes.string_at(0)  # a native crash: SIGSEGV, no Python exception
    return _run(t)


task._run = _faulty_run

if __name__ == "__main__":
    from app.cli.main import main

    sys.exit(main())
