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
latest step that has it where the poses end or the history was reset. Measured segments stay
as measured; the root path stays the live one. A model trained to be best k frames back
(``TrainConfig.answer_lag``) says so in its file (meta ``answer_lag``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from inference.body import frame_kernels as fk
from inference.body.body import Body
from inference.body.rotations import matrix_to_rot6d_np
from inference.body.skeleton import N_SEGMENTS
from inference.features.layout import SL_ROT

# frames an import or a replay of one waits before showing a frame: 200 ms at 20 Hz. Four
# frames back the shipped model's thighs and pelvis on the real logs are 1-2.5 deg nearer their
# own sensors than the newest frame's, dg and the CMU subjects no worse (docs/real_signals.md,
# "Answering late")
OFFLINE_ANSWER_LAG = 4


def lagged_frames(frames: Sequence, body: Body) -> list:
    """``frames`` (``PoseFrame``, in order) with each frame's inferred segments taken from the
    latest later step, at most k frames on, whose window held it (the same history: index
    counting on without a reset). Frames without ``earlier_rot`` come back as they are."""
    out = list(frames)
    if not out:
        return out
    kin = fk.Kinematics(body.offsets)
    n = len(out)
    for j, f in enumerate(frames):
        best = None
        for p in range(j + 1, n):
            g = frames[p]
            d = p - j
            if g.earlier_rot is None or g.index != f.index + d or d > len(g.earlier_rot):
                break
            best = (g, d)
        if best is None:
            continue
        g, d = best
        measured = f.observed[SL_ROT].reshape(N_SEGMENTS, 6).all(axis=-1)
        R = np.where(measured[:, None, None], f.rot, g.earlier_rot[len(g.earlier_rot) - d]).astype(f.rot.dtype)
        feats = f.features.copy()
        rot6 = feats[SL_ROT].reshape(N_SEGMENTS, 6)
        rot6[~measured] = matrix_to_rot6d_np(R[~measured])
        out[j] = replace(f, rot=R, joints=(kin.joints(R) + f.root).astype(f.joints.dtype), features=feats)
    return out


__all__ = ["OFFLINE_ANSWER_LAG", "lagged_frames"]
