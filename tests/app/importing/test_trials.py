"""`imucap import` of a session recorded as trials: a walk with no still start, calibrated from
the session's N-pose (and leg-cycle) trial, sensors matched by id; a whole session folder;
the one-line refusals. Sessions from ``sim_devices.dot_session`` (Movella DOT exports, every
sensor a random heading reference per trial); the truth is what it drew."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from app.cli.main import main
from app.recording import read_recording
from inference.body.conventions import yaw_of
from sim_devices.dot_session import SITES, synthesize_dot_session


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return synthesize_dot_session(tmp_path_factory.mktemp("dot") / "session", seed=3)


def _import(capsys, *args):
    assert main(["import", *map(str, args), "--json", "--no-reconstruct"]) == 0
    return json.loads(capsys.readouterr().out)


def _heading_errors(path, R_WG):
    cal = read_recording(path).calibrations[0][1]
    return {s: float(np.degrees(yaw_of(cal.R_WG[k] @ R_WG[SITES.index(s)].T))) for k, s in enumerate(cal.sites)}


def test_a_walk_without_a_still_start_takes_the_npose_trial_and_finds_its_headings(session, tmp_path, capsys):
    walk = session.trials["walk_001"]
    assert main(["import", str(walk.folder), "--out", str(tmp_path / "alone.h5")]) != 0
    assert "no still stand of 1 s found in 0-" in capsys.readouterr().err
    npose = session.trials["npose"].folder
    out = _import(capsys, *walk.files, "--calibration-trial", npose, "--out", tmp_path / "w.h5")
    cal = out["calibration"]
    assert cal["method"] == "calibration trial" and cal["trials"] == ["npose"]
    assert set(out["sites"]) == set(SITES)
    assert all(cal["sensors"][s]["stand"] == "npose" and cal["sensors"][s]["flexion_axis"] is None for s in SITES)
    err = _heading_errors(tmp_path / "w.h5", walk.R_WG)
    assert max(abs(e) for e in err.values()) < 5.0, err


def test_leg_cycle_trials_give_the_legs_their_flexion_axis(session, tmp_path, capsys):
    walk = session.trials["walk_001"]
    out = _import(capsys, walk.folder, "--calibration-trial", session.trials["npose"].folder,
                  *session.files("legcycle_left"), session.trials["legcycle_right"].folder, "--out", tmp_path / "w.h5")
    sensors = out["calibration"]["sensors"]
    assert out["calibration"]["trials"] == ["npose", "legcycle_left", "legcycle_right"]
    for s in ("l_thigh", "l_shank", "r_thigh", "r_shank"):
        side = "left" if s[0] == "l" else "right"
        assert sensors[s]["flexion_axis"] == f"legcycle_{side}" and sensors[s]["mounting"] == "flexion axis"
    assert sensors["pelvis"]["mounting"] == "walk facing" and sensors["pelvis"]["flexion_axis"] is None
    cal = read_recording(tmp_path / "w.h5").calibrations[0][1]
    for k, s in enumerate(cal.sites):
        if s in ("l_thigh", "l_shank", "r_thigh", "r_shank"):  # a hinge in the synthesized leg cycle: exact
            dR = cal.R_SB[k].T @ walk.R_SB[SITES.index(s)]
            assert np.degrees(np.arccos(np.clip((np.trace(dR) - 1) / 2, -1, 1))) < 1.0


def test_a_session_folder_imports_each_walk_with_the_sessions_calibration(session, tmp_path, capsys):
    out = _import(capsys, session.folder, "--out-dir", tmp_path / "out")
    assert out["calibration_trials"] == ["npose", "legcycle_left", "legcycle_right"]
    assert list(out["trials"]) == ["walk_001"]
    w = out["trials"]["walk_001"]
    assert w["recording"] == str(tmp_path / "out" / "walk_001.h5") and w["calibration"]["trials"] == out[
        "calibration_trials"]
    assert max(abs(e) for e in _heading_errors(tmp_path / "out" / "walk_001.h5",
                                               session.trials["walk_001"].R_WG).values()) < 5.0


def test_calibration_trials_that_do_not_match_or_never_stand_still_are_refused_in_one_line(session, tmp_path,
                                                                                          capsys):
    walk = session.trials["walk_001"]
    few = tmp_path / "npose_few"
    few.mkdir()
    for f in session.files("npose"):
        if "Foot" not in f.name:
            shutil.copy(f, few / f.name)
    assert main(["import", str(walk.folder), "--calibration-trial", str(few), "--out", str(tmp_path / "x.h5")]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no sensor D4CA6EF17235 (l_foot), D4CA6EF17236 (r_foot) of walk_001" in err[0]
    assert main(["import", str(walk.folder), "--calibration-trial", str(walk.folder),
                 "--out", str(tmp_path / "y.h5")]) != 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no still stand of 1 s found in 0-" in err[0] and "of walk_001" in err[0]
