"""`imucap train --contact-detector` (and `--pelvis-odometry`) on a few real files writes a
loadable file that records what it was trained on and how it scored."""

from __future__ import annotations

import json

import pytest

from app.cli import main
from inference.contact_detector import load_detector

pytestmark = pytest.mark.data


def test_train_contact_detector_cli(shared_data, tmp_path, capsys):
    d1 = shared_data / "bandai" / "d1"
    rc = main(["train", "--contact-detector", "--out", str(tmp_path / "run"), "--steps", "30", "--no-progress",
               "--data", str(d1 / "dataset-1_walk_normal_001.bvh.gz"), str(d1 / "dataset-1_walk_happy_001.bvh.gz"),
               "--val", str(d1 / "dataset-1_walk_sad_001.bvh.gz")])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    det = load_detector(tmp_path / "run" / "contact_detector.pt")
    assert det.meta["steps"] == 30 and len(det.meta["acc_val"]) == 4 and det.meta["train_frames"] > 100
    assert out["acc_val"] == det.meta["acc_val"]
    log = [json.loads(line) for line in (tmp_path / "run" / "train.jsonl").read_text().splitlines()]
    assert log[-1]["step"] == 30


def test_train_pelvis_odometry_cli(shared_data, tmp_path, capsys):
    """`imucap train --pelvis-odometry` the same way: the file records the held-out root errors."""
    from inference.pelvis_odometry import load_odometry

    d1 = shared_data / "bandai" / "d1"
    rc = main(["train", "--pelvis-odometry", "--out", str(tmp_path / "run"), "--steps", "30", "--no-progress",
               "--data", str(d1 / "dataset-1_walk_normal_001.bvh.gz"), str(d1 / "dataset-1_walk_happy_001.bvh.gz"),
               "--val", str(d1 / "dataset-1_walk_sad_001.bvh.gz")])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    odo = load_odometry(tmp_path / "run" / "pelvis_odometry.pt")
    assert odo.meta["steps"] == 30 and odo.meta["val_re2_m"] > 0 and odo.meta["train_frames"] > 100
    assert out["val_re10_m"] == odo.meta["val_re10_m"]
    assert main(["train", "--pelvis-odometry", "--contact-detector", "--out", str(tmp_path / "x")]) != 0
    assert "pick one" in capsys.readouterr().err
