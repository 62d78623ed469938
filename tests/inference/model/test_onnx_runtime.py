"""The live model call through ONNX Runtime answers as torch does (to float rounding), the
poser uses it only when asked, and falls back to torch without onnxruntime."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from inference.features.layout import N_FEATURES
from inference.features.mirror import MirrorAveraged
from inference.model import onnx_runtime
from inference.model.config import ModelConfig
from inference.model.files import LoadedModel, build_model
from inference.poser.poser import Poser


def _tiny(mask_input: bool = True, bypass: bool = False) -> LoadedModel:
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    cfg.mask_input, cfg.bypass = mask_input, bypass
    rng = np.random.default_rng(0)
    net = build_model("diffusion", cfg).eval()
    if bypass:  # trained: not the zeros it starts at
        torch.nn.init.normal_(net.bypass.weight, std=0.05)
    return LoadedModel(model=net, kind="diffusion", config=cfg,
                       norm_mean=rng.normal(size=N_FEATURES).astype(np.float32),
                       norm_std=rng.uniform(0.5, 2.0, N_FEATURES).astype(np.float32))


needs_ort = pytest.mark.skipif(not onnx_runtime.onnxruntime_available(), reason="onnx or onnxruntime is not installed")


@needs_ort
@pytest.mark.parametrize("mirror,bypass", [(False, False), (True, False), (False, True)])
def test_onnx_net_matches_the_torch_model(mirror, bypass):
    m = _tiny(bypass=bypass)
    module = MirrorAveraged(m.model, m.norm_mean, m.norm_std) if mirror else m.model
    net = onnx_runtime.OnnxNet(module, 1, m.config.window, N_FEATURES, mask_input=True)
    g = torch.Generator().manual_seed(1)
    z = torch.randn(1, m.config.window, N_FEATURES, generator=g)
    mask = torch.rand(1, m.config.window, N_FEATURES, generator=g) > 0.5
    for level in (1000, 400, 0):
        t, h = torch.tensor([level]), torch.tensor([1.8])
        with torch.no_grad():
            want = module(z, t, h, mask)
        got = net(z, t, h, mask)
        assert got.shape == want.shape and got.dtype == torch.float32
        np.testing.assert_allclose(got.numpy(), want.numpy(), atol=1e-4, rtol=1e-4)


@needs_ort
@pytest.mark.parametrize("batch", [1, 2])
def test_the_live_inpainting_on_numpy_is_the_torch_loops(batch):
    """``inpaint`` with a network that answers numpy (``OnnxNet.run_np``) runs its
    replace-DDIM chain from the mean on numpy: the same answers as the torch loop over the
    same network, the known entries exactly as given."""
    from inference.model.diffusion import inpaint, parse_steps, symmetric_start

    m = _tiny()
    net = onnx_runtime.OnnxNet(m.model, batch, m.config.window, N_FEATURES, mask_input=True)

    class TorchOnly:  # the same network without the numpy call: inpaint's torch loop
        config = m.config

        def __call__(self, *a):
            return net(*a)

    g = torch.Generator().manual_seed(3)
    x = torch.randn(batch, m.config.window, N_FEATURES, generator=g)
    mask = torch.rand(batch, m.config.window, N_FEATURES, generator=g) > 0.6
    h = torch.full((batch,), 1.7)
    kw = {"mode": "replace-ddim", "start": "mean", "mask_input": True}
    calls = []
    run_np = net.run_np
    net.run_np = lambda *a: calls.append(a[1].tolist()) or run_np(*a)
    got = inpaint(net, x, mask, h, parse_steps("10D:3"), **kw)
    assert calls == [[1000] * batch, [400] * batch, [0] * batch]  # the numpy path, one call a level
    want = inpaint(TorchOnly(), x, mask, h, parse_steps("10D:3"), **kw)
    assert got.dtype == torch.float32 and got.shape == want.shape
    np.testing.assert_allclose(got.numpy(), want.numpy(), atol=1e-5, rtol=1e-5)
    assert torch.equal(got[mask], x[mask])
    # a start elsewhere than the data mean (``start_at``): both paths alike, and it changes the answer
    at = torch.as_tensor(symmetric_start(m.norm_mean, m.norm_std))
    got_at = inpaint(net, x, mask, h, parse_steps("10D:3"), start_at=at, **kw)
    want_at = inpaint(TorchOnly(), x, mask, h, parse_steps("10D:3"), start_at=at, **kw)
    np.testing.assert_allclose(got_at.numpy(), want_at.numpy(), atol=1e-5, rtol=1e-5)
    assert torch.equal(got_at[mask], x[mask]) and not torch.allclose(got_at, got, atol=1e-4)
    # the other modes keep the torch loop
    assert torch.equal(inpaint(net, x, mask, h, [1000, 0], mode="replace", start="mean", mask_input=True),
                       inpaint(TorchOnly(), x, mask, h, [1000, 0], mode="replace", start="mean", mask_input=True))


@needs_ort
def test_poser_steps_alike_on_both_runtimes():
    m = _tiny()
    rng = np.random.default_rng(2)
    p_t = Poser(m, body=1.75, steps="3", runtime="torch", contact_detector=None, pelvis_odometry=None)
    p_o = Poser(m, body=1.75, steps="3", runtime="onnx", contact_detector=None, pelvis_odometry=None)
    assert (p_t.runtime, p_o.runtime) == ("torch", "onnx")
    assert isinstance(p_o._net, onnx_runtime.OnnxNet) and not isinstance(p_t._net, onnx_runtime.OnnxNet)
    mask = np.zeros(N_FEATURES, bool)
    mask[:60] = True
    for _ in range(4):
        x = rng.normal(size=N_FEATURES) * 0.1
        a, b = p_t.step(x, mask), p_o.step(x, mask)
        np.testing.assert_allclose(a.rot, b.rot, atol=2e-3)


def test_runtime_choice(monkeypatch):
    assert onnx_runtime.resolve_runtime("torch") == "torch"
    with pytest.raises(ValueError):
        onnx_runtime.resolve_runtime("tpu")
    monkeypatch.setattr(onnx_runtime, "onnxruntime_available", lambda: False)
    monkeypatch.delenv("IMUCAP_RUNTIME", raising=False)
    assert onnx_runtime.resolve_runtime("auto") == "torch"  # the fallback without onnxruntime
    with pytest.raises(ImportError):
        onnx_runtime.resolve_runtime("onnx")
    monkeypatch.setattr(onnx_runtime, "onnxruntime_available", lambda: True)
    assert onnx_runtime.resolve_runtime("auto") == "onnx"
    monkeypatch.setenv("IMUCAP_RUNTIME", "torch")
    assert onnx_runtime.resolve_runtime("auto") == "torch"
    # offline runs never ask: a poser keeps torch unless told
    assert Poser(_tiny(), body=1.75, steps="2", contact_detector=None, pelvis_odometry=None).runtime == "torch"


def test_the_symmetric_start_is_its_own_mirror_image_and_the_poser_reads_it_from_the_file():
    """``symmetric_start``: the data mean's midpoint with its mirror image, in the normaliser's
    units, is its own mirror image (the data mean is not); a file's meta turns it on."""
    from inference.features.mirror import mirror_features
    from inference.model.diffusion import symmetric_start

    m = _tiny()
    mu = torch.as_tensor(m.norm_mean).reshape(1, 1, -1)
    sd = torch.as_tensor(m.norm_std).reshape(1, 1, -1)
    c = torch.as_tensor(symmetric_start(m.norm_mean, m.norm_std)).reshape(1, 1, -1)
    start = mu + sd * c
    torch.testing.assert_close(mirror_features(start), start, atol=1e-5, rtol=1e-5)
    assert not torch.allclose(mirror_features(mu), mu, atol=1e-3)
    assert Poser(m, body=1.75, contact_detector=None, pelvis_odometry=None).start_at is None
    m.meta = {"symmetric_start": True, "noise": "mean"}  # the mean start it moves
    p = Poser(m, body=1.75, contact_detector=None, pelvis_odometry=None)
    torch.testing.assert_close(p.start_at, c.reshape(-1))
    assert Poser(m, body=1.75, contact_detector=None, pelvis_odometry=None, symmetric_start=False).start_at is None


@needs_ort
def test_an_int8_file_runs_its_quantized_graph_one_window_a_call_offline_as_live(monkeypatch):
    """A file whose meta says ``int8`` runs ONNX Runtime's int8 graph whatever runtime the
    caller asked for (an offline evaluation scores what runs live). Its activations are
    quantized over the whole input, so a batch of windows would change each window's answer:
    offline the windows go one a call (``PerWindowNet``), and lanes of clips answer exactly as
    each clip frame by frame. The answer is near the float network's, not equal to it; without
    onnxruntime the float network runs, with a warning."""
    import warnings

    from inference.poser import poser as poser_module
    from inference.poser.batched import reconstruct_many
    from inference.poser.poser import reconstruct_offline

    m = _tiny()
    m.meta = {"int8": True, "noise": "mean", "history": "measured", "inpaint_mode": "replace-ddim"}
    kw = dict(body=1.75, steps="3", contact_detector=None, pelvis_odometry=None)
    p = Poser(m, runtime="torch", **kw)
    assert p.int8 and p.runtime == "onnx" and p._net.quantized
    assert isinstance(p.net_for(4), onnx_runtime.PerWindowNet)
    rng = np.random.default_rng(3)
    mask = np.zeros(N_FEATURES, bool)
    mask[:60] = True
    clips = [(rng.normal(size=(30, N_FEATURES)) * 0.2, mask) for _ in range(3)]
    one = [reconstruct_offline(Poser(m, **kw), f, mk) for f, mk in clips]
    many = reconstruct_many([Poser(m, **kw) for _ in clips], clips, lanes=3)
    for a, b in zip(one, many):
        np.testing.assert_array_equal(a.rot, b.rot)
    flat = reconstruct_offline(Poser(m, int8=False, **kw), *clips[0])
    gap = np.abs(flat.rot - one[0].rot).max()
    assert 1e-5 < gap < 0.2, gap
    monkeypatch.setattr(poser_module, "onnxruntime_available", lambda: False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        p = Poser(m, **kw)
    assert not p.int8 and p.runtime == "torch" and any("int8" in str(w.message) for w in caught)
