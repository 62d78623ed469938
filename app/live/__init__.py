"""The live path in the app: hub frames -> calibration -> resampler -> poser -> sinks
(``pipeline``), run on its own threads (``runner``), fed by a hub or by other frame sources
(``sources``). ``docs/design.md`` draws the whole path."""

from app.live.pipeline import (
    POSE_SKIPPED_EVENT,
    RECALIBRATION_EVENT,
    CallbackSink,
    LivePose,
    Pipeline,
    PipelineStats,
    Sink,
    stride_text,
)
from app.live.runner import LivePipeline, close_sink
from app.live.sources import FrameSource, ListSource, frames_from_signals

__all__ = [
    "POSE_SKIPPED_EVENT", "RECALIBRATION_EVENT", "CallbackSink", "FrameSource", "ListSource", "LivePipeline",
    "LivePose", "Pipeline", "PipelineStats", "Sink", "close_sink", "frames_from_signals", "stride_text",
]
