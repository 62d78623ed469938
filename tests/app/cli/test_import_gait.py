"""`imucap import` of a walk whose sensors do not share a heading, and of a messy folder.

Simulated MT Manager exports (``sim_devices.xsens_export``) of a stand, a walk straight
ahead and a stand: the sensors share one Earth frame except where a test turns one
sensor's frame (a magnetometer disturbed at one shank). The truth is the heading the
synthesis drew per sensor."""

from __future__ import annotations

import json
import re
import shutil
from dataclasses import replace

import numpy as np
import pytest

from app.cli.main import main
from app.recording import read_recording
from inference.body.conventions import yaw_of
from inference.body.rotations import matrix_about_axis, matrix_to_quat, quat_multiply
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.xsens_export import stand_walk_stand, write_mtmanager_exports

SITES = ("pelvis", "torso", "l_thigh", "r_thigh", "l_shank", "r_shank")
IDS = {s: f"00B4{0x3100 + k:04X}" for k, s in enumerate(SITES)}
MAPS = [a for s, i in IDS.items() for a in ("--map", f"{i}={s}")]
OFF_DEG = 45.0


def _yaw_deg(R: np.ndarray) -> np.ndarray:
    return np.degrees(yaw_of(R))


@pytest.fixture(scope="module")
def walk():
    motion = stand_walk_stand(walk_s=6.0, seed=4)
    noise = replace(NoiseModel.typical(), heading_deg=0.0, mounting_deg=20.0)
    return synthesize(motion, noise, rng=4, sites=SITES)


@pytest.fixture(scope="module")
def shank_off(walk, tmp_path_factory):
    """The l_shank sensor's frame turned 45 deg from the others'; returns (folder, true R_WG)."""
    k = SITES.index("l_shank")
    Rz = matrix_about_axis(np.array([0.0, 0.0, 1.0]), np.deg2rad(OFF_DEG))
    quat = walk.quat.copy()
    quat[:, k] = quat_multiply(matrix_to_quat(Rz.T), quat[:, k])
    R_WG = np.array(walk.meta["R_WG"], float)
    R_WG[k] = R_WG[k] @ Rz
    folder = tmp_path_factory.mktemp("off")
    write_mtmanager_exports(replace(walk, quat=quat), folder, IDS)
    return folder, R_WG


@pytest.fixture(scope="module")
def clean(walk, tmp_path_factory):
    folder = tmp_path_factory.mktemp("clean")
    write_mtmanager_exports(walk, folder, IDS)
    return folder


def _import(capsys, *args):
    assert main(["import", *map(str, args), "--json", "--no-reconstruct"]) == 0
    cap = capsys.readouterr()
    return json.loads(cap.out), cap.err


def _heading_errors(path, R_WG_true):
    rec = read_recording(path)
    cal = rec.calibrations[0][1]
    return {s: float((_yaw_deg(cal.R_WG[k] @ R_WG_true[SITES.index(s)].T) + 180) % 360 - 180)
            for k, s in enumerate(rec.sites)}


def test_a_sensor_45_deg_off_is_named_and_corrected(shank_off, tmp_path, capsys):
    folder, R_WG = shank_off
    out, err = _import(capsys, folder, "--out", tmp_path / "w.h5", *MAPS)  # auto: the log holds walking
    cal = out["calibration"]
    assert cal["method"] == "walk"
    off = [w for w in cal["warnings"] if "off the others" in w]
    assert len(off) == 1 and re.fullmatch(r"l_shank: heading 4[3-7] deg off the others \(swing axis\); corrected",
                                          off[0]), cal["warnings"]
    assert off[0] in err
    assert all(w.split(":")[0] in SITES for w in cal["warnings"])  # each names its site
    errors = _heading_errors(tmp_path / "w.h5", R_WG)
    assert max(abs(e) for e in errors.values()) < 5.0, errors
    # the standing calibration names it too, but cannot correct it: one heading for all
    out, _ = _import(capsys, folder, "--out", tmp_path / "s.h5", "--calibration", "standing", *MAPS)
    off = [w for w in out["calibration"]["warnings"] if "off the others" in w]
    assert len(off) == 1 and off[0].startswith("l_shank: heading") and "not corrected" in off[0]
    assert abs(_heading_errors(tmp_path / "s.h5", R_WG)["l_shank"]) > 20.0  # the knees bent by it too


def test_sensors_that_agree_get_no_warning_and_a_log_without_walking_stays_standing(clean, walk, tmp_path,
                                                                                     capsys):
    out, _ = _import(capsys, clean, "--out", tmp_path / "c.h5", *MAPS)
    assert out["calibration"]["method"] == "walk"
    assert not [w for w in out["calibration"]["warnings"] if "off the others" in w]
    errors = _heading_errors(tmp_path / "c.h5", np.array(walk.meta["R_WG"], float))
    assert max(abs(e) for e in errors.values()) < 5.0, errors
    still = tmp_path / "still"  # the stand alone: no gait to learn headings from
    write_mtmanager_exports(replace(walk, t=walk.t[:100], quat=walk.quat[:100], gyro=walk.gyro[:100],
                                    specific_force=walk.specific_force[:100]), still, IDS)
    assert main(["import", str(still), "--out", str(tmp_path / "n.h5"), "--calibration", "walk", *MAPS]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "no walking" in err and "--calibration standing" in err


def test_a_messy_folder_imports_with_warnings(clean, tmp_path, capsys):
    """A lab's own CSV beside the exports is ignored; a byte-identical copy of an export is
    skipped and named; an export that claims to be one but lacks orientation fails in one line."""
    folder = tmp_path / "messy"
    shutil.copytree(clean, folder)
    (folder / "forces.csv").write_text("Time,Acc_X,Acc_Y,Acc_Z\n0.0,1,2,3\n0.1,1,2,3\n")
    copy = folder / "copy of l_shank.txt"
    original = next(folder.glob(f"*{IDS['l_shank']}.txt"))
    shutil.copy(original, copy)
    out, err = _import(capsys, folder, "--out", tmp_path / "m.h5", *MAPS)
    assert out["ignored"] == [str(folder / "forces.csv")]
    assert out["warnings"] == [f"{copy}: byte-identical to {original} (one sensor's export twice?); skipped"]
    assert "byte-identical" in err and len(out["sites"]) == len(SITES)
    damaged = folder / "damaged.txt"
    lines = original.read_text().splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("PacketCounter"))
    cols = lines[head].split("\t")
    keep = [i for i, c in enumerate(cols) if not c.startswith("Quat")]
    damaged.write_text("\n".join(lines[:head] + ["\t".join(line.split("\t")[i] for i in keep)
                                                  for line in lines[head:]]) + "\n")
    assert main(["import", str(folder), "--out", str(tmp_path / "d.h5"), *MAPS]) != 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "damaged.txt" in err and "no orientation columns" in err


def test_an_import_is_reconstructed_and_exports_with_its_time_origin(clean, tmp_path, capsys):
    """By default the import reconstructs the body, so ``imucap export`` works at once; the
    BVH's time origin (which BVH cannot hold) is written beside it. Without reconstruction,
    export says how to get one."""
    assert main(["import", str(clean), "--out", str(tmp_path / "r.h5"), "--json", *MAPS]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["reconstruction"]["poses"] > 100 and out["reconstruction"]["sensors"] == list(out["sites"])
    assert main(["export", str(tmp_path / "r.h5"), "--out", str(tmp_path / "r.bvh")]) == 0
    side = json.loads((tmp_path / "r.bvh.json").read_text())
    rec = read_recording(tmp_path / "r.h5")
    first = float(rec.recon["t"][0] - rec.raw["t"][0])
    assert side["first_frame_time_s"] == pytest.approx(first, abs=1e-6) and first > 1.0  # after the stand
    assert side["log_first_frame_time_s"] == pytest.approx(out["log_time_origin_s"] + first, abs=1e-5)
    assert side["frame_time_s"] == pytest.approx(0.05)
    capsys.readouterr()
    _import(capsys, clean, "--out", tmp_path / "n.h5", *MAPS)
    assert main(["export", str(tmp_path / "n.h5"), "--out", str(tmp_path / "n.bvh")]) != 0
    errors = [line for line in capsys.readouterr().err.splitlines() if "error" in line]
    assert len(errors) == 1 and f"imucap replay {tmp_path / 'n.h5'} --out FILE" in errors[0]
