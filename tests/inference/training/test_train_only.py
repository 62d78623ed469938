"""``TrainConfig.train_only``: a stage grown onto a trained model (a position input) starts as
the model it grew from, and a run can train that stage alone, so that the file it grew from
is its exact control; a selection that names no parameter is refused."""

from __future__ import annotations

from dataclasses import replace

import torch

from inference.features.layout import N_FEATURES, WINDOW
from inference.model.config import ModelConfig
from inference.model.files import build_model
from inference.training.config import TrainConfig
from inference.training.loop import param_groups


def test_a_grown_model_starts_as_the_model_it_grew_from_and_trains_the_stage_alone():
    torch.manual_seed(0)
    base_cfg = replace(ModelConfig.tiny(), mask_input=True)
    plain = build_model("diffusion", base_cfg).eval()
    grown = build_model("diffusion", replace(base_cfg, points=True)).eval()
    grown.load_state_dict({**grown.state_dict(), **plain.state_dict()})
    z, t, h = torch.randn(2, WINDOW, N_FEATURES), torch.tensor([500, 10]), torch.tensor([1.7, 1.8])
    m = torch.rand(2, WINDOW, N_FEATURES) > 0.5
    pts = torch.randn(2, WINDOW, 16)
    with torch.no_grad():
        assert torch.equal(grown(z, t, h, m, points=pts), plain(z, t, h, m))

    groups = param_groups(grown, TrainConfig(train_only=["points_proj."]))
    trained = {id(p) for g in groups for p in g["params"]}
    assert trained == {id(p) for p in grown.points_proj.parameters()}
    assert not any(p.requires_grad for n, p in grown.named_parameters() if not n.startswith("points_proj."))


def test_a_train_only_that_names_nothing_is_refused():
    net = build_model("diffusion", ModelConfig.tiny())
    try:
        param_groups(net, TrainConfig(train_only=["nothing."]))
    except ValueError as e:
        assert "nothing." in str(e)
    else:
        raise AssertionError("an empty train_only selection must be refused")
