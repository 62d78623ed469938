"""Sensor-to-world and sensor-to-bone calibration (imports only ``inference``).

``core``: the maths, stillness checks and the JSON-persisted ``Calibration``;
``walk``: the table-free calibration (N-pose, a walk forward, stand) for sensors that do
not share a heading reference; ``guided``: the steps as a state machine driven by the
stream (prompts, countdown, stillness detection, redo); ``quality``: the per-sensor report
and its warnings; ``live``: the two still windows of a fixed schedule (the demo);
``protocol``: the protocols a subject follows and simulators of them.
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
from .guided import PROTOCOL_NAMES, GuidedCalibration
from .live import CalibrationSchedule, Calibrator
from .protocol import Protocol, WalkProtocol, session_motion, synthesize_session, synthesize_walk_session
from .quality import QualityReport

__all__ = [
    "Calibration", "CalibrationError", "Stillness", "StillnessLimits", "calibrate", "calibrate_tpose",
    "calibrate_world", "identity_calibration", "mean_rotation", "stillness", "CalibrationSchedule", "Calibrator",
    "Protocol", "session_motion", "synthesize_session", "WalkProtocol", "synthesize_walk_session",
    "GuidedCalibration", "PROTOCOL_NAMES", "QualityReport",
]
