"""Trainer: losses, augmentation, EMA, checkpoint/resume, and a 2-process torchrun run."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from inference.body.conventions import rot_z
from inference.body.rotations import matrix_to_rot6d, rot6d_to_matrix
from inference.features.layout import SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT
from inference.features.mirror import mirror_features, mirror_points
from inference.model.config import ModelConfig
from inference.model.files import build_model, load_model, with_window
from inference.training.augment import rotate_yaw, scale_features
from inference.training.config import LossWeights, TrainConfig
from inference.training.data import feature_stats, synthetic_dataset
from inference.training.loop import EMA, StepContext, batch_loss, export_model, train
from inference.training.losses import contact_offsets_for, motion_losses

ROOT = Path(__file__).resolve().parents[3]
TINY = {"layers": 1, "d_model": 32, "heads": 2, "ff": 64, "dropout": 0.1}


def _batch(contacts: float | None = None):
    ds = synthetic_dataset(3, 70, seed=0)
    b = ds.sample(np.random.default_rng(0), 4, 61)
    x = torch.as_tensor(b["x"])
    if contacts is not None:
        x[..., SL_CONTACT] = contacts
    mean, std = (torch.as_tensor(a) for a in feature_stats(ds.clips))
    cl = torch.as_tensor(contact_offsets_for(b["offsets"], b["height"]), dtype=torch.float32)
    return (x - mean) / std, mean, std, torch.as_tensor(b["offsets"]), cl


def test_losses_zero_for_perfect_prediction_positive_otherwise():
    xn, mean, std, off, cl = _batch(contacts=0.0)
    terms = motion_losses(xn.clone(), xn, mean, std, off, cl)
    assert set(terms) == {"simple", "vel", "fk", "drift", "slide", "last", "fk_last", "swing"}
    for k, v in terms.items():
        assert float(v) == pytest.approx(0.0, abs=1e-9), k
    # perturb orientations, root motion and contacts: every term turns positive
    g = torch.Generator().manual_seed(0)
    pert = xn + 0.3 * torch.randn(xn.shape, generator=g)
    pert[..., SL_CONTACT] = (1.0 - mean[SL_CONTACT]) / std[SL_CONTACT]  # predicted in contact
    terms = motion_losses(pert, xn, mean, std, off, cl)
    for k, v in terms.items():
        assert float(v) > 0, k
    # slide vanishes where feet are predicted off the ground even if they move
    pert[..., SL_CONTACT] = (0.0 - mean[SL_CONTACT]) / std[SL_CONTACT]
    assert float(motion_losses(pert, xn, mean, std, off, cl)["slide"]) == 0.0


def _frozen_pose(xn, mean, std):
    """The windows (normalised) with every frame's pose set to the window's first: legs that
    do not swing at all."""
    x = xn * std + mean
    still = x.clone()
    still[..., SL_ROT] = x[:, :1, SL_ROT]
    return (still - mean) / std


def test_swing_compares_the_legs_amplitude_not_their_positions():
    """The swing term is blind to when the legs are where (a window played backwards keeps
    every frame's spread) and sees how far they move (a damped copy, as a conditional-mean
    prediction of an unmeasured thigh would be, under-swings)."""
    xn, mean, std, off, cl = _batch(contacts=0.0)
    backwards = motion_losses(xn.flip(1), xn, mean, std, off, cl)
    assert float(backwards["fk"]) > 1e-4
    assert float(backwards["swing"]) == pytest.approx(0.0, abs=1e-9)
    damped = motion_losses(_frozen_pose(xn, mean, std), xn, mean, std, off, cl)
    assert float(damped["swing"]) > 1e-4


def test_swing_is_asked_for_only_where_pelvis_and_shanks_are_known():
    from inference.features.layout import observation_mask
    from inference.training.losses import sites_known_share

    n = 10
    legs = torch.as_tensor(observation_mask(["pelvis", "l_shank", "r_shank", "head"]))
    known = torch.zeros(4, n, legs.numel(), dtype=torch.bool)
    known[0] = legs
    known[1, n // 2:] = legs  # seen in the second half of the window
    known[2] = torch.as_tensor(observation_mask(["pelvis", "l_wrist", "r_wrist"]))
    known[3] = torch.as_tensor(observation_mask(["l_shank", "r_shank"]))  # thighs' upper end unseen
    assert sites_known_share(known, ["pelvis", "l_shank", "r_shank"]).tolist() == [1.0, 0.5, 0.0, 0.0]
    xn, mean, std, off, cl = _batch(contacts=0.0)
    pred = _frozen_pose(xn, mean, std)
    gate = torch.tensor([1.0, 0.0, 0.0, 0.0])
    full = motion_losses(pred, xn, mean, std, off, cl)["swing"]
    gated = motion_losses(pred, xn, mean, std, off, cl, gate)["swing"]
    assert 0 < float(gated) < float(full)


def test_last_terms_weigh_the_frame_answer_lag_back():
    # an error on the frame 4 before the newest counts in the "last" terms of a model trained
    # to answer 4 frames late (TrainConfig.answer_lag) and not in a live model's
    xn, mean, std, off, cl = _batch(contacts=0.0)
    pert = xn.clone()
    pert[:, -5] += 0.5
    live = motion_losses(pert, xn, mean, std, off, cl)
    lagged = motion_losses(pert, xn, mean, std, off, cl, answer_lag=4)
    assert float(live["last"]) == 0.0 and float(live["fk_last"]) == 0.0
    assert float(lagged["last"]) > 0 and float(lagged["fk_last"]) > 0
    assert float(lagged["simple"]) == pytest.approx(float(live["simple"]))
    with pytest.raises(ValueError, match="answer_lag"):
        TrainConfig.from_dict({"answer_lag": 61})


def test_losses_differentiable():
    xn, mean, std, off, cl = _batch(contacts=1.0)
    pred = (xn + 0.1).requires_grad_(True)
    terms = motion_losses(pred, xn, mean, std, off, cl)
    sum(terms.values()).backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0


def test_rotate_yaw_is_a_consistent_rigid_turn():
    x = torch.as_tensor(synthetic_dataset(1, 61, seed=2).clips[0])[None]
    a = 0.9
    y = rotate_yaw(x, torch.tensor([a]))
    Rz = torch.as_tensor(rot_z(a), dtype=torch.float32)
    R = rot6d_to_matrix(x[..., SL_ROT].reshape(1, 61, 24, 6))
    assert torch.allclose(y[..., SL_ROT], matrix_to_rot6d(Rz @ R).reshape(1, 61, -1), atol=1e-5)
    acc = x[..., SL_ACC].reshape(1, 61, 13, 3)
    assert torch.allclose(y[..., SL_ACC].reshape(1, 61, 13, 3), acc @ Rz.T, atol=1e-5)
    assert torch.allclose(y[..., SL_DP], x[..., SL_DP] @ Rz[:2, :2].T, atol=1e-6)
    assert torch.equal(y[..., SL_PZ], x[..., SL_PZ]) and torch.equal(y[..., SL_CONTACT], x[..., SL_CONTACT])


def _augmentation_batch_and_loss(option: str):
    """A fixed batch (with heel/toe points) and ``loss(batch, value)``: the unweighted loss
    terms of a tiny eval-mode model with ``option`` = value and no yaw turn, drawn from the
    same generators every call, so an augmentation can be compared with its hand-made twin."""
    from inference.model.diffusion import Schedule

    ds = synthetic_dataset(3, 70, seed=0)
    batch = ds.sample(np.random.default_rng(0), 4, 61)
    batch["contact_offsets"] = contact_offsets_for(batch["offsets"], batch["height"])
    mean, std = (torch.as_tensor(a, dtype=torch.float32) for a in feature_stats(ds.clips))
    torch.manual_seed(0)
    model = build_model("diffusion", ModelConfig.from_dict(TINY)).eval()

    def loss(b, value):
        cfg = _cfg(augment_yaw=False, **{option: value})
        ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine())
        return batch_loss(model, b, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))[1]

    return batch, loss


def test_mirror_augmentation_mirrors_the_window_and_its_body(tmp_path):
    """augment_mirror = 1 on a batch must score exactly what no mirroring scores on the
    mirrored batch (features, bone offsets and heel/toe points all mirrored)."""
    from inference.body.skeleton import CONTACTS, SEGMENTS

    batch, loss = _augmentation_batch_and_loss("augment_mirror")
    flipped = dict(batch, x=mirror_features(torch.as_tensor(batch["x"])).numpy(),
                   offsets=mirror_points(torch.as_tensor(batch["offsets"]), SEGMENTS).numpy(),
                   contact_offsets=mirror_points(torch.as_tensor(batch["contact_offsets"]), CONTACTS).numpy())
    mirrored, plain = loss(batch, 1.0), loss(flipped, 1e-12)  # same draws; the second flips nothing
    for k in mirrored:
        assert mirrored[k] == pytest.approx(plain[k], rel=1e-4, abs=1e-7), k
    assert loss(batch, 1e-12)["fk"] != pytest.approx(plain["fk"], rel=1e-3)
    assert TrainConfig.from_dict(_cfg(augment_mirror=0.5).to_dict()).augment_mirror == 0.5


def test_mirror_average_trains_the_averaged_model_the_poser_runs():
    """mirror_average: the loss is the mirror-averaged model's (what the poser runs with a
    file that says ``mirror``), not the plain model's, and gradients reach the weights."""
    from inference.features.mirror import MirrorAveraged
    from inference.model.diffusion import Schedule

    ds = synthetic_dataset(3, 70, seed=0)
    batch = ds.sample(np.random.default_rng(0), 4, 61)
    mean, std = (torch.as_tensor(a, dtype=torch.float32) for a in feature_stats(ds.clips))
    torch.manual_seed(0)
    model = build_model("diffusion", ModelConfig.from_dict(TINY)).eval()

    def terms(net, on: bool):
        cfg = _cfg(augment_yaw=False, mirror_average=on)
        ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine())
        return batch_loss(net, batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))

    (loss_on, on), (_, wrapped), (_, off) = terms(model, True), terms(MirrorAveraged(model, mean, std), False), \
        terms(model, False)
    for k in on:
        assert on[k] == pytest.approx(wrapped[k], rel=1e-5, abs=1e-8), k
    assert on["simple"] != pytest.approx(off["simple"], rel=1e-3)
    loss_on.backward()
    assert all(p.grad is not None and torch.isfinite(p.grad).all() for p in model.parameters() if p.requires_grad)
    assert TrainConfig.from_dict(_cfg(mirror_average=True).to_dict()).mirror_average is True


def test_scale_features_equal_the_features_of_the_scaled_motion():
    """Derive the features of a walk on a 1.15x body from scratch: orientations, gravity-free
    accelerations, root displacement and height must be scale_features of the original's.
    Contact labels are kept by design; the 0.3 m/s threshold moves only borderline frames."""
    from inference.evaluation.runner import synthetic_motion
    from inference.features.codec import features_from_motion

    m = synthetic_motion(seconds=3.0)
    x = features_from_motion(m)
    xs = features_from_motion(m.scaled(1.15))
    got = scale_features(torch.as_tensor(x)[None], torch.tensor([1.15]))[0].numpy()
    keep = np.r_[SL_ROT.start:SL_PZ.stop]
    np.testing.assert_allclose(got[:, keep], xs[:, keep], atol=1e-4)
    assert np.abs(x[:, SL_ACC]).max() > 1.0 and not np.allclose(got[:, SL_ACC], x[:, SL_ACC], atol=1e-2)
    assert np.mean(got[:, SL_CONTACT] == xs[:, SL_CONTACT]) > 0.9


def test_scale_augmentation_scales_the_window_and_its_body():
    """augment_scale on a batch must score what no scaling scores on the batch scaled by the
    same draws: features, height (the model's input), bone offsets and heel/toe points."""
    batch, loss = _augmentation_batch_and_loss("augment_scale")
    a = 0.2
    s = torch.exp((2 * torch.rand(4, generator=torch.Generator().manual_seed(1)) - 1) * math.log1p(a))
    assert float(s.min()) >= 1 / 1.2 - 1e-6 and float(s.max()) <= 1.2 + 1e-6 and float(s.std()) > 0.01
    sn = s.numpy().astype(np.float64)
    scaled = dict(batch, x=scale_features(torch.as_tensor(batch["x"]), s).numpy(),
                  height=(batch["height"] * sn).astype(np.float32), offsets=batch["offsets"] * sn[:, None, None],
                  contact_offsets=batch["contact_offsets"] * sn[:, None, None])
    augmented, plain = loss(batch, a), loss(scaled, 1e-9)  # same draws; the second scales by ~1
    for k in augmented:
        assert augmented[k] == pytest.approx(plain[k], rel=1e-4, abs=1e-7), k
    assert loss(batch, 1e-9)["fk"] != pytest.approx(plain["fk"], rel=1e-3)
    assert TrainConfig.from_dict(_cfg(augment_scale=0.15).to_dict()).augment_scale == 0.15


def test_yaw_invariant_stats():
    clips = synthetic_dataset(4, 80, seed=1).clips
    mean, std = feature_stats(clips)
    assert mean[SL_DP].tolist() == [0.0, 0.0] and std[SL_DP][0] == std[SL_DP][1]
    assert mean[SL_ROT.start] == 0.0 and mean[SL_ROT.start + 2] != 0.0  # z keeps its mean
    assert (std >= 1e-2).all()


def test_ema_update():
    lin = torch.nn.Linear(2, 1, bias=False)
    with torch.no_grad():
        lin.weight.fill_(0.0)
    ema = EMA(lin, decay=0.9)
    with torch.no_grad():
        lin.weight.fill_(1.0)
    ema.update(lin, step=10_000)  # past warm-up: decay 0.9
    assert torch.allclose(ema.model.weight, torch.full((1, 2), 0.1))
    ema.update(lin, step=0)  # warm-up decay min(0.9, 1/10) = 0.1
    assert torch.allclose(ema.model.weight, torch.full((1, 2), 0.1 * 0.1 + 0.9))
    assert not ema.model.weight.requires_grad


def _cfg(kind="diffusion", steps=4, **kw) -> TrainConfig:
    d = {"kind": kind, "model": TINY, "steps": steps, "batch": 4, "warmup": 2, "log_every": 1, "ckpt_every": 2,
         "val_every": 2, "val_batches": 1, "val_batch": 2,
         "data": {"train": {"synthetic": {"clips": 3, "frames": 70, "seed": 0}},
                  "val": {"synthetic": {"clips": 2, "frames": 50, "seed": 1}}}}
    d.update(kw)
    return TrainConfig.from_dict(json.loads(json.dumps(d)))


@pytest.mark.parametrize("kind", ["diffusion", "regressor"])
def test_resume_reproduces_uninterrupted_run(tmp_path, kind):
    full = train(_cfg(kind), tmp_path / "full", progress=False)
    assert full.step == 4 and len(full.losses) == 4
    part = train(_cfg(kind), tmp_path / "part", progress=False, stop_after=2)
    assert part.step == 2 and (tmp_path / "part" / "last.pt").exists()
    with pytest.raises(FileExistsError):
        train(_cfg(kind), tmp_path / "part", progress=False)
    rest = train(_cfg(kind), tmp_path / "part", resume=True, progress=False)
    assert rest.step == 4
    assert rest.losses == pytest.approx(full.losses[2:], rel=1e-5, abs=1e-6)
    a = torch.load(tmp_path / "full" / "last.pt", weights_only=False)
    b = torch.load(tmp_path / "part" / "last.pt", weights_only=False)
    for k in a["ema"]:
        assert torch.allclose(a["ema"][k], b["ema"][k], atol=1e-6), k
    log = [json.loads(s) for s in (tmp_path / "part" / "train.jsonl").read_text().splitlines()]
    events = [e["event"] for e in log]
    assert events.count("start") == 2 and "val" in events and "checkpoint" in events
    assert all(math.isfinite(e["loss"]) for e in log if e["event"] == "train")
    lm = load_model(tmp_path / "part" / "model.pt")
    assert lm.kind == kind and lm.step == 4 and lm.norm_std.shape == (190,)
    from app.cli.main import main

    assert main(["train", "--out", str(tmp_path / "part"), "--export", str(tmp_path / "ship.pt"), "--fp16",
                 "--default-steps", "10", "--history", "measured", "--noise", "fixed",
                 "--contact-threshold", "0.8", "--mirror"]) == 0
    shipped = load_model(tmp_path / "ship.pt")
    assert shipped.meta["default_steps"] == "10" and shipped.step == 4
    assert shipped.meta["history"] == "measured" and shipped.meta["noise"] == "fixed"
    assert shipped.meta["contact_threshold"] == 0.8 and shipped.meta["mirror"] is True
    from inference.poser.models import CONTACT_THRESHOLD
    from inference.poser.poser import Poser

    assert Poser(shipped, freeze=False).mirror and not Poser(lm, freeze=False).mirror
    assert not Poser(shipped, freeze=False, mirror=False).mirror

    assert Poser(shipped, freeze=False).contact_threshold == 0.8
    assert Poser(lm, freeze=False).contact_threshold == CONTACT_THRESHOLD  # a file without one: the default
    assert Poser(shipped, freeze=False, contact_threshold=0.6).contact_threshold == 0.6
    for k, v in lm.model.state_dict().items():
        assert torch.allclose(v, shipped.model.state_dict()[k], atol=1e-2, rtol=1e-2), k


def test_torchrun_two_processes(tmp_path):
    """Two CPU processes with gloo through torch.distributed.run: both ranks finish, rank 0
    alone writes the checkpoint and the summary, and the checkpoint resumes (here in a
    single process, which also covers changing the world size on resume)."""
    cfg = _cfg(steps=2, log_every=1, ckpt_every=2, val_every=0)
    cfg_path = tmp_path / "cfg.json"
    cfg_path.write_text(json.dumps(cfg.to_dict()))
    out = tmp_path / "run"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
           "-m", "app.cli.main", "train", "--config", str(cfg_path), "--out", str(out), "--no-progress"]
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-3000:]  # torchrun fails if any rank fails
    ck = torch.load(out / "last.pt", weights_only=False)
    assert ck["step"] == 2 and ck["world_size"] == 2
    lines = r.stdout.strip().splitlines()
    assert len(lines) == 1 and json.loads(lines[0])["step"] == 2  # one summary line, from rank 0 only
    log = [json.loads(s) for s in (out / "train.jsonl").read_text().splitlines()]
    assert [e["world"] for e in log if e["event"] == "start"] == [2]
    assert [e["step"] for e in log if e["event"] == "train"] == [1, 2]  # rank 0 logs once per step
    cfg.steps = 3
    res = train(cfg, out, resume=True, progress=False)
    assert res.step == 3 and len(res.losses) == 1 and math.isfinite(res.losses[0])


def test_conditioned_diffusion_training_sees_known_entries_clean(tmp_path):
    """cond_prob: windows are noised only where unobserved; with the history always known
    the model must be handed frames 0..N-2 exactly, and the shipped file says to inpaint
    the same way."""
    from inference.model.diffusion import Schedule

    cfg = _cfg(cond_prob=1.0, augment_yaw=False, mask={"p_history_known": 1.0, "p_burst": 0.0,
                                                        "p_frame_drop": 0.0})
    ds = synthetic_dataset(3, 70, seed=0)
    batch = ds.sample(np.random.default_rng(0), 4, 61)
    mean, std = (torch.as_tensor(a, dtype=torch.float32) for a in feature_stats(ds.clips))
    seen = []

    def model(z, t, h):
        seen.append(z.clone())
        return torch.zeros_like(z)

    ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine())
    batch_loss(model, batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))
    xn = (torch.as_tensor(batch["x"]) - mean) / std
    assert torch.equal(seen[0][:, :-1], xn[:, :-1])
    assert not torch.equal(seen[0][:, -1], xn[:, -1])  # the last frame is partly unknown, so noised
    res = train(cfg, tmp_path / "run", progress=False)
    assert res.step == 4
    assert load_model(tmp_path / "run" / "model.pt").meta["inpaint_mode"] == "replace"
    assert load_model_meta_mode(_cfg(), tmp_path / "plain") == "paper"
    masked = _cfg(cond_prob=1.0, model={**TINY, "mask_input": True})
    assert train(masked, tmp_path / "masked", progress=False, stop_after=1).step == 1
    assert load_model(tmp_path / "masked" / "model.pt").config.mask_input


def test_mean_start_trains_the_top_level_on_zeros():
    """mean_start 1: every window drawn at t = T holds zeros in its unknown entries (what a
    poser with noise "mean" shows the model first); windows at other levels keep their noise."""
    from inference.model.diffusion import Schedule

    cfg = _cfg(cond_prob=1.0, augment_yaw=False, t_focus=0.5, infer_steps="1000,400",
               mean_start=1.0, mask={"p_history_known": 1.0, "p_burst": 0.0, "p_frame_drop": 0.0})
    ds = synthetic_dataset(3, 70, seed=0)
    batch = ds.sample(np.random.default_rng(0), 32, 61)
    mean, std = (torch.as_tensor(a, dtype=torch.float32) for a in feature_stats(ds.clips))
    seen = []

    def model(z, t, h):
        seen.append((z.clone(), t.clone()))
        return torch.zeros_like(z)

    ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine())
    batch_loss(model, batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))
    z, t = seen[0]
    xn = (torch.as_tensor(batch["x"]) - mean) / std
    top = t == 1000
    assert 0 < int(top.sum()) < 32
    last = z[:, -1]
    expect_top = Schedule.cosine().sqrt_ab(1000) * xn[:, -1]
    unknown = last != xn[:, -1]  # known entries are clean, the rest noised or zeroed
    assert torch.allclose(last[top][unknown[top]], expect_top[top][unknown[top]])
    low = ~top & (t > 0)
    assert (last[low] - xn[:, -1][low]).abs().max() > 0.5  # still drawn noise elsewhere
    assert _cfg(mean_start=1.0).to_dict()["mean_start"] == 1.0


def load_model_meta_mode(cfg: TrainConfig, out: Path) -> str:
    train(cfg, out, progress=False, stop_after=1)
    return load_model(out / "model.pt").meta["inpaint_mode"]


def test_loss_weights_from_config():
    cfg = TrainConfig.from_dict({"loss": {"fk": 3.0}, "model": {"layers": 2}})
    assert cfg.loss == LossWeights(fk=3.0) and cfg.model.layers == 2 and cfg.model.d_model == ModelConfig().d_model
    with pytest.raises(ValueError):
        TrainConfig.from_dict({"nonsense": 1})
    with pytest.raises(ValueError, match="pelvs"):
        TrainConfig.from_dict({"swing_gate": ["pelvs", "l_shank"]})


@pytest.mark.parametrize("kind", ["diffusion", "regressor"])
def test_a_gated_swing_term_trains_and_is_logged(tmp_path, kind):
    cfg = _cfg(kind, steps=2, cond_prob=1.0, loss={"swing": 50.0},
               mask={"p_common_set": 1.0}, swing_gate=["pelvis", "l_shank", "r_shank"])
    train(cfg, tmp_path / "run", progress=False)
    logged = [json.loads(line) for line in (tmp_path / "run" / "train.jsonl").read_text().splitlines()]
    swing = [e["swing"] for e in logged if e.get("event") == "train"]
    assert len(swing) == 2 and all(math.isfinite(v) and v >= 0 for v in swing)


def test_init_from_starts_a_new_run_from_another_runs_weights(tmp_path):
    base = train(_cfg(steps=2), tmp_path / "base", progress=False)
    assert base.step == 2
    src = torch.load(tmp_path / "base" / "last.pt", weights_only=False)
    # a different mask distribution and loss: what fine-tuning changes
    tuned_cfg = _cfg(steps=1, cond_prob=1.0, mask={"p_history_known": 0.0}, lr=0.0, lr_min=0.0,
                     loss={"last": 1.0, "fk_last": 1.0})
    res = train(tuned_cfg, tmp_path / "tuned", progress=False, init_from=tmp_path / "base" / "last.pt")
    assert res.step == 1  # a new run: its own step count from 0
    out = torch.load(tmp_path / "tuned" / "last.pt", weights_only=False)
    # lr 0: the weights are the source's EMA weights, the normaliser is the source's
    for k, v in src["ema"].items():
        assert torch.allclose(out["model"][k], v), k
    assert np.array_equal(out["norm_mean"], src["norm_mean"])
    assert out["train_config"]["mask"]["p_history_known"] == 0.0
    start = json.loads((tmp_path / "tuned" / "train.jsonl").read_text().splitlines()[0])
    assert start["init_from"].endswith("last.pt")
    # dropout may be switched on for a fine-tune (same weights, other training behaviour)
    drop = train(_cfg(steps=1, lr=0.0, lr_min=0.0, model={**TINY, "dropout": 0.0}), tmp_path / "drop", progress=False,
                 init_from=tmp_path / "base" / "last.pt")
    assert drop.step == 1
    out = torch.load(tmp_path / "drop" / "last.pt", weights_only=False)
    assert out["train_config"]["model"]["dropout"] == 0.0
    for k, v in src["ema"].items():
        assert torch.allclose(out["model"][k], v), k
    # a bypass grown onto those weights starts at zero (the same answers at first) and trains
    grown = train(_cfg(steps=2, lr=1e-2, model={**TINY, "bypass": True}), tmp_path / "bypass", progress=False,
                  init_from=tmp_path / "base" / "last.pt")
    assert grown.step == 2
    out = torch.load(tmp_path / "bypass" / "last.pt", weights_only=False)
    assert out["model_config"]["bypass"] and out["model"]["bypass.weight"].abs().sum() > 0
    # a run of another size cannot start from these weights
    with pytest.raises(ValueError, match="differs"):
        train(_cfg(steps=1, model={**TINY, "ff": TINY["ff"] * 2}), tmp_path / "other", progress=False,
              init_from=tmp_path / "base" / "last.pt")


def test_init_from_a_model_file_fine_tunes_the_shipped_kind_of_file(tmp_path):
    """A shipped weights file (EMA weights in fp16, the normaliser) starts a fine-tune the
    way a checkpoint does: with lr 0 the run's weights are the file's, cast to float32."""
    base = train(_cfg(steps=2), tmp_path / "base", progress=False)
    assert base.step == 2
    export_model(tmp_path / "base" / "last.pt", tmp_path / "w.pt", fp16=True)
    shipped = torch.load(tmp_path / "w.pt", weights_only=False)
    res = train(_cfg(steps=1, lr=0.0, lr_min=0.0), tmp_path / "ft", progress=False, init_from=tmp_path / "w.pt")
    assert res.step == 1
    out = torch.load(tmp_path / "ft" / "last.pt", weights_only=False)
    for k, v in shipped["state_dict"].items():
        assert torch.allclose(out["model"][k], v.float()), k
    assert np.array_equal(out["norm_mean"], shipped["norm_mean"])
    torch.save({"x": 1}, tmp_path / "junk.pt")
    with pytest.raises(ValueError, match="checkpoint .last.pt. or model file"):
        train(_cfg(steps=1), tmp_path / "junk", progress=False, init_from=tmp_path / "junk.pt")


def test_deeper_model_starts_from_a_shallower_ones_outputs(tmp_path):
    """--init into a diffusion model with more layers (same width): the trained layers are
    copied and the extra ones start as identities, so the deeper model's outputs equal the
    trained one's before it learns anything; the extra layers then train."""
    from inference.model.denoiser import deepened_state_dict

    train(_cfg(steps=2), tmp_path / "base", progress=False)
    src = torch.load(tmp_path / "base" / "last.pt", weights_only=False)
    shallow = build_model("diffusion", ModelConfig.from_dict(TINY)).eval()
    shallow.load_state_dict(src["ema"])
    deep = build_model("diffusion", ModelConfig.from_dict({**TINY, "layers": 3})).eval()
    deep.load_state_dict(deepened_state_dict(src["ema"], deep))
    g = torch.Generator().manual_seed(3)
    z, t, h = torch.randn(2, 61, 190, generator=g), torch.tensor([1000, 400]), torch.tensor([1.6, 1.8])
    with torch.no_grad():
        assert torch.allclose(deep(z, t, h), shallow(z, t, h), atol=1e-5)
    with torch.enable_grad():  # the nn.TransformerDecoder path, not the lean one
        assert torch.allclose(deep(z, t, h), shallow(z, t, h), atol=1e-5)

    res = train(_cfg(steps=2, model={**TINY, "layers": 3}), tmp_path / "deep", progress=False,
                init_from=tmp_path / "base" / "last.pt")
    assert res.step == 2
    out = torch.load(tmp_path / "deep" / "last.pt", weights_only=False)["model"]
    assert out["decoder.layers.2.linear2.weight"].abs().sum() > 0  # the new layer learned
    with pytest.raises(ValueError, match="differs"):  # shallower, or another width, is refused
        train(_cfg(steps=1, model={**TINY, "layers": 3, "d_model": 64}), tmp_path / "wide", progress=False,
              init_from=tmp_path / "base" / "last.pt")


def test_last_frame_terms_see_only_the_last_frame():
    from inference.training.losses import motion_losses

    torch.manual_seed(0)
    B, N = 2, 5
    mean, std = torch.zeros(190), torch.ones(190)
    true = torch.randn(B, N, 190) * 0.1
    offsets = torch.randn(B, 24, 3) * 0.1
    contact = torch.randn(B, 4, 3) * 0.05
    pred = true.clone()
    pred[:, 0, :] += 0.5  # error away from the last frame only
    terms = motion_losses(pred, true, mean, std, offsets, contact)
    assert terms["simple"] > 0 and terms["last"] == 0 and terms["fk_last"] == 0
    pred = true.clone()
    pred[:, -1, :] += 0.5
    terms = motion_losses(pred, true, mean, std, offsets, contact)
    assert terms["last"] == pytest.approx(0.25) and terms["fk_last"] > 0


def test_t_focus_draws_the_live_levels():
    from inference.training.loop import training_levels

    gen = torch.Generator().manual_seed(0)
    uniform = training_levels(_cfg(), 4000, gen, 1000)
    assert uniform.min() >= 0 and uniform.max() <= 1000 and len(set(uniform.tolist())) > 900
    focused = training_levels(_cfg(t_focus=1.0, infer_steps="1000,400,0"), 4000, gen, 1000)
    assert set(focused.tolist()) == {1000, 400, 0}
    half = training_levels(_cfg(t_focus=0.5, infer_steps="1000,400,0"), 4000, gen, 1000)
    share = float(torch.isin(half, torch.tensor([1000, 400, 0])).float().mean())
    assert 0.45 < share < 0.56


def test_cli_init_and_stop_after(tmp_path, capsys):
    from app.cli.main import main

    base = tmp_path / "base.json"
    base.write_text(json.dumps(_cfg(steps=2).to_dict()))
    assert main(["train", "--config", str(base), "--out", str(tmp_path / "a"), "--no-progress"]) == 0
    tuned = tmp_path / "tuned.json"
    tuned.write_text(json.dumps(_cfg(steps=4, t_focus=0.5, infer_steps="1000,400,0").to_dict()))
    assert main(["train", "--config", str(tuned), "--out", str(tmp_path / "b"), "--init",
                 str(tmp_path / "a" / "last.pt"), "--stop-after", "1", "--no-progress"]) == 0
    ck = torch.load(tmp_path / "b" / "last.pt", weights_only=False)
    assert ck["step"] == 1 and ck["train_config"]["steps"] == 4 and ck["train_config"]["t_focus"] == 0.5
    capsys.readouterr()
    assert main(["train", "--config", str(tuned), "--out", str(tmp_path / "b"), "--resume", "--init",
                 str(tmp_path / "a" / "last.pt")]) != 0
    assert "pass only one" in capsys.readouterr().err


@pytest.mark.parametrize("path", sorted((Path(__file__).resolve().parents[3] / "configs").rglob("*.json")),
                         ids=lambda p: p.name)
def test_shipped_configs_parse(path):
    cfg = TrainConfig.load(path)
    assert cfg.kind in ("diffusion", "regressor") and cfg.steps > 0 and cfg.data.get("train")


def test_retag_changes_a_model_files_poser_defaults_and_not_its_weights(tmp_path, capsys):
    from app.cli.main import main
    from inference.model.files import save_model

    torch.manual_seed(0)
    net = build_model("regressor", ModelConfig.tiny())
    save_model(tmp_path / "base.pt", net, "regressor", np.zeros(190), np.ones(190), step=7,
               meta={"inpaint_mode": "paper"}, fp16=True)
    assert main(["train", "--retag", str(tmp_path / "base.pt"), "--export", str(tmp_path / "tagged.pt"),
                 "--mirror"]) == 0
    before = torch.load(tmp_path / "base.pt", weights_only=False)
    after = torch.load(tmp_path / "tagged.pt", weights_only=False)
    assert after["meta"] == {"inpaint_mode": "paper", "mirror": True} and after["step"] == 7
    assert all(torch.equal(before["state_dict"][k], v) for k, v in after["state_dict"].items())
    torch.save({"x": 1}, tmp_path / "other.pt")
    assert main(["train", "--retag", str(tmp_path / "other.pt"), "--export", str(tmp_path / "x.pt")]) != 0
    assert "not an imucap model file" in capsys.readouterr().err and not (tmp_path / "x.pt").exists()
    assert main(["train", "--config", "c.json"]) != 0
    assert "--out is required" in capsys.readouterr().err


def test_a_model_trained_to_answer_late_says_so_in_its_file_and_answers_late(tmp_path):
    """A run trained on frame N-1-k (``answer_lag``) exports with meta ``answer_lag`` k, and a
    poser built on the file answers that late without being told; ``--mirror-chains`` is kept."""
    from app.cli.main import main
    from inference.poser.poser import Poser

    train(_cfg(steps=2, answer_lag=3, model={**TINY, "mask_input": True}), tmp_path / "late", progress=False)
    assert main(["train", "--out", str(tmp_path / "late"), "--export", str(tmp_path / "late.pt"), "--noise", "mean",
                 "--mirror", "--mirror-chains"]) == 0
    model = load_model(tmp_path / "late.pt")
    assert model.meta["answer_lag"] == 3 and model.meta["mirror_chains"] is True
    poser = Poser(model)
    assert poser.answer_lag == 3 and poser.chain_mirror
    assert Poser(model, answer_lag=0).answer_lag == 0  # a live answer on request
    train(_cfg(steps=2, model={**TINY, "mask_input": True}), tmp_path / "live", progress=False)
    export_model(tmp_path / "live" / "last.pt", tmp_path / "live.pt")
    assert "answer_lag" not in load_model(tmp_path / "live.pt").meta


def test_blend_mixes_a_file_with_its_fine_tune_and_refuses_strangers(tmp_path, capsys):
    """The blend is each weight's mix, answers between its two files, keeps A's poser
    defaults and normaliser; files of another network or normaliser are refused in one line."""
    from app.cli.main import main
    from inference.model.files import save_model

    torch.manual_seed(0)
    a, b = build_model("diffusion", ModelConfig.tiny()), build_model("diffusion", ModelConfig.tiny())
    mean, std = np.linspace(-1, 1, 190), np.linspace(0.5, 2, 190)
    save_model(tmp_path / "a.pt", a, "diffusion", mean, std, step=9, meta={"mirror": True})
    save_model(tmp_path / "b.pt", b, "diffusion", mean, std, step=12, meta={"mirror": False})
    assert main(["train", "--blend", str(tmp_path / "a.pt"), str(tmp_path / "b.pt"), "--blend-weight", "0.25",
                 "--export", str(tmp_path / "mix.pt"), "--noise", "mean"]) == 0
    mix = torch.load(tmp_path / "mix.pt", weights_only=False)
    sa, sb = a.state_dict(), b.state_dict()
    assert all(torch.allclose(v, 0.75 * sa[k] + 0.25 * sb[k], atol=1e-6) for k, v in mix["state_dict"].items())
    assert mix["meta"]["mirror"] is True and mix["meta"]["noise"] == "mean" and mix["step"] == 9
    assert mix["meta"]["blend"]["weight"] == 0.25
    loaded = load_model(tmp_path / "mix.pt")
    assert np.allclose(loaded.norm_mean, mean) and np.allclose(loaded.norm_std, std)
    for w, ref in ((0.0, a), (1.0, b)):
        main(["train", "--blend", str(tmp_path / "a.pt"), str(tmp_path / "b.pt"), "--blend-weight", str(w),
              "--export", str(tmp_path / "end.pt")])
        end = load_model(tmp_path / "end.pt").model
        assert all(torch.allclose(v, ref.state_dict()[k], atol=1e-6) for k, v in end.state_dict().items())
    capsys.readouterr()

    save_model(tmp_path / "other_norm.pt", b, "diffusion", mean + 1, std)
    bigger = build_model("diffusion", ModelConfig.from_dict({**ModelConfig.tiny().to_dict(), "layers": 3}))
    save_model(tmp_path / "bigger.pt", bigger, "diffusion", mean, std)
    for other, said in (("other_norm.pt", "normalises features differently"), ("bigger.pt", "a different network")):
        assert main(["train", "--blend", str(tmp_path / "a.pt"), str(tmp_path / other),
                     "--export", str(tmp_path / "bad.pt")]) != 0
        err = capsys.readouterr().err
        assert said in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "bad.pt").exists()
    assert main(["train", "--blend", str(tmp_path / "a.pt"), str(tmp_path / "b.pt"), "--blend-weight", "1.5",
                 "--export", str(tmp_path / "bad.pt")]) != 0
    assert "outside 0..1" in capsys.readouterr().err


def _named_dataset(names: list[str]):
    """A synthetic FeatureDataset whose clips are named as the three datasets' files are."""
    from inference.training.dataset import FeatureDataset

    syn = synthetic_dataset(clips=len(names), frames=70, seed=4)
    return FeatureDataset._assemble(syn.clips, syn.heights, syn.offsets,
                                    contact_offsets_for(syn.offsets, syn.heights), np.ones(len(names)), names)


def test_reading_tokens_train_on_each_windows_dataset_from_a_model_without_them(tmp_path):
    """A model told which dataset's reading of a body a window is in (ModelConfig.readings)
    starts, fine-tuned from one without tokens, as that model; the tokens then train from
    the clips' datasets, and an exported file answers in the reading it was given."""
    from inference.model.files import retag_model, with_reading
    from inference.training.splits import readings_of

    names = ["d/bandai/dataset-1/walk.bvh", "d/hdm05/dg/HDM_dg_01-01_01_120.amc", "d/cmu/bvh_cgspeed/05_01.bvh"]
    assert readings_of(names).tolist() == [1, 2, 3]
    ds = _named_dataset(names)
    train(_cfg(steps=2), tmp_path / "base", progress=False)
    told = {**TINY, "readings": 3}
    frozen = train(_cfg(steps=1, lr=0.0, lr_min=0.0, model=told, reading_drop=0.5), tmp_path / "same",
                   train_set=ds, val_set=ds, progress=False, init_from=tmp_path / "base" / "last.pt")
    assert frozen.step == 1
    src = torch.load(tmp_path / "base" / "last.pt", weights_only=False)["ema"]
    same = torch.load(tmp_path / "same" / "last.pt", weights_only=False)["model"]
    assert all(torch.equal(same[k], v) for k, v in src.items()) and not same["reading_emb.weight"].any()

    train(_cfg(steps=6, model=told, reading_drop=0.3), tmp_path / "told", train_set=ds, val_set=ds,
          progress=False, init_from=tmp_path / "base" / "last.pt")
    emb = torch.load(tmp_path / "told" / "last.pt", weights_only=False)["model"]["reading_emb.weight"]
    assert (emb.abs().sum(1) > 0).all()  # every dataset's token, and the untold one, trained
    # the tokens on a learning rate of their own: they move further in the same steps, the rest alike
    train(_cfg(steps=6, model=told, reading_drop=0.3, reading_lr_scale=50.0), tmp_path / "fast", train_set=ds,
          val_set=ds, progress=False, init_from=tmp_path / "base" / "last.pt")
    fast = torch.load(tmp_path / "fast" / "last.pt", weights_only=False)
    assert [g.get("lr_scale", 1.0) for g in fast["optimizer"]["param_groups"]] == [1.0, 50.0]
    assert fast["model"]["reading_emb.weight"].norm() > 5 * emb.norm()

    export_model(tmp_path / "told" / "last.pt", tmp_path / "cmu.pt", reading="cmu")
    retag_model(tmp_path / "cmu.pt", tmp_path / "hdm05.pt", {}, reading="hdm05")
    cmu, hdm = load_model(tmp_path / "cmu.pt"), load_model(tmp_path / "hdm05.pt")
    assert (cmu.config.reading, hdm.config.reading) == (3, 2)
    g = torch.Generator().manual_seed(5)
    z, t, h = torch.randn(2, 61, 190, generator=g), torch.tensor([1000, 400]), torch.tensor([1.6, 1.8])
    with torch.no_grad():
        a, b = cmu.model(z, t, h), hdm.model(z, t, h)
        assert not torch.allclose(a, b)
        assert torch.allclose(a, hdm.model(z, t, h, None, torch.tensor([3, 3])))
    with pytest.raises(ValueError, match="no reading tokens"):
        with_reading(ModelConfig.from_dict(TINY), "cmu")
    with pytest.raises(ValueError, match="unknown reading"):
        with_reading(cmu.config, "mocap")


def test_distillation_targets_the_teachers_chain_over_the_students_window(tmp_path):
    """A teacher distilled into itself at one step: its chain of one call at the top level is
    the student's own answer, so the simple term is zero; with a 3-step chain it is not,
    and a student of a shorter window is scored on the newest frames only."""
    from inference.model.diffusion import Schedule
    from inference.training.loop import load_teacher

    masked = {**TINY, "mask_input": True, "dropout": 0.0}
    base = train(_cfg(steps=2, cond_prob=1.0, model=masked), tmp_path / "base", progress=False)
    assert base.step == 2
    teacher_file = tmp_path / "base" / "model.pt"
    teacher = load_model(teacher_file)
    ds = synthetic_dataset(3, 70, seed=0)
    batch = ds.sample(np.random.default_rng(0), 4, 61)
    mean, std = torch.as_tensor(teacher.norm_mean), torch.as_tensor(teacher.norm_std)

    def terms(steps: str, window: int):
        cfg = _cfg(cond_prob=1.0, model={**masked, "window": window}, teacher=str(teacher_file), teacher_steps=steps,
                   augment_yaw=False, augment_mirror=0.0)
        ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine(),
                          teacher=load_teacher(cfg, teacher.norm_mean, teacher.norm_std))
        student = teacher.model if window == 61 else with_window(teacher, window).model
        return batch_loss(student, batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))[1]

    assert terms("1", 61)["simple"] < 1e-10
    assert terms("10D:3", 61)["simple"] > 1e-6
    assert terms("10D:3", 21)["simple"] > 1e-6
    # the teacher's share of the target where unknown: a student answering the truth scores
    # zero at share 0 (the one call trained on the truth) and share^2 of its distance to the
    # teacher's chain between
    truth_n = (torch.as_tensor(batch["x"], dtype=torch.float32) - mean) / std

    class Truth(torch.nn.Module):
        def forward(self, z, t, h, m):
            return truth_n

    def share_simple(share: float) -> float:
        cfg = _cfg(cond_prob=1.0, model=masked, teacher=str(teacher_file), teacher_steps="10D:3",
                   teacher_share=share, augment_yaw=False, augment_mirror=0.0)
        ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine(),
                          teacher=load_teacher(cfg, teacher.norm_mean, teacher.norm_std))
        return batch_loss(Truth(), batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))[1]["simple"]

    whole = share_simple(1.0)
    assert whole > 1e-6 and share_simple(0.0) < 1e-10
    assert share_simple(0.5) == pytest.approx(0.25 * whole, rel=1e-4)
    with pytest.raises(ValueError, match="teacher_share"):
        load_teacher(_cfg(cond_prob=1.0, model=masked, teacher=str(teacher_file), teacher_share=1.5),
                     teacher.norm_mean, teacher.norm_std)
    # a teacher of another reading of the features is refused, with what to do
    cfg = _cfg(cond_prob=1.0, model=masked, teacher=str(teacher_file))
    with pytest.raises(ValueError, match="--init"):
        load_teacher(cfg, teacher.norm_mean + 1.0, teacher.norm_std)
    with pytest.raises(ValueError, match="model.window"):
        load_teacher(_cfg(cond_prob=1.0, model={**masked, "window": 70}, window=70, teacher=str(teacher_file)),
                     teacher.norm_mean, teacher.norm_std)
    # a whole run trains and writes its one-step student
    res = train(_cfg(steps=2, cond_prob=1.0, model={**masked, "window": 21}, teacher=str(teacher_file),
                     infer_steps="1"), tmp_path / "student", progress=False)
    assert res.step == 2 and load_model(tmp_path / "student" / "model.pt").config.window == 21
    # started from the teacher's file, the student is the teacher reading its newest 21 frames
    train(_cfg(steps=1, lr=0.0, lr_min=0.0, cond_prob=1.0, model={**masked, "window": 21}, teacher=str(teacher_file),
               infer_steps="1"), tmp_path / "init", progress=False, init_from=teacher_file)
    started = torch.load(tmp_path / "init" / "last.pt", weights_only=False)["model"]
    assert torch.equal(started["pos"], with_window(teacher, 21).model.state_dict()["pos"])


def _tiny_teacher(tmp_path):
    """A tiny mask-reading diffusion model trained two steps, its file, a batch and its normaliser."""
    masked = {**TINY, "mask_input": True, "dropout": 0.0}
    train(_cfg(steps=2, cond_prob=1.0, model=masked), tmp_path / "base", progress=False)
    teacher_file = tmp_path / "base" / "model.pt"
    teacher = load_model(teacher_file)
    batch = synthetic_dataset(3, 70, seed=0).sample(np.random.default_rng(0), 4, 61)
    return masked, teacher_file, teacher, batch, torch.as_tensor(teacher.norm_mean), torch.as_tensor(teacher.norm_std)


def test_chain_distillation_trains_each_call_on_the_teachers_call_at_the_students_own_state(tmp_path):
    """A chain student (``student_steps``): every level of its own chain is a training window
    whose target is the teacher's call at that state. The teacher as its own student has
    nothing to learn at any level; a student of another size starts fresh with the
    teacher's normaliser and writes a model of its own size."""
    from inference.model.diffusion import Schedule
    from inference.training.loop import load_teacher

    masked, teacher_file, teacher, batch, mean, std = _tiny_teacher(tmp_path)

    def run(student, **kw):
        cfg = _cfg(**{"cond_prob": 1.0, "model": masked, "teacher": str(teacher_file), "student_steps": "10D:3",
                      "augment_yaw": False, "augment_mirror": 0.0, **kw})
        ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine(),
                          teacher=load_teacher(cfg, teacher.norm_mean, teacher.norm_std))
        return batch_loss(student, batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))

    loss, terms = run(teacher.model)
    assert terms["simple"] < 1e-10 and terms["fk"] < 1e-10
    # the mirror-averaged teacher is another function: the same student now has something to learn
    assert run(teacher.model, teacher_mirror_chains=True)[1]["simple"] > 1e-6
    # three levels, three windows per training window: a student that records its calls sees
    # its own chain (the mean start, then the states its answers lead to) and is trained at each
    calls = []

    class Recording(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.net = teacher.model

        def forward(self, z, t, h, m):
            calls.append((z.shape[0], sorted(set(t.tolist()))))
            return self.net(z, t, h, m)

    run(Recording())
    assert calls == [(4, [1000]), (4, [400]), (12, [0, 400, 1000])]
    # a narrower student than the teacher: fresh weights, the teacher's normaliser
    small = {**masked, "d_model": 16, "ff": 32}
    res = train(_cfg(steps=2, cond_prob=1.0, model=small, teacher=str(teacher_file), student_steps="10D:3",
                     infer_steps="10D:3", keep_every=2), tmp_path / "small", progress=False)
    student = load_model(tmp_path / "small" / "model.pt")
    assert res.step == 2 and student.config.d_model == 16
    # a kept checkpoint exports as the run goes on (--at-step); one never kept is named
    from app.cli.main import main

    assert main(["train", "--out", str(tmp_path / "small"), "--export", str(tmp_path / "s2.pt"), "--at-step", "2",
                 "--no-mirror", "--draws-from", str(teacher_file)]) == 0
    exported = load_model(tmp_path / "s2.pt")
    assert exported.step == 2 and exported.meta["draws_from"] == str(teacher_file)
    # its confidence draws are the teacher's calls (it never learnt the re-noised states they start from)
    from inference.poser.poser import Poser

    assert Poser(exported, confidence=True).draw_model.config.d_model == teacher.config.d_model != 16
    assert main(["train", "--out", str(tmp_path / "small"), "--export", str(tmp_path / "s1.pt"), "--at-step", "1"]) != 0
    assert not (tmp_path / "s1.pt").exists()
    assert np.allclose(student.norm_mean, teacher.norm_mean) and np.allclose(student.norm_std, teacher.norm_std)


def test_a_chain_student_of_fewer_frames_is_answered_by_the_teacher_over_its_whole_window(tmp_path):
    """A chain student reading the newest 21 of the teacher's 61 frames: its calls see 21
    frames, the teacher's see 61 (its own chain in the older frames, the student's state in
    the newest), one teacher call a level; the teacher reading 21 frames as its own student
    learns something (the older frames' answers it does not see), and a run from the
    teacher's file starts from its newest positions and writes a 21-frame model."""
    from inference.model.diffusion import Schedule
    from inference.training.loop import load_teacher

    masked, teacher_file, teacher, batch, mean, std = _tiny_teacher(tmp_path)
    short = {**masked, "window": 21}
    cfg = _cfg(**{"cond_prob": 1.0, "model": short, "teacher": str(teacher_file), "student_steps": "10D:3",
                  "augment_yaw": False, "augment_mirror": 0.0})
    ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine(),
                      teacher=load_teacher(cfg, teacher.norm_mean, teacher.norm_std))
    calls = []

    class Recording(torch.nn.Module):
        def __init__(self, net, who):
            super().__init__()
            self.net, self.who = net, who

        def forward(self, z, t, h, m):
            calls.append((self.who, z.shape[0], z.shape[1], sorted(set(t.tolist()))))
            return self.net(z, t, h, m)

    ctx.teacher = Recording(ctx.teacher, "teacher")
    loss, terms = batch_loss(Recording(with_window(teacher, 21).model, "student"), batch, ctx,
                             np.random.default_rng(1), torch.Generator().manual_seed(1))
    assert calls == [("teacher", 4, 61, [1000]), ("student", 4, 21, [1000]), ("teacher", 4, 61, [400]),
                     ("student", 4, 21, [400]), ("teacher", 4, 61, [0]), ("student", 12, 21, [0, 400, 1000])]
    assert np.isfinite(float(loss.detach())) and terms["simple"] > 0 and "mirror" not in terms
    # the mirror term: a student answering every window as the mirror of its mirror image's answer
    # (the teacher averaged with its mirror image, call by call) has nothing to learn from it
    from inference.features.mirror import MirrorAveraged

    mirrored = replace(ctx, cfg=replace(cfg, loss=replace(cfg.loss, mirror=1.0)), teacher=ctx.teacher.net)
    student = with_window(teacher, 21).model
    _, terms = batch_loss(student, batch, mirrored, np.random.default_rng(1), torch.Generator().manual_seed(1))
    assert terms["mirror"] > 1e-6
    _, terms = batch_loss(MirrorAveraged(student, mean.numpy(), std.numpy()), batch, mirrored,
                          np.random.default_rng(1), torch.Generator().manual_seed(1))
    assert terms["mirror"] < 1e-10
    too_long = _cfg(**{"cond_prob": 1.0, "model": {**masked, "window": 81}, "teacher": str(teacher_file),
                       "student_steps": "10D:3"})
    with pytest.raises(ValueError, match="reads"):
        batch_loss(teacher.model, batch, replace(ctx, cfg=too_long), np.random.default_rng(1),
                   torch.Generator().manual_seed(1))
    res = train(_cfg(steps=2, cond_prob=1.0, model=short, teacher=str(teacher_file), student_steps="10D:3",
                     infer_steps="10D:3"), tmp_path / "short", progress=False, init_from=teacher_file)
    student = load_model(tmp_path / "short" / "model.pt")
    assert res.step == 2 and student.config.window == 21 and student.config.d_model == teacher.config.d_model


def test_a_chain_student_trained_from_the_symmetric_start_starts_there_and_its_file_says_so(tmp_path):
    """``symmetric_start``: the student's first call sees its unknown entries at the data mean's
    symmetric midpoint (where the poser starts a file that says so), not at the data mean; the
    exported file carries the flag, so the poser starts where the student learnt to."""
    from inference.model.diffusion import Schedule, symmetric_start
    from inference.poser.poser import Poser
    from inference.training.loop import export_model, load_teacher

    masked, teacher_file, teacher, batch, mean, std = _tiny_teacher(tmp_path)
    sch = Schedule.cosine()
    firsts = []

    class Recording(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.net = teacher.model

        def forward(self, z, t, h, m):
            if not firsts:
                firsts.append((z.clone(), m.clone()))
            return self.net(z, t, h, m)

    for sym in (False, True):
        firsts.clear()
        cfg = _cfg(**{"cond_prob": 1.0, "model": masked, "teacher": str(teacher_file), "student_steps": "10D:3",
                      "augment_yaw": False, "augment_mirror": 0.0, "symmetric_start": sym})
        ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=sch,
                          teacher=load_teacher(cfg, teacher.norm_mean, teacher.norm_std))
        batch_loss(Recording(), batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))
        z, m = firsts[0]
        c = torch.as_tensor(symmetric_start(mean.numpy(), std.numpy())) if sym else torch.zeros(mean.shape[-1])
        want = (sch.sqrt_1mab(1000) * c).expand_as(z)
        assert (~m).any() and torch.allclose(z[~m], want[~m], atol=1e-6)
        if sym:
            assert float(c.abs().max()) > 0.05  # the midpoint is somewhere else than the data mean
    res = train(_cfg(steps=1, cond_prob=1.0, model=masked, teacher=str(teacher_file), student_steps="10D:3",
                     infer_steps="10D:3", mean_start=1.0, symmetric_start=True), tmp_path / "sym", progress=False,
                init_from=teacher_file)
    assert res.step == 1
    export_model(tmp_path / "sym" / "last.pt", tmp_path / "sym.pt", poser={"noise": "mean"})  # as imucap train --export
    exported = load_model(tmp_path / "sym.pt")
    assert exported.meta["symmetric_start"] is True
    assert Poser(exported, body=1.75, contact_detector=None, pelvis_odometry=None).start_at is not None


def test_distillation_from_mirror_chains_targets_both_chains_averaged(tmp_path):
    """With ``teacher_mirror_chains`` the target is the teacher's chain averaged with the chain
    of the window's mirror image, each started from the data mean (as ``Poser(mirror_chains=True)``
    answers live): at one step, a student that is exactly that scores zero; the plain teacher,
    and the teacher averaged per call (whose mirror half starts from the mean's mirror image),
    do not."""
    from inference.features.mirror import MirrorAveraged
    from inference.model.diffusion import Schedule
    from inference.training.loop import load_teacher

    masked, teacher_file, teacher, batch, mean, std = _tiny_teacher(tmp_path)
    cfg = _cfg(cond_prob=1.0, model=masked, teacher=str(teacher_file), teacher_steps="1", teacher_mirror_chains=True,
               augment_yaw=False, augment_mirror=0.0)
    ctx = StepContext(cfg=cfg, mean=mean, std=std, schedule=Schedule.cosine(),
                      teacher=load_teacher(cfg, teacher.norm_mean, teacher.norm_std))
    op = MirrorAveraged(teacher.model, mean, std)

    class BothChains(torch.nn.Module):
        def forward(self, z, t, h, m):
            mm = m[..., op.idx]
            y = teacher.model(torch.cat([z, torch.where(mm, op.mirror(z), torch.zeros(()))]), torch.cat([t, t]),
                              torch.cat([h, h]), torch.cat([m, mm]))
            return 0.5 * (y[:len(z)] + op.mirror(y[len(z):]))

    def simple(student) -> float:
        return batch_loss(student, batch, ctx, np.random.default_rng(1), torch.Generator().manual_seed(1))[1]["simple"]

    assert simple(BothChains()) < 1e-10
    assert simple(teacher.model) > 1e-6
    assert simple(op) > 1e-6
