"""OpenSim .mot export: the storage header, the coordinate columns, and joint angles of
known poses in OpenSim's (Rajagopal model's) sign conventions: knee flexion positive,
hip Z-X-Y with the left side's X/Y mirrored, arms hanging = 0 with the forearm at neutral
(pro_sup 90 from palms-forward), translations in OpenSim's Y-up ground."""

from __future__ import annotations

import numpy as np
import pytest

from app.export.formats import body_for_recording, motion_from_recording
from app.export.opensim import M_OS, coordinate_names, opensim_coordinates, read_mot, write_mot
from app.recording import read_recording
from inference.body.body import Body, forward_kinematics, global_from_local, npose_rotations, tpose
from inference.body.rotations import axis_angle_to_matrix, euler_to_matrix
from inference.body.skeleton import SEGMENT_INDEX as I
from inference.body.skeleton import SEGMENTS


def _coords(R, root=None):
    R = np.asarray(R)[None] if np.asarray(R).ndim == 3 else np.asarray(R)
    root = np.zeros((len(R), 3)) if root is None else root
    names, vals = opensim_coordinates(R, root)
    return {n: vals[:, k] for k, n in enumerate(names)}


def _with_local(base, **local):
    """Global orientations from `base` (24,3,3) globals with some segments' parent-relative
    rotations replaced (children follow)."""
    from inference.body.body import local_from_global

    L = local_from_global(base[None])[0].copy()
    for seg, Rl in local.items():
        L[I[seg]] = Rl
    return global_from_local(L[None])[0]


def _rot(axis, deg):
    return axis_angle_to_matrix(np.asarray(axis, float) * np.deg2rad(deg))


def test_file_header_and_columns(recorded, tmp_path):
    rec = read_recording(recorded.path)
    m = motion_from_recording(rec, body_for_recording(rec.metadata)[0])
    path = write_mot(tmp_path / "walk.mot", m)
    lines = path.read_text().splitlines()
    assert lines[:6] == ["walk", "version=1", f"nRows={m.n_frames}", "nColumns=30", "inDegrees=yes", "endheader"]
    header, labels, data = read_mot(path)
    assert header["nRows"] == str(m.n_frames) and header["inDegrees"] == "yes"
    assert labels[0] == "time" and labels[1:] == coordinate_names() and len(labels) == 30
    assert "\t" in lines[6] and data.shape == (m.n_frames, 30)
    assert np.allclose(data[:, 0], m.time, atol=1e-6)
    for name in ("pelvis_tilt", "pelvis_tx", "hip_flexion_r", "knee_angle_l", "ankle_angle_r", "lumbar_extension",
                 "arm_flex_r", "elbow_flex_l", "pro_sup_r"):
        assert name in labels
    # the walk itself: knees flex (floor baseline: the shank sensors give the shanks, the
    # thighs stay standing, so the knee angle is what the shank swings)
    knee = data[:, labels.index("knee_angle_r")]
    assert np.isfinite(data).all() and knee.max() - knee.min() > 10.0


def test_knee_bent_60_degrees_reads_60():
    base = tpose(1)[0]
    # our knee axis: the shank turns about +Y (left) so the ankle moves backward
    R = _with_local(base, r_shank=_rot([0, 1, 0], 60.0))
    j = forward_kinematics(R, np.zeros(3), Body.from_height(1.75).offsets)
    assert j[I["r_foot"], 0] - j[I["r_shank"], 0] < -0.1  # the ankle went back: a flexion
    c = _coords(R)
    assert c["knee_angle_r"][0] == pytest.approx(60.0, abs=0.5)
    assert abs(c["knee_angle_l"][0]) < 0.5 and abs(c["hip_flexion_r"][0]) < 0.5 and abs(c["ankle_angle_r"][0]) < 0.5
    c = _coords(_with_local(base, l_shank=_rot([0, 1, 0], 60.0)))
    assert c["knee_angle_l"][0] == pytest.approx(60.0, abs=0.5)


def test_hip_ankle_and_lumbar_follow_the_models_zxy_sequence():
    f, a, r = 35.0, 12.0, -20.0
    base = tpose(1)[0]

    def ours(zxy_deg):  # a rotation given in OpenSim axes as Rz Rx Ry, in our frame
        return M_OS.T @ euler_to_matrix(np.deg2rad(zxy_deg), "ZXY") @ M_OS

    c = _coords(_with_local(base, r_thigh=ours([f, a, r]), l_thigh=ours([f, -a, -r]), r_foot=ours([15.0, 0, 0]),
                            spine1=ours([-10.0, 5.0, 8.0])))
    assert c["hip_flexion_r"][0] == pytest.approx(f, abs=1e-6)
    assert c["hip_adduction_r"][0] == pytest.approx(a, abs=1e-6)
    assert c["hip_rotation_r"][0] == pytest.approx(r, abs=1e-6)
    # the model mirrors the left hip's X and Y axes: the mirrored pose reads the same numbers
    for name in ("flexion", "adduction", "rotation"):
        assert c[f"hip_{name}_l"][0] == pytest.approx(c[f"hip_{name}_r"][0], abs=1e-6)
    assert c["ankle_angle_r"][0] == pytest.approx(15.0, abs=1e-6)  # toes up = dorsiflexion positive
    assert c["lumbar_extension"][0] == pytest.approx(-10.0, abs=1e-6)
    assert c["lumbar_bending"][0] == pytest.approx(5.0, abs=1e-6)
    assert c["lumbar_rotation"][0] == pytest.approx(8.0, abs=1e-6)
    # a thigh swung forward is hip flexion (the knee moves to +X in our world)
    j = forward_kinematics(_with_local(base, r_thigh=ours([f, 0, 0])), np.zeros(3), Body.from_height(1.75).offsets)
    assert j[I["r_shank"], 0] > 0.1


def test_arms_hanging_are_zero_and_the_elbow_flexes_forward():
    hang = npose_rotations(1, 90.0)[0]
    c = _coords(hang)
    for name in ("arm_flex", "arm_add", "arm_rot", "elbow_flex"):
        for s in "lr":
            assert abs(c[f"{name}_{s}"][0]) < 1e-6, (name, s)
    # our rest twist is the forearm's neutral (palm to the thigh): 90 deg of pronation
    # from OpenSim's palms-forward zero
    assert c["pro_sup_r"][0] == pytest.approx(90.0, abs=1e-6) and c["pro_sup_l"][0] == pytest.approx(90.0, abs=1e-6)
    # right forearm raised forward by 90 deg about the elbow's mediolateral axis
    R = hang.copy()
    for seg in ("r_forearm", "r_hand", "r_fingers"):
        R[I[seg]] = _rot([0, 1, 0], -90.0) @ hang[I[seg]]
    j = forward_kinematics(R, np.zeros(3), Body.from_height(1.75).offsets)
    assert j[I["r_hand"], 0] - j[I["r_forearm"], 0] > 0.15  # the hand points forward
    c = _coords(R)
    assert c["elbow_flex_r"][0] == pytest.approx(90.0, abs=0.5) and abs(c["elbow_flex_l"][0]) < 1e-6
    assert c["pro_sup_r"][0] == pytest.approx(90.0, abs=0.5) and abs(c["arm_flex_r"][0]) < 0.5
    # T-pose: arms abducted 90 (adduction negative)
    c = _coords(tpose(1)[0])
    assert c["arm_add_r"][0] == pytest.approx(-90.0, abs=1e-6) and c["arm_add_l"][0] == pytest.approx(-90.0, abs=1e-6)


def test_left_right_mirror_symmetry_of_random_poses():
    rng = np.random.default_rng(7)
    G = global_from_local(axis_angle_to_matrix(rng.normal(scale=0.5, size=(20, 24, 3))))
    root = rng.normal(size=(20, 3))
    S = np.diag([1.0, -1.0, 1.0])  # mirror left/right (our Y)
    swap = [SEGMENTS.index("r_" + s[2:] if s.startswith("l_") else "l_" + s[2:] if s.startswith("r_") else s)
            for s in SEGMENTS]
    a, b = _coords(G, root), _coords(S @ G[:, swap] @ S, root * [1, -1, 1])
    for name in a:
        if name.endswith("_r"):
            assert np.allclose(a[name], b[name[:-2] + "_l"], atol=1e-6), name
    for name in ("pelvis_tilt", "lumbar_extension", "pelvis_tx", "pelvis_ty"):
        assert np.allclose(a[name], b[name], atol=1e-6), name
    for name in ("pelvis_list", "pelvis_rotation", "lumbar_bending", "lumbar_rotation", "pelvis_tz"):
        assert np.allclose(a[name], -b[name], atol=1e-6), name


def test_translations_in_y_up_ground_and_turns_unwrapped():
    T = 80
    yaw = np.linspace(0.0, 4 * np.pi, T)  # two full turns to the left
    Rz = axis_angle_to_matrix(np.stack([np.zeros(T), np.zeros(T), yaw], axis=-1))
    R = np.repeat(Rz[:, None], 24, axis=1)  # the whole body turning about the vertical
    root = np.tile([1.0, 2.0, 0.9], (T, 1))
    c = _coords(R, root)
    assert np.allclose(c["pelvis_tx"], 1.0) and np.allclose(c["pelvis_ty"], 0.9) and np.allclose(c["pelvis_tz"], -2.0)
    rot = c["pelvis_rotation"]
    assert np.all(np.diff(rot) > 0) and rot[-1] - rot[0] == pytest.approx(720.0, abs=1e-6)  # no 360 jumps
    assert np.allclose(c["pelvis_tilt"], 0.0, atol=1e-6) and np.allclose(c["pelvis_list"], 0.0, atol=1e-6)


def test_a_generated_squat_reads_like_a_squat():
    """Whole-chain sanity on a motion with a known shape: a squat flexes hips and knees
    far, dorsiflexes the ankles, never hyperextends the knees; both sides alike."""
    from sim_devices.motions import generate

    m = generate("squat", seconds=4.0, seed=1)
    c = _coords(m.rot, m.root)
    for s in "lr":
        assert c[f"knee_angle_{s}"].max() > 80.0 and c[f"knee_angle_{s}"].min() > -2.0
        assert c[f"hip_flexion_{s}"].max() > 60.0
        assert c[f"ankle_angle_{s}"].max() > 20.0  # shins lean forward over the feet
    assert np.allclose(c["knee_angle_l"], c["knee_angle_r"], atol=1.0)
    assert c["pelvis_ty"].max() - c["pelvis_ty"].min() > 0.3  # the pelvis goes down and up
