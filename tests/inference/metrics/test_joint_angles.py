"""The one joint-angle module: each angle's sign and axis checked on poses built by hand
from single rotations about our world axes (scipy builds them, not our algebra), both
sides, and a mirrored walk giving the same left and right curves."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from inference.body.skeleton import SEGMENT_INDEX as I
from inference.metrics import joint_angles as ja
from inference.metrics.gait import knee_flexion_deg as gait_knee
from sim_devices.motions import generate

TH = np.array([0.0, 10.0, 30.0, 60.0, 95.0])


def about(axis: str, deg) -> np.ndarray:
    return Rotation.from_euler(axis, np.asarray(deg, float)[:, None], degrees=True).as_matrix()


def default_pose(n: int = len(TH)) -> np.ndarray:
    return np.broadcast_to(ja.opensim_default_pose(), (n, 24, 3, 3)).copy()


@pytest.mark.parametrize("side", ["l", "r"])
def test_sagittal_angles_are_positive_in_flexion_and_dorsiflexion(side):
    R = default_pose()
    # our world: X forward, Y left, Z up; a hanging segment swings forward about -Y
    R[:, I[f"{side}_thigh"]] = about("y", -TH)  # thigh forward: hip flexion
    R[:, I[f"{side}_shank"]] = np.eye(3)  # shank hanging: knee flexed as much as the hip
    R[:, I[f"{side}_foot"]] = about("y", -TH / 3)  # toes up: dorsiflexion
    R[:, I[f"{side}_forearm"]] = about("y", -TH) @ ja.opensim_default_pose()[I[f"{side}_forearm"]]
    flex, add, rot = ja.hip_angles_deg(R, side)
    np.testing.assert_allclose(flex, TH, atol=1e-9)
    np.testing.assert_allclose(add, 0, atol=1e-9)
    np.testing.assert_allclose(rot, 0, atol=1e-9)
    np.testing.assert_allclose(ja.knee_flexion_deg(R, side), TH, atol=1e-9)
    np.testing.assert_allclose(ja.ankle_dorsiflexion_deg(R, side), TH / 3, atol=1e-9)
    np.testing.assert_allclose(ja.elbow_flexion_deg(R, side), TH, atol=1e-9)


@pytest.mark.parametrize("side", ["l", "r"])
def test_hip_adduction_and_internal_rotation_are_positive_on_both_sides(side):
    toward_midline = -1.0 if side == "l" else 1.0  # the left thigh's foot end moves right (-Y)
    R = default_pose()
    add = np.r_[TH[:4], 80.0]  # the middle angle of Z-X-Y stays within +-90
    R[:, I[f"{side}_thigh"]] = about("x", toward_midline * add)
    np.testing.assert_allclose(ja.hip_angles_deg(R, side)[1], add, atol=1e-9)
    R = default_pose()
    R[:, I[f"{side}_thigh"]] = about("z", toward_midline * TH)  # the knee's front turns inwards
    np.testing.assert_allclose(ja.hip_angles_deg(R, side)[2], TH, atol=1e-9)


def test_pelvis_tilt_obliquity_rotation_follow_opensim_signs():
    R = default_pose()
    small = TH[:4]
    R = default_pose(4)
    R[:, I["pelvis"]] = about("y", small)  # front down: anterior tilt
    np.testing.assert_allclose(ja.pelvis_angles_deg(R)[0], -small, atol=1e-9)
    R[:, I["pelvis"]] = about("x", small)  # left side up, right side down
    np.testing.assert_allclose(ja.pelvis_angles_deg(R)[1], small, atol=1e-9)
    turn = np.linspace(0, 540, 55)  # one and a half turns to the left: no jump at 180
    R = np.broadcast_to(np.eye(3), (len(turn), 24, 3, 3)).copy()
    R[:, I["pelvis"]] = about("z", turn)
    np.testing.assert_allclose(ja.pelvis_angles_deg(R)[2], turn, atol=1e-9)


def test_a_bad_side_is_refused():
    with pytest.raises(ValueError, match="side"):
        ja.knee_flexion_deg(default_pose(1), "left")


def test_a_mirrored_walk_gives_the_other_sides_angles():
    m = generate("walk", seconds=3.0, seed=2)
    R = m.rot
    # mirror the body in the sagittal plane (our Y): S R S per segment, left and right swapped
    S = np.diag([1.0, -1.0, 1.0])
    swap = [I[n.replace("l_", "#").replace("r_", "l_").replace("#", "r_")] if n[:2] in ("l_", "r_") else I[n]
            for n in I]
    Rm = (S @ R @ S)[:, swap]
    for f in (ja.knee_flexion_deg, ja.ankle_dorsiflexion_deg, ja.elbow_flexion_deg):
        np.testing.assert_allclose(f(Rm, "l"), f(R, "r"), atol=1e-7)
    for a, b in zip(ja.hip_angles_deg(Rm, "l"), ja.hip_angles_deg(R, "r")):
        np.testing.assert_allclose(a, b, atol=1e-7)
    knee = ja.knee_flexion_deg(R, "l")
    assert 40 < np.ptp(knee) < 80 and knee.min() > -10  # a walk's knee: no big hyperextension
    np.testing.assert_array_equal(gait_knee(R), np.stack([knee, ja.knee_flexion_deg(R, "r")], -1))
