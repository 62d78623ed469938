"""Session recording to HDF5, written incrementally so a crash loses at most one second.

Layout (``FORMAT`` / ``VERSION`` in the root attributes, with ``metadata``: a JSON object
with the sensor configuration, model, steps, app version, ...):

    /raw/t (N,) float64 session time of each 60 Hz hub frame, /raw/index (N,) int64
    /raw/<site>/quat (N,4) (w,x,y,z) R_GS as the device sent it, free_acc (N,3) in the
        device's reference frame, acc (N,3) specific force, gyro (N,3), present (N,) bool
        -- raw, *before* calibration, so a replay can recalibrate
    /raw/insoles/force (N,2), contacts (N,4) bool, present (N,) bool
    /calibration/t (K,), R_WG (K,S,3,3), R_SB (K,S,3,3), acc_offset (K,S,3), valid (K,S),
        residual_world_deg, residual_tpose_deg (K,S): every calibration that took effect
        meta (K,) JSON: the protocol and the quality report of each calibration
    /recon/t (M,), index (M,), rot (M,24,4) quaternions R_WB, root (M,3), joints (M,24,3),
        contacts (M,4) bool, contact_prob (M,4), observed_sites (M,13) bool, insoles (M,),
        latency_ms (M,) (NaN when not live), spread_deg (M,24) and root_spread_m (M,): the
        poser's per-segment confidence (inference/poser/confidence.py; NaN when off)
    /events/t (E,), kind (E,), detail (E,): what happened during the session, in order:
        markers (detail = label), notes, devices lost and back, recording errors, and
        ``recalibration`` where a dropped calibration stopped the posing (a replay pauses
        there until the next calibration)

Strings are fixed-length UTF-8 (JSON in ``meta``): SWMR appends to fixed-size types only.

Why it survives ``kill -9``: every dataset is created up front (chunked, resizable), then
the file switches to SWMR mode, where HDF5 orders its writes so that the file on disk is
always a consistent snapshot of the last ``flush``. Data is buffered in memory and
appended + flushed every ``flush_interval`` s. A file whose writer died is read with
``swmr=True`` (``open_recording`` does that by itself), which is also how a second
process can follow a recording live.

Why every chunk carries a Fletcher32 checksum: a session cannot be recorded again, and
without one a flipped block of bytes on a failing disk or a bad copy reads as motion.
``read_recording`` verifies each chunk, skips the ones that fail, keeps all the rest and
lists what it skipped in ``Recording.damage``. Unwritten rows read back as NaN times
(the datasets' fill value), so a file cut short by a full disk cannot pass zeros off as
data either. Files written before the checksums read as they always did.

Why a write error does not raise: the recorder is one sink among the live view's; a full
disk or a vanished folder must stop the recording, loudly (``Recorder.error``,
``on_error``), not the session.

Where each part lives: ``format`` (names, versions, the datasets and their types),
``writer`` (``Recorder``), ``header`` (opening a file as a recording, ``RecordingError``,
the root's attributes), ``reader`` (``read_recording``, ``Recording`` and its damage
report), ``libhdf5`` (the SWMR retry setting h5py does not expose).
"""

from app.recording.format import FORMAT, VERSION
from app.recording.header import (
    RecordingError,
    fixed_dataset,
    open_recording,
    open_recording_header,
    root_attributes,
)
from app.recording.reader import Recording, read_recording
from app.recording.writer import Recorder

__all__ = ["FORMAT", "VERSION", "Recorder", "Recording", "RecordingError", "fixed_dataset", "open_recording",
           "open_recording_header", "read_recording", "root_attributes"]
