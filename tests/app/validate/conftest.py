"""A recorded walk with its truth, and reference files written from that truth with a known
time shift and heading: what every validate test checks itself against.

The recording goes the way ``imucap demo --record`` records (synthesized protocol and
walk, 60 Hz hub frames through the live Pipeline calibrating itself, into the Recorder),
with the floor poser so a replay takes a second; the sites measured are reconstructed
from their sensors, the rest stand, which gives errors large and small to reproduce."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from app.capture.offline_session import record_motion
from inference.body.conventions import rot_z
from inference.body.motion import Motion
from sim_devices.motions import generate

SITES = ("pelvis", "torso", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_upperarm", "r_upperarm", "l_wrist",
         "r_wrist")
T0 = 500.0  # session time of the first hub frame
SHIFT_FRAMES = 37  # the reference starts this many truth frames into the session
HEADING_DEG = 63.0  # the reference's world is turned by this about the vertical


@dataclass
class Walk:
    path: Path
    truth: Motion  # on the session clock: frame i at T0 + i / fps

    def reference_motion(self, shift: int = SHIFT_FRAMES, heading_deg: float = HEADING_DEG) -> Motion:
        """The truth as another system saw it: from frame ``shift`` on, in a world turned by
        ``heading_deg``."""
        Z = rot_z(np.deg2rad(heading_deg))
        m = self.truth
        return Motion(Z @ m.rot[shift:], m.root[shift:] @ Z.T, m.fps, m.body, name="reference")

    def expected_offset(self, shift: int = SHIFT_FRAMES) -> float:
        """Reference clock minus the recording's clock: the reference's frame 0 is truth
        frame ``shift``, the recording's time 0 is truth frame 0."""
        return -shift / self.truth.fps


@pytest.fixture(scope="session")
def walk(tmp_path_factory) -> Walk:
    path = tmp_path_factory.mktemp("validate") / "walk.h5"
    truth = record_motion(path, generate("walk", seconds=14.0, seed=5), SITES, rng=3, t0=T0, flush_interval=0.2)
    return Walk(path, truth)
