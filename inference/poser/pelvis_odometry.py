"""The root's walk from the pelvis sensor alone, for sensor sets without both shanks.

Why a separate stage: the paper's root path is the model's root displacement corrected
by the foot points predicted in contact (sec. 3.4.2). With both shanks measured the
contacts come from the shanks (``contact_detector``) and the stride from their own
accelerations (``stride``). Without them the legs, and so the contacts, are the model's
guess, and on walks that guess cancels the walk: with pelvis + wrists (the paper's best
3-site set for the whole body) the held-out Bandai walks' reconstructed root stood still
(RE10 4.6 m, the floor baseline that never moves scores 4.4; docs/model.md, "Pelvis odometry").

A pelvis sensor does carry the walk: every step lifts and drops the pelvis and rocks it
side to side, and the size and rhythm of that bounce follow step length and cadence
(the inverted-pendulum gait models of pelvis-worn pedometers rest on this). Rather than
a hand-fitted step model, which would also need the direction of travel, a small causal
regressor learns the root's horizontal displacement of this frame from the last
``CONTEXT`` frames (1 s) of the pelvis's orientation and acceleration, on every frame of
the training split and its mirror image. A second net, trained also on the split's forward
walks played backwards (``time_reversal``), takes over while it says the subject walks
backwards (``TwoWayOdometry``, the shipped file).

Inputs per frame (9 numbers): the pelvis orientation (6D) and the pelvis-site
acceleration, all turned about the vertical into the frame facing the *current*
pelvis heading, so a turn within the context shows as one, and the answer is a
displacement in that frame (x forward, y left) that the poser turns back to the world.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch
import torch.nn.functional as F
from torch import Tensor, nn

from inference.body.conventions import turn_cs
from inference.body.rotations import facing_x, matrix_to_rot6d, rot6d_columns_np, rot6d_to_matrix
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
from inference.features.layout import SL_ACC, SL_DP, SL_ROT
from inference.features.time_reversal import is_forward_walk, reverse_features
from inference.poser.small_nets import (
    FitConfig,
    clip_tensors,
    fit,
    net_entry,
    net_from_entry,
    read_file,
    save_file,
    save_net,
    stack_context,
)
from inference.signals.resample import FPS_MODEL

ODOMETRY_FORMAT = "imucap-pelvis-odometry-v1"
TWO_WAY_FORMAT = "imucap-pelvis-odometry-two-way-v1"
# frames at 20 Hz (1 s: a stride of a slow walk). Chosen on clips held out of the training
# split (10 % by clip): RE2 / RE5 0.114 / 0.294 m at 10 frames, 0.108 / 0.271 at 15,
# 0.099 / 0.245 at 20, 0.107 / 0.284 at 30, 0.100 / 0.268 at 40 (docs/model.md, "Pelvis odometry")
CONTEXT = 20
# The two-way odometry's gate (``TwoWayOdometry``): the backward net's mean forward speed
# over the last second. Picked on the clips held out of the training split: RE2 / RE5 at
# 0.3 / 0.5 / 0.7 m/s 0.083 / 0.144, 0.089 / 0.187, 0.098 / 0.242 (the forward net alone
# 0.099 / 0.245; docs/model.md, "Pelvis odometry")
GATE_M_S = 0.3
GATE_FRAMES = 20


def pelvis_feature_index() -> np.ndarray:
    """(9,) indices into a 190-feature frame: the pelvis 6D, then the pelvis-site acceleration."""
    rot = [SL_ROT.start + 6 * SEGMENT_INDEX["pelvis"] + k for k in range(6)]
    acc = [SL_ACC.start + 3 * SITE_INDEX["pelvis"] + k for k in range(3)]
    return np.asarray(rot + acc)


PELVIS_INDEX = pelvis_feature_index()


def current_heading(pelvis: Tensor) -> Tensor:
    """(..., C, 9) pelvis frames -> (...,) R_z(-yaw) of the last frame's pelvis heading
    as (..., 3, 3): the turn that makes the subject face +X now."""
    return facing_x(rot6d_to_matrix(pelvis[..., -1, :6])[..., :2, 0])


def heading_frame_windows(pelvis: Tensor, Rz: Tensor | None = None) -> Tensor:
    """(..., C, 9) raw pelvis frames (oldest first, physical units) -> (..., C * 9) the
    same turned into the frame facing the last frame's heading (``Rz``: its
    ``current_heading`` when the caller has it already)."""
    Rz = (current_heading(pelvis) if Rz is None else Rz)[..., None, :, :]
    R = rot6d_to_matrix(pelvis[..., :6])
    rot = matrix_to_rot6d(Rz @ R)
    acc = (Rz @ pelvis[..., 6:9, None])[..., 0]
    return torch.cat([rot, acc], dim=-1).flatten(-2)


def clip_contexts(x: np.ndarray | Tensor, context: int = CONTEXT) -> Tensor:
    """(T, 190) one clip's features -> (T, context, 9): per frame, its pelvis frames and
    the ``context - 1`` before it (the first frame repeated before the start, as the
    poser's standing history does)."""
    return stack_context(torch.as_tensor(np.asarray(x)[:, PELVIS_INDEX], dtype=torch.float32), context)


class PelvisOdometry(nn.Module):
    """MLP on ``context`` heading-framed pelvis frames -> this frame's root displacement
    (2,) in metres, in the frame facing the current heading. The input normaliser and the
    output scale travel with the weights."""

    def __init__(self, context: int = CONTEXT, hidden: int = 256) -> None:
        super().__init__()
        self.context, self.hidden = context, hidden
        self.meta: dict = {}
        n = context * len(PELVIS_INDEX)
        self.register_buffer("in_mean", torch.zeros(n))
        self.register_buffer("in_std", torch.ones(n))
        self.register_buffer("out_std", torch.ones(2))
        self.net = nn.Sequential(nn.Linear(n, hidden), nn.GELU(), nn.Linear(hidden, hidden), nn.GELU(),
                                 nn.Linear(hidden, 2))

    def forward(self, windows: Tensor) -> Tensor:
        """(B, context * 9) heading-framed windows -> (B, 2) displacement / out_std."""
        return self.net((windows - self.in_mean) / self.in_std)

    @torch.no_grad()
    def displacement(self, pelvis_frames: Tensor) -> Tensor:
        """(context, 9) raw pelvis features of the last frames (oldest first) -> (2,) this
        frame's root displacement in the world (metres)."""
        d, Rz = _heading_answers(self, pelvis_frames.to(torch.float32)[None])
        return _to_world(d[0], Rz[0])


def _heading_answers(net: PelvisOdometry, windows: Tensor) -> tuple[Tensor, Tensor]:
    """(n, context, 9) raw pelvis windows -> each one's answer in the frame facing its last
    frame's heading (n, 2) (metres), and that turn (n, 3, 3)."""
    Rz = current_heading(windows)
    return net(heading_frame_windows(windows, Rz)) * net.out_std, Rz


def _to_world(d: Tensor, Rz: Tensor) -> Tensor:
    return (Rz[..., :2, :2].transpose(-1, -2) @ d[..., None])[..., 0]


class TwoWayOdometry(nn.Module):
    """The odometry as shipped: a net trained on the split as it is (``forward_net``), and a
    second trained also on its forward walks played backwards (``backward_net``,
    ``time_reversal``), whose answer is taken only while it says the subject walks backwards:
    its mean forward speed over the last ``gate_frames`` frames below ``-gate_m_s``.

    Why two: the second alone walks a backward walk backwards but every forward walk ~10 %
    worse, and on the real x-IMU3 log it took knee raises in place for backward steps; the
    first alone walked a held-out style's backward walk in place. Gated, the backward
    walks go backward and forward walks are the first net's (docs/model.md, "Pelvis odometry")."""

    def __init__(self, forward_net: PelvisOdometry, backward_net: PelvisOdometry,
                 gate_m_s: float = GATE_M_S, gate_frames: int = GATE_FRAMES) -> None:
        super().__init__()
        self.forward_net, self.backward_net = forward_net, backward_net
        self.gate_m_s, self.gate_frames = float(gate_m_s), int(gate_frames)
        self.meta: dict = {}

    @property
    def context(self) -> int:
        """Frames each answer reads: the backward net's windows for the whole gate."""
        return max(self.forward_net.context, self.backward_net.context + self.gate_frames - 1)

    def walking_backwards(self, forward_steps: Tensor) -> Tensor:
        """(..., gate_frames) the backward net's forward steps (m per frame) -> (...) the gate."""
        return forward_steps.mean(-1) * FPS_MODEL < -self.gate_m_s

    @torch.no_grad()
    def displacement(self, pelvis_frames: Tensor) -> Tensor:
        """(context, 9) raw pelvis features of the last frames (oldest first) -> (2,) this
        frame's root displacement in the world (metres)."""
        p = pelvis_frames.to(torch.float32)
        cb = self.backward_net.context
        windows = p.unfold(0, cb, 1).transpose(1, 2)[-self.gate_frames:]  # (gate, cb, 9)
        d, Rz = _heading_answers(self.backward_net, windows)
        if bool(self.walking_backwards(d[:, 0])):
            return _to_world(d[-1], Rz[-1])
        return self.forward_net.displacement(p[-self.forward_net.context:])


Odometry = PelvisOdometry | TwoWayOdometry


def _heading_inputs_np(p: np.ndarray, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``heading_frame_windows`` of the windows ``windows`` (n, C) (frame indices into ``p``
    (T, 9), float32) on numpy: (n, C * 9), and each window's cos, sin of its last frame's yaw.
    The 6D of ``R_z(-yaw) @ R`` is the turned first two columns of R, so the turn (written
    out about z) is applied to those and to the acceleration."""
    b1, b2 = rot6d_columns_np(p[:, :6])
    v = np.stack([b1, b2, p[:, 6:9]], axis=1)[windows]  # (n, C, 3 vectors, xyz)
    yaw = np.arctan2(b1[windows[:, -1], 1], b1[windows[:, -1], 0])
    c, s = np.cos(yaw), np.sin(yaw)
    out = turn_cs(v, c[:, None, None], -s[:, None, None])  # R_z(-yaw)
    return out.reshape(len(windows), -1), c, s


class OdometryKernel:
    """An odometry's ``displacement`` with the windows' inputs built on numpy (one frame's call
    of the two-way pair was ~1.7 ms of tiny torch ops); the nets stay torch's (a batch of
    windows through numpy would take OpenBLAS's threaded gemm, which spins on a busy machine:
    ``small_nets.NumpyMLP``). Called frame by frame with the frame's number, it keeps the
    backward net's answer of each frame's window for the gate's later frames: a window holds
    only frames already finished, so its answer does not change, and each frame then adds one
    window instead of the gate's 20."""

    def __init__(self, odo: Odometry) -> None:
        self.context = odo.context
        two_way = isinstance(odo, TwoWayOdometry)
        fwd = odo.forward_net if two_way else odo
        self._forward = (fwd, np.arange(self.context - fwd.context, self.context)[None])
        self._backward = None
        if two_way:
            b, g = odo.backward_net, odo.gate_frames
            last = np.arange(self.context - g, self.context)  # the gate's frames, each a window's last
            self._backward = (b, last[:, None] - np.arange(b.context - 1, -1, -1)[None])
            self._gate = -odo.gate_m_s / FPS_MODEL  # a mean forward step below this walks backwards
        self.reset()

    def reset(self) -> None:
        """Forget the kept answers (the poser's history restarted)."""
        g = 0 if self._backward is None else len(self._backward[1])
        self._kept = np.full(g, -1)  # ring by frame number: which frame's answer each slot holds
        self._d = np.zeros((g, 2), np.float32)
        self._cs = np.zeros((g, 2), np.float32)

    @torch.no_grad()
    def _answers(self, net: nn.Module, pelvis_frames: np.ndarray, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, c, s = _heading_inputs_np(pelvis_frames, windows)
        return (net(torch.from_numpy(x)) * net.out_std).numpy(), np.stack([c, s], axis=-1)

    def __call__(self, pelvis_frames: np.ndarray, frame: int | None = None) -> np.ndarray:
        """(context, 9) float32 raw pelvis features of the last frames (oldest first) -> (2,)
        this frame's root displacement in the world (metres). ``frame``: its number since
        the history started (the kept answers are for it), None to keep nothing."""
        if self._backward is not None:
            net, windows = self._backward
            g = len(windows)
            if frame is None:
                d, cs = self._answers(net, pelvis_frames, windows)
            else:
                frames = np.arange(frame - g + 1, frame + 1)
                slots = frames % g
                todo = np.flatnonzero(self._kept[slots] != frames)
                if len(todo):
                    self._d[slots[todo]], self._cs[slots[todo]] = self._answers(net, pelvis_frames, windows[todo])
                    self._kept[slots[todo]] = frames[todo]
                d, cs = self._d[slots], self._cs[slots]
            if d[:, 0].mean() < self._gate:
                return _turned_back(d[-1], cs[-1])
        d, cs = self._answers(self._forward[0], pelvis_frames, self._forward[1])
        return _turned_back(d[-1], cs[-1])


def _turned_back(d: np.ndarray, cs: np.ndarray) -> np.ndarray:
    """A heading-frame answer (2,) in the world: R_z(yaw) d, with cs = (cos, sin) of the yaw."""
    return turn_cs(d, cs[0], cs[1]).astype(np.float32, copy=False)


# --------------------------------------------------------------------------- training

@dataclass
class OdometryTraining(FitConfig):
    input_noise: float = 0.15  # in normalised units (0.3 did worse on the held-out training clips)
    context: int = CONTEXT
    hidden: int = 256
    # also train on the forward walks played backwards (the backward net of TwoWayOdometry):
    # backward walks then go backward, but forward walks come out worse on their own
    reverse_walks: bool = False


def heading_steps(x: np.ndarray | Tensor) -> np.ndarray:
    """(T, 190) one clip's features -> (T, 2) its root steps in the frame facing the pelvis
    (x forward, y left): the odometry's targets."""
    x = torch.as_tensor(np.asarray(x, dtype=np.float32))
    Rz = current_heading(clip_contexts(x, 1))
    return (Rz[:, :2, :2] @ x[:, SL_DP, None])[..., 0].numpy()


def with_reversed_walks(clips: Sequence[np.ndarray]) -> tuple[list[np.ndarray], int]:
    """The clips, then each forward walk among them played backwards; and how many were added."""
    walks = [reverse_features(np.asarray(x)) for x in clips if is_forward_walk(x, heading_steps(x))]
    return list(clips) + walks, len(walks)


def clip_targets(clips: Sequence[np.ndarray], context: int = CONTEXT, mirror: bool = False) -> tuple[Tensor, Tensor]:
    """Inputs (n, context * 9) and heading-frame root displacements (n, 2) of every frame of every clip."""
    X, Y = [], []
    for x in clip_tensors(clips, mirror):
        w = clip_contexts(x, context)
        Rz = current_heading(w)
        X.append(heading_frame_windows(w, Rz))
        Y.append((Rz[:, :2, :2] @ x[:, SL_DP, None])[..., 0])
    return torch.cat(X), torch.cat(Y)


def _clip_answers(net: PelvisOdometry, x: Tensor, pad: int = 0) -> tuple[Tensor, Tensor]:
    """Every frame's heading-frame answer and turn, as ``_heading_answers``, for a clip
    with ``pad`` copies of its first frame before it."""
    x = torch.cat([x[:1].expand(pad, -1), x]) if pad else x
    return _heading_answers(net, clip_contexts(x, net.context))


def clip_displacements(odo: Odometry, x: np.ndarray | Tensor) -> np.ndarray:
    """(T, 190) one clip's features -> (T, 2) the odometry's world root displacement of
    every frame, each from that frame's context alone (as the poser gets it live, the
    clip's first frame standing in for the history before it)."""
    x = torch.as_tensor(np.asarray(x, dtype=np.float32))
    with torch.no_grad():
        if isinstance(odo, PelvisOdometry):
            return _to_world(*_clip_answers(odo, x)).numpy()
        g = odo.gate_frames
        d, Rz = _clip_answers(odo.forward_net, x)
        db, Rzb = _clip_answers(odo.backward_net, x, pad=g - 1)
        back = odo.walking_backwards(db[:, 0].unfold(0, g, 1))
        d = torch.where(back[:, None], db[g - 1:], d)
        Rz = torch.where(back[:, None, None], Rzb[g - 1:], Rz)
        return _to_world(d, Rz).numpy()


def path_errors(odo: Odometry, clips: Sequence[np.ndarray], seconds: Sequence[int] = (2, 5, 10)) -> dict:
    """RE over ``seconds`` (m, pooled over start points as ``metrics.root_error``) of the
    path the odometry integrates alone from each clip's pelvis; None where no clip is long enough."""
    from inference.metrics.errors import root_error

    errs: dict[int, list[np.ndarray]] = {k: [] for k in seconds}
    for x in clips:
        pred = np.cumsum(clip_displacements(odo, x), axis=0)
        true = np.cumsum(np.asarray(x, np.float64)[:, SL_DP], axis=0)
        for k in seconds:
            e = root_error(pred, true, k, FPS_MODEL)
            if e is not None:
                errs[k].append(e)
    return {f"re{k}_m": round(float(np.concatenate(v).mean()), 4) if v else None for k, v in errs.items()}


def train_odometry(train_clips: Sequence[np.ndarray], val_sets: dict[str, Sequence[np.ndarray]] | None = None,
                   cfg: OdometryTraining | None = None, progress=print) -> PelvisOdometry:
    """Fit the odometry to every frame of ``train_clips`` (and their mirror images, and with
    ``cfg.reverse_walks`` their forward walks played backwards: ``odo.meta``); logs
    the root errors of the path it integrates alone on each validation set every 1000
    steps into ``cfg.log``."""
    cfg = cfg or OdometryTraining()
    reversed_walks = 0
    if cfg.reverse_walks:
        train_clips, reversed_walks = with_reversed_walks(train_clips)
    X, Y = clip_targets(train_clips, cfg.context)
    torch.manual_seed(cfg.seed)  # the initial weights
    odo = PelvisOdometry(cfg.context, cfg.hidden)
    odo.in_mean.copy_(X.mean(0))
    odo.in_std.copy_(X.std(0).clamp(min=1e-3))
    odo.out_std.copy_(Y.std(0).clamp(min=1e-3))
    scores = lambda: {f"{k}_{m}": e for k, v in (val_sets or {}).items()  # noqa: E731
                      for m, e in path_errors(odo, v).items()}
    fit(odo, (X, Y), clip_targets(train_clips, cfg.context, mirror=True), cfg,
        lambda out, y: F.mse_loss(out, y / odo.out_std), scores, progress)
    if cfg.reverse_walks:
        odo.meta = {"reversed_walks": reversed_walks}
    return odo


def train_two_way(train_clips: Sequence[np.ndarray], val_sets: dict[str, Sequence[np.ndarray]] | None = None,
                  cfg: OdometryTraining | None = None, progress=print) -> TwoWayOdometry:
    """The shipped recipe: the forward net on the clips as they are, then the backward net
    with their forward walks also played backwards (``cfg``'s other fields for both), gated.
    The pair's root errors on each validation set are the last entry of ``cfg.log``."""
    cfg = cfg or OdometryTraining()
    nets = []
    for stage, reverse in (("forward", False), ("backward", True)):
        part = replace(cfg, reverse_walks=reverse, log=[])
        report = (lambda e, stage=stage: progress({"stage": stage, **e})) if progress else None
        nets.append(train_odometry(train_clips, val_sets, part, report))
    odo = TwoWayOdometry(*nets)
    odo.meta = dict(nets[1].meta)
    scores = {f"{k}_{m}": e for k, v in (val_sets or {}).items() for m, e in path_errors(odo, v).items()}
    entry = {"step": cfg.steps, "stage": "two-way", **scores}
    cfg.log.append(entry)
    if progress:
        progress(entry)
    return odo


# --------------------------------------------------------------------------- files

def save_odometry(path: str | os.PathLike, odo: Odometry, meta: dict | None = None) -> None:
    if isinstance(odo, PelvisOdometry):
        return save_net(path, ODOMETRY_FORMAT, odo, meta)
    save_file(path, {"format": TWO_WAY_FORMAT, "forward": net_entry(odo.forward_net),
                     "backward": net_entry(odo.backward_net), "gate_m_s": odo.gate_m_s,
                     "gate_frames": odo.gate_frames, "meta": meta or {}})


def load_odometry(path: str | os.PathLike) -> Odometry:
    """Either kind of odometry file (a single net, or the shipped two-way pair)."""
    obj = read_file(path, (ODOMETRY_FORMAT, TWO_WAY_FORMAT), "pelvis odometry")
    if obj["format"] == ODOMETRY_FORMAT:
        odo = net_from_entry(obj, PelvisOdometry)
    else:
        odo = TwoWayOdometry(net_from_entry(obj["forward"], PelvisOdometry),
                             net_from_entry(obj["backward"], PelvisOdometry),
                             obj["gate_m_s"], obj["gate_frames"]).eval()
    odo.meta = obj.get("meta", {})
    return odo
