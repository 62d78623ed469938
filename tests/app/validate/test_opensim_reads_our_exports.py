"""OpenSim 4.6 reads what imucap writes and agrees with it: our ``.mot`` through its own
storage reader (the knee column is our joint-angle module's knee flexion), and OpenSense's
IMU inverse kinematics on our ``_orientations.sto`` of a recorded walk finds our knee
flexion within 3 deg RMS (the same definition: docs/validation.md quotes the figures of
``benchmarks/opensense_ik.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from app.cli.main import main
from app.export.c3d_file import regular_frames
from app.export.formats import body_for_recording, motion_from_recording
from app.recording import read_recording
from benchmarks.opensense_ik import MODEL, compare
from inference.metrics.joint_angles import knee_flexion_deg

osim = pytest.importorskip("opensim")


def test_opensim_reads_our_mot_with_our_knee_flexion(walk, tmp_path, capsys):
    path = tmp_path / "walk.mot"
    assert main(["export", str(walk.path), "--out", str(path)]) == 0
    capsys.readouterr()
    table = osim.TimeSeriesTable(str(path))
    labels = list(table.getColumnLabels())
    assert {"knee_angle_l", "knee_angle_r", "hip_flexion_l", "ankle_angle_r", "pelvis_tilt"} <= set(labels)
    assert table.getTableMetaDataAsString("inDegrees") == "yes"
    rec = read_recording(walk.path)
    body, _ = body_for_recording(rec.metadata)
    m = motion_from_recording(rec, body)
    knee = table.getDependentColumn("knee_angle_l").to_numpy()
    assert knee.shape == (m.n_frames,)
    np.testing.assert_allclose(knee, knee_flexion_deg(m.rot, "l"), atol=1e-4)


def test_opensense_ik_on_our_orientations_finds_our_knee_flexion(walk, tmp_path, capsys):
    assert MODEL.is_file()
    res = compare(walk.path, tmp_path)
    capsys.readouterr()
    assert res["seconds"] > 10.0
    for s in "lr":
        r = res[f"{s}_knee"]
        assert r["rms_deg"] <= 3.0, r
        assert r["range_imucap_deg"] > 40.0 and abs(r["range_imucap_deg"] - r["range_opensim_deg"]) < 5.0, r
    # the frames OpenSense solved are the export's, one per 20 Hz output frame
    m = motion_from_recording(read_recording(walk.path), body_for_recording(read_recording(walk.path).metadata)[0])
    assert res["frames"] == len(regular_frames(m))
