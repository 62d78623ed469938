"""Layout of the 190-number feature frame the model sees (DESIGN.md, "Features").

`R` 24x6 global orientations (6D) | `a` 13x3 world site accelerations | `dp` 2 root
ground-plane displacement since the previous frame | `pz` root height | `b` 4 contacts.
Slices are module constants so every stage (synthesis, poser, training, metrics)
agrees on one layout without passing it around.
"""

from __future__ import annotations

import numpy as np

from inference.body.skeleton import N_CONTACTS, N_SEGMENTS, N_SITES, SITE_INDEX, SITE_SEGMENT_INDEX, SITES

WINDOW = 61

SL_ROT = slice(0, N_SEGMENTS * 6)  # 0:144
SL_ACC = slice(SL_ROT.stop, SL_ROT.stop + N_SITES * 3)  # 144:183
SL_DP = slice(SL_ACC.stop, SL_ACC.stop + 2)  # 183:185
SL_PZ = slice(SL_DP.stop, SL_DP.stop + 1)  # 185:186
SL_CONTACT = slice(SL_PZ.stop, SL_PZ.stop + N_CONTACTS)  # 186:190
N_FEATURES = SL_CONTACT.stop
assert N_FEATURES == 190


def observation_mask(sites: list[str] | tuple[str, ...], insoles: bool = False) -> np.ndarray:
    """Boolean (190,) mask of the features a given sensor configuration observes.

    A sensor at a site observes its segment's 6D orientation and the site's acceleration;
    an insole pair observes the four contact labels.
    """
    m = np.zeros(N_FEATURES, dtype=bool)
    for s in sites:
        k = SITE_INDEX[s]
        seg = SITE_SEGMENT_INDEX[k]
        m[SL_ROT.start + 6 * seg: SL_ROT.start + 6 * seg + 6] = True
        m[SL_ACC.start + 3 * k: SL_ACC.start + 3 * k + 3] = True
    if insoles:
        m[SL_CONTACT] = True
    return m


__all__ = [
    "WINDOW", "SL_ROT", "SL_ACC", "SL_DP", "SL_PZ", "SL_CONTACT",
    "N_FEATURES", "observation_mask", "SITES",
]
