"""AGRoL's MLP (Du et al., CVPR 2023, sec. 3.2 and 4.1, Fig. 2) as a baseline for the
three-point task, on our skeleton, rate and data.

Why: a comparison of our model with three tracked points against the figures printed in
the paper would mix the method with the data (AMASS at 60 Hz against our Bandai, HDM05
and CMU clips at 20 Hz). The paper gives the MLP's architecture in full, so it is built
here and trained on the same windows as the shipped diffusion model
(``inference.training.agrol``), and both are scored on the same held-out clips with the
same rig noise (``benchmarks/vr_baseline.py``).

Architecture as the paper gives it (Fig. 2; the blocks as in its released code): a linear
layer lifts the N x C input to N x D; M blocks follow, each two pre-LayerNorm residual
branches: a 1x1 convolution over the *time* axis (an N x N linear map: the temporal
mixing) then SiLU, and a D x D linear layer over features then SiLU; a linear layer maps
D to the output S. No attention, no recurrence.

Input per frame (C = 54), for the headset (head) and the two controllers (l_hand, r_hand),
grouped by kind as AvatarPoser's and AGRoL's loaders do:
- global orientation of the device, 6D (3 x 6): the head's for the headset, the hand's
  turned by the grip (``tracked.grip_rotation``) for a controller;
- its frame-to-frame rotation R[t-1]^T R[t], 6D (3 x 6): per 20 Hz frame;
- its position minus the headset's floor projection (3 x 3), as ``tracked.point_features``
  gives it: world axes, so the height above the floor is kept;
- its world velocity p[t] - p[t-1] per 20 Hz frame (3 x 3), in metres per frame.
The first frame of a clip has no previous one: its change is the identity, its velocity 0.

Output (S = 144): the 24 segments' global orientations, 6D, for every frame of the window:
our feature layout's rotation block (``layout.SL_ROT``). Live, a frame's pose is the last
frame of the window that ends at it (causal, as the poser answers).

Loss: the paper's objective on the rotations (the squared error of the 6D output, its
eq. 4) plus its appendix's geometric losses L_pos and L_vel (eq. 7, 8: forward-kinematics
joint positions and their frame-to-frame changes), each with weight 1 as the appendix
sets them. Each term is a mean over its elements (6D components; joint coordinates in m;
per-frame changes in m), so with weight 1 the rotations dominate, as in the paper's
L_dm-only model.

Deviations from the paper, and why:
- Window N = 61 frames at 20 Hz (3.05 s), our model's window, not 196 at 60 Hz (3.27 s,
  65 frames at our rate): both models then see the same past, and the feature windows
  the training draws are this length already. The 1x1 temporal convolution is N x N, so
  only the window changes, not the design.
- Output: global orientations of all 24 segments (our rotation block) instead of SMPL's
  22 local rotations with the root's global one: the metrics and our FK take global
  orientations, and the 6D regression target is the same kind of number.
- D = 256 and M = 12 by default (``AgrolConfig``): 0.86 M parameters. The paper's MLP has
  D = 512, M = 12 (~3.4 M parameters for this block design at N = 196; its Table V's 7.48 M
  counts the diffusion model's per-block timestep layers). Two shared CPU cores and
  minutes instead of 200 k iterations on a GPU set the width; ``--d-model 512`` builds the
  paper's width.
- Positions relative to the headset's floor projection, not raw world positions: our
  windows have no absolute place (the data's capture volumes differ), and a live rig's
  origin is wherever its play area is. The paper's AMASS inputs are global.
- Rate: velocities and rotation changes are per 20 Hz frame (the paper's per 60 Hz frame).
- The root translation is not predicted (as in the paper); for scoring, the body is put
  under the tracked headset (``place_under_headset``), the paper's own step.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import Tensor, nn

from inference.body.body import forward_kinematics
from inference.body.rotations import matrix_to_rot6d, rot6d_to_matrix
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX
from inference.body.tracked import grip_rotation, point_features, point_locals, point_positions
from inference.features.layout import WINDOW

KIND = "agrol_mlp"
DEVICES: tuple[str, ...] = ("head", "l_hand", "r_hand")
INPUT_DIM = 18 * len(DEVICES)  # orientation 6 + change 6 + position 3 + velocity 3, per device
OUTPUT_DIM = 6 * N_SEGMENTS
DEVICE_SEGMENTS: tuple[int, ...] = tuple(SEGMENT_INDEX[d] for d in DEVICES)


@dataclass(frozen=True)
class AgrolConfig:
    window: int = WINDOW
    d_model: int = 256
    blocks: int = 12

    def __post_init__(self) -> None:
        if self.window < 2 or self.d_model < 1 or self.blocks < 1:
            raise ValueError(f"AgrolConfig needs window >= 2, d_model >= 1, blocks >= 1; got {self}")


class MlpBlock(nn.Module):
    """One block of Fig. 2: temporal mixing (1x1 conv over the N frames), then feature mixing
    (a D x D linear layer), each pre-normalised, activated by SiLU and added back."""

    def __init__(self, d_model: int, window: int) -> None:
        super().__init__()
        self.norm0 = nn.LayerNorm(d_model)
        self.temporal = nn.Conv1d(window, window, 1)
        self.norm1 = nn.LayerNorm(d_model)
        self.feature = nn.Linear(d_model, d_model)
        self.act = nn.SiLU()

    def forward(self, x: Tensor) -> Tensor:  # (B, N, D)
        x = x + self.act(self.temporal(self.norm0(x)))
        return x + self.act(self.feature(self.norm1(x)))


class AgrolMlp(nn.Module):
    """Sparse-input MLP: (B, N, 54) device features -> (B, N, 144) raw 6D global orientations."""

    def __init__(self, cfg: AgrolConfig | None = None) -> None:
        super().__init__()
        self.cfg = cfg or AgrolConfig()
        self.fc_in = nn.Linear(INPUT_DIM, self.cfg.d_model)
        self.blocks = nn.Sequential(*[MlpBlock(self.cfg.d_model, self.cfg.window) for _ in range(self.cfg.blocks)])
        self.fc_out = nn.Linear(self.cfg.d_model, OUTPUT_DIM)

    def forward(self, p: Tensor) -> Tensor:
        if p.shape[-2:] != (self.cfg.window, INPUT_DIM):
            raise ValueError(f"AGRoL MLP input must be (B, {self.cfg.window}, {INPUT_DIM}); got {tuple(p.shape)}")
        return self.fc_out(self.blocks(self.fc_in(p)))

    def n_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())

    @torch.no_grad()
    def pose_causal(self, inputs: np.ndarray | Tensor, chunk: int = 256) -> np.ndarray:
        """(T, 24, 3, 3) global orientations, frame by frame as live: frame t is the last
        frame of the window ending at t, which sees only frames <= t. Before a full window
        the first frame is held (a standing history, as the live poser starts)."""
        x = torch.as_tensor(np.asarray(inputs), dtype=torch.float32)
        T, N = x.shape[0], self.cfg.window
        padded = torch.cat([x[:1].expand(N - 1, -1), x], dim=0)
        windows = padded.unfold(0, N, 1).permute(0, 2, 1)  # (T, N, C): window t ends at frame t
        self.eval()
        out = [self(windows[s:s + chunk])[:, -1] for s in range(0, T, chunk)]
        return rot6d_to_matrix(torch.cat(out).reshape(T, N_SEGMENTS, 6).double()).numpy()


# --------------------------------------------------------------------------- input features
def device_poses(R: Any, joints: Any, locals_: Any) -> tuple[Any, Any]:
    """World positions (..., 3, 3) and orientations (..., 3, 3, 3) of the headset and the
    two controllers, for global orientations R (..., 24, 3, 3), joints (..., 24, 3) and
    ``tracked.point_locals`` (..., 4, 3): the rig's placement (``inference.body.tracked``)."""
    pos = point_positions(R, joints, locals_)[..., :3, :]
    g = grip_rotation()
    if isinstance(R, np.ndarray):
        rot = np.stack([R[..., DEVICE_SEGMENTS[0], :, :], R[..., DEVICE_SEGMENTS[1], :, :] @ g,
                        R[..., DEVICE_SEGMENTS[2], :, :] @ g], axis=-3)
    else:
        gt = torch.as_tensor(g, dtype=R.dtype, device=R.device)
        rot = torch.stack([R[..., DEVICE_SEGMENTS[0], :, :], R[..., DEVICE_SEGMENTS[1], :, :] @ gt,
                           R[..., DEVICE_SEGMENTS[2], :, :] @ gt], dim=-3)
    return pos, rot


def input_features(pos: Any, rot: Any) -> Any:
    """The MLP's input (..., T, 54) from device positions (..., T, 3, 3) and orientations
    (..., T, 3, 3, 3) over consecutive 20 Hz frames (module docstring for the layout)."""
    is_np = isinstance(pos, np.ndarray)
    xp = np if is_np else torch
    cat = (lambda a: np.concatenate(a, axis=-1)) if is_np else (lambda a: torch.cat(a, dim=-1))
    first = rot[..., :1, :, :, :]
    prev = xp.concatenate([first, rot[..., :-1, :, :, :]], axis=-4) if is_np else \
        torch.cat([first, rot[..., :-1, :, :, :]], dim=-4)
    prev_t = prev.swapaxes(-1, -2) if is_np else prev.transpose(-1, -2)
    change = prev_t @ rot
    p_prev = xp.concatenate([pos[..., :1, :, :], pos[..., :-1, :, :]], axis=-3) if is_np else \
        torch.cat([pos[..., :1, :, :], pos[..., :-1, :, :]], dim=-3)
    vel = pos - p_prev
    # position relative to the headset's floor projection: tracked.point_features with the
    # waist tracker's slot absent
    four = cat([pos.reshape(*pos.shape[:-2], 9), 0 * pos[..., 0, :]]).reshape(*pos.shape[:-2], 4, 3)
    present = np.array([True, True, True, False])
    rel = point_features(four, present)[..., :9]
    lead = pos.shape[:-2]
    return cat([matrix_to_rot6d(rot).reshape(*lead, 18), matrix_to_rot6d(change).reshape(*lead, 18), rel,
                vel.reshape(*lead, 9)])


def window_devices(R: Tensor, root: Tensor, offsets: Tensor, height: Tensor) -> tuple[Tensor, Tensor]:
    """Device positions (B, N, 3, 3) and orientations (B, N, 3, 3, 3) of feature windows:
    FK of the global orientations R (B, N, 24, 3, 3) from the root path (B, N, 3) with each
    window's bone offsets (B, 24, 3) and height (B,)."""
    joints = forward_kinematics(R, root, offsets[:, None])
    return device_poses(R, joints, point_locals(offsets, height)[:, None])


def add_tracking_noise(pos: Tensor, rot: Tensor, jitter_m: float, jitter_deg: float,
                       generator: torch.Generator | None = None) -> tuple[Tensor, Tensor]:
    """White tracking error as the simulated rig draws it (``SimVrRig.poses``): Gaussian
    per axis on positions (m) and a rotation vector per axis (deg) applied in the device
    frame."""
    from inference.body.rotations import axis_angle_to_matrix

    if jitter_m > 0:
        pos = pos + jitter_m * torch.randn(pos.shape, generator=generator, dtype=pos.dtype)
    if jitter_deg > 0:
        rv = np.deg2rad(jitter_deg) * torch.randn(rot.shape[:-1], generator=generator, dtype=rot.dtype)
        rot = rot @ axis_angle_to_matrix(rv)
    return pos, rot


# --------------------------------------------------------------------------- loss
@dataclass(frozen=True)
class LossWeights:
    rot: float = 1.0
    pos: float = 1.0
    vel: float = 1.0


def agrol_loss(pred6d: Tensor, R_true: Tensor, offsets: Tensor, weights: LossWeights = LossWeights(),
               ) -> tuple[Tensor, dict[str, float]]:
    """The paper's L_dm on the 6D output plus L_pos and L_vel on root-relative FK joints
    (module docstring). pred6d (B, N, 144); R_true (B, N, 24, 3, 3); offsets (B, 24, 3)."""
    B, N = pred6d.shape[:2]
    true6d = matrix_to_rot6d(R_true).reshape(B, N, OUTPUT_DIM)
    l_rot = ((pred6d - true6d) ** 2).mean()
    R_pred = rot6d_to_matrix(pred6d.reshape(B, N, N_SEGMENTS, 6))
    zero = torch.zeros(B, N, 3, dtype=pred6d.dtype)
    jp = forward_kinematics(R_pred, zero, offsets[:, None])
    jt = forward_kinematics(R_true, zero, offsets[:, None])
    l_pos = ((jp - jt) ** 2).mean()
    l_vel = (((jp[:, 1:] - jp[:, :-1]) - (jt[:, 1:] - jt[:, :-1])) ** 2).mean()
    total = weights.rot * l_rot + weights.pos * l_pos + weights.vel * l_vel
    return total, {"rot": float(l_rot.detach()), "pos": float(l_pos.detach()), "vel": float(l_vel.detach())}


# --------------------------------------------------------------------------- placement
def place_under_headset(R: np.ndarray, offsets: np.ndarray, height: float, headset: np.ndarray,
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Root (T, 3) and joints (T, 24, 3) of predicted orientations R (T, 24, 3, 3) translated
    so that the predicted headset sits on the tracked one (T, 3): the paper's placement
    (its model predicts no translation)."""
    zero = np.zeros((R.shape[0], 3))
    j0 = forward_kinematics(R, zero, offsets)
    hmd0 = point_positions(R, j0, point_locals(np.asarray(offsets, np.float64), np.float64(height)))[:, 0]
    root = np.asarray(headset, np.float64) - hmd0
    return root, j0 + root[:, None, :]


# --------------------------------------------------------------------------- files
def save_agrol(path: str | Path, model: AgrolMlp, **extra: Any) -> None:
    """One torch file: kind, config, weights, and whatever the trainer adds (step, optimiser)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    torch.save({"kind": KIND, "config": asdict(model.cfg), "state": model.state_dict(), **extra}, tmp)
    tmp.replace(path)


def load_agrol(path: str | Path) -> tuple[AgrolMlp, dict[str, Any]]:
    """The model of a file ``save_agrol`` wrote, and the file's other entries."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such AGRoL MLP file")
    try:
        blob = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable torch file ({exc})") from None
    if not isinstance(blob, dict) or blob.get("kind") != KIND:
        raise ValueError(f"{path}: not an AGRoL MLP file (kind {blob.get('kind') if isinstance(blob, dict) else '?'})")
    model = AgrolMlp(AgrolConfig(**blob["config"]))
    model.load_state_dict(blob["state"])
    model.eval()
    return model, {k: v for k, v in blob.items() if k not in ("kind", "config", "state")}


__all__ = ["KIND", "DEVICES", "INPUT_DIM", "OUTPUT_DIM", "AgrolConfig", "MlpBlock", "AgrolMlp", "device_poses",
           "input_features", "window_devices", "add_tracking_noise", "LossWeights", "agrol_loss",
           "place_under_headset", "save_agrol", "load_agrol"]
