"""Optional parts of imucap and the packages they need: the extras of ``pyproject.toml``.

The core install captures, replays and exports (serial, CAN, HID and UDP devices, the
window, the model). A part that needs more imports it through ``need``, at the moment it
is used, so a missing package is one line naming the extra to install, never a traceback
at start-up:

    imucap batch: error: imucap batch needs pyarrow, which is not installed: pip install 'imucap[batch]'
"""

from __future__ import annotations

import importlib
from types import ModuleType

EXTRAS = {
    "distributed": "batch",  # imucap batch --cluster (Dask)
    "pyarrow": "batch",  # imucap batch's summary.parquet
    "bleak": "ble",  # Movella DOT over Bluetooth LE
    "ximu3": "ximu3",  # x-io's x-IMU3 connection and parser
    "ezc3d": "gaitlab",  # imucap export NAME.c3d
    "c3d": "gaitlab",  # a C3D reference in imucap validate
}


class MissingExtra(ModuleNotFoundError):
    """An optional package is not installed; the message says which extra brings it."""


def need(module: str, what: str) -> ModuleType:
    """``module`` imported, or MissingExtra naming ``what`` needs it and the extra to install."""
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        top = module.split(".")[0]
        if exc.name is not None and exc.name.split(".")[0] != top:
            raise  # the package is there but broken: its own error says more
        extra = EXTRAS.get(top, "all")
        raise MissingExtra(f"{what} needs {top}, which is not installed: pip install 'imucap[{extra}]'",
                           name=top) from None
