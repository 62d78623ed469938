"""The export container and dispatch (app/export/formats.py): built from a recording or from
replayed poses, the body the recording states, unknown extensions refused, and the BVH
written through it read back by our own loader."""

from __future__ import annotations

import numpy as np
import pytest

from app.export.common import ExportMotion
from app.export.formats import (
    body_for_recording,
    check_export_path,
    export_motion,
    motion_from_poses,
    motion_from_recording,
)
from app.recording import read_recording
from inference.body.body import Body, forward_kinematics
from inference.body.rotations import matrix_angle_between
from inference.body.skeleton import SEGMENT_INDEX
from inference.loaders import load_motion


def test_motion_from_recording_is_the_recorded_reconstruction(recorded):
    rec = read_recording(recorded.path)
    body, note = body_for_recording(rec.metadata)
    assert note is None and np.allclose(body.offsets, recorded.body.offsets, atol=1e-6)
    m = motion_from_recording(rec, body)
    assert m.n_frames == len(recorded.live)
    assert np.allclose(m.time, rec.recon["t"] - rec.raw["t"][0]) and m.time[0] > 2.0  # after calibration
    assert np.allclose(m.rot, np.stack([lp.pose.rot for lp in recorded.live]), atol=1e-5)
    assert np.allclose(m.joints, np.stack([lp.pose.joints for lp in recorded.live]), atol=1e-5)
    assert m.meta["source_recording"] == str(recorded.path) and m.meta["sensors"] == list(recorded.sites)
    assert m.meta["model"] == "floor" and m.meta["insoles"] is True and m.meta["time_origin"] == rec.raw["t"][0]
    assert m.gaps() == 0 and abs(m.duration - m.n_frames / 20.0) < 1e-6
    # the same frames built from poses (what replay --out does) give the same arrays
    p = motion_from_poses(recorded.live, body, rec, meta={"model": "floor"})
    assert np.allclose(p.time, m.time) and np.allclose(p.rot, m.rot, atol=1e-5)


def test_body_from_the_recording_or_the_command_line():
    offsets = Body.from_height(1.62).offsets * 1.01
    b, note = body_for_recording({"body_offsets": offsets.tolist(), "body_height_m": 1.64})
    assert note is None and np.allclose(b.offsets[1:], offsets[1:]) and b.height == 1.64
    b, note = body_for_recording({"body_height_m": 1.81})
    assert note is None and np.allclose(b.offsets, Body.from_height(1.81).offsets)
    b, note = body_for_recording({})
    assert b.height == 1.75 and "--height" in note
    b, note = body_for_recording({"body_height_m": 1.81}, height=1.6)
    assert b.height == 1.6 and note is None


def test_unknown_extensions_are_refused_with_the_list(tmp_path):
    for name in ("out.fbx", "out", "out.json"):
        with pytest.raises(ValueError, match=r"supported: \.bvh, \.csv, \.h5, \.hdf5, \.mot"):
            check_export_path(tmp_path / name)
    assert check_export_path(tmp_path / "A.MOT").name == "A.MOT"  # case-insensitive


def test_gaps_count_missing_20hz_frames():
    T = 5
    m = ExportMotion(time=np.array([0.0, 0.05, 0.10, 0.25, 0.30]), rot=np.broadcast_to(np.eye(3), (T, 24, 3, 3)),
                     root=np.zeros((T, 3)), joints=np.zeros((T, 24, 3)), contacts=np.zeros((T, 4), bool),
                     body=Body.from_height(1.7))
    assert m.gaps() == 2
    with pytest.raises(ValueError, match="inconsistent"):
        ExportMotion(time=np.zeros(3), rot=np.zeros((2, 24, 3, 3)), root=np.zeros((3, 3)), joints=np.zeros((3, 24, 3)),
                     contacts=np.zeros((3, 4), bool), body=Body.from_height(1.7))


def test_bvh_through_the_dispatcher_reads_back(recorded, tmp_path):
    rec = read_recording(recorded.path)
    body, _ = body_for_recording(rec.metadata)
    m = motion_from_recording(rec, body)
    path = export_motion(tmp_path / "walk.bvh", m)
    back = load_motion(path)
    assert back.n_frames == m.n_frames and abs(back.fps - 20.0) < 1e-9
    # positions: the same skeleton up to the loader's floor alignment (a constant shift)
    fk = forward_kinematics(m.rot, m.root, body.offsets)
    rel_back, rel = back.joints() - back.root[:, None], fk - m.root[:, None]
    assert np.abs(rel_back - rel).max() < 2e-3
    assert np.abs((back.root - m.root) - (back.root - m.root)[0]).max() < 1e-3
    # limbs keep their orientations (the loader re-derives pelvis/neck frames of
    # anthropometric bodies; app/export/bvh.py)
    for seg in ("l_thigh", "r_shank", "l_forearm", "r_upperarm", "head"):
        i = SEGMENT_INDEX[seg]
        assert np.rad2deg(matrix_angle_between(back.rot[:, i], m.rot[:, i])).max() < 1.0, seg
