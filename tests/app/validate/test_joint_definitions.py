"""Validation's joint angles are the one module's, whatever the reference holds, and its
standing baseline turns with the subject.

- Frames built from joint centres alone (a marker reference) give the same knee and elbow
  flexion as the orientations the centres came from, hyperextension negative.
- On a walk whose reference turns round twice (two 180 deg turns), the baseline's error
  is that of a standing pose turned with the subject frame by frame (computed here from
  the reference's pelvis heading and the standing pose, without the validate code), not
  that of one facing the trial's mean heading."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from app.capture.simulate import save_truth
from app.cli.main import main
from app.recording import read_recording
from app.validate.frames import hinge_frames
from app.validate.kinematics import JOINT_INDEX
from inference.body.body import Body, forward_kinematics, npose_rotations, tpose
from inference.body.conventions import rot_z
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import METRIC_EXCLUDED, SEGMENTS
from inference.body.skeleton import SEGMENT_INDEX as I
from inference.metrics import joint_angles as ja
from tests.app.validate.conftest import T0


def about(axis: str, deg) -> np.ndarray:
    return Rotation.from_euler(axis, np.asarray(deg, float)[:, None], degrees=True).as_matrix()


@pytest.mark.parametrize("yaw", [0.0, 130.0])
def test_flexion_from_joint_centres_is_the_modules_flexion(yaw):
    knee = np.array([-10.0, 0.0, 3.0, 20.0, 65.0, 110.0])
    T = len(knee)
    R = np.broadcast_to(ja.opensim_default_pose(), (T, 24, 3, 3)).copy()
    for s in "lr":
        R[:, I[f"{s}_thigh"]] = about("y", -knee / 2)  # thigh forward by half, shank back by half
        R[:, I[f"{s}_shank"]] = about("y", knee / 2)
        R[:, I[f"{s}_forearm"]] = about("y", -knee) @ ja.opensim_default_pose()[I[f"{s}_forearm"]]
    R = rot_z(np.deg2rad(yaw)) @ R  # facing anywhere
    J = forward_kinematics(R, np.zeros((T, 3)), Body.from_height(1.75).offsets)
    F = hinge_frames({j: J[:, i] for j, i in JOINT_INDEX.items()})
    full = np.stack([F.get(s, R[:, I[s]]) for s in SEGMENTS], axis=1)
    for s in "lr":
        np.testing.assert_allclose(ja.knee_flexion_deg(full, s), knee, atol=1e-6)
        np.testing.assert_allclose(ja.knee_flexion_deg(R, s), knee, atol=1e-6)
        np.testing.assert_allclose(ja.elbow_flexion_deg(full, s), knee, atol=1e-6)


def test_arms_out_in_a_t_pose_still_give_a_frame():
    R = tpose(1)
    J = forward_kinematics(R, np.zeros((1, 3)), Body.from_height(1.75).offsets)
    F = hinge_frames({j: J[:, i] for j, i in JOINT_INDEX.items()})
    full = np.stack([F.get(s, R[:, I[s]]) for s in SEGMENTS], axis=1)
    assert np.all(np.isfinite(full))
    assert abs(ja.elbow_flexion_deg(full, "l")[0]) < 1e-6


def test_the_baseline_turns_with_a_subject_who_turns_round_twice(walk, tmp_path, capsys):
    m = walk.truth
    n = m.n_frames
    # the reference turns by 180 deg twice (about its pelvis), each turn over 2 s
    t = np.arange(n) / m.fps
    turn = np.clip((t - 4.0) / 2.0, 0, 1) + np.clip((t - 9.0) / 2.0, 0, 1)
    Z = rot_z(np.pi * turn)
    rot = Z[:, None] @ m.rot
    root = np.einsum("tij,tj->ti", Z, m.root)
    path = save_truth(tmp_path / "turns.npz", rot, root, m.fps, T0, 0.0, m.body.height, m.body.offsets,
                      ["pelvis"], "walk with turns")
    assert main(["validate", str(walk.path), "--reference", str(path), "--model", "floor", "--json",
                 "--time-offset", "0", "--heading", "0"]) == 0
    out = json.loads(capsys.readouterr().out)
    base = out["baseline"]
    # standing, turned frame by frame to the reference pelvis's heading, at the frames compared
    rec = read_recording(walk.path)
    t = np.asarray(rec.recon["t"], float) - float(rec.raw["t"][0])
    k = np.rint(t * m.fps).astype(int)
    k = k[(k >= 0) & (k < n)]
    assert base["frames"] == pytest.approx(len(k), abs=3)
    fwd = rot[k, I["pelvis"], :, 0]
    stand = rot_z(np.arctan2(fwd[:, 1], fwd[:, 0]))[:, None] @ npose_rotations(len(k))
    err = np.rad2deg(matrix_angle_between(stand, rot[k])).mean(axis=0)
    fixed = rot_z(np.arctan2(fwd[:, 1].mean(), fwd[:, 0].mean()))[None, None] @ npose_rotations(len(k))
    err_fixed = np.rad2deg(matrix_angle_between(fixed, rot[k])).mean(axis=0)
    for s in SEGMENTS:
        if s not in METRIC_EXCLUDED:
            assert base["segments"][s] == pytest.approx(err[I[s]], abs=0.5), s
    assert base["mean_deg"] < 25.0 and np.mean([err_fixed[I[s]] for s in ("pelvis", "l_thigh", "spine3")]) > 60.0
