"""Real files written by other systems, read by validate's readers, each checked against
numbers the file itself or its maker states (not against anything imucap wrote).

Sources and licenses: ``tests/data/README.md``. What is checked:

- Xsens MVN Studio 4.2.4 (MVNX v3, 240 Hz): the knee and hip flexion of our joint-angle
  module on the orientations our loader reads equal MVN's own ``jointAngle`` (the third,
  flexion, component), the elbow's its second (the long axis of MVN's arm segments is
  their Y), the ankle's dorsiflexion its third (MVN counts it from its calibration pose, as
  our loader now does: ``joint_maps.MVN``); the thigh's length is the file's own knee point.
- Vicon Nexus 2.12 (pyCGM2's CGM2.1 model, 100 Hz, frames 153-373): knee, hip and ankle
  angles of our module on the segment axes Nexus wrote (``LFEO/LFEA/LFEL/LFEP``...) equal
  the angles Nexus computed (``LKneeAngles``...); the shank between the file's own knee
  and ankle centres is the ``PROCESSING:LowerLegLength`` the lab measured.
- Qualisys Track Manager 2.17 (200 Hz, frames 705-1044, anatomical markers only): the
  knee flexion our reader computes from epicondyles and malleoli is near straight at
  every heel strike the file's events mark and peaks between each toe off and the next
  heel strike, as a gait cycle does.
- OpenSim's example gait trial subject01_walk1 (TRC of surface markers; the knee and
  ankle landmarks only in the static trial) and OpenSim's own inverse kinematics of it
  (Gait2392, knee flexion negative): our knee and hip flexion agree through the gait
  cycle; thigh and shank lengths against the height in OpenSim's scaling setup.
- An MVN BVH export: none could be had with a license that allows keeping it here; the
  test reads ``$IMUCAP_DATA/third_party/mvn_bvh/*.bvh`` (MVN's naming) when present and
  checks the knee and ankle against the file's own Euler angles, computed by hand.
"""

from __future__ import annotations

import struct
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from app.validate.kinematics import JOINT_INDEX, joint_angles
from app.validate.markers import read_c3d, read_trc
from app.validate.reference import _parse_storage, read_reference
from inference.body.body import Body
from inference.body.skeleton import SEGMENT_INDEX
from inference.loaders import load_motion
from inference.metrics import joint_angles as ja
from tests.conftest import REPO, data_root

DATA = REPO / "tests" / "data" / "third_party"
MVN_NS = "{http://www.xsens.com/mvn/mvnx}"


def bone(ref, a: str, b: str) -> float:
    d = np.linalg.norm(ref.joints[:, JOINT_INDEX[a]] - ref.joints[:, JOINT_INDEX[b]], axis=-1)
    return float(np.nanmean(d))


def header_first_frame(path: Path) -> int:
    """The C3D header's word 4: the first frame's number, 1-based (little-endian files)."""
    return struct.unpack("<H", path.read_bytes()[6:8])[0]


def rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x)))


# ---------------------------------------------------------------------------------- MVN (MVNX)


def test_mvn_studio_mvnx_joint_angles_are_mvns_own():
    path = DATA / "mvn_meri020.mvnx"
    root = ET.parse(path).getroot()
    subject = root.find(f"{MVN_NS}subject")
    assert subject.get("frameRate") == "240" and root.find(f"{MVN_NS}mvn").get("version") == "4.2.4"
    joints = [j.get("label") for j in root.iter(f"{MVN_NS}joint")]
    frames = [f for f in root.iter(f"{MVN_NS}frame") if f.get("type") == "normal"]
    mvn = np.array([[float(v) for v in f.find(f"{MVN_NS}jointAngle").text.split()] for f in frames])
    mvn = mvn.reshape(len(frames), len(joints), 3)

    m = load_motion(path)
    assert m.fps == 240.0 and m.n_frames == len(frames) == 4
    for s, side in (("l", "Left"), ("r", "Right")):
        knee = mvn[:, joints.index(f"j{side}Knee"), 2]
        hip = mvn[:, joints.index(f"j{side}Hip"), 2]
        elbow = mvn[:, joints.index(f"j{side}Elbow"), 1]
        ankle = mvn[:, joints.index(f"j{side}Ankle"), 2]
        np.testing.assert_allclose(ja.knee_flexion_deg(m.rot, s), knee, atol=0.2)
        # before, 13.2 deg below MVN's: its foot was laid on our ankle-to-toe line, not kept flat
        np.testing.assert_allclose(ja.ankle_dorsiflexion_deg(m.rot, s), ankle, atol=0.2)
        np.testing.assert_allclose(ja.hip_angles_deg(m.rot, s)[0], hip, atol=0.2)
        np.testing.assert_allclose(ja.elbow_flexion_deg(m.rot, s), elbow, atol=0.2)
        assert elbow.min() > 100.0  # "Bowing arm": the elbows well bent, so the check has teeth
    # the thigh: the file's own knee point on the upper leg (segment frame, metres)
    leg = next(sg for sg in root.iter(f"{MVN_NS}segment") if sg.get("label") == "RightUpperLeg")
    knee_pt = next(p for p in leg.iter(f"{MVN_NS}point") if p.get("label") == "jRightKnee")
    thigh = np.linalg.norm([float(v) for v in knee_pt.find(f"{MVN_NS}pos_s").text.split()])
    assert np.linalg.norm(m.body.offsets[SEGMENT_INDEX["r_shank"]]) == pytest.approx(thigh, abs=0.002)


# --------------------------------------------------------------------------- Vicon Nexus (C3D)


def test_vicon_nexus_c3d_joint_angles_are_nexus_own():
    ezc3d = pytest.importorskip("ezc3d")
    path = DATA / "vicon_nexus_walk.c3d"
    c = ezc3d.c3d(str(path))  # the other C3D library, for the file's own statements
    prm = c["parameters"]
    assert prm["MANUFACTURER"]["SOFTWARE"]["value"] == ["Vicon Nexus"]
    labels = list(prm["POINT"]["LABELS"]["value"])
    first, rate = header_first_frame(path), float(prm["POINT"]["RATE"]["value"][0])

    ref = read_reference(path)
    assert ref.fps == pytest.approx(rate, rel=1e-6) and rate == 100.0 and ref.n_frames == c["data"]["points"].shape[2]
    assert first == 153 and ref.t[0] == pytest.approx((first - 1) / rate)  # frame 153 of the capture (1-based)
    assert {"pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot"} <= ref.have_frames
    assert "l_knee <- LKJC" in ref.mapping
    ours = joint_angles(ref)
    pts = c["data"]["points"]
    for s, S in (("l", "L"), ("r", "R")):
        for joint, name, tol in (("knee", "KneeAngles", 0.1), ("hip", "HipAngles", 0.1), ("ankle", "AnkleAngles", 2.0)):
            nexus = pts[0, labels.index(f"{S}{name}")]  # X: flexion (dorsiflexion), deg (POINT:ANGLE_UNITS)
            assert rms(ours[f"{s}_{joint}"] - nexus) < tol, (s, joint)
        assert np.nanmax(ours[f"{s}_knee"]) - np.nanmin(ours[f"{s}_knee"]) > 40.0  # a gait cycle's range
    # the shank between the file's knee and ankle centres: the lab's measured lower leg (mm)
    lower = float(prm["PROCESSING"]["LowerLegLength"]["value"][0]) / 1000.0
    for s in "lr":
        assert bone(ref, f"{s}_knee", f"{s}_ankle") == pytest.approx(lower, rel=0.04)


# ------------------------------------------------------------------------------- Qualisys (C3D)


def test_qualisys_c3d_knee_follows_the_files_gait_events():
    ezc3d = pytest.importorskip("ezc3d")
    path = DATA / "qualisys_walk.c3d"
    c = ezc3d.c3d(str(path))
    prm = c["parameters"]
    assert prm["MANUFACTURER"]["SOFTWARE"]["value"] == ["Qualisys Track Manager"]
    first, rate = header_first_frame(path), float(prm["POINT"]["RATE"]["value"][0])
    events = list(zip(prm["EVENT"]["LABELS"]["value"], np.asarray(prm["EVENT"]["TIMES"]["value"])[1]))

    ref = read_reference(path)
    assert ref.fps == pytest.approx(rate, rel=1e-6) and rate == 200.0
    assert first == 705 and ref.t[0] == pytest.approx((first - 1) / rate)
    assert {"l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle"} <= ref.have_joints  # from landmarks only
    knee = joint_angles(ref)
    for s in "lr":
        strikes = sorted(t for lab, t in events if lab == f"{s.upper()}HS")
        offs = sorted(t for lab, t in events if lab == f"{s.upper()}TO")
        assert strikes and offs
        for t in strikes:  # the leg is nearly straight as the heel lands
            assert np.interp(t, ref.t, knee[f"{s}_knee"]) < 15.0, (s, t)
        for t_off in offs:  # swing: the knee bends most between toe off and the next heel strike
            nxt = [t for t in strikes if t > t_off]
            if nxt:
                swing = (ref.t >= t_off) & (ref.t <= nxt[0])
                assert 50.0 < knee[f"{s}_knee"][swing].max() < 75.0, (s, t_off)
            prev = [t for t in strikes if t < t_off]
            if prev:  # mid-stance, halfway from heel strike to toe off: the leg carries the body nearly straight
                assert np.interp(0.5 * (prev[-1] + t_off), ref.t, knee[f"{s}_knee"]) < 25.0, (s, t_off)
        # both legs the same length, the shank a plausible one
        assert abs(bone(ref, "l_knee", "l_ankle") - bone(ref, "r_knee", "r_ankle")) < 0.02
        assert 0.33 < bone(ref, f"{s}_knee", f"{s}_ankle") < 0.45


# ---------------------------------------------------------------------------- OpenSim (TRC, .mot)

SUBJECT01_HEIGHT_M = 1.8034  # subject01_Setup_Scale.xml: <height> 1803.4 </height> (mm)


def test_opensim_example_trial_knee_against_opensims_own_inverse_kinematics():
    folder = DATA / "opensim_subject01"
    walk = read_trc(folder / "subject01_walk1.trc")
    assert walk.rate == 60.0 and len(walk.labels) == 41 and walk.pos.shape[0] == 151
    assert not any("Knee" in lab for lab in walk.labels)  # the knee landmarks are in the static trial only
    ref = read_reference(folder / "subject01_walk1.trc", static=folder / "subject01_static.trc")
    assert any(line.startswith("R.Knee.Lat <- static trial") for line in ref.mapping)
    ours = joint_angles(ref)
    header, labels, data = _parse_storage(folder / "subject01_walk1_ik.mot")
    assert header["inDegrees"] == "yes"
    col = {n: k for k, n in enumerate(labels)}
    t = data[:, 0]
    for s in "lr":
        knee = -data[:, col[f"knee_angle_{s}"]]  # Gait2392 counts knee flexion negative
        hip = data[:, col[f"hip_flexion_{s}"]]
        ok_knee = np.interp(t, ref.t, ours[f"{s}_knee"]) - knee
        ok_hip = np.interp(t, ref.t, ours[f"{s}_hip"]) - hip
        assert np.ptp(knee) > 60.0  # a whole gait cycle's swing
        # within a few degrees all through the cycle; most of it a constant offset (the model's
        # femur and tibia frames against the epicondyle and malleolus axes)
        assert rms(ok_knee) < 5.0 and np.abs(ok_knee).max() < 8.0, s
        assert rms(ok_knee - ok_knee.mean()) < 2.0, s
        assert rms(ok_hip) < 3.0, s
    # lengths against the subject's height, through imucap's anthropometric ratios
    body = Body.from_height(SUBJECT01_HEIGHT_M)
    for s in "lr":
        assert bone(ref, f"{s}_hip", f"{s}_knee") == pytest.approx(
            np.linalg.norm(body.offsets[SEGMENT_INDEX[f"{s}_shank"]]), rel=0.08)
        assert bone(ref, f"{s}_knee", f"{s}_ankle") == pytest.approx(
            np.linalg.norm(body.offsets[SEGMENT_INDEX[f"{s}_foot"]]), rel=0.08)


def test_the_third_party_c3d_files_read_the_same_in_both_libraries():
    """The pure-Python reader validate uses against ezc3d, point for point (missing as NaN)."""
    ezc3d = pytest.importorskip("ezc3d")
    for name in ("vicon_nexus_walk.c3d", "qualisys_walk.c3d"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            m = read_c3d(DATA / name)
        pts = ezc3d.c3d(str(DATA / name))["data"]["points"][:3]
        want = np.transpose(pts, (2, 1, 0)) / 1000.0
        assert m.pos.shape == want.shape
        np.testing.assert_array_equal(np.isnan(m.pos), np.isnan(want))
        np.testing.assert_allclose(m.pos[np.isfinite(want)], want[np.isfinite(want)], atol=1e-6)


# ----------------------------------------------------------------- files that cannot be kept here


def _external(pattern: str) -> list[Path]:
    folder = data_root() / "third_party"
    files = sorted(folder.glob(pattern)) if folder.is_dir() else []
    if not files:
        pytest.skip(f"no {pattern} under {folder} (tests/data/README.md says where to get them)")
    return files


def _bvh_by_hand(path: Path) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """A BVH's own numbers, read without our loader: joint name -> (T, 3, 3) rotation of the
    segment in its parent's frame (the channels' Euler angles, intrinsic, in the file's
    order), and the root's Y position (cm)."""
    from scipy.spatial.transform import Rotation

    tok = path.read_text().split()
    names, chans, i = [], [], 0
    while tok[i] != "MOTION":
        if tok[i] in ("ROOT", "JOINT"):
            names.append(tok[i + 1])
        elif tok[i] == "CHANNELS":
            n = int(tok[i + 1])
            chans.append((names[-1], tok[i + 2:i + 2 + n]))
            i += 1 + n
        i += 1
    frames = int(tok[i + 2])
    data = np.array(tok[i + 6:], float).reshape(frames, -1)
    out, col, root_y = {}, 0, None
    for name, ch in chans:
        for k, c in enumerate(ch):
            if c == "Yposition":
                root_y = data[:, col + k]
        rc = [k for k, c in enumerate(ch) if c.endswith("rotation")]
        order = "".join(ch[k][0] for k in rc)
        out[name] = Rotation.from_euler(order, data[:, [col + k for k in rc]], degrees=True).as_matrix()
        col += len(ch)
    return out, root_y


def _flexion_by_hand(R: np.ndarray) -> np.ndarray:
    """The first angle (deg) of the Z-X-Y decomposition in OpenSim's axes (X anterior, Y up,
    Z right) of a relative rotation given in MVN BVH's axes (X left, Y up, Z forward)."""
    from scipy.spatial.transform import Rotation

    P = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    return Rotation.from_matrix(P @ R @ P.T).as_euler("ZXY", degrees=True)[:, 0]


def test_mvn_bvh_exports_read_with_mvns_skeleton():
    """An MVN Analyze/Studio BVH (Hips, Chest..Chest4, RightCollar, RightHip/Knee/Ankle/Toe):
    mapped as MVN; knee flexion and ankle dorsiflexion are the ones the file's own Euler
    angles give by hand (MVN BVH's segment frames are the world's in its zero pose, so a
    joint's channels are the distal segment in the proximal one; the ankle's is counted
    from MVN's flat foot, ``joint_maps.MVN_BVH.neutral_zero_pose``: laying MVN's
    ankle-to-toe line, 33 deg down, on ours, 17, had put every ankle 16 deg off); the root
    height follows the file's Yposition in cm. Checked on AnyBody's AMMR Xsens examples
    (``tests/data/README.md``): knee within 0.06 deg, ankle within 0.006 deg."""
    for path in _external("mvn_bvh/*.bvh"):
        ref = read_reference(path)
        assert "skeleton mvn-bvh" in ref.mapping, path
        assert {"l_thigh", "r_shank", "pelvis", "l_upperarm"} <= ref.have_rot
        m = load_motion(path)
        local, root_y = _bvh_by_hand(path)
        assert np.ptp(m.root[:, 2] - root_y / 100.0) < 1e-3, path  # cm, Y up (the floor may move)
        for side, S in (("l", "Left"), ("r", "Right")):
            knee = ja.knee_flexion_deg(m.rot, side)
            ankle = ja.ankle_dorsiflexion_deg(m.rot, side)
            assert np.max(np.abs(knee + _flexion_by_hand(local[S + "Knee"]))) < 0.2, (path, side)
            assert np.max(np.abs(ankle - _flexion_by_hand(local[S + "Ankle"]))) < 0.05, (path, side)


def test_plug_in_gait_c3d_files_agree_with_their_own_angles():
    """Any Plug-in Gait / CGM C3D put under ``third_party/pig_c3d`` (e.g. the c3d.org sample
    pyCGM2 walk): our angles on its segment axes against its own ``*KneeAngles``."""
    pytest.importorskip("ezc3d")
    import ezc3d

    for path in _external("pig_c3d/*.c3d"):
        c = ezc3d.c3d(str(path))
        labels = list(c["parameters"]["POINT"]["LABELS"]["value"])
        ours = joint_angles(read_reference(path))
        for s in "lr":
            nexus = c["data"]["points"][0, labels.index(f"{s.upper()}KneeAngles")]
            assert rms(ours[f"{s}_knee"] - nexus) < 1.0, path
