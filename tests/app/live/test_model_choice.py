"""The one place that decides which model a run poses with and on how many torch threads
(app/live/model_choice.py): the floor fallback a live session takes and nothing else does, the
low mode's own model, the label a replay matches recordings by, the thread count."""

from __future__ import annotations

import pytest

from app.live import latency
from app.live.model_choice import FLOOR_FALLBACK_LABEL, choose_model, load_model, model_label, set_torch_threads
from inference.poser.models import DEFAULT_WEIGHTS


def test_missing_weights_fall_back_to_floor_loudly_only_when_asked(monkeypatch, tmp_path):
    from inference.poser import models as poser

    monkeypatch.setitem(poser.DEFAULT_WEIGHTS, "diffusion", tmp_path / "nope.pt")
    model, label, warning = load_model("diffusion", fallback=True)
    assert model is None and label == FLOOR_FALLBACK_LABEL and "NO TRAINED MODEL" in warning
    choice = choose_model("diffusion", "centred", fallback=True)
    assert choice.model is None and choice.label == FLOOR_FALLBACK_LABEL and "NO TRAINED MODEL" in choice.warning
    with pytest.raises(FileNotFoundError):
        load_model("diffusion")  # a replay or a benchmark wants the error
    with pytest.raises(FileNotFoundError):
        load_model(str(tmp_path / "also_missing.pt"), fallback=True)  # a path given is never replaced


def test_the_shipped_model_is_labelled_by_kind_size_and_file():
    if not DEFAULT_WEIGHTS["diffusion"].exists():
        pytest.skip("shipped diffusion weights not installed")
    choice = choose_model("diffusion", "centred")
    c = choice.model.config
    assert choice.label == f"diffusion {c.layers}/{c.d_model}/{c.ff} ({DEFAULT_WEIGHTS['diffusion'].name})"
    assert choice.label == model_label("diffusion", choice.model)
    assert choice.causal == (latency.model_filter(choice.model) == "causal")
    again = choose_model("diffusion", "centred", loaded=choice.model)  # a model loaded once, reused
    assert again.model is choice.model and again.label == choice.label


def test_the_low_mode_runs_its_own_model_when_installed(monkeypatch, tmp_path):
    monkeypatch.setattr(latency, "causal_weights", lambda: tmp_path / "causal.pt")
    assert choose_model("floor", "low").spec == "floor"
    assert choose_model("floor", "low").causal  # the low mode always filters causally
    (tmp_path / "causal.pt").write_bytes(b"")
    with pytest.raises(Exception):  # noqa: B017 - the empty file is taken as the model and fails to load
        choose_model("diffusion", "low")
    assert choose_model("floor", "centred").label == "floor" and not choose_model("floor", "centred").causal


def test_thread_count():
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    try:
        set_torch_threads(1)
        assert torch.get_num_threads() == 1
        set_torch_threads(0)  # leaves torch's own choice alone
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
