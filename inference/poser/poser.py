"""The live poser: one 20 Hz observation in, one reconstructed body frame out.

DiffusionPoser runs autoregressively (paper sec. 3.4): the model always sees a 61-frame
window whose frames 0..N-2 are the *history* (measured + reconstructed features of the
last 60 frames) and whose last frame holds the new measurement. Each step:

1. shift the window by one frame; frame N-1 gets the new measurement for the observed
   features and a copy of frame N-2 for the unobserved ones (an initial guess the first
   inpainting step starts from);
2. inpaint with mask = all of the history + the observed features of frame N-1
   (``diffusion.inpaint``, Algorithm 1) -- or, for the baselines, one regressor pass or
   the standing pose;
3. clean the reconstructed frame (6D -> rotation -> 6D, contacts to 0/1, each knee a
   hinge about its lateral axis: ``joint_constraints``, ``knee_hinge=False`` to skip; on a still,
   upright stand the hinge's flexion settles to a straight knee: ``stand_prior``,
   ``stand_prior=False`` to skip), correct the
   root displacement from the predicted contacts, write it back into the history;
4. with both shanks measured, scale the root displacement by the running ratio of the
   shanks' inertial strides to the reconstructed ones (``stride.StrideScale``;
   ``stride_scale=False`` to skip; docs/model.md, "Stride scaling"): the reconstructed
   stride is the unmeasured thigh's guess; without both shanks, the root displacement
   comes from the pelvis sensor's last second instead
   (``pelvis_odometry.TwoWayOdometry``; ``pelvis_odometry=None`` to skip; docs/model.md,
   "Pelvis odometry"): there the guessed legs cancel the walk, even planted on the
   insoles' contacts;
5. integrate the root path and run FK for the outputs; the output root and the
   unmeasured orientations go through light speed-adaptive low-passes (``smoothing``,
   ``smoothing=False`` to skip): per-frame inference makes them wobble. Output only: the
   history and the root integration use the unfiltered values.

Frame of reference: the model is trained with random-heading augmentation and
heading-invariant normalisation (``training.rotate_yaw`` / ``feature_stats``), i.e. it
works in the *world* frame at any heading. So features go in exactly as calibration
delivers them (world frame, Z up, X = forward at calibration) and no yaw normalisation
is applied here; the standing history faces +X, which is the calibration heading.

A sensor missing in some frames (packet loss, out of range, a NaN from the resampler)
is simply unobserved in those frames: its features are inpainted like any other, the
motion continues, and the measurements take over again when they return.

Speed: the window is a float32 torch buffer (the model's input) that the step reads and
writes through a numpy view of the same memory; it is a view into a double-length buffer,
so shifting it is free except for one copy every N frames. Everything around the model
call (observation, cleaning, contacts, FK, root, filters) is float32/float64 numpy on one
frame's small arrays (``body.frame_kernels``, ``rotations``' ``*_np`` kernels, the helpers'
``NumpyMLP``): torch's per-op cost on tiny tensors was most of that time (docs/latency.md,
"Around the model call").

Default weights live in ``inference/weights/`` (``default_weights``); a missing file
raises a FileNotFoundError that says how to train one.
"""

from __future__ import annotations

import os
import warnings
import weakref
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from inference.body import frame_kernels as fk
from inference.body.body import CONTACT_SEGMENTS, Body, contact_points, forward_kinematics, npose_rotations, tpose
from inference.body.rotations import matrix_to_rot6d, matrix_to_rot6d_np, rot6d_to_matrix_np
from inference.body.skeleton import N_CONTACTS, N_SEGMENTS, SEGMENT_INDEX, SITE_INDEX
from inference.body.tracked import POINT_FEATURES
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT, WINDOW
from inference.features.mirror import MirrorAveraged
from inference.model.denoiser import Denoiser, freeze_for_cpu
from inference.model.diffusion import Schedule, inpaint, parse_steps, redraw
from inference.model.diffusion import symmetric_start as symmetric_start_at
from inference.model.files import LoadedModel
from inference.model.onnx_runtime import onnx_net, onnxruntime_available, resolve_runtime
from inference.model.regressor import regress
from inference.poser.confidence import (
    ConfidenceSettings,
    SpreadPool,
    confidence_settings,
    root_deviation_m,
    segment_deviation_deg,
)
from inference.poser.contact_detector import DETECTOR_THRESHOLD, SHANK_INDEX, ContactDetector, DetectorKernel
from inference.poser.joint_constraints import constrain_knees
from inference.poser.knee_twist import KNEE_TWIST, TurnShare
from inference.poser.lag import lagged_frames
from inference.poser.models import (
    CONTACT_THRESHOLD,
    DEFAULT_WEIGHTS,
    HISTORY_MODES,
    NOISE_MODES,
    POSER_KINDS,
    WEIGHTS_DIR,
    default_steps,
    default_weights,
    draws_model,
    mirror_for,
    noise_mode_for,
    resolve_detector,
    resolve_model,
    resolve_odometry,
)
from inference.poser.pelvis_odometry import PELVIS_INDEX, Odometry, OdometryKernel
from inference.poser.smoothing import ROOT_SMOOTHING, ROTATION_SMOOTHING, RotationOneEuro, VectorOneEuro
from inference.poser.stand_prior import StandPrior
from inference.poser.stride import FOOT_SEGMENTS, SHANK_SITES, StrideScale
from inference.signals.resample import FPS_MODEL, acc_filter_of

# --------------------------------------------------------------------------- models


# --------------------------------------------------------------------------- output

@dataclass
class PoseFrame:
    """One reconstructed 20 Hz frame.

    rot: (24, 3, 3) global segment orientations R_WB; root: (3,) pelvis joint position
    (m, world); joints: (24, 3) world joint positions; contacts: (4,) bool and
    contact_prob: (4,) the model's raw contact values clipped to [0, 1] (l_heel, l_toe,
    r_heel, r_toe); features: (190,) the full frame as written to the history (observed
    entries are exactly the input); observed: (190,) the mask actually used (input mask
    and finite values); index: frame counter since the last reset. spread_deg: (24,) how
    far other inpaintings of the window put each segment (degrees, 0 where measured) and
    root_spread_m: the same for the root (``confidence``); None when the poser computes
    no confidence.
    """

    index: int
    rot: np.ndarray
    root: np.ndarray
    joints: np.ndarray
    contacts: np.ndarray
    contact_prob: np.ndarray
    features: np.ndarray
    observed: np.ndarray
    spread_deg: np.ndarray | None = None
    root_spread_m: float | None = None
    # (k, 24, 3, 3) with ``Poser(answer_lag=k)``: this step's window's answers for the k frames
    # before it (index - k .. index - 1, oldest first), cleaned as the frame's own; None without
    earlier_rot: np.ndarray | None = None


def standing_features(body: Body, pose: str = "npose") -> np.ndarray:
    """(190,) features of a subject standing still on the floor facing +X: N-pose (arms
    down) or T-pose, acceleration 0, dp 0, pelvis at the height that puts the lowest foot
    point on z = 0 (the loaders floor-align every clip the same way), all contacts on."""
    if pose == "npose":
        R = npose_rotations(1)[0]
    elif pose == "tpose":
        R = tpose(1)[0]
    else:
        raise ValueError(f"unknown standing pose {pose!r} (npose, tpose)")
    joints = forward_kinematics(R, np.zeros(3), body.offsets)
    cps = contact_points(R, joints, body)
    x = np.zeros(N_FEATURES)
    x[SL_ROT] = matrix_to_rot6d(R).reshape(-1)
    x[SL_PZ] = -float(cps[:, 2].min())
    x[SL_CONTACT] = 1.0
    return x


# --------------------------------------------------------------------------- the poser

class Observation(NamedTuple):
    """One frame's observation as the poser takes it (numpy): f_in the features as given,
    m the mask used (given and finite), f32 float32 with the standing pose where
    unobserved, fn the same normalised."""

    f_in: np.ndarray
    m: np.ndarray
    f32: np.ndarray
    fn: np.ndarray


class Poser:
    """Frame-by-frame reconstruction with a diffusion model, the regressive baseline or
    the floor baseline, all behind one interface (``step``).

    model: a LoadedModel (kind "diffusion" or "regressor") or None for the floor
    baseline (unobserved segments held at the standing pose, root held). body: the
    subject's Body (bone lengths for FK and the root correction) or a height in metres.
    steps: diffusion step list (anything ``diffusion.parse_steps`` takes); default
    ``default_steps(model)``. seed: the inpainting noise generator's seed, so a replay is
    reproducible. root_xy0: where the root path starts. confidence: a per-segment spread
    with each frame (``confidence.ConfidenceSettings``, True for its defaults; diffusion
    models only); the pose itself is the same with it on or off. mirror_chains: with mirror
    averaging, average whole inpainting chains of the window and its mirror image instead of
    each model call (``_predict_chains``; None: the model file's ``mirror_chains``, off).
    symmetric_start: the mean start at the data mean's symmetric midpoint
    (``diffusion.symmetric_start``) instead of the data mean, for a model that answers without
    mirror chains (None: the model file's ``symmetric_start``, off). int8: the network's linear
    layers in int8 through ONNX Runtime's dynamic quantizer, one window a call, offline too, so
    an evaluation scores what runs live (None: the model file's ``int8``, off; without
    onnxruntime the float network runs, with a warning).
    """

    def __init__(
        self,
        model: LoadedModel | None,
        body: Body | float = 1.75,
        steps: str | int | Sequence[int] | None = None,
        seed: int = 0,
        start_pose: str = "npose",
        root_correction: bool = True,
        root_xy0: tuple[float, float] = (0.0, 0.0),
        inpaint_mode: str | None = None,
        freeze: bool = True,
        history: str | None = None,
        noise: str | None = None,
        smoothing: bool = True,
        knee_hinge: bool = True,
        stand_prior: bool = True,
        contact_threshold: float | None = None,
        contact_detector: ContactDetector | str | os.PathLike | None = "default",
        mirror: bool | None = None,
        stride_scale: bool = True,
        pelvis_odometry: Odometry | str | os.PathLike | None = "default",
        confidence: ConfidenceSettings | bool | None = None,
        runtime: str = "torch",
        mirror_chains: bool | None = None,
        answer_lag: int | None = None,
        knee_twist: float | None = None,
        symmetric_start: bool | None = None,
        int8: bool | None = None,
    ) -> None:
        self.model = model
        # the frame-by-frame call through ONNX Runtime where that is faster (live sessions ask
        # for "auto"; offline runs keep torch's exact results): inference/model/onnx_runtime.py
        self.runtime = resolve_runtime(runtime) if model is not None and model.kind == "diffusion" else "torch"
        self.int8 = int8_for(model, int8)
        if self.int8:  # an int8 file is its ONNX Runtime graph: offline runs take it too
            self.runtime = "onnx"
        self.kind = "floor" if model is None else model.kind
        if self.kind not in POSER_KINDS:
            raise ValueError(f"cannot pose with a model of kind {self.kind!r}")
        self.body = body if isinstance(body, Body) else Body.from_height(float(body))
        self.steps: list[int] = parse_steps(steps) if steps is not None else default_steps(model)
        if self.kind != "diffusion":
            self.steps = [] if self.kind == "floor" else [0]  # one pass; reported as such
        self.window = model.config.window if model is not None else WINDOW
        # frames after a frame whose sensors its shown answer may use (``lagged_frames``): 0
        # live; a model trained to answer late says how late in its file (TrainConfig.answer_lag)
        lag = answer_lag if answer_lag is not None else int(((model.meta or {}) if model is not None else {})
                                                             .get("answer_lag", 0))
        if not 0 <= lag < self.window or (lag and self.kind != "diffusion"):
            raise ValueError(f"answer_lag {lag}: 0 to {self.window - 1} frames, and only for a diffusion model")
        self.answer_lag = int(lag)
        self.root_correction = root_correction and self.kind != "floor"
        self.stride = StrideScale(self.body, FPS_MODEL) if stride_scale and self.root_correction else None
        self.start_pose = start_pose
        # None = what the model file recommends (meta, set at export), else the paper's way
        meta = (model.meta or {}) if model is not None else {}
        history = history or meta.get("history") or "reconstructed"
        noise = noise_mode_for(model, noise)
        if history not in HISTORY_MODES:
            raise ValueError(f"unknown history mode {history!r} ({', '.join(HISTORY_MODES)})")
        if noise not in NOISE_MODES:
            raise ValueError(f"unknown noise mode {noise!r} ({', '.join(NOISE_MODES)})")
        self.history_mode = history
        self.noise_mode = noise
        self.inpaint_mode = inpaint_mode or meta.get("inpaint_mode") or "paper"
        # the acceleration filter the model was trained on: the live resampler must match it
        self.acc_filter = acc_filter_of(meta)
        self.contact_threshold = float(contact_threshold if contact_threshold is not None
                                       else meta.get("contact_threshold", CONTACT_THRESHOLD))
        self.seed = seed
        # contacts from both shank sensors when they are measured (contact_detector.py):
        # far more often right than a reconstruction model's own contact features
        self.contact_detector = None if self.kind == "floor" else resolve_detector(contact_detector)
        self._detector = DetectorKernel(self.contact_detector) if self.contact_detector is not None else None
        # without both shanks the root's walk from the pelvis sensor (pelvis_odometry.py):
        # the guessed legs cancel the walk there, insoles or not
        self.pelvis_odometry = None if self.kind == "floor" else resolve_odometry(pelvis_odometry)
        self._odometry = OdometryKernel(self.pelvis_odometry) if self.pelvis_odometry is not None else None
        # the floor is by definition the standing pose wherever nothing is measured
        self.knee_hinge = knee_hinge and self.kind != "floor"
        # the most of the model's own thigh twist a thigh rebuilt from its shank keeps, while the body
        # turns (knee_twist.py: a living knee lets the shin turn under the thigh; 0 = the strict hinge)
        self.knee_twist = float(knee_twist if knee_twist is not None else meta.get("knee_twist", KNEE_TWIST))
        self._turn_share = TurnShare(self.knee_twist)
        # a still, upright stand straightens the knees the hinge leaves to the model (stand_prior.py)
        self._stand_prior = StandPrior() if stand_prior and self.knee_hinge else None
        # output only: the integrated root path (and so every later frame) is unfiltered
        self.smoothing = smoothing
        self._filters = ((VectorOneEuro(FPS_MODEL, ROOT_SMOOTHING), RotationOneEuro(FPS_MODEL, ROTATION_SMOOTHING))
                         if smoothing else None)
        self.root_xy0 = (float(root_xy0[0]), float(root_xy0[1]))
        self.schedule = Schedule.cosine()
        # the live loop always calls the denoiser with one (1, N, 190) window, or two with
        # mirror averaging (mirror.MirrorAveraged: the window and its mirror image in one
        # batch): a frozen TorchScript trace of that shape is ~25-30% faster per call on CPU
        # (bench_model.py)
        self.mirror = mirror_for(model, mirror)
        self._freeze = freeze
        self._net = self.net_for(1) if model is not None else None
        self.confidence = confidence_settings(confidence) if self.kind == "diffusion" else None
        self._draw_net = None
        # the draws re-noise an answer to a middle level: a chain student never saw such a state
        # (it learns only its own chain's), so its file names the model that draws for it
        self.draw_model = draws_model(model) if self.confidence is not None else model
        if self.confidence is not None:
            self._draw_net = self.draw_net_for(self.confidence.draws)
            self._spread = SpreadPool(self.confidence.pool)
        if model is not None:
            self._mean = torch.as_tensor(model.norm_mean, dtype=torch.float32)
            self._std = torch.as_tensor(model.norm_std, dtype=torch.float32)
        else:
            self._mean = torch.zeros(N_FEATURES)
            self._std = torch.ones(N_FEATURES)
        chains = mirror_chains if mirror_chains is not None else bool(meta.get("mirror_chains", False))
        self.chain_mirror = (chains and self.kind == "diffusion" and bool(self.mirror)
                             and self.noise_mode == "mean" and not self.takes_points)
        self.mirror_op = None
        if self.chain_mirror:
            from inference.features.mirror import MirrorAveraged

            self.mirror_op = MirrorAveraged(model.model, model.norm_mean, model.norm_std)
        sym = symmetric_start if symmetric_start is not None else bool(meta.get("symmetric_start", False))
        # where the mean start's draw sits (None: the data mean, 0); its own mirror image, so the
        # mirror chains' second half starts there too
        self.start_at = (torch.as_tensor(symmetric_start_at(model.norm_mean, model.norm_std))
                         if sym and self.kind == "diffusion" and self.noise_mode == "mean"
                         and model.norm_mean is not None else None)
        self._height = torch.tensor([self.body.height], dtype=torch.float32)
        self._offsets = torch.as_tensor(self.body.offsets, dtype=torch.float32)
        self._contact_offsets = torch.as_tensor(self.body.contact_offsets, dtype=torch.float32)
        self._stand = torch.as_tensor(standing_features(self.body, start_pose), dtype=torch.float32)
        # the per-frame path's numpy forms of the same (Poser.finish)
        self._mean_np, self._std_np, self._stand_np = self._mean.numpy(), self._std.numpy(), self._stand.numpy()
        self._kin = fk.Kinematics(self.body.offsets)
        self._cp_local = np.asarray(self.body.contact_offsets, dtype=np.float32)[:, :, None]
        # frames the history keeps: the model's window, or more where a helper reads further
        # back (the two-way odometry's gate reads 39; a short-window model keeps them anyway)
        self._keep = max([self.window, *(h.context for h in (self._detector, self._odometry) if h is not None)])
        self.reset()

    @property
    def takes_points(self) -> bool:
        """Whether the model reads tracked points' positions (``ModelConfig.points``)."""
        cfg = getattr(self.model, "config", None) if self.model is not None else None
        return bool(getattr(cfg, "points", False)) and self.kind == "diffusion"

    def net_for(self, windows: int, mirror: bool | None = None, model: LoadedModel | None = None):
        """The model (``model``: another one, the draws') as called on ``windows`` windows at
        once: a frozen trace of that batch shape (mirror averaging doubles it) when the poser
        freezes. Traces are kept per model and shape (``_model_nets``), so the many posers of
        an offline run share them."""
        mirror = self.mirror if mirror is None else mirror
        model = model or self.model
        # a model with a position input takes it as a keyword the traces do not carry: eager
        frozen = self._freeze and isinstance(model.model, Denoiser) and not self.takes_points
        nets = _model_nets(model)
        # one window (mirror-averaged inside the graph) or the two chains of whole-chain mirror averaging
        int8 = self.int8 and frozen and model is self.model
        onnx = frozen and (windows == 1 or (windows == 2 and not mirror) or int8) and self.runtime == "onnx"
        key = (windows, mirror, frozen, self.window) + (("onnx",) if onnx else ()) + (("int8",) if int8 else ())
        if key not in nets:
            batch = windows * (2 if mirror else 1)
            fast = None
            if onnx:
                eager = MirrorAveraged(model.model, model.norm_mean, model.norm_std) if mirror else model.model
                fast = onnx_net(eager, windows, self.window, N_FEATURES, model.config.mask_input, quantize=int8)
            if fast is not None:
                nets[key] = fast
            else:
                net = freeze_for_cpu(model.model, batch=batch, window=self.window) if frozen else model.model
                nets[key] = MirrorAveraged(net, model.norm_mean, model.norm_std) if mirror else net
        return nets[key]

    def draw_net_for(self, windows: int):
        """The net of the confidence draws for ``windows`` windows (no mirror averaging: the
        draws estimate a width, not a pose)."""
        return self.net_for(windows, mirror=False, model=self.draw_model)

    # ------------------------------------------------------------------ state
    def reset(self, root_xy0: tuple[float, float] | None = None) -> None:
        """Back to a standing history (e.g. after recalibration or a long dropout)."""
        if self._stand_prior is not None:
            self._stand_prior.reset()
        self._turn_share.reset()
        if root_xy0 is not None:
            self.root_xy0 = (float(root_xy0[0]), float(root_xy0[1]))
        N, K = self.window, self._keep
        with torch.inference_mode():
            stand_n = self._normalize(self._stand)
            # double-length buffer of the K frames kept: the window is buf[:, pos-N+1 : pos+1]
            self._buf = stand_n.repeat(1, 2 * K, 1).contiguous()
            self._pos = K - 1
            self._mask = torch.ones(1, N, N_FEATURES, dtype=torch.bool)
            # per-frame masks aligned with _buf ("measured" history); the standing start
            # counts as known: it is the calibration pose the session began in
            self._mbuf = (torch.ones(1, 2 * K, N_FEATURES, dtype=torch.bool)
                          if self.history_mode == "measured" else None)
            self._stand_win = stand_n.expand(1, N, N_FEATURES)
            # tracked points' position input per frame, aligned with _buf (none at the start)
            self._pbuf = torch.zeros(1, 2 * K, POINT_FEATURES) if self.takes_points else None
            # numpy views of the same memory, for the per-frame path
            self._buf_np = self._buf.numpy()
            self._mask_np = self._mask.numpy()
            self._mbuf_np = self._mbuf.numpy() if self._mbuf is not None else None
            R0 = rot6d_to_matrix_np(self._stand_np[SL_ROT].reshape(N_SEGMENTS, 6))
            self._prev_cps = self._contact_points(R0, self._kin.joints(R0))
            self._root_xy = np.array(self.root_xy0, dtype=np.float64)
            self._root_raw = np.zeros(2)  # the root path without stride scaling
            self._gen = torch.Generator().manual_seed(self.seed)
            if self.confidence is not None:
                self._draw_gen = torch.Generator().manual_seed(self.confidence.seed)
                self._spread.reset()
        for f in self._filters or ():
            f.reset()
        if self._odometry is not None:
            self._odometry.reset()
        if self.stride is not None:
            self.stride.reset()
        self.index = 0

    def _normalize(self, x: Tensor) -> Tensor:
        return (x - self._mean) / self._std

    def _advance(self) -> Tensor:
        """Shift the window by one frame; returns the window view (1, N, F) whose last
        frame is free to fill."""
        N, K = self.window, self._keep
        if self._pos + 1 >= 2 * K:
            self._buf_np[:, : K - 1] = self._buf_np[:, K + 1:]
            if self._mbuf_np is not None:
                self._mbuf_np[:, : K - 1] = self._mbuf_np[:, K + 1:]
            if self._pbuf is not None:
                self._pbuf[:, : K - 1] = self._pbuf[:, K + 1:].clone()
            self._pos = K - 2
        self._pos += 1
        return self._buf[:, self._pos - N + 1: self._pos + 1]

    def history_rows(self) -> Tensor:
        """(N, F) the current window as the model takes it (normalised), oldest first: a
        view, valid until the next ``enter``."""
        return self._buf[0, self._pos - self.window + 1: self._pos + 1]

    def history_mask_rows(self) -> Tensor:
        """(N, F) what the history mode tells the model is known of the current window."""
        if self._mbuf is None:
            return torch.ones(self.window, N_FEATURES, dtype=torch.bool)
        return self._mbuf[0, self._pos - self.window + 1: self._pos + 1]

    def history(self) -> np.ndarray:
        """(N, 190) the current window in physical units (a copy), for inspection/tests."""
        N = self.window
        with torch.inference_mode():
            w = self._buf[0, self._pos - N + 1: self._pos + 1] * self._std + self._mean
            return w.numpy().copy()

    def warm_up(self) -> None:
        """One model call of the live step on the current window, answer thrown away and
        nothing the next step reads changed: the first call of a network builds its runtime's
        graph or trace and sizes its buffers (~0.25 s), which in a live session fell on the
        first pose after calibration and cost the four 20 Hz frames behind it."""
        if self.kind != "diffusion":
            return
        state = self._gen.get_state()
        with torch.inference_mode():
            self._predict(self.history_rows()[None].clone(), self.history_mask_rows()[None].clone())
        self._gen.set_state(state)

    # ------------------------------------------------------------------ one step
    def _predict(self, win: Tensor, mask: Tensor) -> Tensor:
        if self.chain_mirror:
            return self._predict_chains(win, mask)
        if self.kind == "diffusion":
            if self.noise_mode == "fixed":
                self._gen.manual_seed(self.seed)
            return inpaint(self._net, win, mask, self._height, self.steps, generator=self._gen,
                           schedule=self.schedule, mode=self.inpaint_mode,
                           mask_input=self.model.config.mask_input,
                           start="mean" if self.noise_mode == "mean" else "sample", points=self.points_window(),
                           start_at=self.start_at)
        if self.kind == "regressor":
            return regress(self._net, win, mask, self._height)
        return torch.where(mask, win, self._stand_win)

    def _predict_chains(self, win: Tensor, mask: Tensor) -> Tensor:
        """Mirror averaging of whole inpainting chains: the window and its mirror image are
        inpainted side by side (one batch of two) and the answers averaged, the second
        mirrored back. Equivariant exactly: a standing body measured symmetric gets
        symmetric legs, which averaging each model call does not give, since the chains'
        common start (the data mean) is not its own mirror image."""
        P = self.mirror_op.mirror
        w2 = torch.cat([win, P(win)])
        m2 = torch.cat([mask, mask[..., self.mirror_op.idx]])
        out = inpaint(self.net_for(2, mirror=False), w2, m2, self._height.expand(2), self.steps, generator=self._gen,
                      schedule=self.schedule, mode=self.inpaint_mode, mask_input=self.model.config.mask_input,
                      start="mean", start_at=self.start_at)
        # the known entries as measured: the mirror image's round trip moves them by float rounding
        return torch.where(mask, win, 0.5 * (out[:1] + P(out[1:])))

    def step(self, features: np.ndarray | Tensor, observed_mask: np.ndarray | Tensor,
             points: np.ndarray | Tensor | None = None) -> PoseFrame:
        """Reconstruct the next frame from this frame's observation.

        features: (190,) physical units; only the observed entries are read (the others
        may hold anything, NaN included). observed_mask: (190,) bool, True = measured in
        this frame (``features.observation_mask`` of the sensors that delivered).
        points: (16,) this frame's tracked points (``inference.body.tracked.point_features``)
        for a model that reads them; None = none tracked. Their orientations come as the
        segments' entries of ``features`` with ``observed_mask``.
        """
        with torch.inference_mode():
            obs = self.observe(features, observed_mask)
            win, mask = self.enter(obs)
            self.enter_points(points)
            out = self._predict(win, mask)
            draws = None
            if self.confidence_due():
                draws = self.draw(out, win, mask, self.draw_noise())[:, -1]
            return self.finish(out[0, -1], win, obs, draws, self.earlier_rows(out[0]))

    def earlier_rows(self, out: Tensor) -> Tensor | None:
        """(k, F) a window's answers (N, F) for the ``answer_lag`` frames before its newest."""
        k = self.answer_lag
        return out[-1 - k:-1] if k else None

    # The step in stages, so that an offline run can batch the model calls of many frames
    # (``batched.reconstruct_batched``) and still pass each frame through the same code.
    def observe(self, features: np.ndarray | Tensor, observed_mask: np.ndarray | Tensor) -> Observation:
        """This frame's observation, as the model and the history take it."""
        f_in = _numpy(features)
        m = _numpy(observed_mask).astype(bool, copy=False).reshape(N_FEATURES)
        f32 = f_in.astype(np.float32).reshape(N_FEATURES)
        m = m & np.isfinite(f32)
        f32 = np.where(m, f32, self._stand_np)  # no NaN may reach any arithmetic
        return Observation(f_in, m, f32, (f32 - self._mean_np) / self._std_np)

    def enter(self, obs: Observation) -> tuple[Tensor, Tensor]:
        """Shift the window and put the observation into its last frame; returns the
        window view (1, N, F) and the mask the model is given."""
        win = self._advance()
        pos = self._pos
        np.copyto(self._buf_np[0, pos], np.where(obs.m, obs.fn, self._buf_np[0, pos - 1]))
        if self.history_mode == "measured":
            self._mbuf_np[0, pos] = obs.m
            return win, self._mbuf[:, pos - self.window + 1: pos + 1]
        self._mask_np[0, -1] = obs.m
        return win, self._mask

    def enter_points(self, points: np.ndarray | Tensor | None) -> None:
        """This frame's tracked points into the window just entered (a model without a
        position input ignores them; NaN reads as not tracked)."""
        if self._pbuf is None:
            return
        p = torch.zeros(POINT_FEATURES) if points is None else torch.as_tensor(_writable(points)).to(torch.float32)
        self._pbuf[0, self._pos] = torch.where(torch.isfinite(p), p, torch.zeros(()))

    def points_window(self) -> Tensor | None:
        """(1, N, 16) the tracked points of the current window, or None for a model without them."""
        if self._pbuf is None:
            return None
        return self._pbuf[:, self._pos - self.window + 1: self._pos + 1]

    def confidence_due(self) -> bool:
        """Whether the frame about to be finished gets new draws."""
        return self.confidence is not None and self.index % self.confidence.every == 0

    def draw_noise(self, frames: int = 1) -> Tensor:
        """(frames * draws, N, F) the draws' noise of the next ``frames`` due frames, in the
        order a frame-by-frame run draws it."""
        return torch.randn((frames * self.confidence.draws, self.window, N_FEATURES), generator=self._draw_gen)

    def draw(self, out: Tensor, win: Tensor, mask: Tensor, noise: Tensor, net=None,
             heights: Tensor | None = None) -> Tensor:
        """(B * draws, N, F) normalised draws near the answers ``out`` (B, N, F) of the
        windows ``win`` with masks ``mask``; ``net``: the denoiser for that batch size,
        ``heights`` (B,): the subjects' (default: this poser's)."""
        k = self.confidence.draws

        def rep(a: Tensor) -> Tensor:
            return a.repeat_interleave(k, dim=0) if k > 1 else a

        h = rep(heights) if heights is not None else self._height.expand(noise.shape[0])
        pts = self.points_window() if heights is None else None
        return redraw(net or self._draw_net, rep(out), rep(win), rep(mask), h, self.confidence.level, noise,
                      self.schedule, mask_input=self.draw_model.config.mask_input, points=pts)

    def finish(self, y_n: Tensor | np.ndarray, win: Tensor, obs: Observation,
               draws: Tensor | None = None, earlier: Tensor | np.ndarray | None = None) -> PoseFrame:
        """Clean the model's answer ``y_n`` (F,) for the window's last frame (normalised),
        correct and integrate the root, write the frame into the history and return it;
        ``draws`` (k, F): other inpaintings of the frame for the spread, or None;
        ``earlier`` (k, F): the window's answers for the frames before it (``earlier_rows``)."""
        # a degenerate answer (a zero 6D) gives NaN quietly, as torch did
        with np.errstate(divide="ignore", invalid="ignore"):
            frame = self._finish(y_n, win, obs, draws)
            if earlier is not None:
                frame.earlier_rot = self._clean_earlier(earlier, frame.observed)
            return frame

    def _clean_earlier(self, rows: Tensor | np.ndarray, m: np.ndarray) -> np.ndarray:
        """(k, 24, 3, 3) the earlier frames' answers cleaned as a frame's own (valid
        rotations, the knee hinge, the stand prior's settling so far), their measured
        segments as measured (the window keeps them exact)."""
        y = _numpy(rows) * self._std_np + self._mean_np
        R = rot6d_to_matrix_np(y[:, SL_ROT].reshape(-1, N_SEGMENTS, 6))
        if self.knee_hinge:
            measured = m[SL_ROT].reshape(N_SEGMENTS, 6).all(axis=-1)
            R = constrain_knees(R, measured, self._turn_share.now)
            if self._stand_prior is not None:
                R = np.stack([self._stand_prior.settle(r, measured) for r in R])
        return R

    def _finish(self, y_n: Tensor | np.ndarray, win: Tensor, obs: Observation, draws: Tensor | None) -> PoseFrame:
        f_in, m, f32, fn = obs
        wn = win.numpy()[0]  # (N, F), the same memory
        y = _numpy(y_n) * self._std_np + self._mean_np  # physical units, fresh array

        # clean the reconstruction: valid rotations, 0/1 contacts (what the data holds)
        R = rot6d_to_matrix_np(y[SL_ROT].reshape(N_SEGMENTS, 6))
        seg_measured = m[SL_ROT].reshape(N_SEGMENTS, 6).all(axis=-1)
        if self.knee_hinge:
            R = constrain_knees(R, seg_measured, self._turn_share(R[_PELVIS]))
            if self._stand_prior is not None:
                R = self._stand_prior(R, seg_measured)
        y[SL_ROT] = np.where(m[SL_ROT], y[SL_ROT], matrix_to_rot6d_np(R).reshape(-1))
        prob = np.clip(y[SL_CONTACT], 0.0, 1.0)
        threshold = self.contact_threshold
        det = self._detector
        detected = False
        shanks = bool(m[SHANK_INDEX].all())
        if det is not None and shanks and not m[SL_CONTACT].any():
            prob, threshold = det(self._recent(SHANK_INDEX, det.context)), DETECTOR_THRESHOLD
            detected = True
        contact = prob > threshold
        y[SL_CONTACT] = np.where(m[SL_CONTACT], y[SL_CONTACT], contact.astype(np.float32))

        joints_rel = self._kin.joints(R)
        cps = self._contact_points(R, joints_rel)
        dp_measured = bool(m[SL_DP].any())
        root_step = "measured" if dp_measured else "model"
        if self.root_correction and not dp_measured:
            odo = self._odometry
            if odo is not None and not shanks and bool(m[PELVIS_INDEX].all()):
                y[SL_DP] = odo(self._recent(PELVIS_INDEX, odo.context), self.index)
                root_step = "odometry"
            else:
                y[SL_DP] = correct_root_displacement(y[SL_DP], self._prev_cps, cps, contact)
                root_step = "contacts"
        apart = None
        if draws is not None:
            apart = self._draws_apart(draws, R, y, m, seg_measured, contact if detected else None, threshold,
                                      root_step)
        self._prev_cps = cps

        # history keeps the exact normalised measurement where observed
        wn[-1] = np.where(m, fn, (y - self._mean_np) / self._std_np)

        scale = 1.0
        if self.stride is not None and not dp_measured:
            scale = self._stride_scale(joints_rel, f32, m, contact, y[SL_DP])
            y[SL_DP] = y[SL_DP] * scale
        if apart is not None:
            seg_dev, pz_d, dp_d = apart
            yt = torch.from_numpy(y)
            self._spread.add(seg_dev, root_deviation_m(pz_d, yt[SL_PZ], dp_d * scale, yt[SL_DP], FPS_MODEL))
        self._root_xy += y[SL_DP]
        root = np.concatenate([self._root_xy.astype(np.float32), y[SL_PZ]])
        if self._filters is not None:
            root_filter, rot_filter = self._filters
            root = root_filter(root)
            R = rot_filter(R, seg_measured)
            if not seg_measured.all():  # else every segment passed through: the same joints
                joints_rel = self._kin.joints(R)
        joints = joints_rel + root
        feats = np.where(m, f_in.reshape(N_FEATURES), y.astype(np.float64))
        pool = self._spread if self.confidence is not None else None
        frame = PoseFrame(
            index=self.index, rot=R, root=root, joints=joints,
            contacts=contact, contact_prob=prob, features=feats,
            observed=m,
            spread_deg=None if pool is None or pool.spread_deg is None else pool.spread_deg.copy(),
            root_spread_m=None if pool is None else pool.root_spread_m,
        )
        self.index += 1
        return frame

    def _contact_points(self, R: np.ndarray, joints_rel: np.ndarray) -> np.ndarray:
        """(4, 3) heel/toe points relative to the root (``body.contact_points``)."""
        return fk.points_on_segments(R, joints_rel, _CONTACT_SEGMENTS, self._cp_local)

    def _draws_apart(self, draws: Tensor, R: np.ndarray, y: np.ndarray, m: np.ndarray, seg_measured: np.ndarray,
                     detected: np.ndarray | None, threshold: float,
                     root_step: str) -> tuple[np.ndarray, Tensor, Tensor]:
        """How far each draw (k, F) is from the cleaned answer: (k, 24) degrees, and the
        draws' root height (k,) and root step (k, 2) as the answer's root path would take
        them (the same contact rule; the answer's own step where a sensor gives it).
        Torch, on the frame's numpy arrays (shared memory)."""
        R, y, m, seg_measured = (torch.from_numpy(a) for a in (R, y, m, seg_measured))
        detected = torch.from_numpy(detected) if detected is not None else None
        prev_cps = torch.from_numpy(self._prev_cps)
        yd = draws * self._std + self._mean
        k = yd.shape[0]
        # the answer's own kernels: a measured segment's draw is then exactly the answer's
        Rd = rot6d_to_matrix_np(yd[:, SL_ROT].numpy().reshape(k, N_SEGMENTS, 6))
        if self.knee_hinge:
            Rd = constrain_knees(Rd, seg_measured.numpy(), self._turn_share.now)
        Rd = torch.from_numpy(Rd)
        seg_dev = segment_deviation_deg(Rd, R)
        pz_d = torch.where(m[SL_PZ], y[SL_PZ], yd[:, SL_PZ])
        if root_step in ("odometry", "measured"):
            dp_d = y[SL_DP].expand(k, 2)
        elif root_step == "contacts":
            if detected is not None:
                contact_d = detected.expand(k, -1)
            else:
                contact_d = yd[:, SL_CONTACT].clamp(0.0, 1.0) > threshold
                contact_d = torch.where(m[SL_CONTACT], y[SL_CONTACT] > 0.5, contact_d)
            cps_d = contact_points(Rd, forward_kinematics(Rd, torch.zeros(3), self._offsets), self._contact_offsets)
            dp_d = torch.stack([correct_root_displacement(yd[i, SL_DP], prev_cps, cps_d[i], contact_d[i])
                                for i in range(k)])
        else:
            dp_d = yd[:, SL_DP]
        return seg_dev, pz_d, dp_d

    def _recent(self, idx: np.ndarray, n: int) -> np.ndarray:
        """(n, len(idx)) the features ``idx`` of the history's last n frames (this one
        included) in physical units, oldest first: what a helper stage reads, from the kept
        history (a helper may read further back than the model's window)."""
        rows = self._buf_np[0, self._pos - n + 1: self._pos + 1]
        return rows[:, idx] * self._std_np[idx] + self._mean_np[idx]

    def _stride_scale(self, joints_rel: np.ndarray, f32: np.ndarray, m: np.ndarray, contact: np.ndarray,
                      dp: np.ndarray) -> float:
        """Feed this frame to the stride estimator; the factor for this frame's root step.
        Without both shanks the paper's root stands alone (the bias the scale undoes belongs
        to the sensor set it was measured with); the scale is kept for when they return."""
        self._root_raw += dp
        if not (bool(m[_SHANK_ROT].all()) and bool(m[_SHANK_ACC].all())):
            self.stride.drop()
            return 1.0
        ankles = joints_rel[_FOOT_JOINTS, :2].astype(np.float64) + self._root_raw
        R = rot6d_to_matrix_np(f32[_SHANK_ROT].reshape(2, 6))
        return self.stride.update(R, f32[_SHANK_ACC].reshape(2, 3), contact, ankles)


_SHANK_SEGMENTS = tuple(SEGMENT_INDEX[s] for s in SHANK_SITES)
_PELVIS = SEGMENT_INDEX["pelvis"]
_FOOT_JOINTS = np.array([SEGMENT_INDEX[s] for s in FOOT_SEGMENTS])
_SHANK_ROT = np.array([SL_ROT.start + 6 * k + i for k in _SHANK_SEGMENTS for i in range(6)])
_SHANK_ACC = np.array([SL_ACC.start + 3 * SITE_INDEX[s] + i for s in SHANK_SITES for i in range(3)])
_CONTACT_SEGMENTS = np.array(CONTACT_SEGMENTS)


_NETS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def int8_for(model: LoadedModel | None, int8: bool | None = None) -> bool:
    """Whether a poser runs ``model``'s network in int8 (``Poser(int8=)``; None: its file's
    ``int8``): a diffusion model's, where ONNX Runtime is installed (else the float network,
    said once)."""
    if model is None or model.kind != "diffusion":
        return False
    want = bool((model.meta or {}).get("int8", False)) if int8 is None else bool(int8)
    if want and not onnxruntime_available():
        warnings.warn("this model runs its linear layers in int8 through ONNX Runtime, which is not installed: "
                      "running the float network (pip install '.[onnx]')", stacklevel=3)
        return False
    return want


def _model_nets(model: LoadedModel) -> dict:
    """The traced forms of one loaded model's network, dropped with it."""
    return _NETS.setdefault(model.model, {})


def _writable(a):
    """torch refuses to wrap read-only numpy views (e.g. broadcasts) without a warning."""
    if isinstance(a, np.ndarray) and not a.flags.writeable:
        return a.copy()
    return a


def _numpy(a) -> np.ndarray:
    """An array or CPU tensor as numpy, without a copy where none is needed."""
    return a.numpy() if isinstance(a, Tensor) else np.asarray(a)


def correct_root_displacement(dp: Tensor | np.ndarray, prev_points: Tensor | np.ndarray, points: Tensor | np.ndarray,
                              contact: Tensor | np.ndarray) -> Tensor | np.ndarray:
    """The paper's root correction (sec. 3.4.2): subtract from the predicted ground-plane
    root displacement ``dp`` (2,) the mean horizontal *world* displacement, from the
    previous frame to this one, of the foot points predicted in contact.

    prev_points/points: (4, 3) heel/toe points relative to the root at the previous and
    this frame; a point's world displacement is its relative displacement plus ``dp``,
    so a point in contact that moved with the body by ``d`` pulls dp to ``-d`` (the foot
    stays planted, the pelvis moves). With no point in contact dp is unchanged. Torch
    tensors or numpy arrays (all of one kind).
    """
    if not bool(contact.any()):
        return dp
    world = points[:, :2] - prev_points[:, :2] + dp
    return dp - world[contact].mean(0)


# --------------------------------------------------------------------------- offline

@dataclass
class Reconstruction:
    """A whole clip reconstructed frame by frame (20 Hz): rot (T,24,3,3), root (T,3),
    joints (T,24,3), contacts (T,4) bool, contact_prob (T,4), features (T,190);
    spread_deg (T,24) and root_spread_m (T,) the poser's confidence, NaN without it."""

    rot: np.ndarray
    root: np.ndarray
    joints: np.ndarray
    contacts: np.ndarray
    contact_prob: np.ndarray
    features: np.ndarray
    spread_deg: np.ndarray | None = None
    root_spread_m: np.ndarray | None = None

    @classmethod
    def empty(cls, T: int) -> Reconstruction:
        """Arrays for T frames, to be filled frame by frame (``put``)."""
        return cls(rot=np.empty((T, N_SEGMENTS, 3, 3)), root=np.empty((T, 3)), joints=np.empty((T, N_SEGMENTS, 3)),
                   contacts=np.empty((T, N_CONTACTS), dtype=bool), contact_prob=np.empty((T, N_CONTACTS)),
                   features=np.empty((T, N_FEATURES)), spread_deg=np.full((T, N_SEGMENTS), np.nan),
                   root_spread_m=np.full(T, np.nan))

    @classmethod
    def of_frames(cls, frames: Sequence[PoseFrame], poser: Poser) -> Reconstruction:
        """A clip's frames, in order, as ``poser`` shows them: with its ``answer_lag``, each
        frame as the window that many frames later answered it (``lag.lagged_frames``)."""
        if poser.answer_lag:
            frames = lagged_frames(frames, poser.body)
        rec = cls.empty(len(frames))
        for t, frame in enumerate(frames):
            rec.put(t, frame)
        return rec

    def put(self, t: int, fr: PoseFrame) -> None:
        self.rot[t], self.root[t], self.joints[t] = fr.rot, fr.root, fr.joints
        self.contacts[t], self.contact_prob[t], self.features[t] = fr.contacts, fr.contact_prob, fr.features
        if fr.spread_deg is not None:
            self.spread_deg[t] = fr.spread_deg
        if fr.root_spread_m is not None:
            self.root_spread_m[t] = fr.root_spread_m

    def __len__(self) -> int:
        return int(self.rot.shape[0])


def reconstruct_offline(poser: Poser, features: np.ndarray, mask: np.ndarray, progress=None,
                        points: np.ndarray | None = None) -> Reconstruction:
    """Run the live loop over a clip: features (T, 190), mask (T, 190) or (190,) bool,
    points (T, 16) tracked points' input or None.

    Exactly the per-frame ``step`` a live session runs (no look-ahead, no batching), so
    evaluation measures what a user gets; a poser with an ``answer_lag`` then shows each
    frame as the window that many frames later answered it (``lag.lagged_frames``), as an
    import or replay does. ``progress`` is called with 1 after each frame
    (e.g. a tqdm ``update``)."""
    features = np.asarray(features)
    T = features.shape[0]
    mask = np.ascontiguousarray(np.broadcast_to(np.asarray(mask, dtype=bool), (T, N_FEATURES)))
    frames = []
    for t in range(T):
        frames.append(poser.step(features[t], mask[t], None if points is None else points[t]))
        if progress is not None:
            progress(1)
    return Reconstruction.of_frames(frames, poser)


def make_poser(spec: str | os.PathLike | LoadedModel | None, body: Body | float = 1.75,
               steps: str | int | Sequence[int] | None = None, **kwargs) -> Poser:
    """A Poser from a model spec (see ``resolve_model``): "diffusion" (default weights),
    "regressor", "floor", a model file path, or a LoadedModel."""
    return Poser(resolve_model(spec), body=body, steps=steps, **kwargs)


__all__ = [
    "Poser", "PoseFrame", "Reconstruction", "reconstruct_offline", "make_poser", "resolve_model", "mirror_for",
    "default_weights", "default_steps", "standing_features", "correct_root_displacement",
    "DEFAULT_WEIGHTS", "WEIGHTS_DIR", "POSER_KINDS",
]
