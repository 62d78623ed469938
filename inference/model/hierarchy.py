"""HAD's hierarchical motion refinement (Niu et al., Sec. 3.2, "Hierarchical Motion
Refinement") as an optional output stage of the denoiser.

Why: HAD refines a coarse whole-body prediction part by part along the body's tree, the
torso first, then the arms given the torso, then the legs given both, on the argument that
a limb's pose only makes sense relative to the trunk it hangs from. Here the coarse
prediction is the transformer's output window; each part of it is encoded per frame
(linear, GELU, linear: the paper's "linear layer, BasicBlock and linear layer"), and
each part's correction is read from its own code and the codes of the parts above it:

    torso' = FC(f_torso), arms' = FC(f_torso | f_arms), legs' = FC(f_torso | f_arms | f_legs)

The corrections are added to the coarse output (a residual, where HAD replaces it) and
their last layers start at zero, so a model grown with this stage (``ModelConfig.hmr``)
starts as the model it was grown from, and a fine-tune can train the stage alone
(``TrainConfig.train_only``) against that model as its own control.

Parts of the 190-number frame (``inference.features.layout``): each segment's 6D
orientation goes with its part (torso: pelvis, spine, neck, head; arms: collars to
fingers; legs: thighs to toes), each site's acceleration with its segment's part, the root
displacement and height with the torso, the foot contacts with the legs.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn

from inference.body.skeleton import SEGMENTS, SITE_SEGMENT_INDEX, SITES
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT

PARTS: tuple[str, ...] = ("torso", "arms", "legs")
_TORSO = {"pelvis", "spine1", "spine2", "spine3", "neck", "head"}
_LEGS = {"thigh", "shank", "foot", "toes"}


def segment_part(name: str) -> str:
    """The body part (``PARTS``) a segment belongs to."""
    if name in _TORSO:
        return "torso"
    return "legs" if name.split("_", 1)[-1] in _LEGS else "arms"


def part_columns() -> dict[str, list[int]]:
    """The feature columns of each part; together they are every column once."""
    cols: dict[str, list[int]] = {p: [] for p in PARTS}
    for i, seg in enumerate(SEGMENTS):
        cols[segment_part(seg)] += list(range(SL_ROT.start + 6 * i, SL_ROT.start + 6 * i + 6))
    for k in range(len(SITES)):
        part = segment_part(SEGMENTS[SITE_SEGMENT_INDEX[k]])
        cols[part] += list(range(SL_ACC.start + 3 * k, SL_ACC.start + 3 * k + 3))
    cols["torso"] += list(range(SL_DP.start, SL_PZ.stop))
    cols["legs"] += list(range(SL_CONTACT.start, SL_CONTACT.stop))
    return cols


class HierarchicalRefinement(nn.Module):
    """(B, N, 190) coarse prediction -> (B, N, 190) refined one (module docstring)."""

    def __init__(self, width: int) -> None:
        super().__init__()
        cols = part_columns()
        if sorted(c for p in PARTS for c in cols[p]) != list(range(N_FEATURES)):
            raise AssertionError("the body parts must cover every feature column once")
        for p in PARTS:
            self.register_buffer(f"cols_{p}", torch.as_tensor(cols[p], dtype=torch.long), persistent=False)
        self.encoders = nn.ModuleDict({p: nn.Sequential(nn.Linear(len(cols[p]), width), nn.GELU(),
                                                        nn.Linear(width, width)) for p in PARTS})
        self.heads = nn.ModuleDict({p: nn.Linear(width * (k + 1), len(cols[p])) for k, p in enumerate(PARTS)})
        for head in self.heads.values():
            nn.init.zeros_(head.weight)
            nn.init.zeros_(head.bias)

    def forward(self, x: Tensor) -> Tensor:
        codes: list[Tensor] = []
        out = x
        for p in PARTS:
            cols = getattr(self, f"cols_{p}")
            codes.append(self.encoders[p](x.index_select(-1, cols)))
            delta = self.heads[p](torch.cat(codes, dim=-1))
            out = out.index_add(-1, cols, delta)
        return out


__all__ = ["PARTS", "segment_part", "part_columns", "HierarchicalRefinement"]
