"""The one place that decides which model a run poses with and on how many torch threads
(app/live/model_choice.py): the floor fallback a live session takes and nothing else does, the
low mode's own model, the live default's file for the sensors worn, the label a replay matches
recordings by, the thread count."""

from __future__ import annotations

import pytest

from app.live import latency
from app.live.model_choice import (
    FLOOR_FALLBACK_LABEL,
    KEEP_UP_SKIPPED,
    choose_model,
    keep_up_advice,
    load_model,
    model_label,
    set_torch_threads,
)
from inference.poser.models import DEFAULT_WEIGHTS, MODEL_NAMES, model_for_sites


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


def test_a_session_that_did_not_keep_up_is_told_the_lever_for_its_model():
    assert keep_up_advice(1000, 0, "diffusion") is None
    assert keep_up_advice(1000, int(KEEP_UP_SKIPPED * 1000), "diffusion") is None  # within the share
    assert keep_up_advice(40, 30, "diffusion") is None  # too short to say anything of the machine
    line = keep_up_advice(900, 100, "diffusion")
    assert line.startswith("10 % of the poses were skipped") and "--model fast" in line and "\n" not in line
    other = keep_up_advice(900, 100, "fast")
    assert "--model fast" not in other and "fewer diffusion steps" in other


@pytest.mark.skipif(not DEFAULT_WEIGHTS["fast"].exists(), reason="fast weights not installed")
def test_the_fast_model_is_a_short_chain_whose_draws_come_from_the_default():
    """The fast file reads a third of the default's frames, one window a pose (no mirror
    image), with the default's three levels; its confidence draws are the default's calls."""
    model, label, warning = load_model("fast")
    default, _, _ = load_model("diffusion")
    assert warning is None and label.endswith("(diffusionposer_fast.pt)")
    assert 3 * model.config.window <= default.config.window + 2 and model.meta["draws_from"] == "diffusion"
    assert not model.meta.get("mirror") and model.meta["default_steps"] == "10D:3"


def test_the_live_default_is_the_fast_file_except_below_a_thigh_worn_without_its_shank(monkeypatch, tmp_path):
    """"auto" is the 21-frame file wherever it is as good as the full model on the real logs,
    and the full model where a worn thigh has no shank below it (its feet lose there); the
    low mode keeps its own model; any other name is left alone."""
    six = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
    assert model_for_sites("auto", six) == "fast"
    assert model_for_sites("auto", ("pelvis", "l_wrist", "r_wrist")) == "fast"
    assert model_for_sites("auto", ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank")) == "fast"
    assert model_for_sites("auto", ("pelvis", "l_thigh", "r_thigh")) == "diffusion"
    assert model_for_sites("auto", ("pelvis", "l_thigh", "l_shank", "r_thigh")) == "diffusion"  # one leg is enough
    assert model_for_sites("auto") == "fast"  # sites unknown
    assert model_for_sites("diffusion", ("l_thigh",)) == "diffusion" and model_for_sites("x.pt", six) == "x.pt"
    assert "auto" in MODEL_NAMES
    monkeypatch.setattr(latency, "causal_weights", lambda: tmp_path / "causal.pt")
    (tmp_path / "causal.pt").write_bytes(b"")
    assert latency.model_spec_for("low", "auto") == str(tmp_path / "causal.pt")
    assert latency.model_spec_for("centred", "auto") == "auto"
    if not (DEFAULT_WEIGHTS["fast"].exists() and DEFAULT_WEIGHTS["diffusion"].exists()):
        pytest.skip("shipped weights not installed")
    fast = choose_model("auto", "centred", sites=six)
    full = choose_model("auto", "centred", sites=("pelvis", "l_thigh", "r_thigh"))
    assert fast.spec == "fast" and fast.label.endswith("(diffusionposer_fast.pt)")
    assert full.spec == "diffusion" and full.label.endswith("(diffusionposer.pt)")
