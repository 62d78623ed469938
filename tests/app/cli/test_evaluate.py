"""`imucap evaluate`: the DESIGN.md contract (one JSON object on stdout, null for metrics
the clips are too short for), exports, report, and the missing-weights error."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from app.cli.main import main
from app.export.bvh import write_motion_bvh
from inference.evaluation.runner import synthetic_motion
from inference.loaders import load_motion
from inference.model.config import ModelConfig
from inference.model.files import build_model, save_model
from inference.poser import models as poser_mod
from inference.training.data import feature_stats

KEYS = {"clips", "frames", "ga_deg", "la_deg", "jpe_cm", "jitter_ratio", "re2_m", "re5_m", "re10_m",
        "model", "sensors", "steps", "insoles"}


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("motions")
    write_motion_bvh(d / "walk_a.bvh", synthetic_motion(seconds=2.6, seed=1))
    write_motion_bvh(d / "walk_b.bvh", synthetic_motion(seconds=2.2, seed=2, turn_deg_per_s=30.0))
    return d


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory, data_dir):
    d = tmp_path_factory.mktemp("models")
    from inference.features.codec import features_from_motion

    mean, std = feature_stats([features_from_motion(load_motion(data_dir / "walk_a.bvh"))])
    paths = {}
    for kind in ("diffusion", "regressor"):
        torch.manual_seed(0)
        paths[kind] = d / f"{kind}.pt"
        save_model(paths[kind], build_model(kind, ModelConfig.tiny()), kind, mean, std)
    return paths


def _run(capsys, *argv):
    code = main(["evaluate", *argv, "--threads", "1", "--no-progress"])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_json_contract_and_nulls(capsys, data_dir, tiny_models):
    code, out, _ = _run(capsys, "--data", str(data_dir), "--sensors", "pelvis,l_wrist,r_wrist", "--steps", "2",
                        "--model", str(tiny_models["diffusion"]), "--json")
    assert code == 0
    res = json.loads(out)  # stdout is exactly one JSON object
    assert out.strip().count("\n") == 0
    assert KEYS <= set(res)
    assert res["clips"] == 2 and res["frames"] == 53 + 45
    assert res["sensors"] == ["pelvis", "l_wrist", "r_wrist"] and res["steps"] == 2 and res["insoles"] is False
    assert res["re2_m"] is not None and res["re5_m"] is None and res["re10_m"] is None
    assert all(np.isfinite(res[k]) for k in ("ga_deg", "la_deg", "jpe_cm", "jitter_ratio"))
    assert [c["name"] for c in res["per_clip"]] == ["walk_a", "walk_b"]
    assert res["smoothing"] is True and res["mirror"] is False
    # the raw per-frame reconstructions: same angles up to the filter, a rougher path
    code, out, _ = _run(capsys, "--data", str(data_dir), "--sensors", "pelvis,l_wrist,r_wrist", "--steps", "2",
                        "--model", str(tiny_models["diffusion"]), "--json", "--no-smoothing")
    raw = json.loads(out)
    assert code == 0 and raw["smoothing"] is False
    assert raw["jitter_ratio"] > res["jitter_ratio"]


def test_contact_detector_switch(capsys, data_dir, tiny_models):
    """With both shanks measured the shipped shank detector decides the contacts of the root
    correction; --no-contact-detector goes back to the model's own, which moves the root path."""
    args = ("--data", str(data_dir), "--sensors", "l_shank,r_shank", "--steps", "2",
            "--model", str(tiny_models["diffusion"]), "--json")
    code, out, _ = _run(capsys, *args)
    det = json.loads(out)
    code2, out2, _ = _run(capsys, *args, "--no-contact-detector")
    own = json.loads(out2)
    assert code == code2 == 0 and det["contact_detector"] is True and own["contact_detector"] is False
    assert det["re2_m"] != own["re2_m"] and np.isfinite(det["re2_m"])


def test_pelvis_odometry_switch(capsys, data_dir, tiny_models):
    """Without both shanks the shipped pelvis odometry walks the root; --no-pelvis-odometry
    goes back to the model's own displacement with the contact correction. With both shanks
    it does not apply, so the switch changes nothing there."""
    def run(sensors, *extra):
        code, out, err = _run(capsys, "--data", str(data_dir), "--sensors", sensors, "--steps", "2",
                              "--model", str(tiny_models["diffusion"]), "--json", *extra)
        assert code == 0, err
        return json.loads(out)

    odo, own = run("pelvis,l_wrist,r_wrist"), run("pelvis,l_wrist,r_wrist", "--no-pelvis-odometry")
    assert odo["pelvis_odometry"] is True and own["pelvis_odometry"] is False
    assert odo["re2_m"] != own["re2_m"] and np.isfinite(odo["re2_m"])
    assert run("l_shank,r_shank")["re2_m"] == run("l_shank,r_shank", "--no-pelvis-odometry")["re2_m"]


def test_inpaint_noise_override(capsys, data_dir, tiny_models):
    """--inpaint-noise runs the diffusion poser with another noise mode than the model file's
    (here: the file has none, so the paper's fresh draws), without re-exporting the file; the
    JSON says which mode ran. (That the mean start draws nothing in the DDIM mode is
    tests/inference/poser/test_poser.py's.)"""
    args = ("--data", str(data_dir), "--sensors", "l_shank,r_shank", "--steps", "1000,400,0",
            "--model", str(tiny_models["diffusion"]), "--json", "--no-noise")  # --seed: inpainting only
    runs = {}
    for mode, seed in (("default", 0), ("mean", 0), ("fixed", 0), ("fixed", 5)):
        extra = () if mode == "default" else ("--inpaint-noise", mode)
        code, out, _ = _run(capsys, *args, *extra, "--seed", str(seed))
        assert code == 0
        runs[mode, seed] = json.loads(out)
    assert runs["default", 0]["inpaint_noise"] == "fresh" and runs["mean", 0]["inpaint_noise"] == "mean"
    assert runs["mean", 0]["ga_deg"] != runs["default", 0]["ga_deg"]
    assert runs["fixed", 0]["ga_deg"] != runs["fixed", 5]["ga_deg"]
    with pytest.raises(SystemExit) as exc:  # argparse's choices
        _run(capsys, *args, "--inpaint-noise", "brown")
    assert exc.value.code == 2 and "brown" in capsys.readouterr().err


def test_floor_with_insoles_and_bvh_export(capsys, data_dir, tmp_path):
    code, out, _ = _run(capsys, "--data", str(data_dir), "--insoles", "--model", "floor", "--limit", "1",
                        "--no-noise", "--json", "--export-dir", str(tmp_path / "bvh"))
    assert code == 0
    res = json.loads(out)
    assert res["model"] == "floor" and res["steps"] == 0 and res["insoles"] is True and res["clips"] == 1
    recon = load_motion(tmp_path / "bvh" / "walk_a.recon.bvh")
    truth = load_motion(tmp_path / "bvh" / "walk_a.truth.bvh")
    assert recon.n_frames == truth.n_frames == res["frames"]
    assert abs(recon.fps - 20.0) < 1e-6


def test_report_over_sensor_sets_and_models(capsys, data_dir, tiny_models, tmp_path, monkeypatch):
    for kind, path in tiny_models.items():
        monkeypatch.setitem(poser_mod.DEFAULT_WEIGHTS, kind, path)
    report = tmp_path / "report.md"
    code, out, _ = _run(capsys, "--data", str(data_dir / "walk_b.bvh"), "--steps", "2", "--json",
                        "--report", str(report))
    assert code == 0
    res = json.loads(out)
    text = report.read_text()
    assert len(res["report"]["rows"]) == 12
    for label in ("6 sites", "6 sites + insoles", "3 sites (pelvis, wrists)", "2 sites (shanks)"):
        for model in ("diffusion", "regressor", "floor"):
            assert f"| {label} | {model} |" in text
    # the side-by-side table: diffusion minus each baseline on the same clip, set by set
    comps = res["report"]["comparisons"]
    assert [(c["label"], c["baseline"]) for c in comps] == [
        (label, base) for label in ("6 sites", "6 sites + insoles", "3 sites (pelvis, wrists)", "2 sites (shanks)")
        for base in ("regressor", "floor")]
    ga = {(r["label"], r["model"]): r["ga_deg"] for r in res["report"]["rows"]}
    for c in comps:
        assert c["difference"] == pytest.approx(ga[c["label"], "diffusion"] - ga[c["label"], c["baseline"]])
        assert c["clips"] == 1 and c["low"] == c["high"] == c["difference"]  # one clip: nothing to resample
        assert f"| {c['label']} | diffusion | {c['baseline']} | ga_deg | {c['difference']:+.2f} |" in text
    assert "## Side by side, paired over clips" in text and "mirror averaging: none" in text


def test_against_scores_a_second_model_on_the_same_clips(capsys, data_dir, tiny_models):
    common = ("--data", str(data_dir), "--sensors", "pelvis,l_shank,r_shank", "--steps", "2")
    code, out, _ = _run(capsys, *common, "--model", str(tiny_models["diffusion"]), "--against", "floor", "--json")
    assert code == 0
    res = json.loads(out)
    a = res["against"]
    assert a["model"] == "floor" and a["kind"] == "floor" and a["steps"] == 0
    for m in ("ga_deg", "la_deg", "jpe_cm"):
        d = a["differences"][m]
        assert d["difference"] == pytest.approx(res[m] - a[m])
        assert d["low"] <= d["difference"] <= d["high"] and 0 <= d["model_lower"] <= res["clips"] == 2
    assert [c["name"] for c in a["per_clip"]] == [c["name"] for c in res["per_clip"]]
    code, floor_out, _ = _run(capsys, *common, "--model", "floor", "--json")
    assert json.loads(floor_out)["ga_deg"] == pytest.approx(a["ga_deg"])  # the same clips, noise and seed
    # a model against itself: the same reconstruction, so no difference at all
    code, out, _ = _run(capsys, *common, "--model", str(tiny_models["diffusion"]),
                        "--against", str(tiny_models["diffusion"]), "--json")
    same = json.loads(out)["against"]["differences"]["ga_deg"]
    assert same["difference"] == 0.0 and not same["decided"]
    code, out, _ = _run(capsys, *common, "--model", "floor", "--against", "floor")
    assert code == 0 and "ga_deg minus floor: +0.00 [+0.00, +0.00]" in out


def test_missing_weights_is_a_clear_error(capsys, data_dir, tmp_path, monkeypatch):
    monkeypatch.setitem(poser_mod.DEFAULT_WEIGHTS, "diffusion", tmp_path / "none.pt")
    code, out, err = _run(capsys, "--data", str(data_dir), "--json")
    assert code == 2 and out == ""
    assert "imucap train" in err


def test_unknown_site_is_rejected(capsys, data_dir):
    code, out, err = _run(capsys, "--data", str(data_dir), "--sensors", "pelvis,tail", "--model", "floor", "--json")
    assert code == 2 and out == "" and "tail" in err


def test_repair_truth_puts_back_a_broken_foot_before_scoring(capsys, tmp_path):
    from inference.body.rotations import axis_angle_to_matrix
    from inference.body.skeleton import SEGMENT_INDEX

    m = synthetic_motion(seconds=2.6, seed=1)
    n = m.n_frames
    flip = axis_angle_to_matrix(np.array([0.0, np.pi, 0.0]))  # the solver lost the right foot for 0.3 s
    for seg in ("r_foot", "r_toes"):
        m.rot[n // 2:n // 2 + int(0.3 * m.fps), SEGMENT_INDEX[seg]] = flip
    write_motion_bvh(tmp_path / "broken.bvh", m)

    args = ("--data", str(tmp_path), "--model", "floor", "--no-noise", "--json")
    code, out, _ = _run(capsys, *args)
    raw = json.loads(out)
    code2, out2, err2 = _run(capsys, *args, "--repair-truth")
    fixed = json.loads(out2)
    assert code == code2 == 0
    assert raw["truth_repaired"] is None and raw["implausible_truth_share"] > 0.05
    assert fixed["truth_repaired"]["clips"] == 1 and fixed["truth_repaired"]["interpolated_frames"] > 0.3 * m.fps
    assert fixed["implausible_truth_share"] == 0.0 and "repaired in 1 clip" in err2
    # the standing floor's feet are flat: against the repaired truth they are nearer
    assert fixed["ga_deg"] < raw["ga_deg"] - 0.5


def test_mirror_averaging_is_reported_and_changes_the_answer(capsys, data_dir, tiny_models):
    args = ("--data", str(data_dir), "--sensors", "pelvis,l_wrist,r_shank", "--steps", "2", "--json",
            "--model", str(tiny_models["diffusion"]), "--against", str(tiny_models["regressor"]))
    _, out, _ = _run(capsys, *args)
    plain = json.loads(out)
    code, out, _ = _run(capsys, *args, "--mirror")
    mirrored = json.loads(out)
    assert code == 0 and plain["mirror"] is False and plain["against"]["mirror"] is False
    assert mirrored["mirror"] is True and mirrored["against"]["mirror"] is True  # both models, same poser
    assert mirrored["ga_deg"] != plain["ga_deg"] and mirrored["against"]["ga_deg"] != plain["against"]["ga_deg"]


def test_a_held_out_set_by_name_reads_its_files_and_keeps_the_name(capsys, tmp_path, monkeypatch):
    root = tmp_path / "data"
    (root / "cmu" / "bvh_cgspeed").mkdir(parents=True)
    write_motion_bvh(root / "cmu" / "bvh_cgspeed" / "08_01.bvh", synthetic_motion(seconds=2.2, seed=3))
    write_motion_bvh(root / "cmu" / "bvh_cgspeed" / "07_01.bvh", synthetic_motion(seconds=2.2, seed=4))
    monkeypatch.setenv("IMUCAP_DATA", str(root))
    report = tmp_path / "r.md"
    code, out, _ = _run(capsys, "--data", "@cmu-val", "--model", "floor", "--no-noise", "--json",
                        "--report", str(report))
    assert code == 0 and json.loads(out)["clips"] == 1  # subject 08 is held out, 07 is trained on
    text = report.read_text()
    assert "Reproduce: `imucap evaluate --data @cmu-val" in text and "| cmu 08 |" in text
    code, _, err = _run(capsys, "--data", "@cmu", "--model", "floor")
    assert code != 0 and "unknown held-out set @cmu; choose from @dg, @sad, @cmu-val" in err
    code, _, err = _run(capsys, "--data", "@dg", "--model", "floor")
    assert code != 0 and "held-out set @dg: " in err and "hdm05/dg" in err


def test_segments_name_each_segments_ga(capsys, data_dir):
    code, out, _ = _run(capsys, "--data", str(data_dir), "--sensors", "pelvis,l_shank,r_shank", "--model", "floor",
                        "--json")
    res = json.loads(out)
    assert code == 0 and len(res["segments"]) == 24
    assert res["segments"]["l_thigh"] > 0.0 and res["segments"]["pelvis"] < res["segments"]["l_thigh"]


def test_real_set_scores_the_held_out_sites_of_each_real_log(capsys):
    from app.evaluation.real import real_logs
    from inference.training.data import data_root

    if not real_logs(data_root()):
        pytest.skip("no real x-IMU3 log under the data folder")
    code, out, _ = _run(capsys, "--data", "@real", "--model", "floor", "--against", "floor", "--json")
    res = json.loads(out)
    assert code == 0 and res["clips"] == 0 and res["ga_deg"] is None
    sets = res["held_out"]["ximu3/logged_lower_body"]
    # against itself: every left-out site differs by nothing, settled nowhere; no per-frame errors written
    diff = res["against"]["held_out_differences"]["ximu3/logged_lower_body"]["pelvis+shanks"]
    assert set(diff) == set(sets["pelvis+shanks"]["deg"]) and diff["l_thigh"]["blocks"] >= 8
    assert all(d["difference"] == 0.0 and not d["decided"] for d in diff.values())
    assert "frame_errors" not in sets["pelvis+shanks"] and "frame_errors" not in out
    assert set(sets["pelvis+shanks"]["deg"]) == {"l_thigh", "r_thigh", "l_foot", "r_foot"}
    # a standing pose is far from a walk's thighs: the scoring sees the motion
    assert sets["pelvis+shanks"]["deg"]["l_thigh"] > 10.0 and sets["pelvis+shanks"]["frames"] > 300
    # the long axis alone leaves out the turn about the bone: never more than the whole angle
    axis = sets["pelvis+shanks"]["axis_deg"]
    assert all(axis[s] <= sets["pelvis+shanks"]["deg"][s] + 1e-6 for s in axis)
    # per phase and constant / dynamic (app/evaluation/real.py); the log ends standing still
    ps = sets["pelvis+shanks"]
    assert set(ps["phases"]) == {"walking", "turning", "standing", "other"}
    assert ps["phases"]["standing"]["seconds"] > 2.0 and ps["phases"]["walking"]["seconds"] > 2.0
    assert set(ps["constant_deg"]) == set(ps["dynamic_deg"]) == set(ps["deg"])
    if "opensense/xsens_mtw_walk" in res["held_out"]:  # the Xsens MTw trial, imported with its sensor map
        os_sets = res["held_out"]["opensense/xsens_mtw_walk"]
        assert set(os_sets["pelvis+shanks"]["deg"]) == {"torso", "l_thigh", "r_thigh", "l_foot", "r_foot"}


def test_real_set_without_logs_is_a_clear_error(capsys, tmp_path, monkeypatch):
    monkeypatch.setenv("IMUCAP_DATA", str(tmp_path))
    code, _, err = _run(capsys, "--data", "@real", "--model", "floor", "--json")
    assert code != 0 and "--data @real: no real log (x-IMU3 log folder under" in err
