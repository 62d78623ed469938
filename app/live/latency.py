"""The two latency modes of the live path (docs/latency.md), in one place so the demo, the
capture, the replay, the evaluation and the benchmark mean the same thing by them.

``centred`` (the default, what the shipped model was trained on): the hub interpolates
between the samples either side of each 60 Hz grid time, so it waits (``CENTRED_HUB_WAIT``)
for the sample after it; the resampler's centred moving average waits for the 5 samples
after a 20 Hz frame (83 ms).

``low``: nothing waits for a sample from the future. The hub holds each site's latest
sample at or before the grid time and only waits for that sample to be read off its port
(``LOW_HUB_WAIT``); the moving average is trailing (the current sample and ten before), so
a 20 Hz frame goes to the poser as its own sample arrives. A model trained on the centred
filter reads the trailing one 83 ms late (its accelerations lag its orientations by 5
samples), so the low mode prefers a model trained on the trailing filter
(``CAUSAL_WEIGHTS``) and says so when it has to run the centred one.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

LATENCY_MODES = ("centred", "low")
CENTRED_HUB_WAIT = 0.05  # s behind now: the next sample of every site is there, even over a slow link
# s behind now: the selector drains the ports every LOW_HUB_WAIT / 2, so the latest sample at
# or before the grid time has been read by then; a sample read later is simply not used
LOW_HUB_WAIT = 0.01
# s: how far the centred hub may fall behind for samples that reach it late (a busy laptop:
# its readers or the live loop missed their core); without it those samples are lost to
# their frames and to the recording (drivers/hub.py, ``max_latency``)
CENTRED_HUB_MAX_WAIT = 0.25


@dataclass(frozen=True)
class LatencySettings:
    """What a mode sets. hub_wait: the hub's ``latency`` (s); interpolate: the hub
    interpolates to the grid (needs the next sample) instead of holding the latest;
    causal: the resampler's trailing moving average; hub_max_wait: how far the hub's wait
    may grow for late samples (None: fixed; the low mode gives a late sample up instead)."""

    mode: str
    hub_wait: float
    interpolate: bool
    causal: bool
    hub_max_wait: float | None = None


def latency_settings(mode: str) -> LatencySettings:
    if mode not in LATENCY_MODES:
        raise ValueError(f"unknown latency mode {mode!r}; choose from {', '.join(LATENCY_MODES)}")
    if mode == "low":
        return LatencySettings(mode, LOW_HUB_WAIT, interpolate=False, causal=True)
    return LatencySettings(mode, CENTRED_HUB_WAIT, interpolate=True, causal=False, hub_max_wait=CENTRED_HUB_MAX_WAIT)


def hub_options(mode: str) -> dict[str, Any]:
    """Keyword arguments for ``Hub`` in this mode (``latency``, ``max_latency``, ``interpolation``): the
    centred mode interpolates with inference's slerp, the one its offline resampler uses."""
    from drivers.hub import Interpolation
    from inference.signals.resample import slerp_unit

    s = latency_settings(mode)
    return {"latency": s.hub_wait, "max_latency": s.hub_max_wait,
            "interpolation": Interpolation(slerp_unit) if s.interpolate else None}


def causal_weights() -> os.PathLike:
    """Where the diffusion model trained on the trailing filter ships (when it does)."""
    from inference.poser.models import WEIGHTS_DIR

    return WEIGHTS_DIR / "diffusionposer_causal.pt"


def model_spec_for(mode: str, spec: str) -> str:
    """The model to run: in the low mode the default diffusion model (and the live default,
    "auto") becomes the one trained on the trailing filter when that file is installed;
    anything else named explicitly stays."""
    latency_settings(mode)
    if mode == "low" and spec in ("diffusion", "auto"):
        path = causal_weights()
        if os.path.exists(path):
            return os.fspath(path)
    return spec


def model_filter(model: Any) -> str:
    """The acceleration filter ``model`` (a LoadedModel or None) was trained on."""
    from inference.signals.resample import acc_filter_of

    return acc_filter_of(getattr(model, "meta", None)) if model is not None else "centred"


def resolve_filter(mode: str, model: Any) -> tuple[bool, str | None]:
    """(causal resampler?, warning or None) for ``mode`` with ``model``.

    The low mode always filters causally (that is the point of it); a model that was trained
    causally gets the causal filter in either mode (its inputs must look like its training
    data). A centred-trained model in the low mode runs, with a warning: its accuracy there
    is the "untuned" figure of docs/latency.md."""
    s = latency_settings(mode)
    trained = model_filter(model)
    causal = s.causal or trained == "causal"
    warning = None
    if s.causal and trained != "causal" and model is not None:
        warning = (f"--latency low with a model trained on the centred filter: accelerations reach it 83 ms "
                   f"later than it expects (untuned; {causal_weights()} is the model for this mode)")
    return causal, warning


__all__ = [
    "LATENCY_MODES", "CENTRED_HUB_WAIT", "LOW_HUB_WAIT", "LatencySettings", "latency_settings", "hub_options",
    "causal_weights", "model_spec_for", "model_filter", "resolve_filter",
]
