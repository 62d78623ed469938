"""CSV export: header names, one row per frame, quaternions that round-trip to the same
rotations and do not flip sign between frames."""

from __future__ import annotations

import csv

import numpy as np

from app.export.common import continuous_quaternions
from app.export.csv_file import csv_columns, write_csv
from app.export.formats import body_for_recording, motion_from_recording
from app.recording import read_recording
from inference.body.rotations import axis_angle_to_matrix, matrix_to_quat, quat_to_matrix
from inference.body.skeleton import CONTACTS, SEGMENTS


def test_header_rows_and_round_trip(recorded, tmp_path):
    rec = read_recording(recorded.path)
    m = motion_from_recording(rec, body_for_recording(rec.metadata)[0])
    path = write_csv(tmp_path / "walk.csv", m)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    assert header == csv_columns() and len(header) == 4 + 24 * 4 + 24 * 3 + 4 == 176
    assert header[:5] == ["time_s", "root_x_m", "root_y_m", "root_z_m", "pelvis_qw"]
    assert header[-4:] == [f"contact_{c}" for c in CONTACTS] and "r_forearm_joint_z_m" in header
    assert len(body) == m.n_frames and all(len(r) == 176 for r in body)
    col = {n: i for i, n in enumerate(header)}
    data = np.array(body, dtype=np.float64)
    assert np.allclose(data[:, col["time_s"]], m.time, atol=1e-6)
    assert np.allclose(data[:, col["root_x_m"]:col["root_z_m"] + 1], m.root, atol=1e-6)
    for seg_i, seg in enumerate(SEGMENTS):
        q = data[:, [col[f"{seg}_q{c}"] for c in "wxyz"]]
        assert np.allclose(quat_to_matrix(q), m.rot[:, seg_i], atol=1e-6), seg
        assert np.allclose(data[:, [col[f"{seg}_joint_{c}_m"] for c in "xyz"]], m.joints[:, seg_i], atol=1e-6)
    contacts = data[:, [col[f"contact_{c}"] for c in CONTACTS]]
    assert set(np.unique(contacts)) <= {0.0, 1.0} and np.array_equal(contacts.astype(bool), m.contacts)
    assert not (tmp_path / "walk.csv.tmp").exists()


def test_quaternions_are_continuous_in_sign():
    # two segments turning a full circle about X and about a tilted axis: the plain
    # matrix -> quaternion conversion (w >= 0) flips sign half way round
    th = np.linspace(0.0, 2 * np.pi, 60)
    axes = np.array([[1.0, 0.0, 0.0], [0.6, 0.0, 0.8]])
    R = axis_angle_to_matrix(th[:, None, None] * axes[None])
    plain = matrix_to_quat(R)
    assert np.any(np.sum(plain[1:] * plain[:-1], axis=-1) < 0)
    out = continuous_quaternions(R)
    assert np.all(np.sum(out[1:] * out[:-1], axis=-1) > 0)
    assert np.all(out[0, :, 0] >= 0)
    assert np.allclose(quat_to_matrix(out), R, atol=1e-9)
