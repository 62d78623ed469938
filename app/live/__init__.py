"""The live path in the app: hub frames -> calibration and the optional inputs into one typed
live frame (``frame``) -> resampler -> poser -> sinks (``pipeline``), run on its own threads
(``runner``), fed by a hub or by other frame sources (``sources``); beside it the latency
modes (``latency``), the model and thread choice (``model_choice``) and the gait sink
(``gait``). ``docs/design.md`` draws the whole path."""

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
