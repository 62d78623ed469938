"""Motion <-> the 190-number feature frames the model sees (layout in inference.features).

Encoding follows the paper's synthesis: resample to 60 Hz, smooth the site accelerations
with the 11-frame moving average, keep every 3rd frame (20 Hz). Orientation, root height
and contacts are taken at the kept frames; ``dp`` is the root's ground-plane displacement
from the previous kept frame (0 for the first frame, which has no predecessor).

Training, evaluation (ground truth) and the poser's output path all go through these two
functions, so a layout mistake cannot hide in one of them.

``causal``: the trailing moving average of the low-latency mode instead of the centred one
(``inference.signals.resample``), for a model trained on what that mode feeds it.
"""

from __future__ import annotations

import numpy as np

from inference.body.motion import Motion
from inference.body.rotations import matrix_to_rot6d, rot6d_to_matrix
from inference.body.skeleton import N_CONTACTS, N_SEGMENTS, N_SITES
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT
from inference.signals.resample import STEP, moving_average
from inference.signals.synthesis import Kinematics, kinematics


def features_from_kinematics(kin: Kinematics, causal: bool = False) -> np.ndarray:
    """(T20, 190) float32 from 60 Hz kinematics (see module docstring)."""
    rot = kin.rot[::STEP]
    T20 = rot.shape[0]
    x = np.zeros((T20, N_FEATURES), dtype=np.float64)
    x[:, SL_ROT] = matrix_to_rot6d(rot).reshape(T20, -1)
    x[:, SL_ACC] = moving_average(kin.site_acc_raw, STEP, causal).reshape(T20, -1)
    root = kin.root[::STEP]
    x[1:, SL_DP] = root[1:, :2] - root[:-1, :2]
    x[:, SL_PZ] = root[:, 2:3]
    x[:, SL_CONTACT] = kin.contacts[::STEP].astype(np.float64)
    return x.astype(np.float32)


def features_from_motion(motion: Motion, causal: bool = False) -> np.ndarray:
    """(T20, 190) float32 feature frames of a motion (unnormalised)."""
    return features_from_kinematics(kinematics(motion), causal)


motion_to_features = features_from_motion


def decode_features(x: np.ndarray, root_xy0: tuple[float, float] = (0.0, 0.0)) -> dict[str, np.ndarray]:
    """Feature frames (T, 190) -> dict(rot (T,24,3,3), root (T,3), acc (T,13,3),
    contacts (T,4) bool, contact_prob (T,4) raw values, dp (T,2)).

    The root path is ``root_xy0`` plus the cumulative sum of dp (dp[0] included), its
    height is pz; 6D orientations are orthonormalised (Gram-Schmidt), so raw network
    output decodes to valid rotations."""
    x = np.asarray(x, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != N_FEATURES:
        raise ValueError(f"decode_features: expected (T, {N_FEATURES}), got {x.shape}")
    T = x.shape[0]
    rot = rot6d_to_matrix(x[:, SL_ROT].reshape(T, N_SEGMENTS, 6))
    dp = x[:, SL_DP]
    root = np.zeros((T, 3))
    root[:, :2] = np.asarray(root_xy0, dtype=np.float64) + np.cumsum(dp, axis=0)
    root[:, 2] = x[:, SL_PZ][:, 0]
    prob = x[:, SL_CONTACT].reshape(T, N_CONTACTS)
    return {
        "rot": rot, "root": root, "acc": x[:, SL_ACC].reshape(T, N_SITES, 3),
        "contacts": prob > 0.5, "contact_prob": prob, "dp": dp.copy(),
    }


__all__ = ["features_from_motion", "features_from_kinematics", "motion_to_features", "decode_features"]
