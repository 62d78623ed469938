"""The perfect stand: what the poser makes of pelvis and both shanks upright and still.

    .venv/bin/python benchmarks/perfect_stand.py [--model diffusion] [--model runs/x/model.pt] [--chains | --no-chains]

Prints each thigh's bend from vertical (deg), one-second means over 10 s. The measured
segments say "standing straight"; what the thighs settle on is the model's estimate of a
stand (docs/real_signals.md, "A standing body"; docs/model.md, whole-chain mirror averaging).
"""

from __future__ import annotations

import argparse

import numpy as np

from inference.body.rotations import matrix_to_rot6d
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX, SITE_SEGMENT_INDEX
from inference.features.layout import N_FEATURES, SL_ROT, observation_mask
from inference.poser.models import resolve_model
from inference.poser.poser import Poser, reconstruct_offline
from inference.signals.resample import FPS_MODEL


def perfect_stand(seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    sites = ("pelvis", "l_shank", "r_shank")
    T = int(seconds * FPS_MODEL)
    F = np.zeros((T, N_FEATURES))
    for s in sites:
        seg = SITE_SEGMENT_INDEX[SITE_INDEX[s]]
        F[:, SL_ROT.start + 6 * seg: SL_ROT.start + 6 * seg + 6] = matrix_to_rot6d(np.eye(3))
    return F, np.broadcast_to(observation_mask(sites), (T, N_FEATURES)).copy()


def thigh_bend(rot: np.ndarray, side: str) -> np.ndarray:
    """(T,) angle (deg) of the thigh's Z axis from the world's Z: 0 when it hangs as at rest."""
    z = rot[:, SEGMENT_INDEX[f"{side}_thigh"], :, 2]
    return np.degrees(np.arccos(np.clip(z[:, 2], -1.0, 1.0)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", action="append", default=None)
    ap.add_argument("--chains", action=argparse.BooleanOptionalAction, default=None,
                    help="whole-chain mirror averaging (Poser(mirror_chains=...); default: the model file's)")
    a = ap.parse_args(argv)
    F, M = perfect_stand()
    for spec in a.model or ["diffusion"]:
        rec = reconstruct_offline(Poser(resolve_model(spec), body=1.75, mirror_chains=a.chains), F, M)
        for side in ("l", "r"):
            b = thigh_bend(rec.rot, side)
            per_s = [round(float(b[k:k + int(FPS_MODEL)].mean()), 1) for k in range(0, len(b), int(FPS_MODEL))]
            print(f"{spec} {side}_thigh: {per_s}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
