"""The per-segment spread leaves the poser in every output: the recording (NaN when the
poser had none, and for files from before it), the CSV's ``<segment>_spread_deg``
columns and the HDF5 export's datasets."""

from __future__ import annotations

import csv

import numpy as np
import torch

from app.export.csv_file import csv_columns, write_csv
from app.export.formats import body_for_recording, motion_from_poses, motion_from_recording
from app.export.hdf5_file import read_hdf5, write_hdf5
from app.recording import Recorder, read_recording
from app.replay import replay_recording
from inference.body.skeleton import SEGMENTS
from inference.features.layout import N_FEATURES
from inference.model.config import ModelConfig
from inference.model.files import LoadedModel, build_model
from inference.poser.poser import Poser


def _tiny() -> LoadedModel:
    torch.manual_seed(0)
    cfg = ModelConfig.tiny()
    return LoadedModel(model=build_model("diffusion", cfg).eval(), kind="diffusion", config=cfg,
                       norm_mean=np.zeros(N_FEATURES, np.float32), norm_std=np.ones(N_FEATURES, np.float32))


def _replayed(recorded, confidence):
    rec = read_recording(recorded.path)
    body = body_for_recording(rec.metadata)[0]
    poser = Poser(_tiny(), body=body, steps=2, history="measured", noise="mean", inpaint_mode="replace-ddim",
                  confidence=confidence)
    return rec, body, replay_recording(rec, poser).poses


def test_recording_without_confidence_reads_nan(recorded):
    rec = read_recording(recorded.path)
    n = len(rec.recon["t"])
    assert rec.recon["spread_deg"].shape == (n, 24) and np.isnan(rec.recon["spread_deg"]).all()
    assert rec.recon["root_spread_m"].shape == (n,) and np.isnan(rec.recon["root_spread_m"]).all()
    m = motion_from_recording(rec, body_for_recording(rec.metadata)[0])
    assert m.spread_deg is None and m.root_spread_m is None


def test_spread_goes_into_the_recording_and_back(recorded, tmp_path):
    rec, body, poses = _replayed(recorded, True)
    out = Recorder(tmp_path / "again.h5", rec.sites)
    for p in poses:
        out.on_pose(p)
    out.close()
    back = read_recording(tmp_path / "again.h5")
    want = np.stack([p.pose.spread_deg for p in poses])
    assert np.allclose(back.recon["spread_deg"], want, atol=1e-3)
    assert np.allclose(back.recon["root_spread_m"], [p.pose.root_spread_m for p in poses], atol=1e-6)


def test_exports_carry_the_spread_columns(recorded, tmp_path):
    rec, body, poses = _replayed(recorded, True)
    m = motion_from_poses(poses, body, rec)
    with open(write_csv(tmp_path / "m.csv", m), newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    assert header == csv_columns(spread=True) and len(header) == 176 + 25
    assert header[176:178] == ["pelvis_spread_deg", "l_thigh_spread_deg"] and header[-1] == "root_spread_m"
    data = np.array(rows[1:], dtype=np.float64)
    col = header.index("l_thigh_spread_deg")
    assert np.allclose(data[:, col], m.spread_deg[:, SEGMENTS.index("l_thigh")], rtol=1e-3, atol=1e-3)
    data_h5, attrs = read_hdf5(write_hdf5(tmp_path / "m.h5", m))
    assert np.allclose(data_h5["spread_deg"], m.spread_deg) and data_h5["root_spread_m"].shape == (m.n_frames,)
    # without the confidence nothing changes: 176 columns, no datasets
    _, _, plain = _replayed(recorded, None)
    m0 = motion_from_poses(plain, body, rec)
    assert m0.spread_deg is None
    with open(write_csv(tmp_path / "p.csv", m0), newline="") as f:
        assert len(next(csv.reader(f))) == 176
    assert "spread_deg" not in read_hdf5(write_hdf5(tmp_path / "p.h5", m0))[0]
