"""The live frame: what one 60 Hz sample tells the poser, on the model's 13-site layout and in
the model's world, as one numpy record with named fields (``LIVE_FRAME``):

    orientations   (13, 3, 3)  calibrated R_WB of each site, NaN where not observed
    accelerations  (13, 3)     calibrated world free acceleration, NaN where not observed
    flags          (13,)       the site was observed (present, active, finite) in this sample
    contacts       (4,)        the insoles' contact labels, NaN when no insole was read
    positions      (4, 3)      the tracked points (``TRACKED_POINTS``) in the model's world,
                               NaN where not tracked

The record is built at one stage of the live chain (``FrameBuilder.build``): the calibration
turns the IMUs' readings into the first three fields, then each optional input the pipeline
was given (``FrameInput``: the insoles, a VR rig's points) writes its own field. Nothing after
that stage knows which inputs exist: the resampler carries the record of the sample a 20 Hz
frame stands for (and averages the accelerations), ``observation`` turns a record into the
poser's 190 features, mask and position input, and what is absent is simply NaN.

The layout exists here only. A field is added by adding it to ``LIVE_FRAME`` (NaN or False
when absent, in ``empty_frame``), an input that writes it, and its reading in
``observation``; docs/design.md, "The live frame".
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Protocol

import numpy as np

from inference.body.rotations import matrix_to_rot6d
from inference.body.skeleton import N_CONTACTS, N_SITES, SITE_INDEX, SITE_SEGMENT_INDEX, SITES
from inference.body.tracked import TRACKED_POINTS, point_features
from inference.features.layout import N_FEATURES, SL_ACC, SL_CONTACT, SL_ROT, observation_mask

if TYPE_CHECKING:
    from calibration import Calibration
    from drivers.hub import HubFrame

N_POINTS = len(TRACKED_POINTS)

LIVE_FRAME = np.dtype([
    ("orientations", np.float64, (N_SITES, 3, 3)),
    ("accelerations", np.float64, (N_SITES, 3)),
    ("flags", np.bool_, (N_SITES,)),
    ("contacts", np.float64, (N_CONTACTS,)),
    ("positions", np.float64, (N_POINTS, 3)),
])


def empty_frame() -> np.ndarray:
    """A 0-d ``LIVE_FRAME`` record with nothing observed: NaN values, no flag set."""
    f = np.zeros((), LIVE_FRAME)
    for name in LIVE_FRAME.names:
        if LIVE_FRAME[name].base.kind == "f":
            f[name] = np.nan
    return f


class FrameInput(Protocol):
    """An optional input of the live frame: writes its own field(s) of ``frame`` from the hub
    frame (``ok``: the hub's sites that are present, active and hold a finite calibrated
    reading in this sample)."""

    def enter(self, frame: np.ndarray, hub: HubFrame, calibration: Calibration, ok: np.ndarray) -> None: ...


class InsoleInput:
    """The insoles' contacts, while they are in use (``enabled``: the pipeline's ``insoles``)."""

    def __init__(self, enabled: bool = False) -> None:
        self.enabled = bool(enabled)

    def enter(self, frame: np.ndarray, hub: HubFrame, calibration: Calibration, ok: np.ndarray) -> None:
        if self.enabled and hub.insole_present:
            frame["contacts"] = hub.contacts


class FrameBuilder:
    """The stage where a calibrated hub frame over ``sites`` (the hub's order) becomes a live
    frame: the IMUs of the ``active`` sites, then every input in ``inputs``."""

    def __init__(self, sites: Sequence[str], inputs: Sequence[FrameInput] = ()) -> None:
        self.sites = tuple(sites)
        self._site_idx = np.array([SITE_INDEX[s] for s in self.sites], dtype=int)
        self.inputs = list(inputs)

    def build(self, hub: HubFrame, calibration: Calibration, active: np.ndarray) -> np.ndarray:
        R, a = calibration.apply(hub.quat, hub.free_acc, hub.acc, sites=self.sites)
        ok = hub.present & active & np.all(np.isfinite(R), axis=(-1, -2)) & np.all(np.isfinite(a), axis=-1)
        frame = empty_frame()
        k = self._site_idx[ok]
        frame["orientations"][k] = R[ok]
        frame["accelerations"][k] = a[ok]
        frame["flags"][k] = True
        for inp in self.inputs:
            inp.enter(frame, hub, calibration, ok)
        return frame


@dataclass
class Observation:
    """A 20 Hz live frame as the poser reads it: ``x`` (190,) features and ``mask`` (190,)
    True where known; ``points`` the position input (16,) or None (no headset: the points
    are read against it); ``observed`` (13,) the sites measured; ``insoles`` contacts known."""

    x: np.ndarray
    mask: np.ndarray
    points: np.ndarray | None
    observed: np.ndarray
    insoles: bool


def observation(frame: np.ndarray) -> Observation:
    """The poser's view of a live frame (its accelerations already averaged by the resampler)."""
    R, acc = frame["orientations"], frame["accelerations"]
    observed = frame["flags"] & np.all(np.isfinite(acc), axis=-1)
    contacts = frame["contacts"]
    insoles = bool(np.isfinite(contacts).all())
    x = np.zeros(N_FEATURES)
    for k in np.nonzero(observed)[0]:
        seg = SITE_SEGMENT_INDEX[k]
        x[SL_ROT.start + 6 * seg: SL_ROT.start + 6 * seg + 6] = matrix_to_rot6d(R[k]).reshape(6)
        x[SL_ACC.start + 3 * k: SL_ACC.start + 3 * k + 3] = acc[k]
    if insoles:
        x[SL_CONTACT] = contacts
    mask = observation_mask([SITES[k] for k in np.nonzero(observed)[0]], insoles=insoles)
    return Observation(x=x, mask=mask, points=position_input(frame["positions"]), observed=observed,
                       insoles=insoles)


def position_input(points: np.ndarray) -> np.ndarray | None:
    """The frame's position input (16,) (``point_features``) from its tracked points (4, 3)
    in the model's world (NaN = not tracked), or None when the points cannot be read: no
    headset (they are read against it)."""
    flags = np.isfinite(points).all(axis=-1)
    if not flags[0]:
        return None
    return point_features(np.where(flags[:, None], points, 0.0)[None], flags[None])[0]


__all__ = ["LIVE_FRAME", "FrameBuilder", "FrameInput", "InsoleInput", "N_POINTS", "Observation", "empty_frame",
           "observation", "position_input"]
