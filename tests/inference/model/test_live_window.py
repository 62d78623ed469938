"""A model file that asks for a shorter live window (``meta["window"]``): the network reads
the newest frames of its trained window, each with its own learned position."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from inference.model.config import ModelConfig
from inference.model.files import LoadedModel, ModelFileError, build_model, load_model, save_model, with_window
from inference.poser.poser import Poser


def _tiny(kind: str = "diffusion") -> LoadedModel:
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    return LoadedModel(model=build_model(kind, cfg).eval(), kind=kind, config=cfg,
                       norm_mean=np.zeros(190, np.float32), norm_std=np.ones(190, np.float32))


def test_the_file_window_keeps_the_newest_frames_positions(tmp_path):
    m = _tiny()
    path = tmp_path / "m.pt"
    save_model(path, m.model, "diffusion", m.norm_mean, m.norm_std, meta={"window": 9})
    short = load_model(path)
    full_pos = m.model.state_dict()["pos"]
    assert short.config.window == 9 and short.meta["trained_window"] == m.config.window
    pos = short.model.state_dict()["pos"]
    assert pos.shape[1] == 9 + 2
    assert torch.equal(pos[:, :2], full_pos[:, :2])  # the step and height tokens
    assert torch.equal(pos[:, 2:], full_pos[:, -9:])  # the newest frame keeps the newest position
    # every other weight is the model's own
    for k, v in m.model.state_dict().items():
        if k != "pos":
            assert torch.equal(v, short.model.state_dict()[k]), k
    # asked for explicitly, the whole trained window is the model as trained
    whole = load_model(path, window=m.config.window)
    assert whole.config.window == m.config.window and torch.equal(whole.model.state_dict()["pos"], full_pos)


def test_a_poser_runs_the_short_window_and_its_answer_differs_from_the_long_one():
    m = _tiny()
    short = with_window(m, 5)
    rng = np.random.default_rng(0)
    f = rng.normal(size=(12, 190)).astype(np.float32)
    mask = np.zeros(190, bool)
    mask[:40] = True
    outs = []
    for model in (m, short):
        p = Poser(model, steps=[1000], seed=0)
        assert p.window == model.config.window
        for t in range(12):
            fr = p.step(f[t], mask)
        outs.append(fr.rot)
    assert np.all(np.isfinite(outs[1])) and not np.allclose(outs[0], outs[1])
    assert with_window(m, m.config.window) is m


def test_a_window_the_model_cannot_read_is_a_one_line_error(tmp_path):
    m = _tiny()
    with pytest.raises(ValueError, match="trained on"):
        with_window(m, m.config.window + 1)
    with pytest.raises(ValueError, match="regressor"):
        with_window(_tiny("regressor"), 3)
    path = tmp_path / "bad.pt"
    save_model(path, m.model, "diffusion", m.norm_mean, m.norm_std, meta={"window": m.config.window + 10})
    with pytest.raises(ModelFileError) as err:
        load_model(path)
    assert "bad.pt" in str(err.value) and "\n" not in str(err.value)


def test_a_short_window_keeps_the_history_its_helpers_read():
    """The pelvis odometry reads 39 frames of measured pelvis: with a 21-frame model the
    poser keeps them all the same, so the root walked from the pelvis is the 61-frame
    model's to the bit."""
    from inference.evaluation.runner import clip_input, synthetic_motion
    from inference.poser.models import resolve_model

    model = resolve_model("diffusion", window=61)
    short = with_window(model, 21)
    motion = synthetic_motion(seconds=6.0, seed=1)
    inp = clip_input(motion, ("pelvis", "l_wrist", "r_wrist"))
    roots = []
    for m in (model, short):
        p = Poser(m, body=motion.body, steps=[1000], seed=0, smoothing=False)  # the filter mixes in the height
        assert p._keep >= p._odometry.context > 21 or m is model
        roots.append(np.stack([p.step(inp.features[t], inp.mask[t]).root[:2] for t in range(len(inp.features))]))
    assert np.abs(roots[0][-1]).max() > 0.5  # it walked
    np.testing.assert_array_equal(roots[0], roots[1])
