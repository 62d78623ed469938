"""`imucap replay` and `imucap export` through the CLI entry point: a real recording,
replayed with a sensor subset and a tiny random diffusion model, its poses exported in
every format and read back; clear errors for bad sites, extensions and files."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
import torch

from app.cli.main import main
from app.export.hdf5_file import read_hdf5
from app.export.opensim import read_mot
from app.recording import read_recording
from inference.features.layout import N_FEATURES
from inference.loaders import load_motion
from inference.model.config import ModelConfig
from inference.model.files import build_model, save_model


@pytest.fixture(scope="module")
def tiny_model(tmp_path_factory):
    torch.manual_seed(0)
    path = tmp_path_factory.mktemp("model") / "tiny.pt"
    save_model(path, build_model("diffusion", ModelConfig.tiny()).eval(), "diffusion",
               np.zeros(N_FEATURES, np.float32), np.ones(N_FEATURES, np.float32))
    return path


def _run(capsys, *argv):
    code = main(list(argv))
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_replay_with_a_sensor_subset_and_exports(recorded, tiny_model, tmp_path, capsys):
    outs = [tmp_path / f"sub.{ext}" for ext in ("csv", "mot", "h5", "bvh")]
    code, out, err = _run(capsys, "replay", str(recorded.path), "--model", str(tiny_model), "--steps", "2",
                          "--sensors", "pelvis,l_wrist,r_shank", "--no-insoles", "--json",
                          *[a for o in outs for a in ("--out", str(o))])
    assert code == 0, err
    res = json.loads(out)  # stdout is exactly one JSON object
    assert out.strip().count("\n") == 0
    assert res["sensors"] == ["pelvis", "l_wrist", "r_shank"] and res["insoles"] is False
    assert res["steps"] == 2 and len(res["step_list"]) == 2 and res["kind"] == "diffusion"
    assert res["model"].startswith("diffusion 1/32/64 (tiny.pt)")
    assert res["recorded_sensors"] == list(recorded.sites) and res["calibrations"] == 1
    n = res["frames"]
    assert n == len(recorded.live) and res["duration_s"] == pytest.approx(n / 20.0, abs=1e-3)
    assert res["vs_recorded_frames"] == n and res["vs_recorded_ga_deg"] > 0
    assert res["outputs"] == [str(o) for o in outs] and all(o.exists() for o in outs)
    assert "replay: 100%" in err  # progress on stderr
    # every export holds the replayed frames
    with open(outs[0], newline="") as f:
        rows = list(csv.reader(f))
    assert len(rows) == n + 1 and rows[0][0] == "time_s"
    header, labels, data = read_mot(outs[1])
    assert int(header["nRows"]) == n and data.shape == (n, 30)
    h5, attrs = read_hdf5(outs[2])
    assert h5["rot"].shape == (n, 24, 3, 3) and json.loads(attrs["sensors"]) == res["sensors"]
    assert attrs["model"] == res["model"] and attrs["steps"] == 2
    assert load_motion(outs[3]).n_frames == n
    # the re-run differs from the live one (other model, fewer sensors) but is the same length
    rec = read_recording(recorded.path)
    assert np.allclose(h5["time"], rec.recon["t"] - rec.raw["t"][0])


def test_replay_floor_with_all_sensors_matches_the_live_run(recorded, capsys):
    code, out, err = _run(capsys, "replay", str(recorded.path), "--model", "floor", "--json", "--no-progress")
    assert code == 0, err
    res = json.loads(out)
    assert res["steps"] == 0 and res["sensors"] == list(recorded.sites) and res["insoles"] is True
    assert res["vs_recorded_ga_deg"] < 1e-3 and res["outputs"] == [] and err == ""


def test_export_writes_the_recorded_reconstruction(recorded, tmp_path, capsys):
    outs = [tmp_path / "live.bvh", tmp_path / "live.hdf5", tmp_path / "live.csv", tmp_path / "live.mot"]
    code, out, err = _run(capsys, "export", str(recorded.path), "--json", *[a for o in outs for a in ("--out", str(o))])
    assert code == 0, err
    res = json.loads(out)
    rec = read_recording(recorded.path)
    assert res["frames"] == len(rec.recon["t"]) and res["gaps"] == 0 and res["model"] == "floor"
    assert res["sensors"] == list(recorded.sites) and res["outputs"] == [str(o) for o in outs]
    h5, _ = read_hdf5(outs[1])
    assert np.allclose(h5["rot"], rec.recon["R"]) and np.array_equal(h5["contacts"], rec.recon["contacts"])
    assert load_motion(outs[0]).n_frames == res["frames"]


@pytest.mark.parametrize("argv, message", [
    (["replay", "{rec}", "--model", "floor", "--sensors", "pelvis,torso"],
     "torso not in this recording; it has: pelvis, head, l_wrist, r_wrist, l_shank, r_shank"),
    (["replay", "{rec}", "--model", "floor", "--sensors", "pelvis,knee"], "unknown sensor site"),
    (["replay", "{rec}", "--model", "floor", "--out", "x.fbx"], "supported: .bvh, .csv, .h5, .hdf5, .mot"),
    (["export", "{rec}", "--out", "x.txt"], "unknown extension '.txt'"),
    (["export", "{missing}", "--out", "x.csv"], "not found"),
    (["replay", "{rec}", "--model", "{missing}"], "not a file"),
])
def test_clear_errors(recorded, tmp_path, capsys, argv, message):
    argv = [a.format(rec=recorded.path, missing=tmp_path / "nope.h5") for a in argv]
    code, out, err = _run(capsys, *argv)
    assert code == 2 and out == ""
    assert message in err and err.count("\n") == 1  # one line, no traceback


def test_replay_mirrors_as_recorded_else_as_the_model_file_says(recorded, tiny_model, tmp_path, capsys):
    import shutil

    import h5py

    from inference.model.files import retag_model

    tagged = tmp_path / "tagged.pt"
    retag_model(tiny_model, tagged, {"mirror": True})
    base = ("replay", None, "--model", str(tagged), "--steps", "2", "--json", "--no-progress")

    def mirror_of(path, *extra):
        code, out, err = _run(capsys, base[0], str(path), *base[2:], *extra)
        assert code == 0, err
        return json.loads(out)["mirror"]

    assert mirror_of(recorded.path) is True  # nothing recorded: the model file's default
    assert mirror_of(recorded.path, "--no-mirror") is False
    # a session recorded without mirror averaging replays without it with the same model, unless asked
    from app.live.model_choice import model_label
    from inference.poser.models import resolve_model

    old = tmp_path / "old.h5"
    shutil.copy(recorded.path, old)
    with h5py.File(old, "r+") as f:
        meta = json.loads(f.attrs["metadata"])
        f.attrs["metadata"] = json.dumps({**meta, "mirror": False,
                                          "model": model_label(str(tagged), resolve_model(tagged))})
    assert mirror_of(old) is False
    assert mirror_of(old, "--mirror") is True
    # another model than the recorded one runs as its own file says
    with h5py.File(old, "r+") as f:
        f.attrs["metadata"] = json.dumps({**meta, "mirror": False, "model": "diffusion 4/128/512 (other.pt)"})
    assert mirror_of(old) is True


@pytest.mark.parametrize("key, flag", [("stride_scale", "stride-scale"), ("pelvis_odometry", "pelvis-odometry")])
def test_replay_root_stages_as_recorded(recorded, tiny_model, tmp_path, capsys, key, flag):
    """A session recorded before a root stage (stride scaling, pelvis odometry) existed
    replays without it; one that had it replays with it; either way the flag overrides."""
    import shutil

    import h5py

    def stage_of(path, *extra):
        code, out, err = _run(capsys, "replay", str(path), "--model", str(tiny_model), "--steps", "2", "--json",
                              "--no-progress", *extra)
        assert code == 0, err
        return json.loads(out)[key]

    for recorded_as in (None, True):
        rec = tmp_path / f"rec_{recorded_as}.h5"
        shutil.copy(recorded.path, rec)
        with h5py.File(rec, "r+") as f:
            meta = json.loads(f.attrs["metadata"])
            meta.pop(key, None)
            if recorded_as is not None:
                meta[key] = recorded_as
            f.attrs["metadata"] = json.dumps(meta)
        assert stage_of(rec) is bool(recorded_as)
        assert stage_of(rec, f"--{flag}") is True
        assert stage_of(rec, f"--no-{flag}") is False


def test_held_out_sensors_score_a_subset_against_what_they_measured(recorded, capsys):
    from app.replay import held_out_errors, replay_recording
    from inference.poser.poser import make_poser

    code, out, err = _run(capsys, "replay", str(recorded.path), "--model", "floor", "--sensors",
                          "pelvis,head,l_wrist,r_wrist", "--held-out", "--json", "--no-progress")
    assert code == 0, err
    res = json.loads(out)
    ho = res["held_out"]
    assert set(ho["deg"]) == {"l_shank", "r_shank"} and ho["frames"] == res["frames"] > 0
    assert min(ho["deg"].values()) > 3.0  # the floor's standing shanks against the walking ones
    assert ho["mean_deg"] == pytest.approx(np.mean(list(ho["deg"].values())), abs=0.01)
    poses = replay_recording(read_recording(recorded.path), make_poser("floor", body=recorded.body)).poses
    assert held_out_errors(poses, poses, ["l_shank"])["deg"]["l_shank"] == 0.0  # a measured segment is its sensor
    code, _, err = _run(capsys, "replay", str(recorded.path), "--model", "floor", "--held-out")
    assert code != 0 and "--held-out needs --sensors" in err
