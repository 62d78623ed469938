"""Hub frames of a VR rig on a generated walk, for the live chain's and the recording's
tests: an IMU at the pelvis (its own heading reference) and the rig at the head and wrists
(its devices' orientations and positions in the rig's own frame, turned about Z and moved
against ours), with the calibration that maps each site's frame to the world."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration import Calibration
from drivers.hub import HubFrame
from inference.body.conventions import rot_z as rz
from inference.body.motion import Motion
from inference.body.rotations import matrix_to_quat
from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
from inference.body.tracked import point_locals, point_positions
from inference.signals.synthesis import Kinematics, kinematics
from sim_devices.motions import generate

SITES = ("pelvis", "head", "l_wrist", "r_wrist")  # an IMU at the pelvis, the rig at the others
RIG_SITES = ("head", "l_wrist", "r_wrist")
RIG_YAW = math.radians(35.0)  # the rig's frame against ours, as a runtime's room setup puts it
PELVIS_YAW = math.radians(100.0)  # the pelvis IMU's own heading reference: not the rig's
RIG_ORIGIN = np.array([1.3, -0.7, 0.0])  # the room's origin; the floor is z = 0 in both
T0 = 200.0
# the segment each site's device turns with: a controller is held in the fist
DEVICE_SEGMENT = {"pelvis": "pelvis", "head": "head", "l_wrist": "l_hand", "r_wrist": "r_hand"}
POINT = {"head": 0, "l_wrist": 1, "r_wrist": 2}


@dataclass
class Rig:
    motion: Motion
    kin: Kinematics  # the truth at 60 Hz
    frames: list[HubFrame]
    calibration: Calibration


def rig_walk(seconds: float = 4.0, seed: int = 4) -> Rig:
    motion = generate("walk", seconds=seconds, seed=seed)
    kin = kinematics(motion, 60.0)
    pts = point_positions(kin.rot, kin.joints, point_locals(motion.body.offsets, motion.body.height))
    R_WG = np.stack([rz(PELVIS_YAW)] + [rz(RIG_YAW)] * 3)
    frames = []
    for i in range(len(kin.rot)):
        quat, free, pos = np.zeros((4, 4)), np.zeros((4, 3)), np.full((4, 3), np.nan)
        for k, s in enumerate(SITES):
            quat[k] = matrix_to_quat(R_WG[k].T @ kin.rot[i, SEGMENT_INDEX[DEVICE_SEGMENT[s]]])
            free[k] = R_WG[k].T @ kin.site_acc_raw[i, SITE_INDEX[s]]
            if s in POINT:
                pos[k] = R_WG[k].T @ pts[i, POINT[s]] + RIG_ORIGIN
        frames.append(HubFrame(t=T0 + i / 60.0, index=i, sites=SITES, quat=quat, free_acc=free,
                               acc=np.zeros((4, 3)), gyro=np.zeros((4, 3)), present=np.ones(4, bool),
                               insole_force=np.full(2, np.nan), contacts=np.zeros(4, bool), insole_present=False,
                               position=pos))
    cal = Calibration(SITES, R_WG=R_WG, R_SB=np.tile(np.eye(3), (4, 1, 1)), acc_offset=np.zeros((4, 3)),
                      valid=np.ones(4, bool))
    return Rig(motion, kin, frames, cal)
