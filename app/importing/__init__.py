"""Other systems' logged sessions as imucap session recordings (``imucap import``, ``app/cli/importing.py``):
which site each sensor is on (``names``), the devices on the 60 Hz grid (``grid``), one log
calibrated, written and reconstructed (``log``), and a session's trials, a walk calibrated
from another trial (``trials``)."""

from .grid import RATE, gyro_from_orientation
from .log import FORMATS, SOURCE_TITLES, Imported, import_mvnx, import_paths, import_sources, import_ximu3, import_xsens
from .names import BONES, DEVICE_SITES, Source, site_for

__all__ = ["BONES", "DEVICE_SITES", "FORMATS", "Imported", "RATE", "SOURCE_TITLES", "Source", "gyro_from_orientation",
           "import_mvnx", "import_paths", "import_sources", "import_xsens", "import_ximu3", "site_for"]
