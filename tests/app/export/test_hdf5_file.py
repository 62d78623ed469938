"""HDF5 export: every dataset equal to what was exported, units/names/provenance in the
attributes, and a file of another kind refused on reading."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from app.export.formats import body_for_recording, motion_from_recording
from app.export.hdf5_file import read_hdf5, write_hdf5
from app.recording import read_recording
from inference.body.body import forward_kinematics
from inference.body.rotations import quat_to_matrix
from inference.body.skeleton import CONTACTS, PARENTS, SEGMENTS


def test_datasets_and_attributes(recorded, tmp_path):
    rec = read_recording(recorded.path)
    body, _ = body_for_recording(rec.metadata)
    m = motion_from_recording(rec, body)
    path = write_hdf5(tmp_path / "walk.h5", m)
    data, attrs = read_hdf5(path)
    assert set(data) == {"time", "rot", "quat", "root", "joints", "contacts", "contact_prob", "body_offsets"}
    for k in ("time", "rot", "root", "joints", "contact_prob"):
        assert np.array_equal(data[k], getattr(m, k)), k
    assert data["rot"].shape == (m.n_frames, 24, 3, 3) and data["contacts"].dtype == bool
    assert np.array_equal(data["contacts"], m.contacts)
    assert np.allclose(quat_to_matrix(data["quat"]), m.rot, atol=1e-9)
    assert np.array_equal(data["body_offsets"], body.offsets)
    # a reader can redo the joints from rot, root and the offsets
    assert np.abs(forward_kinematics(data["rot"], data["root"], data["body_offsets"]) - data["joints"]).max() < 1e-4
    assert attrs["format"] == "imucap-motion" and attrs["fps"] == 20.0
    assert attrs["segments"] == list(SEGMENTS) and attrs["contacts"] == list(CONTACTS)
    assert list(attrs["parents"]) == list(PARENTS)
    assert attrs["body_height_m"] == pytest.approx(body.height)
    units = json.loads(attrs["units"])
    assert units["root"] == "m" and units["time"] == "s"
    assert attrs["source_recording"] == str(recorded.path) and attrs["model"] == "floor"
    assert json.loads(attrs["sensors"]) == list(recorded.sites) and bool(attrs["insoles"]) is True
    assert attrs["time_origin"] == pytest.approx(rec.raw["t"][0])
    assert "Z up" in attrs["frame"]


def test_reading_another_file_is_refused(tmp_path):
    p = tmp_path / "other.h5"
    with h5py.File(p, "w") as f:
        f["x"] = np.zeros(3)
    with pytest.raises(ValueError, match="not an imucap motion export"):
        read_hdf5(p)
