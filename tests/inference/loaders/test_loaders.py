"""Loaders on files the tests write themselves: a Bandai-style BVH, an Acclaim ASF/AMC pair
and broken variants of each. The real datasets are covered in test_real_data.py."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SEGMENT_INDEX
from inference.loaders import MotionFormatError, find_motion_files, load_motion
from inference.loaders.bvh import parse_bvh

# Bandai-like skeleton, Y-up, cm, standing T-pose at zero rotation:
# (name, parent, offset)
_JOINTS = [
    ("Hips", None, (0, 95, 0)),
    ("Spine", "Hips", (0, 10, 0)), ("Chest", "Spine", (0, 15, 0)), ("Neck", "Chest", (0, 22, 0)),
    ("Head", "Neck", (0, 10, 0)),
    ("Shoulder_L", "Chest", (4, 18, 0)), ("UpperArm_L", "Shoulder_L", (14, 0, 0)),
    ("LowerArm_L", "UpperArm_L", (28, 0, 0)), ("Hand_L", "LowerArm_L", (24, 0, 0)),
    ("Shoulder_R", "Chest", (-4, 18, 0)), ("UpperArm_R", "Shoulder_R", (-14, 0, 0)),
    ("LowerArm_R", "UpperArm_R", (-28, 0, 0)), ("Hand_R", "LowerArm_R", (-24, 0, 0)),
    ("UpperLeg_L", "Hips", (9, -5, 0)), ("LowerLeg_L", "UpperLeg_L", (0, -42, 0)),
    ("Foot_L", "LowerLeg_L", (0, -41, 0)), ("Toes_L", "Foot_L", (0, -5, 13)),
    ("UpperLeg_R", "Hips", (-9, -5, 0)), ("LowerLeg_R", "UpperLeg_R", (0, -42, 0)),
    ("Foot_R", "LowerLeg_R", (0, -41, 0)), ("Toes_R", "Foot_R", (0, -5, 13)),
]
_END = {"Head": (0, 15, 0), "Hand_L": (8, 0, 0), "Hand_R": (-8, 0, 0), "Toes_L": (0, 0, 6), "Toes_R": (0, 0, 6)}


def _write_bvh(path: Path, frames: np.ndarray, names=None, nch_decl=None, gz=False) -> None:
    names = names or [j[0] for j in _JOINTS]
    children: dict[str | None, list[int]] = {}
    for i, (_, par, _) in enumerate(_JOINTS):
        children.setdefault(par, []).append(i)
    out = ["HIERARCHY"]

    def emit(i: int, depth: int) -> None:
        name, par, off = _JOINTS[i]
        ind = "  " * depth
        out.append(f"{ind}{'ROOT' if par is None else 'JOINT'} {names[i]}")
        out.append(ind + "{")
        out.append(f"{ind}  OFFSET {off[0]} {off[1]} {off[2]}")
        if par is None:
            out.append(f"{ind}  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
        else:
            out.append(f"{ind}  CHANNELS 3 Zrotation Xrotation Yrotation")
        for c in children.get(name, []):
            emit(c, depth + 1)
        if name in _END:
            e = _END[name]
            out.extend([f"{ind}  End Site", ind + "  {", f"{ind}    OFFSET {e[0]} {e[1]} {e[2]}", ind + "  }"])
        out.append(ind + "}")

    emit(0, 0)
    out += ["MOTION", f"Frames: {len(frames) if nch_decl is None else nch_decl}", "Frame Time: 0.0333333"]
    out += [" ".join(f"{v:.6f}" for v in row) for row in frames]
    text = "\n".join(out) + "\n"
    if gz:
        with gzip.open(path, "wt") as f:
            f.write(text)
    else:
        path.write_text(text)


def _walk_frames(T: int = 60) -> np.ndarray:
    """Hips travelling +Z (forward for this Y-up skeleton) with swinging legs and arms."""
    n = 6 + 3 * (len(_JOINTS) - 1)
    f = np.zeros((T, n))
    t = np.arange(T) / 30.0
    f[:, 0:3] = np.stack([np.zeros(T), 95 + 2 * np.sin(4 * np.pi * t), 120 * t], -1)
    col = {name: 6 + 3 * (i - 1) for i, (name, _, _) in enumerate(_JOINTS) if i > 0}
    swing = 25 * np.sin(2 * np.pi * t)
    f[:, col["UpperLeg_L"] + 1] = swing  # X rotation (2nd channel)
    f[:, col["UpperLeg_R"] + 1] = -swing
    f[:, col["LowerLeg_L"] + 1] = 20 + 20 * np.sin(2 * np.pi * t)
    f[:, col["UpperArm_L"] + 0] = -70  # Z rotation lowers the arm
    f[:, col["UpperArm_R"] + 0] = 70
    return f


def test_bvh_retarget_keeps_positions_and_orientation(tmp_path):
    p = tmp_path / "walk.bvh"
    frames = _walk_frames()
    _write_bvh(p, frames)
    m = load_motion(p)
    assert m.fps == pytest.approx(30.0, rel=1e-4) and m.n_frames == 60
    assert m.meta["units"] == "cm" and m.meta["skeleton"] == "bandai22"
    src = parse_bvh(p)
    j = m.joints()
    # our FK reproduces the source joints (metres, Z-up), up to the floor shift
    for ours, theirs in (("l_shank", "LowerLeg_L"), ("r_foot", "Foot_R"), ("l_hand", "Hand_L"), ("head", "Head")):
        s = src.pos[:, src.index(theirs)] * 0.01
        ours_p = j[:, SEGMENT_INDEX[ours]]
        d = ours_p - ours_p[:, :1] * 0  # same world heading is arbitrary: compare distances to pelvis
        dist_ours = np.linalg.norm(d - j[:, 0], axis=-1)
        dist_src = np.linalg.norm(s - src.pos[:, src.index("Hips")] * 0.01, axis=-1)
        assert np.allclose(dist_ours, dist_src, atol=1e-9), ours
    # the pelvis stays upright, the root moves 2.36 m horizontally, and the floor is at z = 0
    up = m.rot[:, 0, :, 2]
    assert np.all(up[:, 2] > 0.999)
    travel = m.root[-1] - m.root[0]
    assert np.hypot(travel[0], travel[1]) == pytest.approx(1.2 * 59 / 30, rel=1e-6)
    assert abs(travel[2]) < 0.05
    assert m.contacts()[..., 2].min() == pytest.approx(0.0, abs=1e-9)
    # the subject walks forward: the pelvis forward axis is the travel direction
    fwd = m.rot[0, 0, :, 0]
    assert fwd @ (travel / np.linalg.norm(travel)) > 0.99
    # at zero source rotation (T-pose) every segment of ours is near identity
    assert np.degrees(matrix_angle_between(m.rot[0, SEGMENT_INDEX["spine2"]], np.eye(3))) < 1.0


def test_gzipped_bvh_loads_the_same(tmp_path):
    frames = _walk_frames(20)
    _write_bvh(tmp_path / "a.bvh", frames)
    _write_bvh(tmp_path / "b.bvh.gz", frames, gz=True)
    a, b = load_motion(tmp_path / "a.bvh"), load_motion(tmp_path / "b.bvh.gz")
    assert np.allclose(a.rot, b.rot) and np.allclose(a.root, b.root)
    assert [p.name for p in find_motion_files(tmp_path)] == ["a.bvh", "b.bvh.gz"]


@pytest.mark.parametrize("case", ["truncated", "channels", "nan", "unknown_joint", "not_bvh", "bad_gzip"])
def test_malformed_bvh_gives_clear_error(tmp_path, case):
    p = tmp_path / f"{case}.bvh"
    frames = _walk_frames(10)
    if case == "truncated":
        _write_bvh(p, frames, nch_decl=12)
        expect = "truncated"
    elif case == "channels":
        _write_bvh(p, frames[:, :-1])
        expect = "channels"
    elif case == "nan":
        bad = frames.copy()
        bad[4, 7] = np.nan
        _write_bvh(p, bad)
        expect = "NaN"
    elif case == "unknown_joint":
        names = [j[0] for j in _JOINTS]
        names[names.index("LowerLeg_L")] = "Shin_L"
        _write_bvh(p, frames, names=names)
        expect = "unknown skeleton"
    elif case == "not_bvh":
        p.write_text("hello world\nMOTION\n")
        expect = "not a BVH"
    else:
        p = tmp_path / "x.bvh.gz"
        p.write_bytes(b"\x1f\x8b\x08\x00garbage")
        expect = "compressed"
    with pytest.raises(MotionFormatError) as exc:
        load_motion(p)
    msg = str(exc.value)
    assert p.name in msg and expect in msg
    if case in ("truncated", "channels", "nan"):
        assert exc.value.line is not None and exc.value.line > 0


_ASF_BONES = [
    # name, parent, direction, length, axis, dofs
    ("lhipjoint", "root", (1, -1, 0), 1.5, (0, 0, 0), ""),
    ("lfemur", "lhipjoint", (0, -1, 0), 7.5, (0, 0, 20), "rx ry rz"),
    ("ltibia", "lfemur", (0, -1, 0), 7.5, (0, 0, 20), "rx"),
    ("lfoot", "ltibia", (0, -0.3, 1), 2.3, (-90, 0, 20), "rx rz"),
    ("ltoes", "lfoot", (0, 0, 1), 1.1, (-90, 0, 20), "rx"),
    ("rhipjoint", "root", (-1, -1, 0), 1.5, (0, 0, 0), ""),
    ("rfemur", "rhipjoint", (0, -1, 0), 7.5, (0, 0, -20), "rx ry rz"),
    ("rtibia", "rfemur", (0, -1, 0), 7.5, (0, 0, -20), "rx"),
    ("rfoot", "rtibia", (0, -0.3, 1), 2.3, (-90, 0, -20), "rx rz"),
    ("rtoes", "rfoot", (0, 0, 1), 1.1, (-90, 0, -20), "rx"),
    ("lowerback", "root", (0, 1, 0), 2.2, (0, 0, 0), "rx ry rz"),
    ("upperback", "lowerback", (0, 1, 0), 2.2, (0, 0, 0), "rx ry rz"),
    ("thorax", "upperback", (0, 1, 0), 2.2, (0, 0, 0), "rx ry rz"),
    ("lowerneck", "thorax", (0, 1, 0), 1.8, (0, 0, 0), "rx ry rz"),
    ("upperneck", "lowerneck", (0, 1, 0), 1.6, (0, 0, 0), "rx ry rz"),
    ("head", "upperneck", (0, 1, 0), 1.6, (0, 0, 0), "rx ry rz"),
    ("lclavicle", "thorax", (1, 0.2, 0), 3.0, (0, 0, 0), "ry rz"),
    ("lhumerus", "lclavicle", (1, 0, 0), 5.0, (180, -30, -90), "rx ry rz"),
    ("lradius", "lhumerus", (1, 0, 0), 3.5, (180, -30, -90), "rx"),
    ("lwrist", "lradius", (1, 0, 0), 1.7, (0, 90, 90), "ry"),
    ("lhand", "lwrist", (1, 0, 0), 0.7, (0, 90, 90), "rx rz"),
    ("lfingers", "lhand", (1, 0, 0), 0.5, (0, 90, 90), "rx"),
    ("rclavicle", "thorax", (-1, 0.2, 0), 3.0, (0, 0, 0), "ry rz"),
    ("rhumerus", "rclavicle", (-1, 0, 0), 5.0, (180, 30, 90), "rx ry rz"),
    ("rradius", "rhumerus", (-1, 0, 0), 3.5, (180, 30, 90), "rx"),
    ("rwrist", "rradius", (-1, 0, 0), 1.7, (0, -90, -90), "ry"),
    ("rhand", "rwrist", (-1, 0, 0), 0.7, (0, -90, -90), "rx rz"),
    ("rfingers", "rhand", (-1, 0, 0), 0.5, (0, -90, -90), "rx"),
]


def _write_asf_amc(folder: Path, T: int = 30, corrupt: str = "", moving: tuple[str, ...] | None = None) -> Path:
    """An ASF/AMC pair whose bones (all, or only ``moving``) swing by 10 deg about their first dof."""
    lines = [":version 1.10", ":name test", ":units", "  mass 1.0", "  length 0.45", "  angle deg", ":root",
             "   order TX TY TZ RX RY RZ", "   axis XYZ", "   position 0 0 0", "   orientation 0 0 0", ":bonedata"]
    for i, (name, _, d, ln, ax, dofs) in enumerate(_ASF_BONES, start=1):
        lines += ["  begin", f"     id {i}", f"     name {name}", f"     direction {d[0]} {d[1]} {d[2]}",
                  f"     length {ln}", f"     axis {ax[0]} {ax[1]} {ax[2]} XYZ"]
        if dofs:
            lines.append(f"    dof {dofs}")
        lines.append("  end")
    lines += [":hierarchy", "  begin"]
    kids: dict[str, list[str]] = {}
    for name, par, *_ in _ASF_BONES:
        kids.setdefault(par, []).append(name)
    lines += [f"    {p} {' '.join(c)}" for p, c in kids.items()] + ["  end"]
    (folder / "HDM_zz.asf").write_text("\n".join(lines) + "\n")
    amc = ["#!OML:ASF test \xfc", ":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(T):
        amc.append(str(f + 1))
        amc.append(f"root 0 {17.5 - 3 * np.sin(f / 5):.4f} {f * 0.5:.4f} 0 0 0")
        for name, _, _, _, _, dofs in _ASF_BONES:
            if not dofs:
                continue
            n = len(dofs.split())
            amp = 10.0 if moving is None or name in moving else 0.0
            vals = [amp * np.sin(f / 7)] + [0.0] * (n - 1)
            amc.append(name + " " + " ".join(f"{v:.4f}" for v in vals))
    if corrupt == "truncated":
        amc = amc[:-3]
    elif corrupt == "unknown":
        amc.insert(6, "tail 1 2 3")
    elif corrupt == "count":
        amc[6] = amc[6] + " 5.0"
    elif corrupt == "nan":
        amc[7] = amc[7].split()[0] + " nan" * (len(amc[7].split()) - 1)
    p = folder / "HDM_zz_test_001_120.amc"
    p.write_bytes(("\r\n".join(amc) + "\r\n").encode("latin-1"))
    return p


def test_asf_amc_loads_with_units_and_fps(tmp_path):
    p = _write_asf_amc(tmp_path)
    m = load_motion(p)
    assert m.fps == 120.0 and m.n_frames == 30
    # femur 7.5 units * 0.056444 m/unit
    assert np.linalg.norm(m.body.offsets[SEGMENT_INDEX["l_shank"]]) == pytest.approx(7.5 * 0.0254 / 0.45, rel=1e-9)
    assert m.contacts()[..., 2].min() == pytest.approx(0.0, abs=1e-9)
    assert np.all(m.rot[:, 0, 2, 2] > 0.99)  # pelvis upright (Y-up file mapped to Z-up)
    assert 1.2 < m.body.height < 2.2


def test_asf_forearm_carries_the_wrist_bones_pronation(tmp_path):
    """Acclaim splits the forearm into a hinge (radius) and a twist (wrist); a sensor near
    the wrist turns with both, so our forearm must show the wrist bone's twist, about its
    own bone, with the wrist joint left where it was and the hand not twisted by it."""
    m = load_motion(_write_asf_amc(tmp_path, T=40, moving=("lwrist",)))
    up, fore, hand = (SEGMENT_INDEX[n] for n in ("l_upperarm", "l_forearm", "l_hand"))
    local = np.einsum("tji,tjk->tik", m.rot[:, up], m.rot[:, fore])
    bone = m.body.offsets[hand] / np.linalg.norm(m.body.offsets[hand])
    # a rotation about the bone: it leaves the bone where it was, by the AMC's angle
    np.testing.assert_allclose(local @ bone, np.broadcast_to(bone, (40, 3)), atol=1e-9)
    angle = np.degrees(np.arccos(np.clip((np.trace(local, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    np.testing.assert_allclose(angle, np.abs(10 * np.sin(np.arange(40) / 7)), atol=1e-3)  # AMC: 4 decimals
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", m.rot[:, fore], m.rot[:, hand]),
                               np.broadcast_to(np.eye(3), (40, 3, 3)), atol=1e-9)
    joints = m.joints()
    wrist = joints[:, hand] - joints[:, fore]
    np.testing.assert_allclose(wrist, np.broadcast_to(wrist[0], wrist.shape), atol=1e-9)
    # the forearm runs from the elbow to the end of the wrist bone: radius + wrist lengths
    assert np.linalg.norm(m.body.offsets[hand]) == pytest.approx((3.5 + 1.7) * 0.0254 / 0.45, rel=1e-9)


@pytest.mark.parametrize("corrupt,expect", [("truncated", "truncated"), ("unknown", "unknown bone"),
                                            ("count", "values"), ("nan", "NaN")])
def test_malformed_amc_gives_clear_error(tmp_path, corrupt, expect):
    p = _write_asf_amc(tmp_path, corrupt=corrupt)
    with pytest.raises(MotionFormatError) as exc:
        load_motion(p)
    assert p.name in str(exc.value) and expect in str(exc.value)
    assert exc.value.line is not None


def test_unknown_extension_and_missing_file(tmp_path):
    (tmp_path / "x.fbx").write_text("")
    with pytest.raises(MotionFormatError, match="unknown motion format"):
        load_motion(tmp_path / "x.fbx")
    with pytest.raises(FileNotFoundError, match="nope.bvh"):
        load_motion(tmp_path / "nope.bvh")


# CMU 31-joint layout (as in the cgspeed BVH conversions): Y-up, T-pose at zero rotation
_CMU = [
    ("Hips", None, (0, 17, 0)), ("LHipJoint", "Hips", (0, 0, 0)), ("LeftUpLeg", "LHipJoint", (1.6, -1.7, 0.8)),
    ("LeftLeg", "LeftUpLeg", (2.5, -6.9, 0)), ("LeftFoot", "LeftLeg", (2.5, -6.9, 0)),
    ("LeftToeBase", "LeftFoot", (0.1, -0.4, 2.2)),
    ("RHipJoint", "Hips", (0, 0, 0)), ("RightUpLeg", "RHipJoint", (-1.6, -1.7, 0.8)),
    ("RightLeg", "RightUpLeg", (-2.5, -6.9, 0)), ("RightFoot", "RightLeg", (-2.5, -6.9, 0)),
    ("RightToeBase", "RightFoot", (-0.1, -0.4, 2.2)),
    ("LowerBack", "Hips", (0, 0, 0)), ("Spine", "LowerBack", (0, 2.0, 0)), ("Spine1", "Spine", (0, 2.0, 0)),
    ("Neck", "Spine1", (0, 2.0, 0)), ("Neck1", "Neck", (0, 1.6, 0)), ("Head", "Neck1", (0, 1.6, 0)),
    ("LeftShoulder", "Spine1", (0, 2.0, 0)), ("LeftArm", "LeftShoulder", (3.0, 0.4, 0)),
    ("LeftForeArm", "LeftArm", (5.0, 0, 0)), ("LeftHand", "LeftForeArm", (3.5, 0, 0)),
    ("LeftFingerBase", "LeftHand", (0.6, 0, 0)), ("LeftHandIndex1", "LeftFingerBase", (0.6, 0, 0)),
    ("LThumb", "LeftHand", (0.4, 0, 0.4)),
    ("RightShoulder", "Spine1", (0, 2.0, 0)), ("RightArm", "RightShoulder", (-3.0, 0.4, 0)),
    ("RightForeArm", "RightArm", (-5.0, 0, 0)), ("RightHand", "RightForeArm", (-3.5, 0, 0)),
    ("RightFingerBase", "RightHand", (-0.6, 0, 0)), ("RightHandIndex1", "RightFingerBase", (-0.6, 0, 0)),
    ("RThumb", "RightHand", (-0.4, 0, 0.4)),
]


_CMU_END = {"Head": (0, 1.6, 0), "LeftHandIndex1": (0.5, 0, 0), "RightHandIndex1": (-0.5, 0, 0),
            "LThumb": (0.3, 0, 0.3), "RThumb": (-0.3, 0, 0.3), "LeftToeBase": (0, 0, 1.0), "RightToeBase": (0, 0, 1.0)}


def _cmu_motion(tmp_path, T: int = 40, left_wrist_twist_deg: np.ndarray | None = None,
                finger_base: tuple[float, float, float] | None = None):
    """A CMU 31-joint BVH walking along +Z, optionally turning only its LeftHand joint (the
    Acclaim wrist bone) about the forearm's line (X in this T-pose), and read back.
    ``finger_base``: the LeftFingerBase offset from LeftHand (cgspeed's files have 0 0 0)."""
    global _JOINTS, _END
    saved = (_JOINTS, _END)
    joints = [(n, par, finger_base if finger_base is not None and n.endswith("FingerBase") and n[0] == "L" else off)
              for n, par, off in _CMU]
    _JOINTS, _END = joints, _CMU_END
    try:
        assert len(_CMU) == 31
        f = np.zeros((T, 6 + 3 * 30))
        f[:, 1] = 17.0
        f[:, 2] = np.linspace(0, 30, T)  # walking along +Z (CMU files face +Z)
        if left_wrist_twist_deg is not None:
            hand = [j[0] for j in _CMU].index("LeftHand")  # the file lists joints depth first
            f[:, 6 + 3 * (hand - 1) + 1] = left_wrist_twist_deg  # its Xrotation channel
        p = tmp_path / "cmu.bvh"
        _write_bvh(p, f)
        return load_motion(p)
    finally:
        _JOINTS, _END = saved


def test_cmu_31_joint_bvh(tmp_path):
    m = _cmu_motion(tmp_path)
    assert m.meta["skeleton"] == "cmu31-cgspeed"
    assert m.meta["units"] == "cmu"  # 0.056444 m per unit puts this body near 1.7 m
    assert 1.4 < m.body.height < 2.1
    # zero rotation is a T-pose with the legs 20 deg apart: ours shows exactly that
    ang = np.degrees(matrix_angle_between(m.rot[0], np.eye(3)))
    assert ang[[SEGMENT_INDEX[s] for s in ("pelvis", "l_upperarm", "r_forearm", "spine3")]].max() < 1.0
    assert ang[SEGMENT_INDEX["l_thigh"]] == pytest.approx(np.degrees(np.arctan2(2.5, 6.9)), abs=0.01)
    travel = m.root[-1] - m.root[0]
    assert m.rot[0, 0, :, 0] @ travel / np.linalg.norm(travel) > 0.99


@pytest.mark.parametrize("finger_base", [(0.6, 0.0, 0.0), (0.0, 0.0, 0.0)])
def test_cmu_forearm_carries_the_wrist_joints_pronation(tmp_path, finger_base):
    """cgspeed's BVH keeps one joint per Acclaim bone, so its LeftHand is the wrist bone: as
    for ASF, our forearm shows that joint's twist about its own bone, the wrist stays where
    it was, the hand (LeftFingerBase) does not twist, and the forearm runs to its end. The
    conversion's own files put LeftFingerBase at LeftHand (offset 0 0 0): the same holds."""
    twist = 25 * np.sin(np.arange(40) / 6)
    m = _cmu_motion(tmp_path, left_wrist_twist_deg=twist, finger_base=finger_base)
    up, fore, hand = (SEGMENT_INDEX[n] for n in ("l_upperarm", "l_forearm", "l_hand"))
    local = np.einsum("tji,tjk->tik", m.rot[:, up], m.rot[:, fore])
    bone = m.body.offsets[hand] / np.linalg.norm(m.body.offsets[hand])
    np.testing.assert_allclose(local @ bone, np.broadcast_to(bone, (40, 3)), atol=1e-6)
    angle = np.degrees(np.arccos(np.clip((np.trace(local, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    np.testing.assert_allclose(angle, np.abs(twist), atol=1e-3)
    np.testing.assert_allclose(np.einsum("tji,tjk->tik", m.rot[:, fore], m.rot[:, hand]),
                               np.broadcast_to(np.eye(3), (40, 3, 3)), atol=1e-6)
    joints = m.joints()
    wrist = joints[:, hand] - joints[:, fore]
    np.testing.assert_allclose(wrist, np.broadcast_to(wrist[0], wrist.shape), atol=1e-6)
    forearm = (3.5 + finger_base[0]) * 0.056444  # CMU units
    assert np.linalg.norm(m.body.offsets[hand]) == pytest.approx(forearm, rel=1e-6)
    # the right arm did not move
    assert np.degrees(matrix_angle_between(m.rot[:, SEGMENT_INDEX["r_forearm"]], np.eye(3))).max() < 1e-6


def test_retarget_template_maps_equal_joint_angles_to_equal_orientations(tmp_path):
    """Two actors of one rig whose fitted clavicles point differently: retargeted each with its
    own zero pose, the same joint angles give different collar (and arm) orientations; with a
    shared template they give the same ones, and a skeleton's own template changes nothing."""
    from dataclasses import replace

    from inference.loaders.asf_amc import parse_amc, parse_asf, to_source_skeleton
    from inference.loaders.joint_maps import ASF
    from inference.loaders.retarget import retarget, world_map

    p = _write_asf_amc(tmp_path)
    asf_a = parse_asf(tmp_path / "HDM_zz.asf")
    amc = parse_amc(p, asf_a)
    asf_b = parse_asf(tmp_path / "HDM_zz.asf")
    asf_b.bones["lclavicle"] = replace(asf_b.bones["lclavicle"], direction=np.array([1.0, 0.6, -0.2]))
    a, b = to_source_skeleton(asf_a, amc, 120.0), to_source_skeleton(asf_b, amc, 120.0)
    W = world_map(np.array([0.0, 1.0, 0.0]))
    collar, arm = SEGMENT_INDEX["l_collar"], SEGMENT_INDEX["l_upperarm"]

    own_a, own_b = retarget(a, ASF, asf_a.scale, W), retarget(b, ASF, asf_b.scale, W)
    assert np.rad2deg(matrix_angle_between(own_a.rot[:, collar], own_b.rot[:, collar])).min() > 10.0
    shared_b = retarget(b, ASF, asf_b.scale, W, template=a)
    np.testing.assert_allclose(shared_b.rot, own_a.rot, atol=1e-9)
    # the body keeps b's own geometry: its clavicle still points its own way
    assert not np.allclose(shared_b.body.offsets[arm], own_a.body.offsets[arm])
    np.testing.assert_allclose(retarget(a, ASF, asf_a.scale, W, template=a).rot, own_a.rot, atol=1e-12)
    other_rig = replace(a, names=[*a.names[:-1], "elsewhere"])
    with pytest.raises(ValueError, match="same rig"):
        retarget(b, ASF, asf_b.scale, W, template=other_rig)


def test_prefixed_joint_names_keep_the_forearm_orientation_source():
    """A namespace prefix ('rig:LeftHand') is matched without it, and the bone that orients
    our forearm is looked up under the file's own name too."""
    from inference.loaders.joint_maps import match_joint_map

    names = [f"rig:{j[0]}" for j in _CMU]
    jm = match_joint_map(names, "x.bvh")
    assert jm.name == "cmu31-cgspeed"
    assert jm.orient == {"l_forearm": "rig:LeftHand", "r_forearm": "rig:RightHand"}
    assert jm.segments["l_hand"] == "rig:LeftFingerBase" and jm.required() <= set(names)


def test_an_amc_read_bone_by_bone_equals_its_line_by_line_reading(tmp_path, monkeypatch):
    """A regular AMC (every frame the same bones in the same order) is read per bone over all frames
    at once; the values are those of the line-by-line reading, which a frame in another order falls
    back to with the same result."""
    from inference.loaders import asf_amc

    p = _write_asf_amc(tmp_path, T=25, moving=("lwrist",))
    asf = asf_amc.parse_asf(tmp_path / "HDM_zz.asf")
    fast = asf_amc.parse_amc(p, asf)
    with monkeypatch.context() as m:
        m.setattr(asf_amc, "_parse_regular", lambda lines, ndof: None)
        slow = asf_amc.parse_amc(p, asf)
    assert fast.keys() == slow.keys() and len(fast) > 3
    for k in fast:
        np.testing.assert_array_equal(fast[k], slow[k])
    lines = p.read_bytes().decode("latin-1").split("\r\n")
    ndof = {name: len([d for d in b.dofs if d != "l"]) for name, b in asf.bones.items()} | {"root": 6}
    assert asf_amc._parse_regular(lines, ndof) is not None  # noqa: SLF001 (read bone by bone)
    # one frame's bones in another order: not regular, read line by line, the same values
    at = lines.index("3")
    lines[at + 1], lines[at + 2] = lines[at + 2], lines[at + 1]
    p.write_bytes("\r\n".join(lines).encode("latin-1"))
    assert asf_amc._parse_regular(lines, ndof) is None  # noqa: SLF001
    shuffled = asf_amc.parse_amc(p, asf)
    for k in fast:
        np.testing.assert_array_equal(shuffled[k], fast[k])
