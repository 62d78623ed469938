"""Answering late (inference/poser/lag.py): each frame shown as the window k frames later
answered it, its measured segments as measured, the same whether the clip runs frame by frame
or in lock step with others, and no answer taken across a reset of the history."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from inference.body.rotations import rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.evaluation.runner import SIX, clip_input, synthetic_motion
from inference.features.layout import N_FEATURES, SL_ROT
from inference.poser.batched import reconstruct_many
from inference.poser.lag import below_worn, lagged_frames, zero_phase
from inference.poser.poser import Poser, reconstruct_offline
from tests.conftest import F32_PATHS
from tests.inference.poser.tiny import tiny_diffusion

SHIPPED = dict(history="measured", noise="mean", inpaint_mode="replace-ddim")
SHANKS = ("pelvis", "l_shank", "r_shank")



@pytest.fixture(scope="module")
def model():
    return tiny_diffusion()


@pytest.fixture(scope="module")
def clip():
    return clip_input(synthetic_motion(seconds=2.0, seed=3), SHANKS)


def _measured(mask_row: np.ndarray) -> np.ndarray:
    return mask_row[SL_ROT].reshape(N_SEGMENTS, 6).all(-1)


def test_each_frame_is_the_answer_of_the_window_k_frames_later(model, clip):
    k = 3
    poser = Poser(model, body=clip.body, smoothing=False, answer_lag=k, **SHIPPED)
    rows = []
    predict = poser._predict

    def keep(win, mask):
        out = predict(win, mask)
        rows.append(out[0].numpy().copy())
        return out

    poser._predict = keep
    frames = [poser.step(clip.features[t], clip.mask[t]) for t in range(len(clip.features))]
    assert all(f.earlier_rot.shape == (k, N_SEGMENTS, 3, 3) for f in frames)
    lagged = lagged_frames(frames, poser.body, smooth_hz=None)
    measured = _measured(clip.mask[0])
    live = below_worn(measured)  # the feet, below the worn shanks: the live answer
    assert {i for i in np.flatnonzero(live)} == {SEGMENT_INDEX[s] for s in ("l_foot", "r_foot", "l_toes", "r_toes")}
    hips = [i for i in range(N_SEGMENTS) if not measured[i] and not live[i]]
    T = len(frames)
    for t in range(T):
        m = min(t + k, T - 1)  # the step whose window answered frame t last
        R = lagged[t].rot
        assert np.array_equal(R[measured], frames[t].rot[measured])  # measured: as measured
        assert np.array_equal(R[live], frames[t].rot[live])
        if m == t:
            assert np.array_equal(R, frames[t].rot)
            continue
        # the window's row for frame t: rows of step m are frames m - N + 1 .. m
        y = rows[m][len(rows[m]) - 1 - (m - t)] * poser._std_np + poser._mean_np
        raw = rot6d_to_matrix(torch.as_tensor(y[SL_ROT].reshape(N_SEGMENTS, 6))).numpy()
        # the knee hinge rebuilds the thighs from the shanks; every other inferred segment is the row's own
        other = [i for i in hips if i not in (SEGMENT_INDEX['l_thigh'], SEGMENT_INDEX['r_thigh'])]
        assert np.allclose(R[other], raw[other], atol=1e-5)
        joints = lagged[t].joints - lagged[t].root
        assert np.allclose(joints, poser._kin.joints(R), atol=1e-5)
    # the live answers differ: a later window answered the frame again
    assert not np.allclose(np.array([f.rot for f in lagged]), np.array([f.rot for f in frames]))


def test_segments_below_a_legs_lowest_worn_sensor_keep_the_live_answer():
    def seg(*names):
        m = np.zeros(N_SEGMENTS, dtype=bool)
        m[[SEGMENT_INDEX[n] for n in names]] = True
        return m

    assert np.array_equal(below_worn(seg("pelvis", "l_thigh", "r_thigh")),
                          seg("l_shank", "r_shank", "l_foot", "r_foot", "l_toes", "r_toes"))
    assert np.array_equal(below_worn(seg("pelvis", "l_forearm", "r_forearm")), seg())  # no leg worn: all late
    # the lowest worn sensor counts: a thigh over a worn foot keeps only the toes live
    assert np.array_equal(below_worn(seg("l_thigh", "l_foot", "r_shank")), seg("l_toes", "r_foot", "r_toes"))


def test_no_answer_is_taken_across_a_reset(model, clip):
    poser = Poser(model, body=clip.body, smoothing=False, answer_lag=4, **SHIPPED)
    frames = [poser.step(clip.features[t], clip.mask[t]) for t in range(10)]
    poser.reset()
    frames += [poser.step(clip.features[t], clip.mask[t]) for t in range(10, 20)]
    lagged = lagged_frames(frames, poser.body, smooth_hz=None)
    # the last frame before the reset has no later window of its own history: it stays live
    assert np.array_equal(lagged[9].rot, frames[9].rot)
    assert not np.allclose(lagged[5].rot, frames[5].rot)


def test_lock_step_clips_give_each_clip_its_frame_by_frame_lagged_answer(model):
    clips = [clip_input(synthetic_motion(seconds=s, seed=k), sites)
             for k, (s, sites) in enumerate([(1.6, SIX), (2.2, SHANKS)])]

    def posers():
        return [Poser(model, body=c.body, smoothing=False, answer_lag=2, **SHIPPED) for c in clips]

    one = [reconstruct_offline(p, c.features, c.mask) for p, c in zip(posers(), clips)]
    many = reconstruct_many(posers(), [(c.features, c.mask) for c in clips], lanes=2)
    for a, b in zip(one, many):
        assert np.allclose(a.rot, b.rot, **F32_PATHS)
        assert np.allclose(a.joints, b.joints, **F32_PATHS)


def test_the_late_poses_are_low_passed_without_lag():
    # a 1 Hz swing with 8 Hz jitter: the jitter goes, the swing keeps its phase and size
    t = np.arange(80) / 20.0
    angle = 0.6 * np.sin(2 * np.pi * 1.0 * t)
    jitter = 0.05 * np.sin(2 * np.pi * 8.0 * t)
    from scipy.spatial.transform import Rotation

    R = Rotation.from_rotvec(np.stack([np.zeros_like(t), angle + jitter, np.zeros_like(t)], -1)).as_matrix()
    out = Rotation.from_matrix(zero_phase(R[:, None], 6.0)[:, 0]).as_rotvec()[:, 1]
    inner = slice(10, -10)
    assert np.abs(out - angle)[inner].max() < 0.02 < np.abs(jitter).max()
    assert np.argmax(out[:20]) == np.argmax(angle[:20])  # no phase lag
    assert np.allclose(zero_phase(R[:5, None], 6.0), R[:5, None])  # too short to filter: as it was


def test_answer_lag_is_checked(model):
    with pytest.raises(ValueError, match="answer_lag"):
        Poser(model, answer_lag=model.config.window)
    with pytest.raises(ValueError, match="answer_lag"):
        Poser(None, answer_lag=2)  # the floor has no window that answers earlier frames
    frame = Poser(model, **SHIPPED).step(np.zeros(N_FEATURES), np.zeros(N_FEATURES, bool))
    assert frame.earlier_rot is None
    assert lagged_frames([replace(frame)], Poser(model).body)[0] is not None
