"""The x-IMU3 GUI log reader (drivers/ximu3/log.py): units, joining the two files on
timestamp, bad rows counted and skipped; and the real log in shared data."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.ximu3 import LogError, read_device_log, read_log
from inference.body.rotations import quat_to_matrix
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate
from sim_devices.ximu3_log import write_ximu3_log


@pytest.fixture(scope="module")
def signals():
    return synthesize(generate("walk", seconds=2.0), NoiseModel.typical(), rng=2, sites=("pelvis", "l_shank"))


def test_a_written_log_reads_back_in_si_units(tmp_path, signals):
    write_ximu3_log(signals, tmp_path, {"pelvis": "pelvis", "l_shank": "Left Lower Leg"}, drop=[10, 11, 50])
    logs = read_log(tmp_path)
    assert [d.name for d in logs] == ["Left Lower Leg", "pelvis"]
    d = logs[0]
    keep = np.setdiff1d(np.arange(len(signals.t)), [10, 11, 50])
    assert len(d.t) == len(keep) and d.rate_hz == pytest.approx(60.0, rel=0.01)
    np.testing.assert_allclose(d.t - d.t[0], signals.t[keep] - signals.t[keep][0], atol=2e-6)
    np.testing.assert_allclose(d.gyro, signals.gyro[keep, 1], atol=1e-5)
    np.testing.assert_allclose(d.acc, signals.specific_force[keep, 1], atol=1e-4)
    np.testing.assert_allclose(np.abs(np.sum(d.quat * signals.quat[keep, 1], axis=1)), 1.0, atol=1e-5)
    assert d.skipped == {"malformed": 0, "duplicate": 0, "unpaired": 0, "bad_quaternion": 0}


def test_bad_rows_are_counted_and_skipped(tmp_path, signals):
    write_ximu3_log(signals, tmp_path, {"pelvis": "pelvis", "l_shank": "Left Lower Leg"})
    folder = next(p for p in tmp_path.iterdir() if p.name.startswith("pelvis"))
    good = read_device_log(folder)
    lines = (folder / "Inertial.csv").read_text().splitlines()
    lines[5] = lines[5][:20]  # a truncated row
    lines[6] = lines[6].replace(",", ",x", 1)  # garbage
    lines.insert(8, lines[8])  # a duplicate
    (folder / "Inertial.csv").write_text("\n".join(lines) + "\n")
    q = (folder / "Quaternion.csv").read_text().splitlines()
    del q[20]  # a quaternion lost
    q[30] = q[30].split(",")[0] + ",0,0,0,0"  # an invalid one
    (folder / "Quaternion.csv").write_text("\n".join(q) + "\n")
    d = read_device_log(folder)
    assert d.skipped == {"malformed": 2, "duplicate": 1, "unpaired": 3, "bad_quaternion": 1}
    assert len(d.t) == len(good.t) - 4 and np.all(np.diff(d.t) > 0)
    with pytest.raises(LogError, match="no x-IMU3 device folders"):
        read_log(folder)  # a device folder is not a log


def test_the_real_log(shared_data):
    root = shared_data / "ximu3" / "logged_lower_body"
    if not root.is_dir():
        pytest.skip("no x-IMU3 log in shared data")
    logs = read_log(root)
    assert len(logs) == 7 and {d.name for d in logs} >= {"pelvis", "Left Lower Leg", "Right Foot"}
    for d in logs:
        assert 49.0 < d.rate_hz < 51.0 and 17.0 < d.t[-1] - d.t[0] < 20.0
        assert sum(d.skipped.values()) == 0
        # the first samples are a still stand: the specific force, turned to Earth, is +1 g up
        up = np.einsum("tij,tj->ti", quat_to_matrix(d.quat[:20]), d.acc[:20]).mean(axis=0)
        np.testing.assert_allclose(up, [0.0, 0.0, 9.81], atol=0.15)
    starts = [d.t[0] for d in logs]
    assert max(starts) - min(starts) < 0.1  # one clock for all devices
