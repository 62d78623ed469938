"""The live poser's step around the model call as it was written in torch, before the
numpy per-frame path (``inference/poser/poser.py``, ``body.frame_kernels``): the reference
that test_fast_path.py holds the fast path to, and that benchmarks/poser_stages.py times
beside it. It composes the library's general (numpy-or-torch) functions, one torch op at a
time, exactly as ``Poser.observe``/``enter``/``finish`` did; only the model call is shared.
"""

from __future__ import annotations

import math

import numpy as np
import torch
from torch import Tensor

from inference.body.body import contact_points, forward_kinematics
from inference.body.rotations import matrix_to_rot6d, rot6d_to_matrix, so3_exp, so3_log
from inference.body.skeleton import N_SEGMENTS, SEGMENT_INDEX, SITE_INDEX
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_DP, SL_PZ, SL_ROT
from inference.poser.confidence import root_deviation_m, segment_deviation_deg
from inference.poser.contact_detector import DETECTOR_THRESHOLD, SHANK_INDEX
from inference.poser.joint_constraints import constrain_knees
from inference.poser.pelvis_odometry import PELVIS_INDEX
from inference.poser.poser import Observation, PoseFrame, Poser, _writable, correct_root_displacement
from inference.poser.smoothing import ROOT_SMOOTHING, ROTATION_SMOOTHING, OneEuroConfig
from inference.poser.stride import FOOT_SEGMENTS, SHANK_SITES
from inference.signals.resample import FPS_MODEL

# --------------------------------------------------------------------------- the filters in torch


def _gain_torch(cutoff_hz: Tensor | float, dt: float) -> Tensor:
    """Gain of a first-order low-pass with this cutoff sampled every dt seconds."""
    tau = 1.0 / (2.0 * math.pi * torch.as_tensor(cutoff_hz))
    return 1.0 / (1.0 + tau / dt)


class _OneEuro:
    """State and gains shared by the filters: the last output and the filtered speed."""

    def __init__(self, fps: float, config: OneEuroConfig | None = None) -> None:
        self.dt = 1.0 / float(fps)
        self.config = config or OneEuroConfig()
        self._rate_gain = float(_gain_torch(self.config.rate_cutoff_hz, self.dt))
        self.reset()

    def reset(self) -> None:
        """Forget the past: the next sample passes through and starts the state."""
        self._last: Tensor | None = None
        self._rate: Tensor | None = None

    def _gain(self, speed: Tensor) -> Tensor:
        """Update the filtered speed with this sample's and return the smoothing gain."""
        assert self._rate is not None
        self._rate = self._rate + self._rate_gain * (speed - self._rate)
        return _gain_torch(self.config.min_cutoff_hz + self.config.beta * self._rate, self.dt)

    def _start(self, x: Tensor, rows: tuple[int, ...]) -> Tensor:
        self._last = x.clone()
        self._rate = torch.zeros(rows, dtype=x.dtype)
        return x.clone()


class TorchVectorOneEuro(_OneEuro):
    """1-Euro filter of a vector signal (..., D): each row's cutoff follows its speed."""

    def __call__(self, x: Tensor) -> Tensor:
        if self._last is None:
            return self._start(x, tuple(x.shape[:-1]))
        step = x - self._last
        gain = self._gain(step.norm(dim=-1) / self.dt).to(x.dtype)
        self._last = self._last + gain[..., None] * step
        return self._last.clone()


class TorchRotationOneEuro(_OneEuro):
    """1-Euro filter of rotations (S, 3, 3), one state per rotation; the speed that sets
    each cutoff is the filtered angular rate (rad/s)."""

    def __call__(self, R: Tensor, passthrough: Tensor | None = None) -> Tensor:
        """Filtered R (S, 3, 3); ``passthrough`` (S,) bool: returned as given (and kept
        as the state), for measured segments."""
        if self._last is None:
            return self._start(R, (R.shape[0],))
        step = so3_log(self._last.transpose(-1, -2) @ R)  # (S, 3) in each rotation's own frame
        gain = self._gain(step.norm(dim=-1) / self.dt).to(R.dtype)
        out = self._last @ so3_exp(step * gain[:, None])
        if passthrough is not None:
            out = torch.where(passthrough[:, None, None], R, out)
        self._last = out
        return out.clone()


# --------------------------------------------------------------------------- the poser

class ReferencePoser(Poser):
    """A Poser whose step around the model call is the torch code it was written as."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._shank_idx = torch.as_tensor(SHANK_INDEX)
        self._pelvis_idx = torch.as_tensor(PELVIS_INDEX)
        if self._filters is not None:
            self._filters = (TorchVectorOneEuro(FPS_MODEL, ROOT_SMOOTHING),
                             TorchRotationOneEuro(FPS_MODEL, ROTATION_SMOOTHING))
        self.reset()

    def reset(self, root_xy0: tuple[float, float] | None = None) -> None:
        super().reset(root_xy0)
        with torch.inference_mode():
            R0 = rot6d_to_matrix(self._stand[SL_ROT].view(N_SEGMENTS, 6))
            j0 = forward_kinematics(R0, torch.zeros(3), self._offsets)
            self._prev_cps = contact_points(R0, j0, self._contact_offsets)
            self._root_xy = torch.tensor(self.root_xy0, dtype=torch.float64)

    def _advance(self) -> Tensor:
        """Shift the window by one frame; returns the window view (1, N, F) whose last
        frame is free to fill."""
        N = self.window
        if self._pos + 1 >= 2 * N:
            self._buf[:, : N - 1] = self._buf[:, N + 1:].clone()
            if self._mbuf is not None:
                self._mbuf[:, : N - 1] = self._mbuf[:, N + 1:].clone()
            if self._pbuf is not None:
                self._pbuf[:, : N - 1] = self._pbuf[:, N + 1:].clone()
            self._pos = N - 2
        self._pos += 1
        return self._buf[:, self._pos - N + 1: self._pos + 1]

    def observe(self, features: np.ndarray | Tensor, observed_mask: np.ndarray | Tensor) -> Observation:
        """This frame's observation, as the model and the history take it."""
        f_in = torch.as_tensor(_writable(features))
        m = torch.as_tensor(_writable(observed_mask)).to(torch.bool).reshape(N_FEATURES)
        f32 = f_in.to(torch.float32).reshape(N_FEATURES)
        m = m & torch.isfinite(f32)
        f32 = torch.where(m, f32, self._stand)  # no NaN may reach any arithmetic
        return Observation(f_in, m, f32, self._normalize(f32))

    def enter(self, obs: Observation) -> tuple[Tensor, Tensor]:
        """Shift the window and put the observation into its last frame; returns the
        window view (1, N, F) and the mask the model is given."""
        win = self._advance()
        win[0, -1] = torch.where(obs.m, obs.fn, win[0, -2])
        if self.history_mode == "measured":
            self._mbuf[0, self._pos] = obs.m
            return win, self._mbuf[:, self._pos - self.window + 1: self._pos + 1]
        self._mask[0, -1] = obs.m
        return win, self._mask

    def finish(self, y_n: Tensor, win: Tensor, obs: Observation, draws: Tensor | None = None,
               earlier: Tensor | None = None) -> PoseFrame:
        """Clean the model's answer ``y_n`` (F,) for the window's last frame (normalised),
        correct and integrate the root, write the frame into the history and return it;
        ``draws`` (k, F): other inpaintings of the frame for the spread, or None. The reference
        is the live step's: it answers the newest frame only (``earlier`` is None)."""
        assert earlier is None, "the reference poser has no answer lag"
        f_in, m, f32, fn = obs
        y = y_n * self._std + self._mean  # physical units, fresh tensor

        # clean the reconstruction: valid rotations, 0/1 contacts (what the data holds)
        R = rot6d_to_matrix(y[SL_ROT].reshape(N_SEGMENTS, 6))
        seg_measured = m[SL_ROT].view(N_SEGMENTS, 6).all(dim=-1)
        if self.knee_hinge:
            R = constrain_knees(R, seg_measured, self._turn_share(R[SEGMENT_INDEX["pelvis"]].numpy()))
        y[SL_ROT] = torch.where(m[SL_ROT], y[SL_ROT], matrix_to_rot6d(R).reshape(-1))
        prob = y[SL_CONTACT].clamp(0.0, 1.0)
        threshold = self.contact_threshold
        det = self.contact_detector
        detected = False
        if det is not None and not bool(m[SL_CONTACT].any()) and bool(m[self._shank_idx].all()):
            prob, threshold = det.probabilities(self._recent(win, self._shank_idx, det.context)), DETECTOR_THRESHOLD
            detected = True
        contact = prob > threshold
        y[SL_CONTACT] = torch.where(m[SL_CONTACT], y[SL_CONTACT], contact.to(y.dtype))

        joints_rel = forward_kinematics(R, torch.zeros(3), self._offsets)
        cps = contact_points(R, joints_rel, self._contact_offsets)
        root_step = "measured" if bool(m[SL_DP].any()) else "model"
        if self.root_correction and not bool(m[SL_DP].any()):
            odo = self.pelvis_odometry
            if odo is not None and not bool(m[self._shank_idx].all()) and bool(m[self._pelvis_idx].all()):
                y[SL_DP] = odo.displacement(self._recent(win, self._pelvis_idx, odo.context))
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
        win[0, -1] = torch.where(m, fn, self._normalize(y))

        scale = 1.0
        if self.stride is not None and not bool(m[SL_DP].any()):
            scale = self._stride_scale(joints_rel, f32, m, contact, y[SL_DP])
            y[SL_DP] = y[SL_DP] * scale
        if apart is not None:
            seg_dev, pz_d, dp_d = apart
            self._spread.add(seg_dev, root_deviation_m(pz_d, y[SL_PZ], dp_d * scale, y[SL_DP], FPS_MODEL))
        self._root_xy += y[SL_DP].to(torch.float64)
        root = torch.cat([self._root_xy.to(torch.float32), y[SL_PZ]])
        if self._filters is not None:
            root_filter, rot_filter = self._filters
            root = root_filter(root)
            R = rot_filter(R, seg_measured)
            joints_rel = forward_kinematics(R, torch.zeros(3), self._offsets)
        joints = joints_rel + root
        feats = torch.where(m, f_in.to(torch.float64).reshape(N_FEATURES), y.to(torch.float64))
        pool = self._spread if self.confidence is not None else None
        frame = PoseFrame(
            index=self.index, rot=R.numpy(), root=root.numpy(), joints=joints.numpy(),
            contacts=contact.numpy(), contact_prob=prob.numpy(), features=feats.numpy(),
            observed=m.numpy(),
            spread_deg=None if pool is None or pool.spread_deg is None else pool.spread_deg.copy(),
            root_spread_m=None if pool is None else pool.root_spread_m,
        )
        self.index += 1
        return frame

    def _draws_apart(self, draws: Tensor, R: Tensor, y: Tensor, m: Tensor, seg_measured: Tensor,
                     detected: Tensor | None, threshold: float, root_step: str) -> tuple[np.ndarray, Tensor, Tensor]:
        """How far each draw (k, F) is from the cleaned answer: (k, 24) degrees, and the
        draws' root height (k,) and root step (k, 2) as the answer's root path would take
        them (the same contact rule; the answer's own step where a sensor gives it)."""
        yd = draws * self._std + self._mean
        k = yd.shape[0]
        Rd = rot6d_to_matrix(yd[:, SL_ROT].reshape(k, N_SEGMENTS, 6))
        if self.knee_hinge:
            Rd = constrain_knees(Rd, seg_measured, self._turn_share.now)
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
            dp_d = torch.stack([correct_root_displacement(yd[i, SL_DP], self._prev_cps, cps_d[i], contact_d[i])
                                for i in range(k)])
        else:
            dp_d = yd[:, SL_DP]
        return seg_dev, pz_d, dp_d

    def _recent(self, win: Tensor, idx: Tensor, n: int) -> Tensor:
        """(n, len(idx)) the features ``idx`` of the window's last n frames in physical
        units, oldest first: what a helper stage reads."""
        return win[0, -n:, idx] * self._std[idx] + self._mean[idx]

    def _stride_scale(self, joints_rel: Tensor, f32: Tensor, m: Tensor, contact: Tensor,
                      dp: Tensor) -> float:
        """Feed this frame to the stride estimator; the factor for this frame's root step.
        Without both shanks the paper's root stands alone (the bias the scale undoes belongs
        to the sensor set it was measured with); the scale is kept for when they return."""
        self._root_raw += dp.numpy().astype(np.float64)
        if not (bool(m[_SHANK_ROT].all()) and bool(m[_SHANK_ACC].all())):
            self.stride.drop()
            return 1.0
        ankles = joints_rel.numpy()[list(_FOOT_JOINTS), :2].astype(np.float64) + self._root_raw
        R = rot6d_to_matrix(f32[_SHANK_ROT].reshape(2, 6)).numpy()
        return self.stride.update(R, f32[_SHANK_ACC].numpy().reshape(2, 3), contact.numpy(), ankles)



_SHANK_SEGMENTS = tuple(SEGMENT_INDEX[s] for s in SHANK_SITES)
_FOOT_JOINTS = tuple(SEGMENT_INDEX[s] for s in FOOT_SEGMENTS)
_SHANK_ROT = torch.tensor([SL_ROT.start + 6 * k + i for k in _SHANK_SEGMENTS for i in range(6)])
_SHANK_ACC = torch.tensor([SL_ACC.start + 3 * SITE_INDEX[s] + i for s in SHANK_SITES for i in range(3)])
