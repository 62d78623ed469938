"""`imucap advise`: the ranked table (one set per line, best first), the JSON object and
the plot, on a generated motion file."""

from __future__ import annotations

import json

import pytest

from app.cli.main import main
from inference.poser.models import DEFAULT_WEIGHTS
from sim_devices.motions import generate, write_amass_npz

pytestmark = pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory):
    return write_amass_npz(generate("walk", seconds=2.5, seed=0), tmp_path_factory.mktemp("m") / "walk.npz")


def test_table_lists_sets_best_first(motion_file, capsys):
    code = main(["advise", "--task", "legs", "--data", str(motion_file), "--max-sensors", "1", "--frame-step", "5",
                 "--top", "0", "--no-progress"])
    out = capsys.readouterr().out.splitlines()
    assert code == 0
    rows = [line.split() for line in out[2:] if line.strip() and line.split()[0].isdigit()]
    assert len(rows) == 13 and [int(r[0]) for r in rows] == list(range(1, 14))
    errors = [float(r[1]) for r in rows]
    assert errors == sorted(errors) and all(r[3] == "1" for r in rows)


def test_json_and_plot(motion_file, capsys, tmp_path):
    png = tmp_path / "advisor.png"
    code = main(["advise", "--task", "whole", "--data", str(motion_file), "--max-sensors", "1", "--frame-step", "5",
                 "--json", "--plot", str(png), "--no-progress"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and png.stat().st_size > 1000
    assert res["task"] == "whole" and res["sets_scored"] == 13 and res["unit"] == "deg"
    errs = [r["error"] for r in res["ranking"]]
    assert errs == sorted(errs) and res["best_by_size"]["1"]["sites"] == res["ranking"][0]["sites"]
    assert set(res["curves"]) == {"whole", "legs", "arms", "back", "root"}
    assert set(res["other_tasks"]) == {"legs", "arms", "back"}


def test_the_cli_knows_every_task():
    from app.cli.advise import TASK_NAMES
    from inference.evaluation.advisor import TASKS

    assert TASK_NAMES == tuple(TASKS)
