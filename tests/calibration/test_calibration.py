"""Calibration against synthesized truth: random strap rotations and sensor headings are
drawn by ``inference.synthesis`` (NoiseModel mounting_deg / heading_deg); calibration
must undo them so the bones come out as the motion had them."""

from __future__ import annotations

import numpy as np
import pytest

from calibration import (
    Calibration,
    CalibrationError,
    Calibrator,
    Protocol,
    calibrate,
    calibrate_tpose,
    calibrate_world,
    stillness,
    synthesize_session,
)
from inference.body.rotations import matrix_angle_between, quat_to_matrix
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from inference.signals.resample import moving_average
from inference.signals.synthesis import NoiseModel, kinematics
from sim_devices.motions import generate

FPS = 60


def _noise(mounting: float = 25.0, heading: float = 180.0) -> NoiseModel:
    nz = NoiseModel.typical()
    nz.mounting_deg, nz.heading_deg = mounting, heading
    return nz


@pytest.fixture(scope="module")
def session():
    act = generate("walk", seconds=4.0, seed=2)
    sig, truth = synthesize_session(act, noise=_noise(), rng=7)
    return sig, truth


def _windows(sig):
    sch = sig.meta["protocol"].schedule()
    w = slice(int(sch.world_start * FPS), int((sch.world_start + sch.world_seconds) * FPS))
    t = slice(int(sch.tpose_start * FPS), int((sch.tpose_start + sch.tpose_seconds) * FPS))
    return w, t


def _arrays(sig, sl):
    return {"quat": sig.quat[sl], "free_acc": sig.meta["free_acc_raw"][sl], "gyro": sig.gyro[sl]}


def _deg(a, b):
    return np.rad2deg(matrix_angle_between(a, b))


def test_recovers_mounting_heading_bones_and_accelerations(session):
    sig, truth = session
    w, t = _windows(sig)
    cal = calibrate(sig.sites, _arrays(sig, w), _arrays(sig, t))
    # the drawn rotations themselves (mounting up to 25 deg, heading anywhere in +-180 deg)
    assert _deg(cal.R_WG, sig.meta["R_WG"]).max() < 0.5
    assert _deg(cal.R_SB, sig.meta["R_SB"]).max() < 0.5
    assert cal.valid.all() and cal.residual_deg < 1.0  # ~0.5 deg: the orientation noise

    R, a = cal.apply(sig.quat, sig.free_acc)
    a0 = int(sig.meta["activity_start"] * FPS)
    seg = [SITE_SEGMENT_INDEX[SITE_INDEX[s]] for s in sig.sites]
    err = _deg(R[a0:], truth.rot[a0:, seg])
    assert err.mean() < 1.0 and np.percentile(err, 99) < 2.0, (err.mean(), err.max())
    # accelerations: truth smoothed like the signals; error at the level of the sensor noise
    acc_true = moving_average(kinematics(truth).site_acc_raw[:, [SITE_INDEX[s] for s in sig.sites]])
    e = np.linalg.norm(a[a0:] - acc_true[a0:], axis=-1)
    assert e.mean() < 0.2, e.mean(0)
    # the test has teeth: without calibration both are far off
    raw = quat_to_matrix(sig.quat[a0:])
    assert _deg(raw, truth.rot[a0:, seg]).mean() > 20.0
    assert np.linalg.norm(sig.free_acc[a0:] - acc_true[a0:], axis=-1).mean() > 1.0


def test_world_frame_x_is_forward_at_calibration(session):
    """After calibration a sensor lying on the table reads exactly the reference orientation
    (x forward), whatever its own heading was."""
    sig, _ = session
    w, t = _windows(sig)
    cal = calibrate(sig.sites, _arrays(sig, w), _arrays(sig, t))
    R_WS = cal.R_WG @ quat_to_matrix(sig.quat[w]).mean(0)
    assert np.allclose(R_WS, np.eye(3), atol=0.02)


def test_specific_force_path_equals_free_acc_path(session):
    """Devices that send only the raw accelerometer: a_G = R_GS f + g gives the same world
    acceleration as the device's own free acceleration."""
    sig, _ = session
    w, t = _windows(sig)
    cal = calibrate(sig.sites, _arrays(sig, w), _arrays(sig, t))
    _, a1 = cal.apply(sig.quat, sig.meta["free_acc_raw"])
    _, a2 = cal.apply(sig.quat, None, acc=sig.specific_force)
    assert np.allclose(a1, a2, atol=1e-9)


def test_moving_subject_is_refused_with_the_site_named(session):
    sig, _ = session
    w, _ = _windows(sig)
    R_WG, *_ = calibrate_world(sig.sites, **_arrays(sig, w))
    a0 = int(sig.meta["activity_start"] * FPS)
    walking = slice(a0, a0 + 120)  # "T-pose" window taken while walking
    with pytest.raises(CalibrationError, match=r"T-pose: not still: .*l_shank: rotated"):
        calibrate_tpose(sig.sites, sig.quat[walking], R_WG, gyro=sig.gyro[walking])
    strap = slice(int(sig.meta["protocol"].table * FPS), int((sig.meta["protocol"].table + 1.0) * FPS))
    with pytest.raises(CalibrationError, match="sensor-to-world: not still"):
        calibrate_world(sig.sites, **_arrays(sig, strap))


def test_stillness_measures(session):
    sig, _ = session
    w, t = _windows(sig)
    st = stillness(sig.sites, **_arrays(sig, w))
    assert st.still.all() and st.rotation_deg.max() < 2.0 and st.acc_std.max() < 0.2
    a0 = int(sig.meta["activity_start"] * FPS)
    st = stillness(sig.sites, **_arrays(sig, slice(a0, a0 + 120)))
    assert not st.still[list(sig.sites).index("l_shank")]


def test_site_without_data_is_left_uncalibrated(session):
    sig, _ = session
    w, t = _windows(sig)
    ww, tt = _arrays(sig, w), _arrays(sig, t)
    k = list(sig.sites).index("head")
    tt["quat"] = tt["quat"].copy()
    tt["quat"][:, k] = np.nan
    cal = calibrate(sig.sites, ww, tt)
    assert not cal.valid[k] and cal.valid.sum() == len(sig.sites) - 1
    R, a = cal.apply(sig.quat[-5:], sig.free_acc[-5:])
    assert np.isnan(R[:, k]).all() and np.isfinite(np.delete(R, k, axis=1)).all()
    with pytest.raises(CalibrationError, match="no data from head"):
        calibrate(sig.sites, ww, tt, strict=True)


def test_json_round_trip(tmp_path, session):
    sig, _ = session
    w, t = _windows(sig)
    cal = calibrate(sig.sites, _arrays(sig, w), _arrays(sig, t))
    path = tmp_path / "cal.json"
    cal.save(path)
    back = Calibration.load(path)
    assert back.sites == cal.sites
    for name in ("R_WG", "R_SB", "acc_offset", "valid", "residual_world_deg", "residual_tpose_deg"):
        assert np.array_equal(getattr(back, name), getattr(cal, name)), name
    R1, a1 = cal.apply(sig.quat[-3:], sig.free_acc[-3:])
    R2, a2 = back.apply(sig.quat[-3:], sig.free_acc[-3:])
    assert np.array_equal(R1, R2) and np.array_equal(a1, a2)
    with pytest.raises(ValueError, match="not an imucap calibration"):
        Calibration.from_dict({"format": "other"})


def test_apply_reorders_sites(session):
    sig, _ = session
    w, t = _windows(sig)
    cal = calibrate(sig.sites, _arrays(sig, w), _arrays(sig, t))
    order = ["r_foot", "pelvis"]
    idx = [list(sig.sites).index(s) for s in order]
    R1, _ = cal.apply(sig.quat[-2:, idx], sig.free_acc[-2:, idx], sites=order)
    R2, _ = cal.apply(sig.quat[-2:], sig.free_acc[-2:])
    assert np.allclose(R1, R2[:, idx])


def test_live_calibrator_on_a_schedule_matches_batch(session):
    sig, _ = session
    p: Protocol = sig.meta["protocol"]
    c = Calibrator(sig.sites, schedule=p.schedule())
    done = None
    t0 = 100.0  # any session clock
    for i in range(int((p.calibrated_at + 0.5) * FPS)):
        r = c.push(t0 + i / FPS, sig.quat[i], sig.meta["free_acc_raw"][i], None, sig.gyro[i])
        done = done or r
    assert c.done and done is c.calibration
    w, t = _windows(sig)
    batch = calibrate(sig.sites, _arrays(sig, w), _arrays(sig, t))
    assert _deg(done.R_SB, batch.R_SB).max() < 0.05 and _deg(done.R_WG, batch.R_WG).max() < 0.05


def test_live_calibrator_reports_movement():
    act = generate("walk", seconds=2.0, seed=0)
    sig, _ = synthesize_session(act, protocol=Protocol(table=1.0, strap=0.5, tpose=1.0, blend=0.3, margin=0.1),
                                noise=_noise(), rng=1, sites=("pelvis", "l_shank"))
    p = sig.meta["protocol"]
    sch = p.schedule()
    sch.tpose_start = sig.meta["activity_start"] + 0.2  # the "T-pose" falls into the walk
    c = Calibrator(sig.sites, schedule=sch)
    for i in range(len(sig)):
        c.push(i / FPS, sig.quat[i], sig.meta["free_acc_raw"][i])
    assert c.phase == "failed" and "l_shank" in c.error and "not still" in c.status()
