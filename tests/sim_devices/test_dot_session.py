"""The synthesized DOT session has the shape of a recorded one: its files, columns and frames."""

from __future__ import annotations

import numpy as np

from drivers.xsens_export import read_exports
from inference.body.rotations import quat_to_matrix
from sim_devices.dot_session import SITES, nominal_mounting, synthesize_dot_session


def test_a_session_is_trials_of_dot_exports_with_a_heading_per_sensor_and_trial(tmp_path):
    s = synthesize_dot_session(tmp_path / "s", seed=1, walks=2)
    assert list(s.trials) == ["npose", "legcycle_left", "legcycle_right", "walk_001", "walk_002"]
    head = s.files("walk_001")[0].read_text().splitlines()
    columns = head[head.index("") + 1]
    assert columns == ("PacketCounter,SampleTimeFine,Quat_W,Quat_X,Quat_Y,Quat_Z,Acc_X,Acc_Y,Acc_Z,Gyr_X,Gyr_Y,"
                       "Gyr_Z,Mag_X,Mag_Y,Mag_Z,Status,")
    assert head[head.index("") + 2].endswith(",0,")
    logs = read_exports(s.files("npose"))
    assert [d.serial for d in logs] == [d.serial for d in read_exports(s.files("walk_001"))]
    assert abs(logs[0].rate_hz - 120.0) < 0.1
    # +X up: standing, each sensor's accelerometer reads +g on its X axis
    assert all(np.nanmean(d.acc[:100, 0]) > 9.0 for d in logs)
    # same mounting, a different heading reference in every trial
    assert np.allclose(s.trials["npose"].R_SB, s.trials["walk_001"].R_SB)
    assert not np.allclose(s.trials["npose"].R_WG, s.trials["walk_001"].R_WG)
    assert np.allclose(nominal_mounting("l_thigh")[:, 2], [0, 1, 0]) and np.allclose(nominal_mounting("r_foot")[:, 2],
                                                                                     [0, -1, 0])
    assert np.allclose(nominal_mounting("pelvis")[:, 2], [-1, 0, 0])
    # the walk trial starts walking: its legs turn fast in the first second
    walk = read_exports(s.files("walk_001"))
    assert max(np.degrees(np.linalg.norm(d.gyro[:120], axis=-1)).max() for d in walk[1:5]) > 90.0
    assert np.linalg.det(quat_to_matrix(logs[0].quat[0])) > 0.99 and len(SITES) == 7
