"""Every real motion file we are given loads into a sane Motion (issue 2, "Must show").

These read ../shared/data (or $IMUCAP_DATA) where it lies and skip when it is absent."""

from __future__ import annotations

import numpy as np
import pytest

from inference.loaders import find_motion_files, load_motion
from inference.loaders.asf_amc import parse_asf

pytestmark = pytest.mark.data


def _check(m, fps):
    assert np.isfinite(m.rot).all() and np.isfinite(m.root).all()
    assert 1.4 <= m.body.height <= 2.1, m.name
    assert abs(m.contacts()[..., 2].min()) < 0.03, m.name
    assert m.fps == pytest.approx(fps, rel=1e-4), m.name
    # orientations are rotations
    RtR = np.einsum("...ji,...jk->...ik", m.rot[::10], m.rot[::10])
    assert np.abs(RtR - np.eye(3)).max() < 1e-9


# the file lists are read in shards, so that the two workers of the suite share them (every
# file is still read, by exactly one shard)
HDM05_SHARDS = 2
BANDAI_SHARDS = 4


@pytest.mark.parametrize("shard", range(HDM05_SHARDS))
def test_every_hdm05_file_loads(shared_data, shard):
    files = find_motion_files(shared_data / "hdm05")
    assert len(files) >= 180
    for f in files[shard::HDM05_SHARDS]:
        _check(load_motion(f), 120.0)


@pytest.mark.parametrize("shard", range(BANDAI_SHARDS))
def test_every_bandai_file_loads(shared_data, shard):
    files = find_motion_files(shared_data / "bandai")
    assert len(files) >= 2300
    for f in files[shard::BANDAI_SHARDS]:
        _check(load_motion(f), 30.0)


def test_hdm05_squat_drops_the_root(shared_data):
    for f in find_motion_files(shared_data / "hdm05")[:]:
        if "squat" in f.name:
            m = load_motion(f)
            assert m.root[:, 2].max() - m.root[:, 2].min() > 0.3, f.name


def test_hdm05_retarget_reproduces_source_joint_positions(shared_data):
    """Our FK on the retargeted motion puts the knees, ankles and elbows where the source
    skeleton has them (to the millimetre): bone lengths come from the source."""
    f = next(p for p in find_motion_files(shared_data / "hdm05" / "dg") if "jog" in p.name)
    from inference.loaders.asf_amc import find_asf, parse_amc, to_source_skeleton

    asf = parse_asf(find_asf(f))
    src = to_source_skeleton(asf, parse_amc(f, asf), 120.0)
    m = load_motion(f)
    j = m.joints()
    pairs = {"l_shank": "ltibia", "r_foot": "rfoot", "l_forearm": "lradius", "r_upperarm": "rhumerus",
             "l_hand": "lhand"}
    from inference.body.skeleton import SEGMENT_INDEX

    for ours, theirs in pairs.items():
        d_ours = np.linalg.norm(j[:, SEGMENT_INDEX[ours]] - j[:, 0], axis=-1)
        d_src = np.linalg.norm(src.pos[:, src.index(theirs)] - src.pos[:, 0], axis=-1) * asf.scale
        assert np.abs(d_ours - d_src).max() < 1e-3, ours


def test_hdm05_forearm_pronates_with_the_wrist_bone(shared_data):
    """HDM05 puts pronation in a short ``wrist`` bone after the hinged ``radius``; our
    forearm (where the wrist sensor sits) must turn with it: its twist about its own bone,
    relative to the upper arm, is the AMC's wrist angle, frame by frame."""
    from scipy.spatial.transform import Rotation

    from inference.body.skeleton import SEGMENT_INDEX
    from inference.loaders.asf_amc import find_asf, parse_amc

    f = next(p for p in find_motion_files(shared_data / "hdm05" / "dg") if "throw" in p.name)
    amc = parse_amc(f, parse_asf(find_asf(f)))
    m = load_motion(f)
    for s in "lr":
        local = np.swapaxes(m.rot[:, SEGMENT_INDEX[f"{s}_upperarm"]], -1, -2) @ m.rot[:, SEGMENT_INDEX[f"{s}_forearm"]]
        bone = m.body.offsets[SEGMENT_INDEX[f"{s}_hand"]] / np.linalg.norm(m.body.offsets[SEGMENT_INDEX[f"{s}_hand"]])
        q = Rotation.from_matrix(local).as_quat()  # x, y, z, w
        twist = np.degrees(2 * np.arctan2(q[:, :3] @ bone, q[:, 3]))
        ry = amc[f"{s}wrist"][:, 0]
        assert np.ptp(ry) > 20, "the clip should pronate"
        np.testing.assert_allclose((twist + ry + 180) % 360 - 180, 0.0, atol=0.2)


def test_bandai_walk_faces_where_it_goes(shared_data):
    m = load_motion(shared_data / "bandai" / "d1" / "dataset-1_walk_normal_001.bvh.gz")
    travel = m.root[-1] - m.root[0]
    travel[2] = 0
    fwd = m.rot[:, 0, :, 0].mean(axis=0)
    assert fwd @ travel / np.linalg.norm(travel) / np.linalg.norm(fwd) > 0.95


def test_left_right_and_spine_conventions_agree_across_datasets(shared_data):
    """Rigs hide a roll about each bone that the zero pose cannot show (Bandai: right
    side 180 deg, spine 90 deg). After retargeting, every dataset must say the same thing
    when a person walks upright: pelvis-relative orientations of the trunk and legs stay
    near our standing pose. A rolled segment would sit at 90-180 deg here."""
    from inference.body.body import npose_rotations
    from inference.body.rotations import matrix_angle_between
    from inference.body.skeleton import SEGMENT_INDEX

    files = [shared_data / "bandai" / "d1" / "dataset-1_walk_normal_001.bvh.gz",
             shared_data / "bandai" / "d2" / "dataset-2_walk_feminine_002.bvh.gz"]
    files += [f for f in find_motion_files(shared_data / "hdm05" / "dg") if "jog" in f.name][:2]
    segs = ["spine1", "spine2", "spine3", "neck", "head", "l_collar", "r_collar", "l_thigh", "r_thigh"]
    N = npose_rotations(1)[0]
    for f in files:
        m = load_motion(f)
        rel = np.swapaxes(m.rot[:, :1], -1, -2) @ m.rot  # pelvis-relative
        for s in segs:
            i = SEGMENT_INDEX[s]
            ang = np.degrees(matrix_angle_between(rel[:, i], N[i])).mean()
            assert ang < 45.0, (f.name, s, ang)


def test_shank_strides_of_a_real_walk_come_from_the_shanks_alone(shared_data):
    """The stride estimator on a real walk, through the sensor noise model and the model's
    20 Hz input: told a path 1.25x too long, it scales by ~0.8 (no model involved)."""
    from inference.body.rotations import rot6d_to_matrix
    from inference.body.skeleton import SEGMENT_INDEX, SITE_INDEX
    from inference.evaluation.runner import clip_input, evaluation_noise
    from inference.features.layout import SL_ACC, SL_CONTACT, SL_ROT
    from inference.poser.stride import SHANK_SITES, StrideScale

    m = load_motion(shared_data / "bandai" / "d1" / "dataset-1_walk_proud_001.bvh.gz")
    inp = clip_input(m, list(SHANK_SITES), insoles=True, noise=evaluation_noise(), seed=3)
    seg = [SEGMENT_INDEX[s] for s in SHANK_SITES]
    R = np.stack([rot6d_to_matrix(inp.features[:, SL_ROT][:, 6 * k: 6 * k + 6]) for k in seg], axis=1)
    acc = np.stack([inp.features[:, SL_ACC][:, 3 * SITE_INDEX[s]: 3 * SITE_INDEX[s] + 3] for s in SHANK_SITES], 1)
    contacts = inp.features[:, SL_CONTACT] > 0.5
    ankles = inp.joints[:, [SEGMENT_INDEX["l_foot"], SEGMENT_INDEX["r_foot"]], :2]
    est = StrideScale(inp.body, 20.0)
    for i in range(len(R)):
        est.update(R[i], acc[i], contacts[i], 1.25 * ankles[i])
    assert len(est.strides) >= 6
    ratios = np.array([a / b for a, b in est.strides])
    assert np.median(ratios) == pytest.approx(0.8, abs=0.04)
    assert est.scale == pytest.approx(0.8, abs=0.05)


def test_real_amc_files_read_bone_by_bone_as_line_by_line(shared_data, monkeypatch):
    """HDM05's and CMU's own AMC files take the bone-by-bone reading (every frame lists the same
    bones in the same order) and give the line-by-line reading's values to the bit."""
    from inference.loaders import asf_amc
    from inference.loaders.text import read_text_lines

    files = [f for f in find_motion_files(shared_data / "hdm05")[::60] if ".amc" in f.name]
    cmu = shared_data / "cmu"
    if cmu.is_dir():
        files += [f for f in find_motion_files(cmu) if ".amc" in f.name][::10]
    assert len(files) >= 4
    regular = asf_amc._parse_regular  # noqa: SLF001
    for f in files:
        asf = parse_asf(asf_amc.find_asf(f))
        ndof = {n: len([d for d in b.dofs if d != "l"]) for n, b in asf.bones.items()} | {
            "root": len(asf.root_order) or 6}
        assert regular(read_text_lines(f), ndof) is not None, f.name  # taken bone by bone
        fast = asf_amc.parse_amc(f, asf)
        with monkeypatch.context() as m:
            m.setattr(asf_amc, "_parse_regular", lambda lines, ndof: None)
            slow = asf_amc.parse_amc(f, asf)
        assert fast.keys() == slow.keys(), f.name
        for k in fast:
            np.testing.assert_array_equal(fast[k], slow[k])
