"""The live chain with a VR rig's positions: hub frames that carry the headset's and the
controllers' positions in the rig's own frame (turned about Z and moved against ours),
the rig's yaw from the calibration, and the arms' reach onto the controllers after the
poser's answer (``Pipeline(reach=...)``). Real parts: a generated walk, its device points
(``inference.body.tracked``), a calibration that turns each site's reference frame, the
floor poser (the model's place in the chain; its arms hang, so the reach has work to do)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.live import Pipeline
from app.live.tracked import rig_yaw
from calibration import Calibration
from drivers.hub import HubFrame
from inference.body.skeleton import SEGMENT_INDEX
from inference.metrics.vr import head_anchored
from inference.poser.poser import make_poser
from tests.app.rig_frames import SITES, T0, rig_walk, rz

HANDS = (SEGMENT_INDEX["l_hand"], SEGMENT_INDEX["r_hand"])


@pytest.fixture(scope="module")
def rig():
    r = rig_walk()
    return r.motion, r.kin, r.frames, r.calibration


def _run(rig, frames=None, **kw):
    motion, kin, all_frames, cal = rig
    pipe = Pipeline(make_poser("floor", body=motion.body), SITES, calibration=cal, **kw)
    out = []
    for f in all_frames if frames is None else frames:
        out += pipe.push(f)
    return out


def hand_error_cm(rig, poses) -> np.ndarray:
    """(T, 2) each hand joint's distance from the truth's, both read against the head joint
    (the three-point papers' hand PE)."""
    motion, kin, frames, cal = rig
    i = np.array([round((lp.t - T0) * 60) for lp in poses])
    pred = head_anchored(np.stack([lp.pose.joints for lp in poses]), kin.joints[i])
    true = head_anchored(kin.joints[i], kin.joints[i])
    return 100 * np.linalg.norm(pred[:, HANDS] - true[:, HANDS], axis=-1)


def test_the_arms_reach_the_controllers(rig):
    on, off = _run(rig), _run(rig, reach=False)
    assert len(on) == len(off) > 60
    err_on, err_off = hand_error_cm(rig, on), hand_error_cm(rig, off)
    print("hand PE cm: reach", err_on.mean().round(2), "without", err_off.mean().round(2))
    assert err_off.mean() > 4.0  # the floor poser's arms hang (6.2 cm)
    assert err_on.max() < 0.5, err_on.max()  # exact devices, the controller's orientation for the hand
    assert all(lp.points is not None and lp.points.shape == (16,) for lp in on)
    assert all(lp.points is None for lp in off)
    # only the arms move, and the joints are the reached body's
    arms = [SEGMENT_INDEX[f"{s}_{p}"] for s in "lr" for p in ("collar", "upperarm", "forearm", "hand")]
    rest = [k for k in range(24) if k not in arms]
    for a, b in zip(on, off, strict=True):
        np.testing.assert_allclose(a.pose.rot[rest], b.pose.rot[rest], atol=1e-12)
        np.testing.assert_allclose(a.pose.root, b.pose.root, atol=1e-12)
    assert not np.allclose(np.stack([lp.pose.rot[arms] for lp in on]), np.stack([lp.pose.rot[arms] for lp in off]))


def test_without_the_headset_nothing_is_reached(rig):
    motion, kin, frames, cal = rig
    blind = [HubFrame(**{**f.__dict__, "position": np.where(np.arange(4)[:, None] == 1, np.nan, f.position)})
             for f in frames]
    poses, off = _run(rig, blind), _run(rig, reach=False)
    assert all(lp.points is None for lp in poses)
    for a, b in zip(poses, off, strict=True):
        np.testing.assert_allclose(a.pose.joints, b.pose.joints, atol=1e-12)


def test_one_controller_is_reached_and_the_other_arm_kept(rig):
    motion, kin, frames, cal = rig
    one = [HubFrame(**{**f.__dict__, "position": np.where(np.arange(4)[:, None] == 2, np.nan, f.position)})
           for f in frames]  # the left controller lost
    err = hand_error_cm(rig, _run(rig, one))
    off = hand_error_cm(rig, _run(rig, reach=False))
    assert err[:, 1].max() < 0.5
    np.testing.assert_allclose(err[:, 0], off[:, 0], atol=1e-4)  # the poser's float32 joints, refitted


def test_the_rigs_yaw_is_the_mean_of_its_sites_and_no_imus():
    sites = ("pelvis", "head", "l_wrist", "r_wrist")
    R_WG = np.stack([rz(2.0), rz(0.50), rz(0.54), rz(0.58)])
    cal = Calibration(sites, R_WG=R_WG, R_SB=np.tile(np.eye(3), (4, 1, 1)), acc_offset=np.zeros((4, 3)),
                      valid=np.ones(4, bool))
    np.testing.assert_allclose(rig_yaw(cal, ("head", "l_wrist", "r_wrist")), rz(0.54), atol=1e-12)
    # across the +-180 deg seam the mean is still the middle
    cal.R_WG[1:] = np.stack([rz(math.pi - 0.1), rz(-math.pi + 0.1), rz(math.pi)])
    np.testing.assert_allclose(rig_yaw(cal, ("head", "l_wrist", "r_wrist")), rz(math.pi), atol=1e-12)
    cal.valid[:] = False
    assert rig_yaw(cal, ("head",)) is None


def test_a_model_with_a_position_input_reads_each_frames_points(rig, tmp_path):
    """A model that takes tracked points (``ModelConfig.points``; a tiny untrained one) gets
    each frame's position input from the live chain, the one the arms reach with."""
    from dataclasses import replace

    import torch

    from inference.features.codec import features_from_motion
    from inference.model.config import ModelConfig
    from inference.model.files import build_model, save_model
    from inference.poser.models import resolve_model
    from inference.poser.poser import Poser
    from inference.training.data import feature_stats

    motion, kin, frames, cal = rig
    mean, std = feature_stats([features_from_motion(motion)])
    torch.manual_seed(0)
    net = build_model("diffusion", replace(ModelConfig.tiny(), mask_input=True, points=True))
    path = tmp_path / "points.pt"
    save_model(path, net, "diffusion", mean, std, meta={"default_steps": "10D:2", "inpaint_mode": "replace-ddim",
                                                        "history": "measured", "noise": "mean"})
    poser = Poser(resolve_model(str(path)), body=motion.body)
    assert poser.takes_points
    pipe = Pipeline(poser, SITES, calibration=cal)
    seen = 0
    for f in frames[:120]:
        for lp in pipe.push(f):
            assert lp.points is not None
            torch.testing.assert_close(poser.points_window()[0, -1], torch.as_tensor(lp.points, dtype=torch.float32))
            seen += 1
    assert seen > 20
