"""A denoiser with a position input for tracked VR points (ModelConfig.points): it starts
as the model it was fine-tuned from, reads points as the mirror symmetry says it must,
and the training, the poser and the evaluation carry the points to it."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from app.cli.main import main
from app.export.bvh import write_motion_bvh
from inference.body.body import forward_kinematics
from inference.body.rotations import rot6d_to_matrix
from inference.body.skeleton import SEGMENT_INDEX, SEGMENTS
from inference.body.tracked import (
    POINT_FEATURES,
    TRACKED_POINTS,
    mirror_point_features,
    point_features,
    point_locals,
    point_positions,
)
from inference.features.codec import features_from_motion
from inference.features.layout import N_FEATURES, SL_PZ, SL_ROT, WINDOW
from inference.features.mirror import MirrorAveraged, mirror_features, mirror_points
from inference.model.config import ModelConfig
from inference.model.files import build_model, save_model
from inference.poser.models import resolve_model
from inference.poser.poser import Poser, reconstruct_offline
from inference.training.data import feature_stats
from inference.training.points import draw_presence, known_orientations, window_points
from sim_devices.devices.vr_rig import tracked_points
from sim_devices.motions import generate


def _config(points: bool) -> ModelConfig:
    return replace(ModelConfig.tiny(), mask_input=True, points=points)


def test_a_new_position_input_starts_as_the_model_without_it():
    torch.manual_seed(0)
    plain = build_model("diffusion", _config(False)).eval()
    with_points = build_model("diffusion", _config(True)).eval()
    with_points.load_state_dict({**with_points.state_dict(), **plain.state_dict()})
    z = torch.randn(2, WINDOW, N_FEATURES)
    t = torch.tensor([500, 10])
    h = torch.tensor([1.7, 1.8])
    m = torch.rand(2, WINDOW, N_FEATURES) > 0.5
    pts = torch.randn(2, WINDOW, POINT_FEATURES)
    with torch.no_grad():
        a = plain(z, t, h, m)
        assert torch.equal(with_points(z, t, h, m, points=pts), a)  # zero-initialised
        torch.nn.init.normal_(with_points.points_proj.weight, std=0.1)
        assert not torch.allclose(with_points(z, t, h, m, points=pts), a)
        assert torch.equal(with_points(z, t, h, m), a)  # no points given: none tracked


def test_the_mirror_average_mirrors_the_points_too():
    torch.manual_seed(1)
    net = build_model("diffusion", _config(True)).eval()
    torch.nn.init.normal_(net.points_proj.weight, std=0.1)
    mean, std = torch.zeros(N_FEATURES), torch.ones(N_FEATURES)
    avg = MirrorAveraged(net, mean, std)
    z = torch.randn(1, WINDOW, N_FEATURES)
    t, h = torch.tensor([300]), torch.tensor([1.75])
    m = torch.rand(1, WINDOW, N_FEATURES) > 0.5
    pts = torch.randn(1, WINDOW, POINT_FEATURES)
    with torch.no_grad():
        y = avg(z, t, h, m, points=pts)
        y_mirrored = avg(avg.mirror(z), t, h, m[..., avg.idx], points=mirror_point_features(pts))
    # the averaged model answers a mirrored window with the mirror of its answer
    torch.testing.assert_close(avg.mirror(y_mirrored), y, atol=1e-5, rtol=1e-5)


def test_training_points_are_the_rigs_points_of_the_window():
    motion = generate("walk", seconds=3.0, seed=4)
    x = torch.as_tensor(features_from_motion(motion), dtype=torch.float64)[None]
    off = torch.as_tensor(motion.body.offsets, dtype=torch.float64)[None]
    h = torch.tensor([motion.body.height], dtype=torch.float64)
    present = torch.tensor([[True, True, True, False]])
    got = window_points(x, off, h, present, noise=False)[0].numpy()
    # the simulated rig's devices on the same motion, at the features' 20 Hz frames
    rig = tracked_points(motion.resample(20.0), TRACKED_POINTS)
    pos = np.stack([rig[p][0] for p in TRACKED_POINTS], axis=1)
    want = point_features(pos, present[0].numpy())
    np.testing.assert_allclose(got, want, atol=2e-3)  # the features' root height is the 20 Hz one
    assert got[:, 9:12].max() == 0 and (got[:, 12:] == [1, 1, 1, 0]).all()  # no waist tracker


def test_tracked_windows_know_their_points_segment_orientations():
    gen = torch.Generator().manual_seed(0)
    present = draw_presence(400, 0.6, 0.3, gen)
    assert 0.5 < present[:, 0].float().mean() < 0.7
    assert (present[:, 1:3] == present[:, :1]).all() and not (present[:, 3] & ~present[:, 0]).any()
    m = known_orientations(present, WINDOW)
    for k, name in enumerate(TRACKED_POINTS):
        cols = slice(SL_ROT.start + 6 * SEGMENT_INDEX[name], SL_ROT.start + 6 * SEGMENT_INDEX[name] + 6)
        assert torch.equal(m[:, :, cols].all(-1).all(-1), present[:, k])
    assert m.sum() == 6 * WINDOW * present.sum()


@pytest.fixture(scope="module")
def points_model(tmp_path_factory):
    d = tmp_path_factory.mktemp("model")
    motion = generate("walk", seconds=3.0, seed=1)
    mean, std = feature_stats([features_from_motion(motion)])
    torch.manual_seed(0)
    net = build_model("diffusion", _config(True))
    torch.nn.init.normal_(net.points_proj.weight, std=0.1)
    path = d / "points.pt"
    save_model(path, net, "diffusion", mean, std, meta={"default_steps": "10D:2", "inpaint_mode": "replace-ddim",
                                                         "history": "measured", "noise": "mean"})
    return path


def test_the_poser_feeds_each_frame_its_points(points_model):
    model = resolve_model(str(points_model))
    motion = generate("walk", seconds=2.0, seed=2)
    f = features_from_motion(motion)
    mask = np.zeros(N_FEATURES, bool)
    mask[SL_ROT.start + 6 * SEGMENT_INDEX["head"]: SL_ROT.start + 6 * SEGMENT_INDEX["head"] + 6] = True
    x = torch.as_tensor(f)[None]
    pts = window_points(x, torch.as_tensor(motion.body.offsets, dtype=x.dtype)[None],
                        torch.tensor([motion.body.height], dtype=x.dtype), torch.tensor([[True] * 4]),
                        noise=False)[0].numpy()
    with_pts = reconstruct_offline(Poser(model, body=motion.body), f, mask, points=pts)
    without = reconstruct_offline(Poser(model, body=motion.body), f, mask)
    poser = Poser(model, body=motion.body)
    assert poser.takes_points
    for k in range(3):
        poser.step(f[k], mask, pts[k])
    win = poser.points_window()[0]
    torch.testing.assert_close(win[-3:], torch.as_tensor(pts[:3], dtype=torch.float32))
    assert (win[:-3] == 0).all()  # the standing start tracked nothing
    assert not np.allclose(with_pts.rot, without.rot)  # the points reach the model
    assert not Poser(resolve_model("floor"), body=motion.body).takes_points


def test_evaluate_reads_points_as_positions_for_a_model_that_takes_them(points_model, tmp_path, capsys):
    write_motion_bvh(tmp_path / "walk.bvh", generate("walk", seconds=3.0, seed=3))
    code = main(["evaluate", "--data", str(tmp_path), "--sensors", "l_shank,r_shank", "--points", "head,l_hand,r_hand",
                 "--model", str(points_model), "--json", "--no-progress", "--threads", "1"])
    out = capsys.readouterr()
    assert code == 0, out.err
    res = json.loads(out.out)
    assert res["points_read_as"] == "positions" and res["ga_deg"] > 0
    code = main(["evaluate", "--data", str(tmp_path), "--points", "l_hand,r_hand", "--sensors", "l_shank",
                 "--model", str(points_model), "--no-progress", "--threads", "1"])
    assert code != 0 and "add head to --points" in capsys.readouterr().err


def test_window_points_geometry_matches_forward_kinematics():
    motion = generate("walk", seconds=1.0, seed=5)
    x = torch.as_tensor(features_from_motion(motion), dtype=torch.float64)[None]
    off = torch.as_tensor(motion.body.offsets, dtype=torch.float64)[None]
    h = torch.tensor([motion.body.height], dtype=torch.float64)
    R = rot6d_to_matrix(x[..., SL_ROT].reshape(1, -1, 24, 6))
    root = torch.zeros(1, x.shape[1], 3, dtype=x.dtype)
    root[..., 2] = x[..., SL_PZ.start]
    pos = point_positions(R, forward_kinematics(R, root, off[:, None]), point_locals(off, h)[:, None])
    f = window_points(x, off, h, torch.tensor([[True] * 4]), noise=False)
    torch.testing.assert_close(f, point_features(pos, torch.tensor([True] * 4)))
    # a mirrored window's points are the mirror of the window's points
    fm = window_points(mirror_features(x), mirror_points(off, SEGMENTS), h,
                       torch.tensor([[True] * 4]), noise=False)
    torch.testing.assert_close(fm, mirror_point_features(f), atol=1e-9, rtol=0)


def test_the_position_input_learns_on_its_own_rate():
    from inference.training.config import TrainConfig
    from inference.training.loop import param_groups

    net = build_model("diffusion", _config(True))
    groups = param_groups(net, TrainConfig(points_lr_scale=30.0))
    own = [g for g in groups if g.get("lr_scale") == 30.0]
    assert len(own) == 1 and {id(p) for p in own[0]["params"]} == {id(p) for p in net.points_proj.parameters()}
    assert sum(len(g["params"]) for g in groups) == len(list(net.parameters()))
    assert len(param_groups(net, TrainConfig())) == 1
