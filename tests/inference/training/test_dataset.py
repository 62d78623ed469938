"""Feature frames, normaliser, clip sampling and the cached dataset builder."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from inference.body.body import Body, tpose
from inference.body.motion import Motion
from inference.body.rotations import axis_angle_to_matrix
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT, WINDOW
from inference.training.dataset import (
    FeatureDataset,
    Normalizer,
    build_dataset,
    clip_weights,
    decode_features,
    motion_to_features,
)


def moving_motion(T: int = 240, fps: float = 60.0, speed: float = 1.0, height: float = 1.75) -> Motion:
    t = np.arange(T) / fps
    R = tpose(T)
    yaw = 0.2 * np.sin(2 * t)
    R[:, 0] = axis_angle_to_matrix(np.stack([np.zeros(T), np.zeros(T), yaw], -1))
    R[:, 4] = R[:, 0] @ axis_angle_to_matrix(np.stack([np.zeros(T), 0.6 * np.sin(5 * t), np.zeros(T)], -1))
    root = np.stack([speed * t, 0.05 * np.sin(t), 0.9 + 0.03 * np.sin(6 * t)], -1)
    return Motion(rot=R, root=root, fps=fps, body=Body.from_height(height), name=f"moving{speed}")


def still_motion(T: int = 100, fps: float = 60.0) -> Motion:
    return Motion(rot=tpose(T), root=np.tile([0.0, 0.0, 0.93], (T, 1)), fps=fps, body=Body.from_height(1.6),
                  name="still")


def test_features_layout_and_decode_round_trip():
    m = moving_motion()
    x = motion_to_features(m)
    assert x.dtype == np.float32 and x.shape == (80, N_FEATURES)
    d = decode_features(x)
    np.testing.assert_allclose(d["rot"], m.rot[::3], atol=1e-5)
    np.testing.assert_allclose(d["root"][:, 2], m.root[::3, 2], atol=1e-6)
    np.testing.assert_allclose(d["root"][:, :2], m.root[::3, :2] - m.root[0, :2], atol=1e-5)
    assert np.all(x[0, SL_DP] == 0)
    assert set(np.unique(x[:, SL_CONTACT])) <= {0.0, 1.0}
    assert d["acc"].shape == (80, 13, 3) and d["contacts"].dtype == bool


def test_features_of_still_pose():
    x = motion_to_features(still_motion())
    np.testing.assert_allclose(x[:, SL_ACC], 0.0, atol=1e-6)
    assert np.all(x[:, SL_CONTACT] == 1.0)
    np.testing.assert_allclose(x[:, SL_ROT][:, :6], np.tile([1, 0, 0, 0, 1, 0], (x.shape[0], 1)))


def test_normalizer_numpy_torch_save_load(tmp_path: Path):
    clips = [motion_to_features(moving_motion(speed=s)) for s in (0.5, 1.5)] + [motion_to_features(still_motion())]
    nz = Normalizer.fit(clips)
    assert np.all(nz.mean[SL_ROT] == 0) and np.all(nz.std[SL_ROT] == 1)
    assert np.all(nz.mean[SL_CONTACT] == 0) and np.all(nz.std[SL_CONTACT] == 1)
    assert np.all(nz.std[SL_PZ] >= 0.02) and np.all(nz.std[SL_ACC] >= 0.1)
    x = clips[0]
    xn = nz.normalize(x)
    assert xn.dtype == np.float32
    np.testing.assert_allclose(nz.denormalize(xn), x, atol=1e-5)
    xt = nz.normalize(torch.as_tensor(x))
    np.testing.assert_allclose(xt.numpy(), xn, atol=1e-6)
    p = tmp_path / "norm.json"
    nz.save(p)
    back = Normalizer.load(p)
    np.testing.assert_array_equal(back.mean, nz.mean)
    np.testing.assert_array_equal(back.std, nz.std)


def test_sampling_windows_padding_and_energy_weights():
    ds = FeatureDataset.from_motions([moving_motion(T=600, speed=1.5), still_motion(T=60)])
    assert ds.weights.shape == (2,) and ds.weights.sum() == pytest.approx(1.0)
    assert ds.weights[0] > 5 * ds.weights[1] > 0  # the moving clip is drawn far more often
    rng = np.random.default_rng(0)
    b = ds.sample(rng, 16)
    assert b["x"].shape == (16, WINDOW, N_FEATURES) and b["x"].dtype == np.float32
    assert b["height"].shape == (16,) and b["offsets"].shape == (16, 24, 3)
    assert b["contact_offsets"].shape == (16, 4, 3)
    # the short clip (20 frames at 20 Hz) is padded at the front with its first frame, dp = 0
    w = ds.window(1, 0)
    clip = ds.clips[1]
    assert w.shape == (WINDOW, N_FEATURES)
    np.testing.assert_array_equal(w[-clip.shape[0]:], clip)
    first = clip[0].copy()
    first[SL_DP] = 0
    np.testing.assert_array_equal(w[: WINDOW - clip.shape[0]], np.tile(first, (WINDOW - clip.shape[0], 1)))


def test_windows_end_at_every_frame_of_a_clip():
    """The live poser reconstructs the last frame of its window: sampling must make every
    frame of a clip (also of a clip shorter than the window) a possible last frame."""
    ds = FeatureDataset.from_motions([moving_motion(T=150, speed=1.5)])  # 50 frames at 20 Hz
    clip = ds.clips[0]
    assert clip.shape[0] < WINDOW
    b = ds.sample(np.random.default_rng(1), 400)
    last = b["x"][:, -1]
    hit = {int(np.flatnonzero((clip == row).all(axis=1))[0]) for row in last}
    assert hit == set(range(clip.shape[0]))
    # a window ending k frames in: the standing first frame held, then frames 0..k-1
    w = ds.window(0, 5 - WINDOW)
    np.testing.assert_array_equal(w[-5:], clip[:5])
    assert (w[:-5, SL_DP] == 0).all() and np.array_equal(w[0, SL_ROT], clip[0, SL_ROT])


def test_energy_per_window_draws_every_window_by_its_clip_energy():
    """Per-trial weights give a clip its draws whatever its length; per-window weights make
    a frame of a clip 3x as long as another, at the same energy, as likely to end a window."""
    energy = np.array([2.0, 2.0, 6.0])
    lengths = np.array([100, 300, 100])
    np.testing.assert_allclose(clip_weights(energy), [0.2, 0.2, 0.6])
    w = clip_weights(energy, lengths)
    np.testing.assert_allclose(w, np.array([200, 600, 600]) / 1400)
    per_frame = w / lengths  # window ends are uniform within a clip
    assert per_frame[0] == pytest.approx(per_frame[1]) and per_frame[2] == pytest.approx(3 * per_frame[0])
    # the floor for still clips applies before the length
    still = clip_weights(np.array([0.0, 10.0, 10.0]), np.array([50, 50, 50]))
    assert still[0] == pytest.approx(0.05 * 10 / (0.5 + 20))


def test_train_set_refuses_an_unknown_energy_weighting():
    from inference.training.splits import train_set

    with pytest.raises(ValueError, match="energy_per"):
        train_set(progress=False, energy_per="frame")  # refused before any data is read


def _write_clips(root: Path, n: int) -> list[Path]:
    root.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        p = root / f"clip{i}.npz"
        np.savez(p, speed=0.5 + i)
        paths.append(p)
    return paths


def test_build_dataset_caches_by_content(tmp_path: Path):
    data = tmp_path / "data"
    paths = _write_clips(data, 3)
    calls: list[Path] = []

    def loader(p: Path) -> Motion:
        calls.append(p)
        if p.name == "clip2.npz":
            raise ValueError(f"{p}: broken on purpose")
        return moving_motion(T=200, speed=float(np.load(p)["speed"]))

    def finder(ps):
        return sorted(Path(ps[0]).glob("*.npz"))

    cache = tmp_path / "cache"
    ds = build_dataset([data], cache, loader=loader, finder=finder, progress=False)
    assert len(ds) == 2 and len(ds.skipped) == 1 and len(calls) == 3
    assert len(list(cache.glob("*.npz"))) == 1
    ds2 = build_dataset([data], cache, loader=loader, finder=finder, progress=False)
    assert len(calls) == 3  # cache hit: nothing reloaded
    assert ds2.names == ds.names and ds2.key == ds.key
    for a, b in zip(ds.clips, ds2.clips):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_allclose(ds2.weights, ds.weights)
    np.testing.assert_allclose(ds2.offsets, ds.offsets)
    # a changed file changes the key and triggers a rebuild
    np.savez(paths[0], speed=3.0)
    ds3 = build_dataset([data], cache, loader=loader, finder=finder, progress=False)
    assert ds3.key != ds.key and len(calls) == 6


def test_build_dataset_variant_keys_its_own_cache(tmp_path: Path):
    """A loader that changes the motions (here: faster) must not hit the plain cache."""
    data = tmp_path / "data"
    _write_clips(data, 2)

    def finder(ps):
        return sorted(Path(ps[0]).glob("*.npz"))

    cache = tmp_path / "cache"
    plain = build_dataset([data], cache, loader=lambda p: moving_motion(T=200), finder=finder, progress=False)
    fast = build_dataset([data], cache, loader=lambda p: moving_motion(T=200).at_speed(1.25), finder=finder,
                         progress=False, variant="speed=1.25")
    assert fast.key != plain.key and len(list(cache.glob("*.npz"))) == 2
    # the same frames played faster: fewer 20 Hz frames, and the root covers its path sooner
    assert fast.clips[0].shape[0] < plain.clips[0].shape[0]


def test_motion_at_speed_is_the_same_path_in_less_time():
    m = moving_motion(T=241, fps=60.0)
    f = m.at_speed(1.5)
    assert f.fps == 90.0 and f.duration == pytest.approx(m.duration / 1.5) and f.meta["speed"] == 1.5
    r = f.resample(60.0)  # what the dataset builder does first
    # frame k of the faster motion is the original at time 1.5 k / 60
    np.testing.assert_allclose(r.root[40], m.root[60], atol=1e-9)
    np.testing.assert_allclose(r.rot[100], m.rot[150], atol=1e-9)
    # velocities scale with the speed, accelerations with its square
    v0 = np.diff(m.root[:, 0]).mean() * m.fps
    v1 = np.diff(r.root[:, 0]).mean() * r.fps
    assert v1 == pytest.approx(1.5 * v0, rel=1e-6)
    with pytest.raises(ValueError):
        m.at_speed(0.0)


def test_motion_scaled_is_the_same_pose_on_a_larger_body():
    m = moving_motion(T=121, fps=60.0)
    b = m.scaled(1.2)
    np.testing.assert_array_equal(b.rot, m.rot)
    np.testing.assert_allclose(b.root, 1.2 * m.root)
    assert b.body.height == pytest.approx(1.2 * m.body.height) and b.meta["body_scale"] == 1.2
    # every point of the body (joints, sensor sites, heel/toe) lies 1.2x as far from the origin
    np.testing.assert_allclose(b.joints(), 1.2 * m.joints(), atol=1e-12)
    np.testing.assert_allclose(b.sites(), 1.2 * m.sites(), atol=1e-12)
    np.testing.assert_allclose(b.body.contact_offsets, 1.2 * m.body.contact_offsets, atol=1e-12)
    assert b.scaled(0.5).meta["body_scale"] == pytest.approx(0.6)
    with pytest.raises(ValueError):
        m.scaled(-1.0)


def test_concat_keeps_every_clip_and_reweights():
    a = FeatureDataset.from_motions([moving_motion(T=200, speed=0.5), still_motion()], names=["a0", "a1"])
    b = FeatureDataset.from_motions([moving_motion(T=150, speed=2.0)], names=["b0"])
    c = FeatureDataset.concat([a, b])
    assert c.names == ["a0", "a1", "b0"] and len(c) == 3 and c.n_frames == a.n_frames + b.n_frames
    np.testing.assert_array_equal(c.clips[2], b.clips[0])
    np.testing.assert_allclose(c.offsets[2], b.offsets[0])
    assert c.weights.sum() == pytest.approx(1.0)
    # kinetic-energy weights over the whole set: the fast clip outweighs the still one
    assert c.weights[2] > c.weights[1]
    b.energy = None
    with pytest.raises(ValueError):
        FeatureDataset.concat([a, b])
