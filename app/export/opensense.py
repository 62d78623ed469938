"""Write a reconstruction's sensor orientations as OpenSense's ``_orientations.sto``: the
quaternion table OpenSim's IMU placer and IMU inverse kinematics read
(``STOFileAdapterQuaternion``), one column per IMU named as OpenSense names them for the
Rajagopal model (``pelvis_imu``, ``torso_imu``, ``femur_r_imu``, ``tibia_r_imu``,
``calcn_r_imu``, ``humerus_r_imu``, ``radius_r_imu``, and ``_l``).

Header: ``DataRate=``, ``DataType=Quaternion``, ``version=3``, ``OpenSimVersion=4.6``,
``endheader``; then ``time`` and the IMU names, tab-separated; each cell ``w,x,y,z``.

What each quaternion is: the calibrated orientation at the sensor's site, with the
sensor-to-segment mounting taken out, i.e. the orientation of the OpenSim body the IMU
sits on (``inference.metrics.joint_angles.opensim_frames``: G_os = M R Q^T M^T), in OpenSim's ground (X forward,
Y up, Z right). So in OpenSense leave ``sensor_to_opensim_rotations`` at 0 0 0, and the
IMU placer finds each IMU aligned with its body when the placement frame is the model's
default pose (stand the subject still, arms by the sides, at the start, or pick such a
time for placement). Columns: the sites the reconstruction was made with (its
``sensors``), else all twelve; the head has no body of its own in Rajagopal's model and is
not written. Equally spaced frames as the C3D's; time in seconds since the recording's
first raw frame.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from app.export.c3d_file import regular_frames
from app.export.common import ExportMotion, atomic_target, continuous_quaternions
from inference.body.skeleton import SITE_SEGMENT
from inference.metrics.joint_angles import opensim_frames

SUFFIX = "_orientations.sto"

# our site -> OpenSense's IMU name on the Rajagopal model
IMU_NAMES: dict[str, str] = {
    "pelvis": "pelvis_imu", "torso": "torso_imu",
    **{f"{s}_{site}": f"{bone}_{s}_imu" for s in "rl" for site, bone in (
        ("thigh", "femur"), ("shank", "tibia"), ("foot", "calcn"), ("upperarm", "humerus"), ("wrist", "radius"))},
}


def imu_sites(m: ExportMotion) -> list[str]:
    used = [s for s in (m.meta.get("sensors") or []) if s in IMU_NAMES]
    return used or list(IMU_NAMES)


def body_quaternions(rot: np.ndarray, sites: list[str]) -> np.ndarray:
    """(T, S, 4) OpenSim body orientations in ground at ``sites``, continuous in time."""
    return continuous_quaternions(opensim_frames(rot, [SITE_SEGMENT[s] for s in sites]))


def sto_text(rate: float, time: np.ndarray, names: list[str], quat: np.ndarray) -> str:
    lines = [f"DataRate={rate:.6f}", "DataType=Quaternion", "version=3", "OpenSimVersion=4.6", "endheader",
             "\t".join(["time", *names])]
    for t in range(len(time)):
        lines.append("\t".join([f"{time[t]:.6f}", *(",".join(f"{v:.8f}" for v in q) for q in quat[t])]))
    return "\n".join(lines) + "\n"


def write_orientations_sto(path: str | os.PathLike, m: ExportMotion) -> Path:
    path = Path(path)
    k = regular_frames(m)
    sites = imu_sites(m)
    q = body_quaternions(m.rot[k], sites)
    time = m.time[0] + np.arange(len(k)) / m.fps
    tmp = atomic_target(path)
    tmp.write_text(sto_text(m.fps, time, [IMU_NAMES[s] for s in sites], q))
    os.replace(tmp, path)
    return path


__all__ = ["SUFFIX", "IMU_NAMES", "imu_sites", "body_quaternions", "sto_text", "write_orientations_sto"]
