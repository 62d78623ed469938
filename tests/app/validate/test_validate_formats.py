"""imucap validate against references in every format, each written from the walk's truth
with a known time shift and heading: the offset is found within one reference frame, the
heading within 2 deg, and the errors are the ones the reconstruction has against the
truth itself (computed here directly, frame by frame, without the validate code)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from app.capture.simulate import save_truth
from app.cli.main import main
from app.export.bvh import bvh_text
from app.export.opensim import mot_text, opensim_coordinates
from app.recording import read_recording
from app.replay import ReplaySettings, build_replay_poser, replay_recording
from app.validate.frames import hinge_frames
from app.validate.kinematics import JOINT_ANGLES, JOINT_INDEX, angle_of, directions
from inference.body.body import Body, forward_kinematics
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import METRIC_EXCLUDED, SEGMENT_INDEX, SEGMENTS
from inference.metrics import joint_angles as ja
from inference.signals.synthesis import synthesize
from sim_devices.xsens_export import write_mvnx
from tests.app.validate.conftest import HEADING_DEG, SHIFT_FRAMES, T0

ALL = set(JOINT_INDEX)
ANGLES = {"knee": ja.knee_flexion_deg, "hip": lambda R, s: ja.hip_angles_deg(R, s)[0],
          "ankle": ja.ankle_dorsiflexion_deg, "elbow": ja.elbow_flexion_deg}


@pytest.fixture(scope="module")
def known(walk):
    """The reconstruction (all recorded sensors, as validate re-runs it) against the truth
    at the same moments: per-segment orientation and direction errors, joint-angle RMS."""
    rec = read_recording(walk.path)
    body = walk.truth.body
    built = build_replay_poser(rec, ReplaySettings(model="floor"), body)
    poses = replay_recording(rec, built.poser, causal=built.causal).poses
    t = np.array([p.t for p in poses])
    k = np.rint((t - T0) * walk.truth.fps).astype(int)
    ok = (k >= SHIFT_FRAMES) & (k < walk.truth.n_frames)  # what every shifted reference still covers
    R = np.stack([p.pose.rot for p in poses])[ok]
    J = np.stack([p.pose.joints for p in poses])[ok]
    Rt = walk.truth.rot[k[ok]]
    Jt = forward_kinematics(Rt, walk.truth.root[k[ok]], body.offsets)
    seg = np.rad2deg(matrix_angle_between(R, Rt)).mean(axis=0)
    d, dt = directions(J, ALL), directions(Jt, ALL)
    dirs = {s: float(np.rad2deg(np.arccos(np.clip((d[s] * dt[s]).sum(-1), -1, 1))).mean()) for s in d}
    # joint angles: the one module on both sides' orientations (a reference with orientations)
    a = {f"{s}_{j}": f(R, s) for s in "lr" for j, f in ANGLES.items()}
    at = {f"{s}_{j}": f(Rt, s) for s in "lr" for j, f in ANGLES.items()}
    rms = {j: float(np.sqrt(np.mean((a[j] - at[j]) ** 2))) for j in a}
    return {"orientation": {s: float(seg[SEGMENT_INDEX[s]]) for s in SEGMENTS if s not in METRIC_EXCLUDED},
            "direction": dirs, "rms": rms, "R": R, "J": J, "Jt": Jt}


def centre_rms(known: dict, have: set[str]) -> dict[str, float]:
    """Joint-angle RMS when the reference has joint centres only (``have``): both sides'
    segment frames built from the centres they share, then the one module."""
    P = {j: known["J"][:, JOINT_INDEX[j]] for j in have}
    Pt = {j: known["Jt"][:, JOINT_INDEX[j]] for j in have}
    F, Ft = hinge_frames(P), hinge_frames(Pt)
    out = {}
    for joint, (p, c, _) in JOINT_ANGLES.items():
        if p in F and c in F:
            x = angle_of(np.stack([F.get(s, np.broadcast_to(np.eye(3), F[p].shape)) for s in SEGMENTS], 1), joint)
            y = angle_of(np.stack([Ft.get(s, np.broadcast_to(np.eye(3), F[p].shape)) for s in SEGMENTS], 1), joint)
            d = (x - y)[np.isfinite(x - y)]
            out[joint] = float(np.sqrt(np.mean(d ** 2)))
    return out


def _validate(capsys, walk, ref, *extra) -> dict:
    assert main(["validate", str(walk.path), "--reference", str(ref), "--model", "floor", "--json", *extra]) == 0
    cap = capsys.readouterr()
    return json.loads(cap.out)


def _check(out: dict, walk, known: dict, fps: float, kind: str, segments=None, joints=None, tol=0.5,
           rms=None) -> None:
    assert out["time_offset_s"] == pytest.approx(walk.expected_offset(), abs=1.0 / fps)
    assert out["time_offset_correlation"] > 0.9
    assert out["heading_deg"] == pytest.approx(HEADING_DEG, abs=2.0)
    full = out["subsets"][0]
    want = known[kind]
    for s in segments or want:
        assert full["segments"][s] == pytest.approx(want[s], abs=tol), s
    rms = rms or known["rms"]
    for j in joints or rms:
        assert full["joints"][j]["rms_deg"] == pytest.approx(rms[j], abs=tol), j
    # and the numbers mean something: the measured segments beat standing still
    base = out["baseline"]
    for s in ("l_thigh", "r_shank"):
        if s in full["segments"]:
            assert full["segments"][s] < base["segments"][s] - 5.0


def test_truth_npz(walk, known, tmp_path, capsys):
    tr = walk.reference_motion(heading_deg=HEADING_DEG)
    path = save_truth(tmp_path / "truth.npz", tr.rot, tr.root, tr.fps, T0, 0.0, tr.body.height, tr.body.offsets,
                      ["pelvis"], "walk")
    out = _validate(capsys, walk, path, "--sensors", "pelvis,l_shank,r_shank", "--sensors",
                    "pelvis,torso,l_thigh,r_thigh,l_shank,r_shank,l_upperarm,r_upperarm,l_wrist,r_wrist")
    out["subsets"] = out["subsets"][::-1]  # the full set second on the command line: the alignment uses it anyway
    _check(out, walk, known, tr.fps, "orientation")
    few = out["subsets"][1]
    assert few["sensors"] == ["pelvis", "l_shank", "r_shank"] and few["mean_deg"] > out["subsets"][0]["mean_deg"]
    assert set(out) >= {"time_offset_s", "heading_deg", "subsets", "baseline"}
    assert set(few["joints"]["l_knee"]) >= {"rms_deg", "range_deg", "reference_range_deg"}


def test_mvnx_take(walk, known, tmp_path, capsys):
    ref = walk.reference_motion()
    labels = {"pelvis": "Pelvis", "l_shank": "LeftLowerLeg", "r_shank": "RightLowerLeg"}
    sig = synthesize(ref, None, rng=1, sites=tuple(labels))
    path = write_mvnx(sig, tmp_path / "take.mvnx", labels, motion=ref)
    out = _validate(capsys, walk, path)
    assert out["reference_format"] == "mvnx" and "skeleton mvn23" in out["mapping"]
    # MVN's 23 segments have no fingers; the hand and the spine's lumped segments are read as MVN holds them
    _check(out, walk, known, ref.fps, "orientation", segments=["pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank",
                                                                "l_foot", "r_foot", "l_upperarm", "r_forearm"])


def test_bvh_of_another_skeleton(walk, known, tmp_path, capsys):
    """A Mixamo-named rig (``mixamorig:`` prefix, Spine/Spine1/Spine2) of another body
    height: mapped by joint names, and the mapping printed."""
    ref = walk.reference_motion()
    text = bvh_text(ref.rot, ref.root, Body.from_height(1.62), ref.fps)
    names = {"LowerBack": "Spine", "Spine": "Spine1", "Spine1": "Spine2"}
    text = re.sub(r"\b(ROOT|JOINT) (\w+)", lambda m: f"{m[1]} mixamorig:{names.get(m[2], m[2])}", text)
    path = tmp_path / "other.bvh"
    path.write_text(text)
    assert main(["validate", str(walk.path), "--reference", str(path), "--model", "floor", "--json"]) == 0
    cap = capsys.readouterr()
    out = json.loads(cap.out)
    assert "validate: mapping skeleton mixamo" in cap.err and "validate: mapping l_shank <- LeftLeg" in cap.err
    _check(out, walk, known, ref.fps, "orientation",
           segments=["pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_upperarm", "r_upperarm"])


def test_c3d_of_joint_centres(walk, known, tmp_path, capsys):
    """Markers as a lab's Plug-in Gait model exports its joint centres (LHJC, LKJC, ...),
    in millimetres at 60 Hz, in the lab's world; written with ezc3d."""
    ezc3d = pytest.importorskip("ezc3d")
    ref = walk.reference_motion()
    J = ref.joints() * 1000.0
    lab = {"l_hip": "LHJC", "r_hip": "RHJC", "l_knee": "LKJC", "r_knee": "RKJC", "l_ankle": "LAJC",
           "r_ankle": "RAJC", "l_shoulder": "LSJC", "r_shoulder": "RSJC", "l_elbow": "LEJC", "r_elbow": "REJC",
           "l_wrist": "LWJC", "r_wrist": "RWJC", "l_mtp": "LTOE", "r_mtp": "RTOE"}
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [ref.fps]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(f"Subject01:{n}" for n in lab.values())
    c.add_parameter("POINT", "UNITS", ["mm"])
    pts = np.ones((4, len(lab), ref.n_frames))
    pts[:3] = np.transpose(J[:, [JOINT_INDEX[j] for j in lab]], (2, 1, 0))
    c["data"]["points"] = pts
    path = tmp_path / "lab.c3d"
    c.write(str(path))
    out = _validate(capsys, walk, path)
    assert out["heading_from"] == "segment directions" and "l_knee <- Subject01:LKJC" in out["mapping"]
    full = out["subsets"][0]
    assert set(full["segments"]) == {"pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot",
                                     "l_upperarm", "r_upperarm", "l_forearm", "r_forearm"}
    assert set(full["segment_error"].values()) == {"direction"}
    rms = centre_rms(known, set(lab))
    assert set(full["joints"]) == set(rms) == {f"{s}_{j}" for s in "lr" for j in ("knee", "hip", "elbow")}
    _check(out, walk, known, ref.fps, "direction", segments=sorted(full["segments"]), rms=rms)


def test_opensim_mot(walk, known, tmp_path, capsys):
    """A .mot in Rajagopal's coordinates (OpenSim's ground: Y up), e.g. from OpenSim's IK."""
    ref = walk.reference_motion()
    names, values = opensim_coordinates(ref.rot, ref.root)
    path = tmp_path / "ik.mot"
    path.write_text(mot_text("ik", np.arange(ref.n_frames) / ref.fps, names, values))
    out = _validate(capsys, walk, path)
    assert out["reference_format"] == "mot" and "l_shank <- knee_angle_l" in out["mapping"]
    # three rotations each: the same orientations as the truth; the hinges keep only their flexion
    _check(out, walk, known, ref.fps, "orientation", segments=["pelvis", "l_thigh", "r_thigh", "l_upperarm",
                                                                "r_upperarm"],
           joints=["l_knee", "r_knee", "l_hip", "r_hip", "l_ankle", "r_ankle"], tol=1.0)


def test_offset_and_heading_can_be_given(walk, known, tmp_path, capsys):
    tr = walk.reference_motion()
    path = save_truth(tmp_path / "t.npz", tr.rot, tr.root, tr.fps, T0, 0.0, tr.body.height, tr.body.offsets,
                      ["pelvis"], "walk")
    out = _validate(capsys, walk, path, "--time-offset", f"{walk.expected_offset()}", "--heading", f"{HEADING_DEG}")
    assert out["time_offset_given"] and out["heading_given"] and out["time_offset_correlation"] is None
    assert out["subsets"][0]["segments"]["l_shank"] == pytest.approx(known["orientation"]["l_shank"], abs=0.3)


BAD = {
    "garbage.c3d": (b"\x00\x01not a c3d at all", "not a readable C3D file"),
    "short.trc": (b"PathFileType\t4\n", "not a TRC file"),
    "noheader.trc": (b"hello\nworld\n\n\n\n\n", "not a TRC file"),
    "bad.mot": (b"ik\nversion=1\ntime\tknee_angle_r\n0\t1\n", "no 'endheader' line"),
    "cols.mot": (b"ik\nendheader\ntime\tknee_angle_r\n0\t1\t2\n0.1\t1\n", "3 values for 2 columns"),
    "alien.mot": (b"x\nendheader\ntime\tfoo\n0\t1\n0.1\t2\n", "none of its columns is an OpenSim coordinate"),
    "broken.bvh": (b"HIERARCHY\nROOT Hips\n{\n", "MOTION"),
    "notes.txt": (b"hello", "not a reference file we read"),
    "junk.npz": (b"PK\x03\x04 nope", "not a readable .npz"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_a_bad_reference_gets_one_line_naming_it(walk, tmp_path, capsys, name):
    data, what = BAD[name]
    path = tmp_path / name
    path.write_bytes(data)
    assert main(["validate", str(walk.path), "--reference", str(path), "--model", "floor"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and what in err[0], err


def test_a_c3d_without_joint_centres_says_what_it_looked_for(walk, tmp_path, capsys):
    ezc3d = pytest.importorskip("ezc3d")
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = ("FOO", "BAR")
    c["data"]["points"] = np.ones((4, 2, 10))
    path = tmp_path / "nolabels.c3d"
    c.write(str(path))
    assert main(["validate", str(walk.path), "--reference", str(path), "--model", "floor"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and "joint centre" in err[0] and "FOO" in err[0]


def test_trc_written_by_our_export_and_a_report(walk, tmp_path, capsys):
    """The reconstruction's own TRC (OpenSim's axes, mm) as the reference: the alignment
    finds no offset and no turn, the errors vanish, and --report writes the markdown,
    its three plots and the JSON."""
    assert main(["export", str(walk.path), "--out", str(tmp_path / "self.trc")]) == 0
    capsys.readouterr()
    out = _validate(capsys, walk, tmp_path / "self.trc", "--sensors", "pelvis,torso,l_thigh,r_thigh,l_shank,r_shank,"
                    "l_upperarm,r_upperarm,l_wrist,r_wrist", "--report", str(tmp_path / "report"))
    assert abs(out["time_offset_s"]) < 0.01 and abs(out["heading_deg"]) < 0.5
    assert out["subsets"][0]["mean_deg"] < 1.0 and out["baseline"]["mean_deg"] > 5.0
    md = (tmp_path / "report" / "report.md").read_text()
    for png in ("joint_angles.png", "segments.png", "bland_altman.png"):
        assert (tmp_path / "report" / png).stat().st_size > 1000 and f"]({png})" in md
    assert json.loads((tmp_path / "report" / "validation.json").read_text())["heading_deg"] == out["heading_deg"]


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.95])
def test_a_c3d_cut_short_gets_one_line(walk, tmp_path, capsys, keep):
    """A copy that stopped part way: read by the pure-Python reader (ezc3d, which writes
    our exports, ends the process on some such files)."""
    assert main(["export", str(walk.path), "--out", str(tmp_path / "full.c3d")]) == 0
    capsys.readouterr()
    data = (tmp_path / "full.c3d").read_bytes()
    path = tmp_path / "cut.c3d"
    path.write_bytes(data[:int(len(data) * keep)])
    code = main(["validate", str(walk.path), "--reference", str(path), "--model", "floor", "--json"])
    cap = capsys.readouterr()
    if code == 0:  # the frames before the cut are a usable reference
        assert json.loads(cap.out)["reference_frames"] < 0.96 * len(read_recording(walk.path).recon["t"])
    else:
        err = cap.err.strip().splitlines()
        assert code == 2 and len(err) == 1 and str(path) in err[0], err


MVN_BVH_NAMES = {"Hips": "Hips", "LowerBack": "Chest", "Spine": "Chest3", "Spine1": "Chest4", "Neck": "Neck",
                 "Head": "Head", **{f"{side}{ours}": f"{side}{mvn}" for side in ("Left", "Right") for ours, mvn in (
                     ("Shoulder", "Collar"), ("Arm", "Shoulder"), ("ForeArm", "Elbow"), ("Hand", "Wrist"),
                     ("UpLeg", "Hip"), ("Leg", "Knee"), ("Foot", "Ankle"), ("ToeBase", "Toe"))}}


def test_mvn_analyze_bvh(walk, known, tmp_path, capsys):
    """MVN Analyze's BVH naming (Chest..Chest4, RightCollar/Shoulder/Elbow/Wrist, RightHip/Knee/Ankle/Toe)."""
    ref = walk.reference_motion()
    text = bvh_text(ref.rot, ref.root, ref.body, ref.fps)
    text = re.sub(r"\b(ROOT|JOINT) (\w+)", lambda m: f"{m[1]} {MVN_BVH_NAMES.get(m[2], m[2])}", text)
    path = tmp_path / "mvn.bvh"
    path.write_text(text)
    out = _validate(capsys, walk, path)
    assert "skeleton mvn-bvh" in out["mapping"] and "l_upperarm <- LeftShoulder" in out["mapping"]
    _check(out, walk, known, ref.fps, "orientation",
           segments=["pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "spine3", "l_upperarm", "r_forearm"])


def test_replay_truth_points_a_bvh_to_validate(walk, tmp_path, capsys):
    """replay --truth takes imucap's own truth only; another system's file is pointed to
    validate in one line, not refused with numpy's words about pickles."""
    path = tmp_path / "take.bvh"
    path.write_text(bvh_text(walk.truth.rot[:5], walk.truth.root[:5], walk.truth.body, walk.truth.fps))
    assert main(["replay", str(walk.path), "--truth", str(path), "--model", "floor", "--json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "imucap validate" in err[0] and str(path) in err[0] and "pickle" not in err[0]
