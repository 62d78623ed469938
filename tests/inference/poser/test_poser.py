"""The live poser: pass-through of measurements, dropouts, root correction, baselines,
default weights. Tiny random models and a generated motion; no trained weights needed."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from inference.body.body import Body, contact_points, forward_kinematics, npose_rotations
from inference.body.skeleton import SEGMENT_INDEX
from inference.evaluation.runner import SIX, clip_input, synthetic_motion
from inference.features.layout import N_FEATURES, SL_CONTACT, SL_DP, SL_PZ, SL_ROT, observation_mask
from inference.model.config import ModelConfig
from inference.model.files import LoadedModel, build_model
from inference.poser import models as poser_mod
from inference.poser.poser import Poser, correct_root_displacement, reconstruct_offline, standing_features
from inference.training.data import feature_stats


@pytest.fixture(scope="module")
def clip():
    m = synthetic_motion(seconds=3.0, seed=1)
    return m, clip_input(m, SIX)


def _loaded(kind: str, module: nn.Module | None = None, clip_features=None) -> LoadedModel:
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    model = (module or build_model(kind, cfg)).eval()
    if clip_features is not None:
        mean, std = feature_stats([clip_features])
    else:
        mean, std = np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32)
    return LoadedModel(model=model, kind=kind, config=cfg, norm_mean=mean, norm_std=std)


class Echo(nn.Module):
    """A denoiser that returns its input: with the single clean step [0] the poser then
    holds every unobserved feature at its previous value (a perfect 'hold' prior)."""

    def __init__(self, dp: tuple[float, float] | None = None, mean=None, std=None, contact: float | None = None):
        super().__init__()
        self.config = ModelConfig.tiny()
        self.dp = dp
        self.contact = contact
        self.mean, self.std = mean, std

    def forward(self, z, t, height):
        out = z.clone()
        if self.dp is not None:  # predict a constant root displacement (normalised units)
            out[..., SL_DP] = (torch.tensor(self.dp) - self.mean[SL_DP]) / self.std[SL_DP]
        if self.contact is not None:  # an unsure contact value on every foot point
            out[..., SL_CONTACT] = (self.contact - self.mean[SL_CONTACT]) / self.std[SL_CONTACT]
        return out


def test_standing_start_puts_feet_on_the_floor():
    body = Body.from_height(1.62)
    x = standing_features(body)
    R = npose_rotations(1)[0]
    j = forward_kinematics(R, np.array([0.0, 0.0, x[SL_PZ][0]]), body.offsets)
    assert contact_points(R, j, body)[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    assert np.all(x[SL_CONTACT] == 1) and np.all(x[SL_DP] == 0)
    p = Poser(None, body)
    np.testing.assert_allclose(p.history(), np.broadcast_to(x, (61, N_FEATURES)), atol=1e-6)


@pytest.mark.parametrize("kind", ["diffusion", "regressor", "floor"])
def test_observed_features_pass_through_exactly(kind, clip):
    _, inp = clip
    model = None if kind == "floor" else _loaded(kind, clip_features=inp.features)
    p = Poser(model, inp.body, steps=3, seed=0)
    for t in range(4):
        fr = p.step(inp.features[t], inp.mask[t])
        m = inp.mask[t]
        assert np.array_equal(fr.features[m], inp.features[t][m])
        assert np.all(np.isfinite(fr.features)) and np.all(np.isfinite(fr.joints))
        assert fr.rot.shape == (24, 3, 3) and fr.joints.shape == (24, 3) and fr.root.shape == (3,)
        assert fr.contacts.dtype == bool and fr.contacts.shape == (4,)
        # valid rotations everywhere, observed segments equal to the sensor's
        np.testing.assert_allclose(fr.rot @ np.swapaxes(fr.rot, -1, -2), np.broadcast_to(np.eye(3), (24, 3, 3)),
                                   atol=1e-5)
        np.testing.assert_allclose(fr.rot[SEGMENT_INDEX["head"]], inp.rot[t, SEGMENT_INDEX["head"]], atol=1e-5)
        # joints are FK of the output
        j = forward_kinematics(fr.rot.astype(np.float64), fr.root.astype(np.float64), inp.body.offsets)
        np.testing.assert_allclose(fr.joints, j, atol=1e-4)
    # what was measured is in the history exactly as the next window sees it
    hist = p.history()
    np.testing.assert_allclose(hist[-1][inp.mask[3]], inp.features[3][inp.mask[3]], atol=1e-5)


def test_dropped_sensor_stays_finite_and_rejoins(clip):
    _, inp = clip
    feats = inp.features.copy()
    mask = inp.mask.copy()
    wrist = observation_mask(["l_wrist"])
    mask[10:20] &= ~wrist  # one sensor lost for 0.5 s
    mask[25:32] = False  # every sensor lost
    feats[~mask] = np.nan  # what a lost packet looks like after resampling
    p = Poser(_loaded("diffusion", clip_features=inp.features), inp.body, steps=3)
    rec = reconstruct_offline(p, feats, mask)
    assert np.all(np.isfinite(rec.features)) and np.all(np.isfinite(rec.joints)) and np.all(np.isfinite(rec.root))
    # back to the measurement when the sensors return
    for t in (20, 32, 40):
        np.testing.assert_array_equal(rec.features[t][mask[t]], inp.features[t][mask[t]])


def test_dropout_is_continuous_with_a_hold_prior(clip):
    """With a prior that holds the past, a lost sensor's segment neither jumps at the
    drop nor drifts during it: unobserved frames start from a copy of frame N-2."""
    _, inp = clip
    lm = LoadedModel(model=Echo(), kind="diffusion", config=ModelConfig.tiny(),
                     norm_mean=np.zeros(N_FEATURES, np.float32), norm_std=np.ones(N_FEATURES, np.float32))
    mask = inp.mask.copy()
    mask[10:20] &= ~observation_mask(["l_wrist"])
    rec = reconstruct_offline(Poser(lm, inp.body, steps=[0]), inp.features, mask)
    seg = SEGMENT_INDEX["l_forearm"]
    for t in range(10, 20):
        np.testing.assert_allclose(rec.rot[t, seg], rec.rot[9, seg], atol=1e-5)
    np.testing.assert_allclose(rec.rot[20, seg], inp.rot[20, seg], atol=1e-5)


def test_root_correction_zeroes_dp_when_feet_planted():
    # direct: both feet in contact and still relative to the body -> the root stays
    pts = torch.tensor(np.random.default_rng(0).normal(size=(4, 3)), dtype=torch.float32)
    dp = torch.tensor([0.07, -0.03])
    out = correct_root_displacement(dp, pts, pts.clone(), torch.ones(4, dtype=torch.bool))
    torch.testing.assert_close(out, torch.zeros(2), atol=1e-7, rtol=0)
    # no contact: unchanged; a stance foot sliding back 5 cm under the body -> root +5 cm
    torch.testing.assert_close(correct_root_displacement(dp, pts, pts, torch.zeros(4, dtype=torch.bool)), dp)
    moved = pts.clone()
    moved[:2, 0] -= 0.05
    c = torch.tensor([True, True, False, False])
    torch.testing.assert_close(correct_root_displacement(dp, pts, moved, c), torch.tensor([0.05, 0.0]),
                               atol=1e-6, rtol=0)


def test_root_correction_inside_the_poser():
    """A model insisting on dp = 10 cm/frame while standing with both feet down: the
    corrected root does not move; without the correction it walks off."""
    body = Body.from_height(1.75)
    mean, std = np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32)
    echo = Echo(dp=(0.1, 0.0), mean=torch.as_tensor(mean), std=torch.as_tensor(std))
    lm = LoadedModel(model=echo, kind="diffusion", config=ModelConfig.tiny(), norm_mean=mean, norm_std=std)
    feats = np.zeros(N_FEATURES)
    none = np.zeros(N_FEATURES, bool)
    p = Poser(lm, body, steps=[0])
    for _ in range(5):
        fr = p.step(feats, none)
    np.testing.assert_allclose(fr.root[:2], 0.0, atol=1e-6)
    assert fr.contacts.all()
    p = Poser(lm, body, steps=[0], root_correction=False, smoothing=False)
    for _ in range(5):
        fr = p.step(feats, none)
    np.testing.assert_allclose(fr.root[:2], [0.5, 0.0], atol=1e-5)
    # the output filter trails the raw path a little and keeps the same heading
    p = Poser(lm, body, steps=[0], root_correction=False)
    xs = [p.step(feats, none).root[0] for _ in range(40)]
    assert 0.0 < xs[4] < 0.5 and np.all(np.diff(xs) > 0)
    assert 4.0 - 0.2 < xs[-1] < 4.0


def test_contact_threshold_decides_which_contacts_correct_the_root():
    """Contacts predicted at 0.7: planted for a 0.5 threshold (the root holds still), not
    for 0.85 (the model's displacement goes through)."""
    body = Body.from_height(1.75)
    mean, std = np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32)
    echo = Echo(dp=(0.1, 0.0), mean=torch.as_tensor(mean), std=torch.as_tensor(std), contact=0.7)
    lm = LoadedModel(model=echo, kind="diffusion", config=ModelConfig.tiny(), norm_mean=mean, norm_std=std)
    feats, none = np.zeros(N_FEATURES), np.zeros(N_FEATURES, bool)
    for thr, moves in ((0.5, False), (0.85, True)):
        p = Poser(lm, body, steps=[0], smoothing=False, contact_threshold=thr)
        for _ in range(5):
            fr = p.step(feats, none)
        assert fr.contacts.all() != moves
        np.testing.assert_allclose(fr.root[0], 0.5 if moves else 0.0, atol=1e-5)


def test_floor_baseline_holds_unobserved_and_root(clip):
    _, inp = clip
    p = Poser(None, inp.body)
    rec = reconstruct_offline(p, inp.features, inp.mask)
    Rn = npose_rotations(1)[0]
    np.testing.assert_allclose(rec.rot[:, SEGMENT_INDEX["l_thigh"]], np.broadcast_to(Rn[1], (len(rec), 3, 3)),
                               atol=1e-6)
    np.testing.assert_allclose(rec.rot[:, SEGMENT_INDEX["pelvis"]], inp.rot[:, 0], atol=1e-5)
    np.testing.assert_allclose(rec.root, np.broadcast_to(rec.root[0], rec.root.shape), atol=1e-6)
    np.testing.assert_allclose(rec.root[0, 2], standing_features(inp.body)[SL_PZ][0], atol=1e-6)


def test_reproducible_and_reset(clip):
    _, inp = clip
    lm = _loaded("diffusion", clip_features=inp.features)
    p = Poser(lm, inp.body, steps=4, seed=3)
    a = reconstruct_offline(p, inp.features[:6], inp.mask[:6])
    p.reset()
    b = reconstruct_offline(p, inp.features[:6], inp.mask[:6])
    np.testing.assert_array_equal(a.features, b.features)


def test_window_wraps_around():
    body = Body.from_height(1.7)
    p = Poser(None, body)
    x = standing_features(body)
    m = observation_mask(["head"])
    for k in range(130):  # more than 2 windows
        x = x.copy()
        x[SL_ROT.start + 6 * SEGMENT_INDEX["head"]] = np.cos(0.01 * k)
        fr = p.step(x, m)
        assert fr.index == k
    assert np.array_equal(fr.features[m], x[m])
    h = p.history()
    assert h.shape == (61, N_FEATURES)
    np.testing.assert_allclose(h[-1][m], x[m], atol=1e-6)


def test_missing_default_weights_say_how_to_train(monkeypatch, tmp_path):
    monkeypatch.setitem(poser_mod.DEFAULT_WEIGHTS, "diffusion", tmp_path / "nope.pt")
    with pytest.raises(FileNotFoundError, match="imucap train"):
        poser_mod.resolve_model("diffusion")
    assert poser_mod.resolve_model("floor") is None
    with pytest.raises(FileNotFoundError):
        poser_mod.resolve_model(str(tmp_path / "missing.pt"))


class MaskSpy(nn.Module):
    """A denoiser that reads the mask (mask_input) and keeps the last one it was given."""

    def __init__(self) -> None:
        super().__init__()
        self.config = ModelConfig.tiny()
        self.config.mask_input = True
        self.masks: list[torch.Tensor] = []

    def forward(self, z, t, h, mask=None):
        self.masks.append(mask.clone())
        return torch.zeros_like(z)


@pytest.mark.parametrize("history", ["reconstructed", "measured"])
def test_history_mode_decides_what_the_model_is_told_is_known(history):
    spy = MaskSpy()
    lm = LoadedModel(model=spy, kind="diffusion", config=spy.config, norm_mean=np.zeros(N_FEATURES, np.float32),
                     norm_std=np.ones(N_FEATURES, np.float32), meta={"inpaint_mode": "replace"})
    p = Poser(lm, steps="1000,0", history=history)
    assert p.inpaint_mode == "replace"  # the model file's mode is the default
    masks = [observation_mask(list(SIX)), observation_mask(["pelvis"]), observation_mask(list(SIX))]
    for i in range(70):
        p.step(np.zeros(N_FEATURES), masks[i % 3])
    seen = spy.masks[-1][0].numpy()  # (N, F) of the last frame's last call
    expect_recent = np.stack([masks[i % 3] for i in range(70 - p.window, 70)])
    if history == "measured":
        np.testing.assert_array_equal(seen, expect_recent)
    else:
        assert seen[:-1].all() and np.array_equal(seen[-1], expect_recent[-1])
    with pytest.raises(ValueError, match="history mode"):
        Poser(lm, history="guessed")


def test_noise_mode_mean_draws_nothing_and_does_not_depend_on_the_seed():
    """noise "mean" with the DDIM replacement mode: the first level starts from the prior's
    mean, so the output is a function of the measurements alone: the generator is never
    used and posers with different seeds agree exactly; a drawn start does depend on it."""
    lm = _loaded("diffusion")
    lm.meta = {"noise": "mean", "history": "measured", "inpaint_mode": "replace-ddim"}
    rng = np.random.default_rng(4)
    frames = [rng.normal(size=N_FEATURES).astype(np.float32) for _ in range(4)]
    obs = observation_mask(["l_shank", "r_shank"])

    def run(seed, **kw):
        p = Poser(lm, steps="1000,400,0", seed=seed, **kw)
        state = p._gen.get_state()
        outs = [p.step(f, obs).rot.copy() for f in frames]
        return outs, torch.equal(state, p._gen.get_state())

    a, untouched = run(0)
    b, _ = run(7)
    assert untouched
    assert all(np.array_equal(x, y) for x, y in zip(a, b))
    c, _ = run(0, noise="fixed")
    d, _ = run(7, noise="fixed")
    assert not all(np.array_equal(x, y) for x, y in zip(c, d))


@pytest.mark.parametrize("noise", ["fresh", "fixed"])
def test_noise_mode_fixed_reuses_one_draw_per_frame(noise):
    """fixed: every frame's inpainting starts from the same noise (the generator is reseeded),
    so the output is a deterministic function of the window; fresh: new noise each frame.
    The model file's meta picks the default, as `imucap train --export --noise` writes it."""
    from app.cli import train as cli_train

    assert cli_train.NOISE_MODES == poser_mod.NOISE_MODES and cli_train.HISTORY_MODES == poser_mod.HISTORY_MODES
    from inference.model.diffusion import INPAINT_MODES

    assert cli_train.INPAINT_MODES == INPAINT_MODES
    lm = _loaded("diffusion")
    lm.meta = {"noise": noise, "history": "measured"}
    p = Poser(lm, steps="1000,400,0")
    assert p.noise_mode == noise and p.history_mode == "measured"
    states = []
    for _ in range(3):
        p.step(np.zeros(N_FEATURES), observation_mask(list(SIX)))
        states.append(p._gen.get_state())
    assert torch.equal(states[0], states[1]) == (noise == "fixed")
    assert torch.equal(states[1], states[2]) == (noise == "fixed")
    with pytest.raises(ValueError, match="noise mode"):
        Poser(lm, noise="brown")


def test_mirror_averaging_makes_the_live_output_the_same_for_a_motion_and_its_mirror_image():
    """With the knee hinge, the smoothing, the root correction and the contact detector
    off (each is its own, non-symmetric stage), a mirror-averaged poser fed a sequence's
    mirror image returns the mirror image of what it returns for the sequence; a plain one
    does not, so the averaging is what makes it so."""
    from inference.body.skeleton import SEGMENTS
    from inference.features.mirror import mirror_features, mirror_tables

    lm = _loaded("diffusion")
    lm.meta = {"noise": "mean", "history": "measured", "inpaint_mode": "replace-ddim"}
    rng = np.random.default_rng(5)
    obs = observation_mask(["pelvis", "l_wrist", "r_shank"])
    frames = [rng.normal(size=N_FEATURES).astype(np.float32) for _ in range(5)]
    swap = [SEGMENTS.index({"l_": "r_", "r_": "l_"}.get(n[:2], n[:2]) + n[2:]) for n in SEGMENTS]
    M = np.diag([1.0, -1.0, 1.0])

    def gap(mirror: bool) -> float:
        kw = dict(steps="1000,400,0", mirror=mirror, knee_hinge=False, smoothing=False, root_correction=False,
                  contact_detector=None, start_pose="tpose")
        a, b = Poser(lm, **kw), Poser(lm, **kw)
        worst = 0.0
        for f in frames:
            fm = mirror_features(torch.as_tensor(f)).numpy()
            ra = a.step(f, obs).rot
            rb = b.step(fm, obs[mirror_tables()[0]]).rot
            worst = max(worst, float(np.abs(M @ rb[swap] @ M - ra).max()))
        return worst

    assert gap(True) < 1e-4
    assert gap(False) > 1e-2


class _FixedStride:
    """Stands in for the stride estimator: always the same factor, and counts its calls."""

    def __init__(self, scale: float) -> None:
        self.scale, self.updates, self.drops = scale, 0, 0

    def update(self, R, acc, contacts, ankle_xy) -> float:
        assert R.shape == (2, 3, 3) and acc.shape == (2, 3) and contacts.shape == (4,) and ankle_xy.shape == (2, 2)
        self.updates += 1
        return self.scale

    def drop(self, leg=None) -> None:
        self.drops += 1

    def reset(self) -> None:
        pass


@pytest.mark.parametrize("shanks", [True, False])
def test_stride_scale_multiplies_the_root_step_only_while_both_shanks_deliver(shanks):
    """A model walking 10 cm per frame with no foot down: scaled by the estimator's factor
    when both shanks are measured, left alone (and the pending strides dropped) when not."""
    body = Body.from_height(1.75)
    mean, std = np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32)
    echo = Echo(dp=(0.1, 0.0), contact=0.0, mean=torch.as_tensor(mean), std=torch.as_tensor(std))
    lm = LoadedModel(model=echo, kind="diffusion", config=ModelConfig.tiny(), norm_mean=mean, norm_std=std)
    sites = ["pelvis", "l_shank", "r_shank"] if shanks else ["pelvis", "l_shank"]
    m = observation_mask(sites)
    feats = standing_features(body)
    # without both shanks the pelvis odometry would walk the root instead: its own tests
    p = Poser(lm, body, steps=[0], smoothing=False, contact_detector=None, stride_scale=True, pelvis_odometry=None)
    fake = p.stride = _FixedStride(0.5)
    for _ in range(10):
        fr = p.step(feats, m)
    expected = 0.5 if shanks else 1.0
    np.testing.assert_allclose(fr.root[0], 10 * 0.1 * expected, atol=1e-5)
    np.testing.assert_allclose(fr.features[SL_DP], [0.1 * expected, 0.0], atol=1e-6)
    assert (fake.updates, fake.drops) == ((10, 0) if shanks else (0, 10))
    off = Poser(lm, body, steps=[0], smoothing=False, contact_detector=None, stride_scale=False,
                pelvis_odometry=None)
    assert off.stride is None
    for _ in range(10):
        fr_off = off.step(feats, m)
    np.testing.assert_allclose(fr_off.root[0], 1.0, atol=1e-5)


def test_floor_baseline_has_no_stride_scale():
    assert Poser(None, 1.75, stride_scale=True).stride is None
