"""The per-segment spread: it leaves the pose alone, is 0 where a sensor measures, pools
the latest draws, and (with the shipped weights) is lower on measured segments than on
the ones the sensors leave open."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch

from inference.body.skeleton import SEGMENT_INDEX, SITE_SEGMENT
from inference.evaluation.runner import clip_input, synthetic_motion
from inference.features.layout import N_FEATURES
from inference.model.config import ModelConfig
from inference.model.files import LoadedModel, build_model, load_model, save_model
from inference.poser.batched import reconstruct_many
from inference.poser.confidence import ConfidenceSettings, SpreadPool, band
from inference.poser.models import DEFAULT_WEIGHTS, resolve_model
from inference.poser.poser import Poser, reconstruct_offline

THREE = ("pelvis", "l_wrist", "r_wrist")
SHIPPED = dict(history="measured", noise="mean", inpaint_mode="replace-ddim")


def _tiny(seed: int = 0) -> LoadedModel:
    torch.manual_seed(seed)
    cfg = ModelConfig.tiny()
    return LoadedModel(model=build_model("diffusion", cfg).eval(), kind="diffusion", config=cfg,
                       norm_mean=np.zeros(N_FEATURES, np.float32), norm_std=np.ones(N_FEATURES, np.float32))


@pytest.fixture(scope="module")
def clip():
    m = synthetic_motion(seconds=2.0, seed=3)
    return m, clip_input(m, THREE)


def _measured_segments(sites) -> list[int]:
    return [SEGMENT_INDEX[SITE_SEGMENT[s]] for s in sites]


@pytest.mark.parametrize("settings", [ConfidenceSettings(), ConfidenceSettings(draws=3, every=2, pool=5)])
def test_the_pose_is_the_same_with_confidence_on_or_off(clip, settings):
    m, inp = clip
    model = _tiny()
    off = reconstruct_offline(Poser(model, body=m.body, steps=3, **SHIPPED), inp.features, inp.mask)
    on = reconstruct_offline(Poser(model, body=m.body, steps=3, confidence=settings, **SHIPPED), inp.features,
                             inp.mask)
    for name in ("rot", "root", "joints", "contacts", "contact_prob", "features"):
        assert np.array_equal(getattr(off, name), getattr(on, name)), name
    assert np.isnan(off.spread_deg).all() and np.isnan(off.root_spread_m).all()
    assert np.isfinite(on.spread_deg).all() and np.isfinite(on.root_spread_m).all()
    measured = _measured_segments(THREE)
    assert np.all(on.spread_deg[:, measured] == 0.0)
    assert np.all(np.delete(on.spread_deg, measured, axis=1).mean(axis=0) > 0.0)


def test_spread_is_held_between_computed_frames_and_reset_restarts_it(clip):
    m, inp = clip
    p = Poser(_tiny(), body=m.body, steps=2, confidence=ConfidenceSettings(every=3), **SHIPPED)
    frames = [p.step(inp.features[t], inp.mask[t]) for t in range(7)]
    assert np.array_equal(frames[1].spread_deg, frames[0].spread_deg)
    assert np.array_equal(frames[2].spread_deg, frames[0].spread_deg)
    assert not np.array_equal(frames[3].spread_deg, frames[0].spread_deg)
    p.reset()
    again = p.step(inp.features[0], inp.mask[0])
    assert np.array_equal(again.spread_deg, frames[0].spread_deg)


def test_no_confidence_for_models_that_draw_nothing(clip):
    m, inp = clip
    p = Poser(None, body=m.body, confidence=True)
    assert p.confidence is None and p.step(inp.features[0], inp.mask[0]).spread_deg is None


def test_a_student_file_draws_with_the_model_it_names(clip, tmp_path):
    """A chain student's pose is its own; its draws are the named teacher's calls near that
    pose, frame by frame and in lock step alike."""
    m, inp = clip
    student, teacher = _tiny(0), _tiny(1)
    path = tmp_path / "teacher.pt"
    save_model(path, teacher.model, "diffusion", teacher.norm_mean, teacher.norm_std)
    named = replace(student, meta={"draws_from": str(path)})
    settings = ConfidenceSettings(draws=2)

    def run(model, draw_model=None):
        p = Poser(model, body=m.body, steps=3, confidence=settings, **SHIPPED)
        if draw_model is not None:  # the reference: the teacher's net put in by hand
            p.draw_model = draw_model
            p._draw_net = p.draw_net_for(settings.draws)
        return reconstruct_offline(p, inp.features, inp.mask)

    got, own = run(named), run(student)
    assert np.array_equal(got.rot, own.rot) and np.array_equal(got.root, own.root)
    assert not np.allclose(got.spread_deg, own.spread_deg)
    ref = run(student, load_model(path))
    assert np.array_equal(got.spread_deg, ref.spread_deg)
    assert np.array_equal(got.root_spread_m, ref.root_spread_m)
    [many] = reconstruct_many([Poser(named, body=m.body, steps=3, confidence=settings, **SHIPPED)],
                              [(inp.features, inp.mask)])
    assert np.allclose(many.spread_deg, got.spread_deg, atol=1e-2)


def test_a_draws_model_that_reads_other_features_is_refused(clip, tmp_path):
    m, _ = clip
    teacher = _tiny(1)
    path = tmp_path / "teacher.pt"
    save_model(path, teacher.model, "diffusion", teacher.norm_mean + 1.0, teacher.norm_std)
    with pytest.raises(ValueError, match="draws_from"):
        Poser(replace(_tiny(0), meta={"draws_from": str(path)}), body=m.body, confidence=True, **SHIPPED)
    with pytest.raises(FileNotFoundError, match="missing"):
        Poser(replace(_tiny(0), meta={"draws_from": str(tmp_path / "gone.pt")}), body=m.body, confidence=True)


def test_spread_pool_is_the_mean_of_the_latest_draws():
    pool = SpreadPool(3)
    for k in range(5):
        pool.add(np.full((1, 24), float(k)), np.array([k / 10]))
    assert np.allclose(pool.spread_deg, 3.0) and pool.root_spread_m == pytest.approx(0.3)
    pool.add(np.stack([np.zeros(24), np.full(24, 9.0)]), np.array([0.0, 0.0]))
    assert np.allclose(pool.spread_deg, (4 + 0 + 9) / 3)


def test_bands_have_a_floor_and_grow_with_the_spread():
    assert band(0.0, 0.9) > 0 and band(10.0, 0.9) > band(10.0, 0.5) > band(1.0, 0.5)
    with pytest.raises(ValueError):
        band(1.0, 0.7)


@pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")
def test_shipped_model_is_surer_of_measured_segments_than_of_open_ones():
    m = synthetic_motion(seconds=2.5, seed=5)
    inp = clip_input(m, THREE)
    rec = reconstruct_offline(Poser(resolve_model("diffusion"), body=m.body, confidence=True), inp.features, inp.mask)
    spread = rec.spread_deg[10:].mean(axis=0)
    measured = _measured_segments(THREE)
    open_ = [SEGMENT_INDEX[s] for s in ("l_upperarm", "r_upperarm", "l_thigh", "r_thigh", "head")]
    assert spread[measured].max() < 0.5 < spread[open_].min()
