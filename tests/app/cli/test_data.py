"""`imucap data ...` end to end on generated motions (no data files needed)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli.main import main


@pytest.fixture(scope="module")
def walk_file(tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("gen") / "walk.npz"
    assert main(["data", "generate", "walk", "--out", str(p), "--seconds", "3", "--height", "1.8", "--seed", "2"]) == 0
    return p


def test_inspect_json(walk_file: Path, capsys):
    capsys.readouterr()
    assert main(["data", "inspect", str(walk_file), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    for key in ("frames", "fps", "duration_s", "height_m", "root_z_min_m", "root_z_max_m", "min_foot_z_m",
                "name", "source", "format"):
        assert key in info
    assert info["frames"] == 181 and info["fps"] == 60.0 and info["format"] == "amass"
    assert info["height_m"] == pytest.approx(1.8)
    assert abs(info["min_foot_z_m"]) < 0.01
    assert 0.8 < info["root_z_min_m"] < info["root_z_max_m"] < 1.2


def test_inspect_table_and_missing_file(walk_file: Path, capsys):
    assert main(["data", "inspect", str(walk_file)]) == 0
    assert "min_foot_z_m" in capsys.readouterr().out
    assert main(["data", "inspect", str(walk_file.parent / "nope.npz")]) == 2
    assert "nope.npz" in capsys.readouterr().err


def test_build_then_cache_hit(walk_file: Path, tmp_path: Path, capsys):
    main(["data", "generate", "squat", "--out", str(walk_file.parent / "squat.npz"), "--seconds", "2"])
    capsys.readouterr()
    args = ["data", "build", "--data", str(walk_file.parent), "--out", str(tmp_path / "cache"), "--json"]
    assert main(args) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["clips"] == 2 and first["frames"] > 0 and Path(first["cache"]).exists()
    mtime = Path(first["cache"]).stat().st_mtime_ns
    assert main(args) == 0
    second = json.loads(capsys.readouterr().out)
    assert second["cache"] == first["cache"] and Path(first["cache"]).stat().st_mtime_ns == mtime


def test_plot_writes_png(walk_file: Path, tmp_path: Path):
    out = tmp_path / "walk.png"
    assert main(["data", "plot", str(walk_file), "--out", str(out), "--sites", "pelvis,r_shank"]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 10_000


def test_generate_rejects_unknown_kind(tmp_path: Path):
    with pytest.raises(SystemExit):
        main(["data", "generate", "moonwalk", "--out", str(tmp_path / "x.npz")])
