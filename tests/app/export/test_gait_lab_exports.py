"""C3D, TRC and OpenSense exports read back by the libraries a gait lab uses: ezc3d for
the C3D (marker count, names, rate, positions, events), OpenSim 4.6's own adapters for
the TRC (``TRCFileAdapter``) and the ``_orientations.sto`` (``STOFileAdapterQuaternion``
into a ``TimeSeriesTableQuaternion``); and ``imucap export`` picking them by name."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli.main import main
from app.export.formats import body_for_recording, check_export_path, export_motion, motion_from_recording
from app.export.markers import marker_names, marker_positions
from app.export.opensense import IMU_NAMES, body_quaternions
from app.export.opensim import M_OS
from app.recording import read_recording
from inference.body.rotations import quat_to_matrix

ezc3d = pytest.importorskip("ezc3d")


@pytest.fixture(scope="module")
def motion(recorded):
    rec = read_recording(recorded.path)
    body, _ = body_for_recording(rec.metadata)
    return motion_from_recording(rec, body)


def test_c3d_reads_back_with_its_markers_rate_positions_and_contact_events(motion, tmp_path):
    path = export_motion(tmp_path / "walk.c3d", motion)
    c = ezc3d.c3d(str(path))
    labels = list(c["parameters"]["POINT"]["LABELS"]["value"])
    assert labels == marker_names() and len(labels) == 29 and labels[4] == "l_knee" and labels[-1] == "r_finger_tip"
    assert float(c["parameters"]["POINT"]["RATE"]["value"][0]) == pytest.approx(20.0)
    assert list(c["parameters"]["POINT"]["UNITS"]["value"]) == ["mm"]
    pts = c["data"]["points"]
    assert pts.shape == (4, 29, motion.n_frames)  # the recorded frames have no gaps
    want = marker_positions(motion.rot, motion.joints, motion.body) * 1000.0
    assert np.abs(np.transpose(pts[:3], (2, 1, 0)) - want).max() < 0.01  # float32 mm
    ev = c["parameters"]["EVENT"]
    labels_ev = set(ev["LABELS"]["value"])
    assert labels_ev <= {"Foot Strike", "Foot Off"} and set(ev["CONTEXTS"]["value"]) <= {"Left", "Right"}
    assert int(ev["USED"]["value"][0]) == len(ev["LABELS"]["value"]) >= 2  # the walk's steps
    times = np.asarray(ev["TIMES"]["value"])[1]
    assert np.all((times >= 0) & (times <= motion.duration))


def test_trc_is_read_by_opensims_trc_adapter(motion, tmp_path):
    osim = pytest.importorskip("opensim")
    path = export_motion(tmp_path / "walk.trc", motion)
    adapter = osim.TRCFileAdapter()
    raw = adapter.getDataTable(adapter.read(str(path)), "markers")
    assert raw.getNumRows() == motion.n_frames and raw.getNumColumns() == 29
    table = osim.TimeSeriesTableVec3(str(path))  # the same adapter, picked by the extension, typed
    assert list(table.getColumnLabels()) == marker_names()
    assert float(table.getTableMetaDataAsString("DataRate")) == pytest.approx(20.0)
    assert table.getTableMetaDataAsString("Units") == "mm"
    knee = table.getDependentColumn("l_knee")
    want = motion.joints[:, 4] @ M_OS.T * 1000.0  # OpenSim's ground: Y up
    row = 7
    got = knee[row]
    assert np.allclose([got.get(0), got.get(1), got.get(2)], want[row], atol=1e-3)
    assert table.getIndependentColumn()[row] == pytest.approx(motion.time[row], abs=1e-6)


def test_orientations_sto_is_read_by_opensims_quaternion_adapter(motion, tmp_path):
    osim = pytest.importorskip("opensim")
    path = export_motion(tmp_path / "walk_orientations.sto", motion)
    table = osim.TimeSeriesTableQuaternion(str(path))  # STOFileAdapter's quaternion reading (DataType=Quaternion)
    sites = list(motion.meta["sensors"])  # pelvis, head, wrists, shanks; the head has no OpenSim body
    names = [IMU_NAMES[s] for s in sites if s in IMU_NAMES]
    assert list(table.getColumnLabels()) == names == ["pelvis_imu", "radius_l_imu", "radius_r_imu", "tibia_l_imu",
                                                      "tibia_r_imu"]
    assert table.getNumRows() == motion.n_frames
    q = table.getRowAtIndex(5).getElt(0, names.index("tibia_l_imu"))
    got = quat_to_matrix(np.array([q.get(0), q.get(1), q.get(2), q.get(3)]))
    want = quat_to_matrix(body_quaternions(motion.rot[5:6], ["l_shank"])[0, 0])
    assert np.allclose(got, want, atol=1e-6)
    # the shank's long axis points down in the standing frames of OpenSim's ground (Y up)
    assert got[1, 1] > 0.8


def test_export_picks_the_new_formats_by_name(recorded, tmp_path, capsys):
    outs = [tmp_path / "a.c3d", tmp_path / "a.trc", tmp_path / "a_orientations.sto"]
    args = ["export", str(recorded.path), "--json"]
    for o in outs:
        args += ["--out", str(o)]
    assert main(args) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["outputs"] == [str(o) for o in outs] and all(o.stat().st_size > 0 for o in outs)
    with pytest.raises(ValueError, match="NAME_orientations.sto"):
        check_export_path(tmp_path / "plain.sto")
