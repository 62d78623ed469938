"""`imucap train --contact-detector` and `--pelvis-odometry` on a few real files write a
loadable file that records what it was trained on and how it scored."""

from __future__ import annotations

import json

import pytest

from app.cli.main import main
from inference.poser.contact_detector import load_detector
from inference.poser.pelvis_odometry import TwoWayOdometry, load_odometry

pytestmark = pytest.mark.data


@pytest.mark.parametrize("flag, name, load, scored", [
    ("--contact-detector", "contact_detector", load_detector, "acc_val"),
    ("--pelvis-odometry", "pelvis_odometry", load_odometry, "val_re10_m"),
])
def test_train_helper_stage_cli(shared_data, tmp_path, capsys, flag, name, load, scored):
    d1 = shared_data / "bandai" / "d1"
    rc = main(["train", flag, "--out", str(tmp_path / "run"), "--steps", "30", "--no-progress",
               "--data", str(d1 / "dataset-1_walk_normal_001.bvh.gz"), str(d1 / "dataset-1_walk_happy_001.bvh.gz"),
               "--val", str(d1 / "dataset-1_walk_sad_001.bvh.gz")])
    assert rc == 0
    out = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    stage = load(tmp_path / "run" / f"{name}.pt")
    assert stage.meta["steps"] == 30 and stage.meta["train_frames"] > 100
    assert stage.meta[scored] and out[scored] == stage.meta[scored]
    if name == "contact_detector":
        assert len(stage.meta["acc_val"]) == 4
    else:  # the shipped pair: both walks are forward walks, so both are also played backwards
        assert stage.meta["val_re2_m"] > 0 and stage.meta["reversed_walks"] == 2
        assert isinstance(stage, TwoWayOdometry)
    log = [json.loads(line) for line in (tmp_path / "run" / "train.jsonl").read_text().splitlines()]
    assert log[-1]["step"] == 30
    if name == "pelvis_odometry":
        assert [e.get("stage") for e in log] == ["forward", "backward", "two-way"]


def test_one_helper_stage_at_a_time(tmp_path, capsys):
    assert main(["train", "--pelvis-odometry", "--contact-detector", "--out", str(tmp_path / "x")]) != 0
    assert "pick one" in capsys.readouterr().err

