"""Which sensors to wear for a task: candidate sensor sets scored on the user's motions.

One model serves every subset of the 13 sites, so the question "which k sensors?" has an
answer per task that only a reconstruction can give: each candidate set's signals are
synthesized from the motions (all 13 sites once, a set is a mask over them), the model
reconstructs them, and the set is scored by the error on the body parts the task names
(``TASKS``: GA of those segments; for ``root`` the horizontal root error over 2 s, RE2).

Search: every set of 1-3 sensors (13 + 78 + 286), then, per size up to ``max_sensors``,
a beam: the ``beam`` best sets of the size below, each grown by every site it lacks.
Exhaustive search stops at 3 because the sets grow fast (715 of 4, 1716 of 6) and each
costs a reconstruction; a beam rather than plain greedy growth, because two sensors can
be worth more together than each alone (both shanks give strides, one gives none).

Speed (docs/advisor.md): angle tasks score frames independently, many windows per
model call. The shipped poser tells the model only the measurements of its window (the
reconstructed history weighs 5e-5, ``poser.batched``), so a frame's answer needs no
frames before it: every ``frame_step``-th frame of every clip and set goes through one
model call at level 1000 from the prior's mean, without mirror averaging (the poser's
first call, which already gives its answer: docs/model.md, "Inference"), and the knee
hinge. The root needs every frame in order (contacts, odometry, strides), so it runs
the live poser with those same fast model settings, many clips and sets per batch
(``batched.reconstruct_many``). ``exact=True`` scores with the live poser's own settings
instead (every frame, all steps, mirror averaging, output filters): slower, to check
the fast ranking.
"""

from __future__ import annotations

import itertools
import math
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from inference.body.motion import Motion
from inference.body.rotations import matrix_angle_between, rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX, SEGMENTS, SITE_INDEX, SITES
from inference.evaluation.runner import clip_input, clip_seed, evaluation_noise
from inference.features.layout import N_FEATURES, SL_ROT, observation_mask
from inference.metrics.errors import EVAL_SEGMENTS, root_error
from inference.model.diffusion import inpaint
from inference.model.files import LoadedModel
from inference.poser.batched import reconstruct_many
from inference.poser.joint_constraints import constrain_knees
from inference.poser.poser import Poser, standing_features
from inference.signals.resample import FPS_MODEL
from inference.signals.synthesis import NoiseModel

# the segments each task is scored on; None = the root (RE2)
TASKS: dict[str, tuple[str, ...] | None] = {
    "whole": tuple(SEGMENTS[i] for i in EVAL_SEGMENTS),
    "legs": ("l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot"),
    "arms": ("l_upperarm", "r_upperarm", "l_forearm", "r_forearm"),
    "back": ("spine1", "spine2", "spine3", "neck"),
    "root": None,
}
# the paper's best 3-sensor sets (DiffusionPoser, sec. 4, synthesized TotalCapture)
PAPER_SETS: dict[str, tuple[str, ...]] = {
    "whole": ("pelvis", "l_wrist", "r_wrist"),
    "legs": ("pelvis", "l_thigh", "r_thigh"),
    "back": ("pelvis", "l_upperarm", "r_upperarm"),
    "root": ("pelvis", "l_shank", "r_shank"),
}
ROOT_SECONDS = 2.0
EXHAUSTIVE = 3
FAST_STEPS = (1000,)
WINDOWS_PER_CALL = 32


@dataclass
class Scored:
    """One sensor set: per task, the error per clip (deg, or m for the root)."""

    sites: tuple[str, ...]
    per_clip: dict[str, list[float]] = field(default_factory=dict)

    def error(self, task: str) -> float:
        v = self.per_clip.get(task) or []
        return float(np.mean(v)) if v else math.nan

    def spread(self, task: str) -> float:
        """Standard deviation over clips: how much the ranking could depend on the motion."""
        v = self.per_clip.get(task) or []
        return float(np.std(v)) if len(v) > 1 else 0.0


@dataclass
class AdvisorClip:
    """A motion with every site's synthesized signals (features of all 13 sites) and its truth."""

    name: str
    height: float
    body: object
    features: np.ndarray  # (T, 190)
    insoles_mask: np.ndarray  # (190,) what the insoles add
    rot: np.ndarray  # (T, 24, 3, 3)
    root: np.ndarray  # (T, 3)


def advisor_clips(motions: Iterable[Motion], insoles: bool = False, noise: NoiseModel | None = None,
                  seed: int = 0) -> list[AdvisorClip]:
    """Signals of all 13 sites per motion, as ``imucap evaluate`` synthesizes them (noise
    model, 60 -> 20 Hz), once: a candidate set is then a mask over them, and every set
    sees the same sensor noise."""
    noise = evaluation_noise() if noise is None else noise
    out = []
    for m in motions:
        inp = clip_input(m, SITES, insoles, noise, clip_seed(seed, m.name))
        extra = observation_mask([], insoles)
        out.append(AdvisorClip(inp.name, float(inp.body.height), inp.body, inp.features, extra, inp.rot, inp.root))
    return out


def set_mask(sites: Sequence[str], clip: AdvisorClip) -> np.ndarray:
    return observation_mask(list(sites)) | clip.insoles_mask


def sets_of_size(k: int) -> list[tuple[str, ...]]:
    return list(itertools.combinations(SITES, k))


class Advisor:
    """Scores sensor sets on clips with one model (see the module docstring); every set
    is reconstructed once and scored for every task, so rankings of several tasks share
    the work. ``frame_step``: every n-th frame scores the angle tasks."""

    def __init__(self, model: LoadedModel, clips: Sequence[AdvisorClip], frame_step: int = 4, exact: bool = False,
                 progress: Callable[[str], object] | None = None) -> None:
        if model is None or model.kind != "diffusion":
            raise ValueError("the advisor needs a diffusion model (one model for every sensor set)")
        if not clips:
            raise ValueError("the advisor needs at least one motion")
        self.model = model
        self.clips = list(clips)
        self.frame_step = max(1, int(frame_step))
        self.exact = exact
        self.progress = progress
        self.scored: dict[tuple[str, ...], Scored] = {}
        self._root_done: set[tuple[str, ...]] = set()
        self._template = Poser(model, body=self.clips[0].body, **self._poser_settings())

    def _poser_settings(self) -> dict:
        if self.exact:
            return {}
        # the output filters only smooth what is shown; the root path is integrated before them
        return {"steps": list(FAST_STEPS), "mirror": False, "smoothing": False}

    # ------------------------------------------------------------------ scoring
    def score(self, sets: Iterable[Sequence[str]], tasks: Iterable[str]) -> list[Scored]:
        """Score ``sets`` for ``tasks`` (cached); returns their Scored in the given order."""
        sets = [_canonical(s) for s in sets]
        tasks = list(tasks)
        angle = [t for t in tasks if TASKS[t] is not None]
        todo = [s for s in dict.fromkeys(sets) if s not in self.scored]
        if todo and (angle or "root" in tasks):
            self._say(f"reconstructing {len(todo)} set(s)")
            if self.exact:
                self._score_exact(todo)
            else:
                self._score_angles(todo)
        if "root" in tasks and not self.exact:
            need = [s for s in dict.fromkeys(sets) if s not in self._root_done]
            if need:
                self._score_root(need)
        return [self.scored[s] for s in sets]

    def _say(self, text: str) -> None:
        if self.progress is not None:
            self.progress(text)

    def _score_angles(self, sets: list[tuple[str, ...]]) -> None:
        """Every frame_step-th frame of every clip, each an independent window; the windows
        of all sets of a clip fill the model calls one after the other (a short clip's few
        windows per set would leave most of a call empty)."""
        p = self._template
        net = p.net_for(WINDOWS_PER_CALL, mirror=False)
        mean, std = p._mean, p._std
        stand_n = (torch.as_tensor(standing_features(p.body), dtype=torch.float32) - mean) / std
        N = p.window
        for s in sets:
            self.scored[s] = Scored(s)
        for ci, clip in enumerate(self.clips):
            frames = np.arange(0, len(clip.features), self.frame_step)
            feats_n = (torch.as_tensor(clip.features, dtype=torch.float32) - mean) / std
            truth = torch.as_tensor(clip.rot[frames], dtype=torch.float64)
            masks = {s: torch.as_tensor(set_mask(s, clip)) for s in sets}
            group = max(1, (8 * WINDOWS_PER_CALL) // len(frames))  # sets per round of calls
            for k in range(0, len(sets), group):
                part = sets[k: k + group]
                W, M = zip(*(_set_windows(feats_n, stand_n, masks[s], frames, N) for s in part))
                y = _last_frames(net, torch.cat(W), torch.cat(M), clip.height, p, WINDOWS_PER_CALL) * std + mean
                for j, s in enumerate(part):
                    self._add_angles(s, y[j * len(frames): (j + 1) * len(frames)], masks[s], truth)
            self._say(f"clip {ci + 1}/{len(self.clips)} {clip.name}")

    def _add_angles(self, s: tuple[str, ...], y: torch.Tensor, m: torch.Tensor, truth: torch.Tensor) -> None:
        """Score one set's answers (F, 190) against the truth for every angle task."""
        R = rot6d_to_matrix(y[:, SL_ROT].reshape(-1, N_SEGMENTS, 6))
        R = constrain_knees(R, m[SL_ROT].view(N_SEGMENTS, 6).all(dim=-1))
        err = np.degrees(matrix_angle_between(R.to(torch.float64), truth).numpy())  # (F, 24)
        for task, segs in TASKS.items():
            if segs is not None:
                idx = [SEGMENT_INDEX[g] for g in segs]
                self.scored[s].per_clip.setdefault(task, []).append(float(err[:, idx].mean()))

    def _run(self, sets: list[tuple[str, ...]], clips: Sequence[int] | None = None):
        """Each (set, clip) through the live poser, many per model call; yields (set, clip
        index, reconstruction). ``clips``: the indices to run (default all)."""
        clips = range(len(self.clips)) if clips is None else clips
        jobs = [(s, ci) for s in sets for ci in clips]
        posers, inputs = [], []
        for s, ci in jobs:
            c = self.clips[ci]
            posers.append(Poser(self.model, body=c.body, seed=clip_seed(0, c.name),
                                root_xy0=(c.root[0, 0], c.root[0, 1]), **self._poser_settings()))
            inputs.append((c.features, set_mask(s, c)))
        recs = reconstruct_many(posers, inputs, lanes=WINDOWS_PER_CALL // (2 if posers[0].mirror else 1))
        for (s, ci), rec in zip(jobs, recs):
            yield s, ci, rec

    def _score_root(self, sets: list[tuple[str, ...]]) -> None:
        """RE2 per clip with the fast live poser; clips shorter than 2 s have none and are
        not run."""
        self._say(f"root: {len(sets)} set(s) frame by frame")
        long = [ci for ci, c in enumerate(self.clips) if len(c.features) > round(ROOT_SECONDS * FPS_MODEL)]
        for k in range(0, len(sets), 8):
            for s, ci, rec in self._run(sets[k: k + 8], long):
                self._add_root(s, ci, rec.root)
            self._say(f"root: {min(k + 8, len(sets))}/{len(sets)} sets")
        self._root_done.update(sets)

    def _add_root(self, s: tuple[str, ...], ci: int, root: np.ndarray) -> None:
        e = root_error(root, self.clips[ci].root, ROOT_SECONDS, FPS_MODEL)
        if e is not None:
            self.scored.setdefault(s, Scored(s)).per_clip.setdefault("root", []).append(float(e.mean()))

    def _score_exact(self, sets: list[tuple[str, ...]]) -> None:
        """The live poser as shipped, every frame; angle tasks and the root from one run."""
        for s in sets:
            self.scored[s] = Scored(s)
        for s, ci, rec in self._run(sets):
            clip = self.clips[ci]
            err = np.degrees(matrix_angle_between(rec.rot, clip.rot))
            for task, segs in TASKS.items():
                if segs is not None:
                    idx = [SEGMENT_INDEX[g] for g in segs]
                    self.scored[s].per_clip.setdefault(task, []).append(float(err[:, idx].mean()))
            self._add_root(s, ci, rec.root)
        self._root_done.update(sets)

    # ------------------------------------------------------------------ search
    def search(self, task: str, max_sensors: int = EXHAUSTIVE, beam: int = 5,
               min_sensors: int = 1) -> list[Scored]:
        """Every set of ``min_sensors``..3 sensors, then a beam up to ``max_sensors``;
        the sets scored for ``task``, best first."""
        if task not in TASKS:
            raise ValueError(f"unknown task {task!r}; tasks: {', '.join(TASKS)}")
        if not 1 <= max_sensors <= len(SITES):
            raise ValueError(f"--max-sensors must lie in 1..{len(SITES)}")
        cands: list[tuple[str, ...]] = []
        for k in range(max(1, min_sensors), min(EXHAUSTIVE, max_sensors) + 1):
            cands += sets_of_size(k)
        self.score(cands, [task])
        size = min(EXHAUSTIVE, max_sensors)
        while size < max_sensors:
            best = sorted((self.scored[s] for s in self.scored if len(s) == size and _has(self.scored[s], task)),
                          key=lambda r: r.error(task))[:beam]
            grown = {_canonical(b.sites + (x,)) for b in best for x in SITES if x not in b.sites}
            self.score(sorted(grown), [task])
            size += 1
        return ranked(self.scored.values(), task, max_sensors, min_sensors)

    def best_by_size(self, task: str, max_sensors: int) -> dict[int, Scored]:
        """The best set of each size among those scored for ``task``."""
        out: dict[int, Scored] = {}
        for r in ranked(self.scored.values(), task, max_sensors):
            out.setdefault(len(r.sites), r)
        return dict(sorted(out.items()))


def ranked(rows: Iterable[Scored], task: str, max_sensors: int = len(SITES), min_sensors: int = 1) -> list[Scored]:
    """Rows scored for ``task`` within the size limits, best (lowest error) first; ties by
    fewer sensors."""
    rows = [r for r in rows if _has(r, task) and min_sensors <= len(r.sites) <= max_sensors]
    return sorted(rows, key=lambda r: (r.error(task), len(r.sites), r.sites))


def _has(r: Scored, task: str) -> bool:
    return bool(r.per_clip.get(task))


def _canonical(sites: Sequence[str]) -> tuple[str, ...]:
    """Sites in the vocabulary's order, once each (a set, as the cache keys it)."""
    bad = [s for s in sites if s not in SITE_INDEX]
    if bad:
        raise ValueError(f"unknown site(s) {bad}")
    return tuple(s for s in SITES if s in set(sites))


def _set_windows(feats_n: torch.Tensor, stand_n: torch.Tensor, m: torch.Tensor, frames: np.ndarray,
                 N: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The windows (F, N, 190) and masks of one set at ``frames`` as a live poser that
    started standing would build them, the reconstructed history guessed as standing (it
    weighs 5e-5: module docstring)."""
    T = feats_n.shape[0]
    rows = torch.cat([stand_n.expand(N - 1, N_FEATURES), torch.where(m, feats_n, stand_n)])
    mrows = torch.cat([torch.ones(N - 1, N_FEATURES, dtype=torch.bool), m.expand(T, N_FEATURES)])
    return rows.unfold(0, N, 1).permute(0, 2, 1)[frames], mrows.unfold(0, N, 1).permute(0, 2, 1)[frames]


def _last_frames(net, W: torch.Tensor, M: torch.Tensor, height: float, poser: Poser, batch: int) -> torch.Tensor:
    """(F, 190) normalised answers for the last frame of each window, ``batch`` windows per
    call (the last call padded to that shape)."""
    out = []
    h = torch.full((batch,), float(height))
    with torch.inference_mode():
        for k in range(0, W.shape[0], batch):
            w, m = W[k: k + batch], M[k: k + batch]
            n = w.shape[0]
            if n < batch:
                w = torch.cat([w, w[-1:].expand(batch - n, *w.shape[1:])])
                m = torch.cat([m, m[-1:].expand(batch - n, *m.shape[1:])])
            x = inpaint(net, w.contiguous(), m.contiguous(), h, list(FAST_STEPS), schedule=poser.schedule,
                        mode=poser.inpaint_mode, mask_input=poser.model.config.mask_input, start="mean")
            out.append(x[:n, -1])
    return torch.cat(out)


def table(rows: Sequence[Scored], task: str, top: int | None = None) -> str:
    """The ranked table as text, one set per line, best first."""
    unit = "m" if task == "root" else "deg"
    lines = [f"{'rank':>4}  {'error ' + unit:>10}  {'+- clips':>8}  {'sensors':>7}  set"]
    for i, r in enumerate(rows[:top] if top else rows):
        nd = 3 if task == "root" else 2
        lines.append(f"{i + 1:>4}  {r.error(task):>10.{nd}f}  {r.spread(task):>8.{nd}f}  {len(r.sites):>7}  "
                     f"{'+'.join(r.sites)}")
    return "\n".join(lines)


def plot_best(curves: dict[str, dict[int, float]], path, title: str = "") -> None:
    """Best error against the number of sensors, one line per task (angle tasks in deg on
    the left, the root in m on the right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax2 = None
    for task, curve in curves.items():
        if not curve:
            continue
        ks = sorted(curve)
        if task == "root":
            ax2 = ax2 or ax.twinx()
            ax2.plot(ks, [curve[k] for k in ks], "k--o", label="root (RE2, m, right axis)")
            ax2.set_ylabel("root error RE2 (m)")
        else:
            ax.plot(ks, [curve[k] for k in ks], "-o", label=f"{task} (GA of its segments)")
    ax.set_xlabel("number of sensors (IMUs)")
    ax.set_ylabel("angle error (deg)")
    ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    if ax2 is not None:
        h2, l2 = ax2.get_legend_handles_labels()
        handles, labels = handles + h2, labels + l2
    ax.legend(handles, labels, fontsize=8, loc="upper right")
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def progress_printer(prefix: str = "advise") -> Callable[[str], None]:
    def say(text: str) -> None:
        print(f"{prefix}: {text}", file=sys.stderr, flush=True)

    return say


__all__ = ["TASKS", "PAPER_SETS", "Advisor", "AdvisorClip", "Scored", "advisor_clips", "ranked", "table",
           "plot_best", "sets_of_size", "set_mask", "progress_printer"]
