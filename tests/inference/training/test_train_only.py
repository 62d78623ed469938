"""HAD's hierarchical refinement as a stage of the denoiser (ModelConfig.hmr): the parts
cover the frame, the torso is refined from the torso alone and each limb from the parts
above it, a grown model starts as the model it grew from, and a run can train the stage
alone against that model."""

from __future__ import annotations

from dataclasses import replace

import torch

from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_PZ, SL_ROT, WINDOW
from inference.model.config import ModelConfig
from inference.model.files import build_model
from inference.model.hierarchy import PARTS, HierarchicalRefinement, part_columns
from inference.training.config import TrainConfig
from inference.training.loop import param_groups, train
from tests.inference.training.test_training import TINY, _cfg


def _rot(seg: str) -> int:
    return SL_ROT.start + 6 * SEGMENT_INDEX[seg]


def test_the_parts_cover_the_frame_once_along_the_body():
    cols = part_columns()
    assert sorted(c for p in PARTS for c in cols[p]) == list(range(N_FEATURES))
    where = {c: p for p in PARTS for c in cols[p]}
    assert where[_rot("pelvis")] == where[_rot("head")] == where[SL_PZ.start] == "torso"
    assert where[_rot("l_upperarm")] == where[_rot("r_collar")] == "arms"
    assert where[SL_ACC.start + 3 * SITE_INDEX["l_wrist"]] == "arms"  # the wrist site is on the forearm
    assert where[_rot("r_shank")] == where[_rot("l_toes")] == where[SL_CONTACT.start] == "legs"
    assert where[SL_ACC.start + 3 * SITE_INDEX["torso"]] == "torso"


def test_each_part_is_refined_from_itself_and_the_parts_above_it():
    torch.manual_seed(0)
    hmr = HierarchicalRefinement(16)
    x = torch.randn(1, 4, N_FEATURES)
    assert torch.equal(hmr(x), x)  # zero at first
    for head in hmr.heads.values():
        torch.nn.init.normal_(head.weight, std=0.1)
    cols = {p: torch.as_tensor(c) for p, c in part_columns().items()}
    base = hmr(x)

    def changed(src: str) -> set[str]:
        y = x.clone()
        y[..., cols[src]] += 1.0
        out = hmr(y) - y  # the correction alone
        ref = base - x
        return {p for p in PARTS if not torch.allclose(out[..., cols[p]], ref[..., cols[p]], atol=1e-6)}

    assert changed("torso") == {"torso", "arms", "legs"}
    assert changed("arms") == {"arms", "legs"}
    assert changed("legs") == {"legs"}


def test_a_grown_model_starts_as_the_model_it_grew_from_and_trains_the_stage_alone(tmp_path):
    torch.manual_seed(0)
    base_cfg = replace(ModelConfig.tiny(), mask_input=True)
    plain = build_model("diffusion", base_cfg).eval()
    grown = build_model("diffusion", replace(base_cfg, hmr=True)).eval()
    grown.load_state_dict({**grown.state_dict(), **plain.state_dict()})
    z, t, h = torch.randn(2, WINDOW, N_FEATURES), torch.tensor([500, 10]), torch.tensor([1.7, 1.8])
    m = torch.rand(2, WINDOW, N_FEATURES) > 0.5
    with torch.no_grad():
        assert torch.equal(grown(z, t, h, m), plain(z, t, h, m))

    groups = param_groups(grown, TrainConfig(train_only=["hmr."]))
    trained = {id(p) for g in groups for p in g["params"]}
    assert trained == {id(p) for p in grown.hmr.parameters()}
    assert not any(p.requires_grad for n, p in grown.named_parameters() if not n.startswith("hmr."))

    # --init from a run without the stage: the trunk stays the source's, the stage learns
    train(_cfg(steps=2), tmp_path / "base", progress=False)
    src = torch.load(tmp_path / "base" / "last.pt", weights_only=False)
    train(_cfg(steps=3, lr=1e-2, model={**TINY, "hmr": True}, train_only=["hmr."]), tmp_path / "hmr",
          progress=False, init_from=tmp_path / "base" / "last.pt")
    out = torch.load(tmp_path / "hmr" / "last.pt", weights_only=False)["model"]
    for k, v in src["ema"].items():
        assert torch.equal(out[k], v), k
    assert any(out[k].abs().sum() > 0 for k in out if k.startswith("hmr.heads."))


def test_a_train_only_that_names_nothing_is_refused():
    net = build_model("diffusion", ModelConfig.tiny())
    try:
        param_groups(net, TrainConfig(train_only=["nothing."]))
    except ValueError as e:
        assert "nothing." in str(e)
    else:
        raise AssertionError("an empty train_only selection must be refused")
