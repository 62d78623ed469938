"""Xsens exports on disk: MT Manager text/CSV exports (``mtmanager``) and Xsens DOT CSV
exports (``dot``), one file per sensor, read into the ``DeviceLog`` every log reader
returns, so ``imucap import`` treats them as it treats an x-IMU3 log."""

from drivers.xsens_export.dot import DOT, read_dot
from drivers.xsens_export.mtmanager import MTMANAGER, read_mtmanager
from drivers.xsens_export.reader import LAYOUTS, detect_layout, layout_of, read_export, read_exports
from drivers.xsens_export.samples import G, Layout
from drivers.xsens_export.table import ExportError

__all__ = ["DOT", "MTMANAGER", "LAYOUTS", "ExportError", "G", "Layout", "detect_layout", "layout_of",
           "read_dot", "read_export", "read_exports", "read_mtmanager"]
