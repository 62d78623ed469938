"""Denoiser and regressor: shapes, conditioning, the paper size, model files."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import torch

from inference.features.layout import N_FEATURES, WINDOW, observation_mask
from inference.model.config import ModelConfig, count_parameters
from inference.model.denoiser import Denoiser, timestep_embedding
from inference.model.files import build_model, load_model, save_model
from inference.model.regressor import MaskConfig, Regressor, random_observation_mask, regress
from tests.conftest import F32_PATHS


def _inputs(b=2, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(b, WINDOW, N_FEATURES, generator=g), torch.tensor([10, 900][:b]), torch.tensor([1.6, 1.9][:b])


def test_shapes_and_conditioning():
    torch.manual_seed(0)
    m = Denoiser(ModelConfig.tiny()).eval()
    z, t, h = _inputs()
    with torch.no_grad():
        y = m(z, t, h)
        assert y.shape == z.shape
        # the step and the height both change the prediction (they are really used)
        assert not torch.allclose(y, m(z, t + 50, h))
        assert not torch.allclose(y, m(z, t, h + 0.2))
        # shorter windows work too (positions are sliced)
        assert m(z[:, :20], t, h).shape == (2, 20, N_FEATURES)
    assert timestep_embedding(t, 33).shape == (2, 33)


def test_memory_tokens_feed_cross_and_self_attention():
    m = Denoiser(ModelConfig.tiny()).eval()
    seen = {}
    layer = m.decoder.layers[0]
    orig = layer.forward

    def spy(tgt, memory, *a, **k):
        seen["tgt"], seen["memory"] = tgt.shape, memory.shape
        return orig(tgt, memory, *a, **k)

    layer.forward = spy
    z, t, h = _inputs()
    m(z, t, h)  # with grad: the nn.TransformerDecoder path (the lean path is pinned to it below)
    assert seen["memory"] == (2, 2, 32)  # step + height tokens as cross-attention memory
    assert seen["tgt"] == (2, WINDOW + 2, 32)  # ... and prepended for self-attention


def test_paper_size_constructs():
    cfg = ModelConfig.paper()
    assert (cfg.layers, cfg.d_model, cfg.ff) == (8, 512, 2048)
    m = Denoiser(cfg)
    assert len(m.decoder.layers) == 8
    assert 30e6 < count_parameters(m) < 40e6


def test_regressor_shapes_and_mask_use():
    torch.manual_seed(0)
    r = Regressor(ModelConfig.tiny()).eval()
    x, _, h = _inputs()
    mask = torch.zeros_like(x, dtype=torch.bool)
    mask[:, :, :12] = True
    with torch.no_grad():
        y = r(x, mask, h)
        assert y.shape == x.shape
        # unobserved inputs are ignored ...
        x2 = x.clone()
        x2[~mask] = 99.0
        assert torch.allclose(y, r(x2, mask, h))
        # ... and the mask itself is an input
        assert not torch.allclose(y, r(x, ~mask, h))
    out = regress(r, x, mask, h)
    assert torch.equal(out[mask], x[mask])


def test_random_masks():
    rng = np.random.default_rng(0)
    cfg = MaskConfig(p_history_known=1.0)
    m = random_observation_mask(rng, 16, WINDOW, cfg)
    assert m.shape == (16, WINDOW, N_FEATURES) and m.dtype == bool
    assert m[:, :-1].all()
    m = random_observation_mask(rng, 64, WINDOW, MaskConfig(p_history_known=0.0, p_frame_drop=0.0, p_burst=0.0,
                                                            p_site_drop=0.0))
    site_union = np.zeros(N_FEATURES, bool)
    for s in ("pelvis", "torso", "head", "l_upperarm", "r_upperarm", "l_wrist", "r_wrist", "l_thigh",
              "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot"):
        site_union |= observation_mask([s], insoles=True)
    assert not (m & ~site_union).any()  # only sensor-observable features are ever observed
    assert (m == m[:, :1]).all()  # no dropouts asked for: constant over time
    sizes = {int(x[0].sum()) for x in m}
    assert len(sizes) > 3  # varied subsets


def test_save_load_roundtrip(tmp_path):
    for kind in ("diffusion", "regressor"):
        torch.manual_seed(0)
        m = build_model(kind, ModelConfig.tiny()).eval()
        mean, std = np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32) * 2
        for fp16 in (False, True):
            p = tmp_path / f"{kind}{fp16}.pt"
            save_model(p, m, kind, mean, std, step=7, fp16=fp16)
            lm = load_model(p)
            assert lm.kind == kind and lm.step == 7 and lm.config == m.config
            x = torch.ones(1, 3, N_FEATURES)
            assert torch.allclose(lm.denormalize(lm.normalize(x)), x)
            for (k, a), b in zip(m.state_dict().items(), lm.model.state_dict().values()):
                assert b.dtype == a.dtype, k
                assert torch.allclose(a, b, atol=1e-2 if fp16 else 0), k


def test_lean_inference_path_matches_modules():
    torch.manual_seed(1)
    m = Denoiser(ModelConfig(layers=2, d_model=64, heads=4, ff=128, dropout=0.3)).eval()
    z, t, h = _inputs()
    ref = m(z, t, h)  # grad enabled: the nn.TransformerDecoder path
    with torch.inference_mode():
        lean = m(z, t, h)
    assert torch.allclose(ref, lean, **F32_PATHS)


def test_bfloat16_model_runs():
    m = Denoiser(ModelConfig.tiny()).eval().to(torch.bfloat16)
    z, t, h = _inputs()
    with torch.inference_mode():
        y = m(z.bfloat16(), t, h.bfloat16())
    assert y.dtype == torch.bfloat16 and y.shape == z.shape


def test_freeze_for_cpu_same_outputs():
    from inference.model.denoiser import freeze_for_cpu
    from inference.model.diffusion import inpaint, paper_steps

    torch.manual_seed(0)
    m = Denoiser(ModelConfig.tiny()).eval()
    f = freeze_for_cpu(m)
    z, t, h = _inputs(1)
    with torch.inference_mode():
        assert torch.allclose(f(z, t, h), m(z, t, h), **F32_PATHS)
    mask = torch.ones_like(z, dtype=torch.bool)
    mask[:, -1] = False
    a = inpaint(m, z, mask, h, paper_steps(), generator=torch.Generator().manual_seed(0))
    b = inpaint(f, z, mask, h, paper_steps(), generator=torch.Generator().manual_seed(0))
    assert torch.allclose(a, b, atol=1e-4)


def test_skip_parameterisation_passes_clean_input_through_and_round_trips(tmp_path):
    """With skip=True a clean window (t = 0) comes back exactly; at the top level the
    output is the network's alone. The flag survives save/load."""
    from inference.model.config import ModelConfig
    from inference.model.denoiser import Denoiser
    from inference.model.files import load_model, save_model

    torch.manual_seed(0)
    cfg = ModelConfig(layers=1, d_model=32, heads=2, ff=64, dropout=0.0, skip=True)
    m = Denoiser(cfg).eval()
    z = torch.randn(2, cfg.window, 190)
    h = torch.tensor([1.7, 1.8])
    with torch.no_grad():
        assert torch.equal(m(z, torch.tensor([0, 0]), h), z)
        top = m(z, torch.tensor([cfg.T, cfg.T]), h)
        plain = Denoiser(ModelConfig(layers=1, d_model=32, heads=2, ff=64, dropout=0.0))
        plain.load_state_dict(m.state_dict())
        assert torch.allclose(top, plain.eval()(z, torch.tensor([cfg.T, cfg.T]), h), atol=1e-3)
    path = tmp_path / "m.pt"
    save_model(path, m, "diffusion", np.zeros(190, np.float32), np.ones(190, np.float32))
    back = load_model(path)
    assert back.config.skip
    with torch.no_grad():
        assert torch.allclose(back.model(z, torch.tensor([500, 3]), h), m(z, torch.tensor([500, 3]), h), **F32_PATHS)


def test_mask_input_model_reads_the_mask_traced_or_not():
    """mask_input: the same window with a different known/unknown mask gives a different
    prediction; the frozen trace and inpainting pass the mask the same way."""
    from inference.model.denoiser import freeze_for_cpu
    from inference.model.diffusion import inpaint, paper_steps, wants_mask

    torch.manual_seed(0)
    m = Denoiser(replace(ModelConfig.tiny(), mask_input=True)).eval()
    assert wants_mask(m) and not wants_mask(Denoiser(ModelConfig.tiny()))
    z, t, h = _inputs(1)
    mask = torch.ones_like(z, dtype=torch.bool)
    mask[:, -1] = False
    with torch.inference_mode():
        a, b = m(z, t, h, mask), m(z, t, h, ~mask)
        assert not torch.allclose(a, b)
        assert torch.equal(m(z, t, h), m(z, t, h, torch.zeros_like(mask)))  # None = nothing known
        f = freeze_for_cpu(m)
        assert torch.allclose(f(z, t, h, mask), a, **F32_PATHS)
    x = inpaint(m, z, mask, h, paper_steps(), generator=torch.Generator().manual_seed(0), mode="replace")
    y = inpaint(f, z, mask, h, paper_steps(), generator=torch.Generator().manual_seed(0), mode="replace",
                mask_input=True)
    assert torch.allclose(x, y, atol=1e-4)


def test_a_bypass_starts_at_zero_and_adds_a_linear_map_of_the_input(tmp_path):
    """The bypass (``ModelConfig.bypass``): grown onto a trained network it changes nothing
    until trained; trained, each frame's output gains a linear map of that frame's input and
    mask, and the file round trip keeps it."""
    torch.manual_seed(0)
    base = replace(ModelConfig.tiny(), mask_input=True)
    plain = build_model("diffusion", base).eval()
    grown = build_model("diffusion", replace(base, bypass=True)).eval()
    grown.load_state_dict({**grown.state_dict(), **plain.state_dict()})
    z, t, h = _inputs()
    m = torch.rand(z.shape) > 0.5
    with torch.no_grad():
        assert torch.equal(grown(z, t, h, m), plain(z, t, h, m))
        torch.nn.init.normal_(grown.bypass.weight, std=0.1)
        inp = torch.cat([z, m.float()], dim=-1)
        want = plain(z, t, h, m) + inp @ grown.bypass.weight.T + grown.bypass.bias
        assert torch.allclose(grown(z, t, h, m), want, **F32_PATHS)
    save_model(tmp_path / "b.pt", grown, "diffusion", np.zeros(N_FEATURES), np.ones(N_FEATURES))
    back = load_model(tmp_path / "b.pt")
    assert back.config.bypass
    with torch.no_grad():
        assert torch.equal(back.model(z, t, h, m), grown(z, t, h, m))
