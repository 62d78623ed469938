"""A recording's poses shown with k frames of the sensors after each: the answer-lag pass.

A live pose must be the newest frame's, and the newest frame of a window has only the
sensors' past. On the real logs the inferred thighs trail their sensors by 150-200 ms
(docs/real_signals.md, "The thighs stage by stage"): the thigh leads the shank in a step, so
the shanks' next few frames say where the thigh went. An import, a replay or a report has no
need to answer at once: it can show each frame as the window k frames later answered it.

The poser does the live work as always (the newest frame's answer goes into the history, the
root and the contacts follow it) and, with ``Poser(answer_lag=k)``, also hands each frame the
window's answers for the k frames before it (``PoseFrame.earlier_rot``). ``lagged_frames``
then swaps each frame's inferred segments for the answer of the step k frames later, or of the
latest step that has it where the poses end or the history was reset, and low-passes them
forward and backward (a pose that has its future needs no causal filter and its lag). Measured
segments stay as measured; the root path stays the live one. The leg segments below a leg's lowest
worn sensor (the feet below worn shanks) keep the live answer: later frames of the sensors above them
say little of them, and their late answers swing less than the truth (the gait check's ankle range
off by 15.8 deg late against 9.6 live with pelvis + shanks; docs/real_signals.md, "Answering late").
A model trained to be best k frames back (``TrainConfig.answer_lag``) says so in its file (meta
``answer_lag``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from inference.body import frame_kernels as fk
from inference.body.body import Body
from inference.body.rotations import matrix_to_rot6d_np
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.features.layout import SL_ROT
from inference.signals.resample import FPS_MODEL

# frames an import or a replay of one waits before showing a frame: 200 ms at 20 Hz. Four
# frames back the shipped model's thighs and pelvis on the real logs are 1-3 deg nearer their
# own sensors than the newest frame's, dg and the CMU subjects no worse (docs/real_signals.md,
# "Answering late")
OFFLINE_ANSWER_LAG = 4
# the late poses' low-pass (Hz, zero phase): the cut-off gait kinematics are commonly filtered at
# (Winter, Biomechanics and Motor Control of Human Movement); not tuned on the checks here
SMOOTH_HZ = 6.0


def lagged_frames(frames: Sequence, body: Body, smooth_hz: float | None = SMOOTH_HZ,
                  live_below: bool = True) -> list:
    """``frames`` (``PoseFrame``, in order) with each frame's inferred segments taken from the
    latest later step, at most k frames on, whose window held it (the same history: index
    counting on without a reset), then low-passed without phase lag at ``smooth_hz`` over each
    run of frames of one history (``zero_phase``; None: not); with ``live_below`` the segments
    ``below_worn`` keep the frame's live answer. Frames without ``earlier_rot`` come back as
    they are."""
    frames = list(frames)
    if not frames or all(f.earlier_rot is None for f in frames):
        return frames
    n = len(frames)
    rots = []
    for j, f in enumerate(frames):
        best = None
        for p in range(j + 1, n):
            g = frames[p]
            d = p - j
            if g.earlier_rot is None or g.index != f.index + d or d > len(g.earlier_rot):
                break
            best = (g, d)
        rots.append(f.rot if best is None else best[0].earlier_rot[len(best[0].earlier_rot) - best[1]])
    R_all = np.array(rots, dtype=np.float64)
    if smooth_hz is not None:
        start = 0
        for j in range(1, n + 1):  # each run of one history (the index counts on by one)
            if j == n or frames[j].index != frames[j - 1].index + 1:
                R_all[start:j] = zero_phase(R_all[start:j], smooth_hz)
                start = j
    kin = fk.Kinematics(body.offsets)
    out = []
    for f, R in zip(frames, R_all):
        measured = f.observed[SL_ROT].reshape(N_SEGMENTS, 6).all(axis=-1)
        keep = measured | below_worn(measured) if live_below else measured
        R = np.where(keep[:, None, None], f.rot, R).astype(f.rot.dtype)
        feats = f.features.copy()
        rot6 = feats[SL_ROT].reshape(N_SEGMENTS, 6)
        rot6[~measured] = matrix_to_rot6d_np(R[~measured])
        out.append(replace(f, rot=R, joints=(kin.joints(R) + f.root).astype(f.joints.dtype), features=feats))
    return out


_LEGS = tuple(tuple(SEGMENT_INDEX[f"{side}_{s}"] for s in ("thigh", "shank", "foot", "toes")) for side in "lr")


def below_worn(measured: np.ndarray) -> np.ndarray:
    """(S,) bool: the leg segments below a leg's lowest worn sensor (the feet below worn shanks,
    the shanks and feet below worn thighs)."""
    out = np.zeros(N_SEGMENTS, dtype=bool)
    for chain in _LEGS:
        worn = [i for i, s in enumerate(chain) if measured[s]]
        if worn:
            out[list(chain[worn[-1] + 1:])] = True
    return out


def zero_phase(R: np.ndarray, cutoff_hz: float, fps: float = FPS_MODEL) -> np.ndarray:
    """(T, S, 3, 3) orientations low-passed forward and backward (a 2nd-order Butterworth, so no
    lag and 4th-order roll-off) on their quaternions, kept in one hemisphere frame to frame. A
    late answer has its future, so it needs no causal filter's lag; the live 1-Euro filters
    would flatten the knee's swing peak (docs/report.md). Runs too short for the filter's
    padding come back as they are."""
    from scipy.signal import butter, filtfilt
    from scipy.spatial.transform import Rotation

    T, S = R.shape[:2]
    b, a = butter(2, cutoff_hz / (fps / 2.0))
    if T <= 3 * max(len(a), len(b)):
        return R
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat().reshape(T, S, 4)
    flip = np.cumprod(np.where(np.sum(q[1:] * q[:-1], axis=-1) < 0, -1.0, 1.0), axis=0)
    q[1:] *= flip[..., None]
    q = filtfilt(b, a, q, axis=0)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(T, S, 3, 3)


__all__ = ["OFFLINE_ANSWER_LAG", "SMOOTH_HZ", "below_worn", "lagged_frames", "zero_phase"]
