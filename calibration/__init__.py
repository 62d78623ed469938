"""Sensor-to-world and sensor-to-bone calibration (imports only ``inference``).

``core``: the maths, stillness checks and the JSON-persisted ``Calibration``;
``live``: the two still windows collected from a stream; ``protocol``: the protocol a
subject follows and a simulator of it.
"""

from .core import (
    Calibration,
    CalibrationError,
    Stillness,
    StillnessLimits,
    calibrate,
    calibrate_tpose,
    calibrate_world,
    identity_calibration,
    mean_rotation,
    stillness,
)
from .live import CalibrationSchedule, Calibrator
from .protocol import Protocol, session_motion, synthesize_session

__all__ = [
    "Calibration", "CalibrationError", "Stillness", "StillnessLimits", "calibrate", "calibrate_tpose",
    "calibrate_world", "identity_calibration", "mean_rotation", "stillness", "CalibrationSchedule", "Calibrator",
    "Protocol", "session_motion", "synthesize_session",
]
