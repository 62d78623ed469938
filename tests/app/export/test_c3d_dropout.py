"""A C3D of a recording with a dropout and a flickering contact, read back by both C3D
libraries a lab uses: the frames the poser dropped are not measured (ezc3d: NaN; the
``c3d`` package: residual -1), every measured frame is, and each step gives one foot
strike and one foot off however the contact flickers."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from app.export.formats import body_for_recording, export_motion, motion_from_recording
from app.export.markers import marker_positions
from app.recording import read_recording

ezc3d = pytest.importorskip("ezc3d")
c3d = pytest.importorskip("c3d")

PERIOD_S = 1.1  # a stride, each foot down for 60 % of it
DROP = slice(30, 37)  # seven 20 Hz frames the poser never produced


@pytest.fixture(scope="module")
def dropped(recorded):
    rec = read_recording(recorded.path)
    body, _ = body_for_recording(rec.metadata)
    m = motion_from_recording(rec, body)
    t = m.time - m.time[0]
    # contacts made here (not the reconstruction's): one clean square wave per foot ...
    clean = np.zeros((m.n_frames, 4), bool)
    for side, phase in ((0, 0.0), (2, 0.5)):
        down = ((t / PERIOD_S + phase) % 1.0) < 0.6
        clean[:, side] = clean[:, side + 1] = down
    # ... with a flicker: one frame up, and back down, right after every strike
    flick = clean.copy()
    for side in (0, 2):
        strikes = np.flatnonzero(np.diff(clean[:, side].astype(int)) > 0) + 1
        for k in strikes:
            if k + 2 < m.n_frames:
                flick[k + 1, side:side + 2] = False
    keep = np.ones(m.n_frames, bool)
    keep[DROP] = False
    cut = dataclasses.replace(m, time=m.time[keep], rot=m.rot[keep], root=m.root[keep], joints=m.joints[keep],
                              contacts=flick[keep], contact_prob=None, spread_deg=None, root_spread_m=None)
    return m, cut, clean


def test_dropped_frames_read_back_as_not_measured_by_ezc3d_and_c3d(dropped, tmp_path):
    full, cut, _ = dropped
    path = export_motion(tmp_path / "gap.c3d", cut)
    c = ezc3d.c3d(str(path))
    pts = c["data"]["points"]
    assert pts.shape[2] == full.n_frames  # equally spaced: the gap's frames are there ...
    missing = np.isnan(pts[:3]).any(axis=(0, 1))
    assert np.flatnonzero(missing).tolist() == list(range(DROP.start, DROP.stop))  # ... and only they are NaN
    want = marker_positions(full.rot, full.joints, full.body) * 1000.0
    ok = ~missing
    assert np.abs(np.transpose(pts[:3], (2, 1, 0))[ok] - want[ok]).max() < 0.01
    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = np.array([p[:, 3] for _, p, _ in c3d.Reader(fh).read_frames()])
    assert np.all(res[DROP] == -1.0) and np.all(res[ok] >= 0.0)


def test_a_flickering_contact_gives_one_strike_and_one_off_per_step(dropped, tmp_path):
    _, cut, clean = dropped
    path = export_motion(tmp_path / "steps.c3d", cut)
    ev = ezc3d.c3d(str(path))["parameters"]["EVENT"]
    labels, contexts = list(ev["LABELS"]["value"]), list(ev["CONTEXTS"]["value"])
    times = np.asarray(ev["TIMES"]["value"])[1]
    for side, col in (("Left", 0), ("Right", 2)):
        up = np.flatnonzero(np.diff(clean[:, col].astype(int)) > 0) + 1  # the clean wave's strikes
        strikes = sorted(t for t, lab, ctx in zip(times, labels, contexts) if lab == "Foot Strike" and ctx == side)
        offs = [t for t, lab, ctx in zip(times, labels, contexts) if lab == "Foot Off" and ctx == side]
        assert len(strikes) == len(up) and abs(len(offs) - len(strikes)) <= 1
        # each at the clean strike's time (the flicker is debounced away, not shifted); a
        # strike inside the dropout is seen at the first frame after it
        want = np.where((up >= DROP.start) & (up < DROP.stop), DROP.stop, up) / cut.fps
        assert np.allclose(strikes, want, atol=1e-3)
