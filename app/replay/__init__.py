"""Offline replay of a recorded session (``run``: the recording's raw stream through the live
``Pipeline`` with any model and sensor subset) and how a replay compares with the live
reconstruction, a held-out sensor or a simulator's truth (``compare``). ``from app.replay
import ...`` is the public way in."""

from app.replay.compare import (
    MATCH_TOLERANCE_S,
    SAME_FRAME_S,
    compare_to_recorded,
    held_out_errors,
    match_times,
    truth_errors,
)
from app.replay.run import (
    ReplayPoser,
    ReplayResult,
    ReplaySettings,
    build_replay_poser,
    live_skipped_times,
    poser_metadata,
    recorded_model,
    recording_has_insoles,
    replay_model,
    replay_recording,
    resolve_insoles,
    resolve_sensors,
)
from inference.body.skeleton import SITES

__all__ = [
    "MATCH_TOLERANCE_S", "SAME_FRAME_S", "SITES", "ReplayPoser", "ReplayResult", "ReplaySettings",
    "build_replay_poser", "compare_to_recorded", "held_out_errors", "live_skipped_times", "match_times",
    "poser_metadata", "recorded_model", "recording_has_insoles", "replay_model", "replay_recording",
    "resolve_insoles", "resolve_sensors",
    "truth_errors",
]
