"""Procedural motions: plausible, floor-aligned, and readable back through the AMASS path."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from inference.body.body import estimate_height
from inference.loaders.amass_frames import amass_poses_to_global
from inference.signals.synthesis import synthesize
from sim_devices.motions import KINDS, generate, write_amass_npz


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_is_finite_floor_aligned_and_round_trips_through_amass(kind: str, tmp_path: Path):
    m = generate(kind, height=1.68, seconds=3.0, seed=5)
    assert m.n_frames == 181 and m.fps == 60.0
    assert np.all(np.isfinite(m.rot)) and np.all(np.isfinite(m.root))
    cp = m.contacts()
    assert abs(cp[..., 2].min()) < 1e-9
    assert abs(estimate_height(m.body.offsets) - 1.68) < 0.02
    p = write_amass_npz(m, tmp_path / f"{kind}.npz")
    with np.load(p) as z:
        assert z["poses"].shape == (m.n_frames, 156) and z["trans"].shape == (m.n_frames, 3)
        assert float(z["mocap_framerate"]) == 60.0 and float(z["imucap_height_m"]) == pytest.approx(1.68)
        assert str(z["gender"]) == "neutral" and z["betas"].shape == (16,)
        np.testing.assert_allclose(amass_poses_to_global(z["poses"]), m.rot, atol=1e-9)
        np.testing.assert_allclose(z["trans"], m.root)


def test_lead_loader_reads_generated_file(tmp_path: Path):
    loaders = pytest.importorskip("inference.loaders")
    m = generate("walk", seconds=2.0, seed=1)
    p = write_amass_npz(m, tmp_path / "walk.npz")
    back = loaders.load_motion(p)
    np.testing.assert_allclose(back.rot, m.rot, atol=1e-6)
    np.testing.assert_allclose(back.root[:, :2], m.root[:, :2], atol=1e-6)
    assert back.body.height == pytest.approx(m.body.height)


@pytest.mark.parametrize(("kind", "speed"), [("walk", 0.9), ("walk", 1.5), ("jog", 2.5), ("jog", 3.5)])
def test_gait_speed_and_foot_contact(kind: str, speed: float):
    m = generate(kind, speed=speed, seconds=6.0, seed=3)
    v = np.linalg.norm(m.root[-1, :2] - m.root[0, :2]) / m.duration
    assert v == pytest.approx(speed, rel=0.06)
    sig = synthesize(m)
    # each foot is in contact during part of every stride and off during the swing
    on = sig.contacts.reshape(-1, 2, 2).any(-1).mean(0)
    assert np.all(on > (0.25 if kind == "walk" else 0.01)) and np.all(on < 0.8)
    # no impact spikes in the pelvis (real walking peaks ~10-15 m/s^2, running 2-3 g)
    raw = np.linalg.norm(sig.meta["free_acc_raw"][:, 0], axis=-1)
    assert raw.max() < (25.0 if kind == "walk" else 60.0)
    # pelvis bob is a few centimetres, not a hop
    assert 0.01 < np.ptp(m.root[:, 2]) < (0.06 if kind == "walk" else 0.2)


@pytest.mark.parametrize("kind", ["walk", "jog"])
def test_the_gait_is_its_own_mirror_image_half_a_stride_later(kind: str):
    """Left and right legs alike, and the pelvis drops on the swing side: a gait that is its own
    mirror image, so a symmetric body is asked of the model (a pelvis that rolled the same way
    on both steps made the reconstruction's knees swing 70 / 46 deg on a 63 / 63 walk)."""
    from inference.body.skeleton import SEGMENT_INDEX as I

    m = generate(kind, seconds=8.0, seed=3)
    j = m.joints()
    hips = j[:, I["l_thigh"], 2] - j[:, I["r_thigh"], 2]  # left hip above the right, m
    feet = j[:, I["l_foot"], 2] - j[:, I["r_foot"], 2]
    on_left, on_right = feet < -0.02, feet > 0.02  # which foot is the lower one: the stance side
    assert on_left.sum() > 20 and on_right.sum() > 20
    # the swing side's hip drops: left stance, the right hip lower, and the other way round, equally
    assert hips[on_left].mean() > 0.005 and hips[on_right].mean() < -0.005
    assert hips[on_left].mean() == pytest.approx(-hips[on_right].mean(), rel=0.15)
    # the same swing on both sides
    for seg in ("thigh", "shank", "foot"):
        pitch_l, pitch_r = (Rotation.from_matrix(m.rot[:, I[f"{s}_{seg}"]]).as_euler("ZYX", degrees=True)[:, 1]
                            for s in ("l", "r"))
        assert np.ptp(pitch_l) == pytest.approx(np.ptp(pitch_r), abs=1.0), seg


def test_walk_is_reproducible_and_seed_dependent():
    a, b, c = (generate("walk", seed=s, seconds=2) for s in (1, 1, 2))
    np.testing.assert_array_equal(a.rot, b.rot)
    assert not np.allclose(a.rot, c.rot)


def test_squat_and_jump_have_the_right_shape():
    sq = generate("squat", seconds=4.0)
    assert np.ptp(sq.root[:, 2]) > 0.3
    cp = sq.contacts()
    assert np.ptp(cp[..., :2], axis=0).max() < 1e-6  # feet stay exactly planted
    j = generate("jump", seconds=3.0, seed=0)
    stand = j.root[0, 2]
    assert j.root[:, 2].max() - stand > 0.15
    # during flight the pelvis free acceleration is gravity (away from take-off/landing)
    sig = synthesize(j)
    air = j.contacts()[..., 2].min(-1) > 0.005
    idx = np.flatnonzero(air[: int(1.9 * 60)])  # the first flight
    inner = idx[(idx > idx.min() + 6) & (idx < idx.max() - 6)]
    assert inner.size > 5
    np.testing.assert_allclose(sig.free_acc[inner, 0, 2], -9.81, atol=0.3)


@pytest.mark.parametrize("kind", ["tpose", "npose"])
def test_holds_are_still(kind: str):
    sig = synthesize(generate(kind, seconds=2.0))
    np.testing.assert_allclose(sig.free_acc, 0.0, atol=1e-9)
    assert sig.contacts.all()


def test_rejects_unknown_kind():
    with pytest.raises(ValueError, match="unknown motion kind"):
        generate("moonwalk")


def test_a_walk_trial_stands_then_walks_turns_and_speeds_up():
    """``walk_trial``: still for its first 3 s, then walking; each 180 deg turn turns the
    pelvis round (read off the pelvis's forward axis, not the profile); the second half
    is brisker (speed from the root path, cadence from the knee's spectrum)."""
    from inference.metrics.joint_angles import knee_flexion_deg
    from sim_devices.motions import walk_trial_profile

    m = generate("walk_trial", seconds=40.0, seed=21)
    prof = walk_trial_profile(np.arange(m.n_frames) / m.fps)
    assert prof["stand_s"] == 3.0 and prof["turns_s"] == [12.0, 22.0, 32.0]
    fps = m.fps
    still = slice(0, int(2.9 * fps))
    assert np.ptp(m.root[still], axis=0).max() < 2e-3
    assert np.abs(m.rot[still] - m.rot[0]).max() < 1e-9
    sig = synthesize(m)
    assert np.abs(sig.free_acc[: int(2.5 * fps)]).max() < 0.05  # every site still, bar the smoothing's edge
    assert np.ptp(knee_flexion_deg(m.rot[still], "l")) < 0.1
    # walking: the knee flexes in swing
    assert np.ptp(knee_flexion_deg(m.rot[int(5 * fps):int(11 * fps)], "l")) > 40.0
    fwd = m.rot[:, 0, :2, 0]  # the pelvis's forward axis in the ground plane
    yaw = np.unwrap(np.arctan2(fwd[:, 1], fwd[:, 0]))

    def mean_yaw(a: float, b: float) -> float:  # over whole strides, so the pelvis's own swing averages out
        return float(np.degrees(yaw[int(a * fps):int(b * fps)].mean()))
    before, after1, after2 = mean_yaw(6.0, 11.0), mean_yaw(15.0, 21.0), mean_yaw(25.0, 31.0)
    assert abs(before) < 3.0 and after1 == pytest.approx(180.0, abs=3.0) and abs(after2) < 3.0
    speed = np.linalg.norm(np.diff(m.root[:, :2], axis=0), axis=-1) * fps

    def cadence(a: float, b: float) -> float:
        k = knee_flexion_deg(m.rot[int(a * fps):int(b * fps)], "l")
        f = np.fft.rfftfreq(len(k) * 8, 1 / fps)
        spec = np.abs(np.fft.rfft(k - k.mean(), len(k) * 8))
        return float(f[np.argmax(spec)])
    slow, brisk = speed[int(14 * fps):int(21 * fps)].mean(), speed[int(24 * fps):int(31 * fps)].mean()
    assert slow == pytest.approx(1.3, rel=0.06) and brisk / slow == pytest.approx(1.3, abs=0.06)
    assert cadence(24.0, 31.0) / cadence(14.0, 21.0) == pytest.approx(1.2, abs=0.05)
