"""AGRoL's MLP baseline: shapes, causality, that it can learn at all (overfits one batch),
that its input is the rig's geometry (inference.body.tracked), and its file round trip."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from inference.body.body import Body, forward_kinematics, npose_rotations
from inference.body.rotations import axis_angle_to_matrix, matrix_to_rot6d, rot6d_to_matrix
from inference.body.skeleton import SEGMENT_INDEX
from inference.body.tracked import grip_rotation, point_features, point_locals, point_positions
from inference.model.agrol_mlp import (
    INPUT_DIM,
    OUTPUT_DIM,
    AgrolConfig,
    AgrolMlp,
    agrol_loss,
    device_poses,
    input_features,
    load_agrol,
    place_under_headset,
    save_agrol,
)
from inference.training.agrol import main as train_main
from inference.training.agrol import window_batch
from inference.training.data import synthetic_dataset

SMALL = AgrolConfig(window=61, d_model=64, blocks=2)


def _walk(T: int = 12) -> tuple[Body, np.ndarray, np.ndarray]:
    """An N-pose turning its head about the vertical at 0.1 rad per frame and walking 0.05 m
    per frame along +X."""
    body = Body.from_height(1.72)
    R = npose_rotations(T)
    for t in range(T):
        R[t, SEGMENT_INDEX["head"]] = axis_angle_to_matrix(np.array([0.0, 0.0, 0.1 * t]))
    root = np.stack([0.05 * np.arange(T), np.zeros(T), np.full(T, 0.93)], axis=-1)
    return body, R, root


def test_shapes_and_bad_input():
    m = AgrolMlp(SMALL)
    assert m(torch.zeros(3, 61, INPUT_DIM)).shape == (3, 61, OUTPUT_DIM)
    with pytest.raises(ValueError, match="input must be"):
        m(torch.zeros(3, 60, INPUT_DIM))
    with pytest.raises(ValueError):
        AgrolConfig(window=1)


def test_pose_causal_sees_only_the_past():
    torch.manual_seed(0)
    m = AgrolMlp(SMALL)
    x = np.random.default_rng(0).normal(size=(90, INPUT_DIM)).astype(np.float32)
    a = m.pose_causal(x, chunk=17)
    assert a.shape == (90, 24, 3, 3)
    np.testing.assert_allclose(a @ a.swapaxes(-1, -2), np.broadcast_to(np.eye(3), a.shape), atol=1e-5)
    y = x.copy()
    y[50:] += 1.0  # a different future changes nothing before it
    b = m.pose_causal(y)
    np.testing.assert_allclose(a[:50], b[:50], atol=1e-5)
    assert np.abs(a[50:] - b[50:]).max() > 1e-3
    # frame t is the last frame of the window ending at t
    w = torch.as_tensor(x[70 - 60:71])[None]
    last = rot6d_to_matrix(m(w)[0, -1].reshape(24, 6).double())
    np.testing.assert_allclose(a[70], last.detach().numpy(), atol=1e-4)


def test_input_features_are_the_rig_geometry():
    body, R, root = _walk()
    J = forward_kinematics(R, root, body.offsets)
    locals_ = point_locals(body.offsets, body.height)
    f = input_features(*device_poses(R, J, locals_))
    assert f.shape == (12, INPUT_DIM)
    pts = point_positions(R, J, locals_)  # (T, 4, 3): head, l_hand, r_hand, pelvis
    # orientations: the head's, the hands' turned by the grip
    np.testing.assert_allclose(f[:, 0:6], matrix_to_rot6d(R[:, SEGMENT_INDEX["head"]]), atol=1e-12)
    np.testing.assert_allclose(f[:, 6:12], matrix_to_rot6d(R[:, SEGMENT_INDEX["l_hand"]] @ grip_rotation()),
                               atol=1e-12)
    # rotation change: the head's 0.1 rad per frame about Z, the hands' none
    np.testing.assert_allclose(f[1:, 18:24], np.broadcast_to(matrix_to_rot6d(axis_angle_to_matrix(
        np.array([0.0, 0.0, 0.1]))), (11, 6)), atol=1e-12)
    np.testing.assert_allclose(f[:, 24:36], np.tile(matrix_to_rot6d(np.eye(3)), (12, 2)), atol=1e-12)
    np.testing.assert_allclose(f[0, 18:24], matrix_to_rot6d(np.eye(3)), atol=1e-12)
    # positions: tracked.point_features of the three points
    rel = point_features(pts, np.array([True, True, True, False]))[:, :9]
    np.testing.assert_allclose(f[:, 36:45], rel, atol=1e-12)
    assert abs(f[0, 38] - 0.936 * 1.72) < 0.08  # the headset at about eye height
    # velocities: the walk's 0.05 m per frame along +X for the hands (the head turns too)
    np.testing.assert_allclose(f[1:, 48:54].reshape(11, 2, 3), np.broadcast_to([0.05, 0.0, 0.0], (11, 2, 3)),
                               atol=1e-12)
    np.testing.assert_allclose(f[0, 45:54], 0.0)
    # torch gives the same numbers
    ft = input_features(*device_poses(torch.as_tensor(R), torch.as_tensor(J), torch.as_tensor(locals_)))
    np.testing.assert_allclose(ft.numpy(), f, atol=1e-12)


def test_window_batch_without_noise_is_the_geometry_of_its_window():
    ds = synthetic_dataset(clips=2, frames=80, seed=3)
    batch = ds.sample(np.random.default_rng(0), 2, 62)
    inp, R, off = window_batch(batch, torch.Generator().manual_seed(0), yaw=False, jitter_m=0.0, jitter_deg=0.0)
    assert inp.shape == (2, 61, INPUT_DIM) and R.shape == (2, 61, 24, 3, 3)
    # the hand rows are the same geometry on the decoded window, root path from dp and pz
    from inference.features.codec import decode_features

    d = decode_features(batch["x"][0])
    J = forward_kinematics(d["rot"], d["root"], batch["offsets"][0].astype(np.float64))
    f = input_features(*device_poses(d["rot"], J, point_locals(batch["offsets"][0].astype(np.float64),
                                                               np.float64(batch["height"][0]))))
    np.testing.assert_allclose(inp[0].numpy(), f[1:], atol=2e-4)
    noisy, _, _ = window_batch(batch, torch.Generator().manual_seed(0), yaw=False)
    d_pos = (noisy - inp)[..., 36:45].numpy()
    assert 0.0005 < d_pos.std() < 0.002  # 1 mm per axis


def test_overfits_one_batch():
    torch.manual_seed(0)
    ds = synthetic_dataset(clips=2, frames=80, seed=1)
    inp, R, off = window_batch(ds.sample(np.random.default_rng(0), 2, 62), torch.Generator().manual_seed(0))
    m = AgrolMlp(SMALL)
    opt = torch.optim.Adam(m.parameters(), lr=1e-3)
    first = None
    for _ in range(300):
        loss, _ = agrol_loss(m(inp), R, off)
        first = float(loss.detach()) if first is None else first
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert float(loss.detach()) < first / 10


def test_save_load_round_trip(tmp_path):
    torch.manual_seed(0)
    m = AgrolMlp(SMALL)
    save_agrol(tmp_path / "m.pt", m, step=7)
    back, extra = load_agrol(tmp_path / "m.pt")
    assert back.cfg == SMALL and extra["step"] == 7
    x = torch.randn(2, 61, INPUT_DIM)
    torch.testing.assert_close(back(x), m(x))
    torch.save({"kind": "diffusion"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="other.pt: not an AGRoL MLP file"):
        load_agrol(tmp_path / "other.pt")
    (tmp_path / "junk.pt").write_text("junk")
    with pytest.raises(ValueError, match="junk.pt: not a readable torch file"):
        load_agrol(tmp_path / "junk.pt")
    with pytest.raises(FileNotFoundError, match="none.pt"):
        load_agrol(tmp_path / "none.pt")


def test_place_under_headset_puts_the_headset_on_the_tracked_one():
    body, R, root = _walk()
    J = forward_kinematics(R, root, body.offsets)
    hmd = point_positions(R, J, point_locals(body.offsets, body.height))[:, 0]
    r, j = place_under_headset(R, body.offsets, body.height, hmd)
    np.testing.assert_allclose(r, root, atol=1e-12)
    np.testing.assert_allclose(j, J, atol=1e-12)


def test_training_resumes_from_its_checkpoint(tmp_path, capsys):
    args = ["--out", str(tmp_path), "--steps", "4", "--synthetic", "--d-model", "32", "--blocks", "1",
            "--ckpt-every", "2", "--val-every", "2"]
    assert train_main(args) == 0
    assert train_main([*args[:3], "6", *args[4:]]) == 0
    rows = [json.loads(s) for s in (tmp_path / "log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows if "val_loss" in r] == [2, 4, 6]
    _, extra = load_agrol(tmp_path / "agrol_mlp.pt")
    assert extra["step"] == 6
    assert "resuming" in capsys.readouterr().err
