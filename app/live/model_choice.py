"""Which model a run poses with, and on how many torch threads: two decisions that every
entry point makes (the demo, the capture, the CLI replay and the window's re-run, batch,
bench, advise, train) and that used to be made in each, a little differently. They are
made here.

The model: a CLI-style spec ("diffusion", "fast", "regressor", "floor" or a file), which the latency
mode may turn into the model trained for it (``app.live.latency.model_spec_for``), loaded
(``inference.poser.models.resolve_model``), labelled the way recordings and summaries name
it (``model_label``: a replay compares labels to know it runs the recorded model), and
paired with the acceleration filter the mode and the model need
(``app.live.latency.resolve_filter``). A live session falls back to the floor baseline, loudly,
when the default model's weights are not installed (the model is trained separately);
everything else wants the error.

The threads: torch's intra-op threads. Two cores are shared with the devices, the hub's
threads and the window, and an oversubscribed OpenMP pool crawls, so each entry point says
how many it wants and nothing else calls torch for it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.live.latency import model_spec_for, resolve_filter

if TYPE_CHECKING:
    from inference.model.files import LoadedModel

FLOOR_FALLBACK_LABEL = "floor (fallback: weights missing)"


@dataclass(frozen=True)
class ModelChoice:
    """spec: what was asked for after the latency mode's substitution; model: the loaded
    model (None for the floor); label: how recordings and summaries name it; causal: the
    resampler's trailing filter; warning: what the user must be told (the floor fallback,
    a centred-trained model in the low mode), else None."""

    spec: str
    model: LoadedModel | None
    label: str
    causal: bool
    warning: str | None = None


def model_label(spec: str, model: Any) -> str:
    """``diffusion 4/128/512 (diffusionposer.pt)``: the kind, size and file of a model."""
    from inference.poser.models import DEFAULT_WEIGHTS

    if model is None:
        return "floor"
    c = model.config
    where = DEFAULT_WEIGHTS.get(spec, spec)
    return f"{model.kind} {c.layers}/{c.d_model}/{c.ff} ({Path(str(where)).name})"


def load_model(spec: str, fallback: bool = False) -> tuple[LoadedModel | None, str, str | None]:
    """(model or None, label, warning) for ``spec`` as given. fallback: the default model
    whose weights are missing becomes the floor baseline with a warning the caller must
    show (a live session); an explicit path that does not exist is an error either way."""
    from inference.poser.models import DEFAULT_WEIGHTS, resolve_model

    try:
        model = resolve_model(spec)
    except FileNotFoundError as exc:
        if not fallback or spec not in DEFAULT_WEIGHTS:
            raise
        warning = (f"!!! NO TRAINED MODEL: {DEFAULT_WEIGHTS[spec]} is missing; running the FLOOR BASELINE "
                   f"(observed segments only, everything else held standing). {exc}")
        return None, FLOOR_FALLBACK_LABEL, warning
    return model, model_label(spec, model), None


def choose_model(spec: str, latency: str = "centred", *, fallback: bool = False,
                 loaded: Any = "resolve", sites: Sequence[str] | None = None) -> ModelChoice:
    """The model a run in latency mode ``latency`` poses with (see the module docstring).
    loaded: a model already loaded for ``spec`` in this mode (a batch worker or the window
    loads it once), or "resolve" to load it here. sites: the sensors the run wears, which
    the live default ("auto") chooses its file by (``inference.poser.models.model_for_sites``)."""
    from inference.poser.models import model_for_sites

    spec = model_for_sites(model_spec_for(latency, spec), sites)
    if isinstance(loaded, str) and loaded == "resolve":
        model, label, warning = load_model(spec, fallback)
    else:
        model, label, warning = loaded, model_label(spec, loaded), None
    causal, latency_warning = resolve_filter(latency, model)
    warning = "; ".join(w for w in (warning, latency_warning) if w) or None
    return ModelChoice(spec, model, label, causal, warning)


# share of the 20 Hz frames passed over (late poses) above which a session says the machine did not
# keep up: a slow laptop's first sign, on which the user can act (a lighter model or fewer steps)
KEEP_UP_SKIPPED = 0.02
KEEP_UP_MIN_FRAMES = 100  # fewer frames say nothing about a machine


def keep_up_advice(posed: int, skipped: int, spec: str) -> str | None:
    """One line for a session whose poses were skipped past ``KEEP_UP_SKIPPED``, naming the
    lever for the model it ran (``spec`` as asked: the default has a lighter twin), else None."""
    total = posed + skipped
    if total < KEEP_UP_MIN_FRAMES or skipped <= KEEP_UP_SKIPPED * total:
        return None
    share = f"{100.0 * skipped / total:.0f} % of the poses were skipped: this machine did not keep up with the model"
    if spec == "diffusion":
        return (f"{share}; --model fast (a setup's [model] name = \"fast\") runs the same three-level chain at about "
                "a third of the compute, a little less accurately (docs/latency.md)")
    return f"{share}; fewer diffusion steps or a lighter model would (docs/latency.md)"


def set_torch_threads(threads: int) -> None:
    """Run torch's operators on ``threads`` threads; 0 or less leaves torch's own choice."""
    if threads > 0:
        import torch

        torch.set_num_threads(threads)


__all__ = ["FLOOR_FALLBACK_LABEL", "KEEP_UP_SKIPPED", "ModelChoice", "choose_model", "keep_up_advice", "load_model",
           "model_label", "set_torch_threads"]
