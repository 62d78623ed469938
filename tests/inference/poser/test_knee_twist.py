"""The knee twist's share: the strict hinge standing or walking straight, the twist while the body turns."""

from __future__ import annotations

import numpy as np
import pytest

from inference.body.conventions import rot_z, yaw_of
from inference.body.skeleton import SEGMENT_INDEX
from inference.features.layout import N_FEATURES
from inference.poser.knee_twist import FULL_TURN_DEG_S, TurnShare
from inference.signals.resample import FPS_MODEL


def _shares(gauge: TurnShare, rate_deg_s: float, frames: int = 30, wobble_deg: float = 0.0) -> list[float]:
    """Feed a pelvis turning at ``rate_deg_s`` (with a stride's heading wobble at 1 Hz)."""
    out = []
    for k in range(frames):
        t = k / FPS_MODEL
        h = np.radians(rate_deg_s * t + wobble_deg * np.sin(2 * np.pi * t))
        out.append(gauge(rot_z(np.array(h))))
    return out


def test_the_share_grows_with_the_turn_and_stops_at_its_most():
    assert _shares(TurnShare(0.5), 0.0)[-1] == 0.0
    assert _shares(TurnShare(0.5), FULL_TURN_DEG_S / 2)[-1] == pytest.approx(0.25)
    assert _shares(TurnShare(0.5), 3 * FULL_TURN_DEG_S)[-1] == pytest.approx(0.5)
    # either way round, and across the +-180 deg seam of the heading
    assert _shares(TurnShare(0.5), -3 * FULL_TURN_DEG_S, frames=80)[-1] == pytest.approx(0.5)
    g = TurnShare(0.5)
    assert g.now == 0.0 and g(np.eye(3)) == 0.0  # one heading is no turn
    assert _shares(g, 3 * FULL_TURN_DEG_S)[-1] == g.now


def test_the_strict_hinge_keeps_no_share_and_a_reset_forgets_the_turn():
    assert max(_shares(TurnShare(0.0), 200.0)) == 0.0
    g = TurnShare(0.5)
    _shares(g, 200.0)
    g.reset()
    assert g.now == 0.0 and g(np.eye(3)) == 0.0
    with pytest.raises(ValueError, match="knee_twist"):
        TurnShare(1.5)


def test_the_poser_turns_the_thighs_only_while_the_pelvis_turns():
    """With pelvis + shanks, a body that stands and then turns on the spot: the rebuilt thighs
    are the strict hinge's until the pelvis turns, and ``knee_twist=0`` is the hinge throughout."""
    from inference.body.rotations import matrix_to_rot6d
    from inference.features.layout import SL_ROT, observation_mask
    from inference.poser.joint_constraints import KNEES
    from inference.poser.poser import Poser, reconstruct_offline

    from .tiny import tiny_diffusion

    sites = ("pelvis", "l_shank", "r_shank")
    T, turn_from = 60, 30
    F = np.zeros((T, N_FEATURES))
    heading = np.radians(np.concatenate([np.zeros(turn_from), 90.0 * np.arange(1, T - turn_from + 1) / FPS_MODEL]))
    for k in range(T):
        R = rot_z(np.array(heading[k]))
        for s in sites:
            i = SEGMENT_INDEX[s]
            F[k, SL_ROT.start + 6 * i: SL_ROT.start + 6 * i + 6] = matrix_to_rot6d(R if s == "pelvis" else np.eye(3))
    M = np.broadcast_to(observation_mask(sites), (T, N_FEATURES)).copy()
    model = tiny_diffusion()
    kw = dict(body=1.75, steps=2, smoothing=False, stand_prior=False)
    twisted = reconstruct_offline(Poser(model, knee_twist=0.5, **kw), F, M).rot
    strict = reconstruct_offline(Poser(model, knee_twist=0.0, **kw), F, M).rot
    for t, s in KNEES:
        for rot in (twisted, strict):  # the shank is the measurement
            np.testing.assert_allclose(rot[:, s], np.broadcast_to(np.eye(3), (T, 3, 3)), atol=1e-5)
        hinge_twist = np.abs(yaw_of(np.swapaxes(strict[:, t], -1, -2) @ twisted[:, t]))
        assert hinge_twist[:turn_from].max() < 1e-6  # standing still: the strict hinge
    # turning at 90 deg/s, once the gauge has seen it: the thighs keep some of the model's twist
    late = [np.abs(yaw_of(strict[turn_from + 12:, t].transpose(0, 2, 1) @ twisted[turn_from + 12:, t])).max()
            for t, _ in KNEES]
    assert max(late) > np.radians(0.05)
