"""Evaluation harness: the sensor path matches the training features, models run
through one harness, metrics come back with the contract's keys."""

from __future__ import annotations

import numpy as np
import pytest

from inference.evaluation.runner import (
    SIX,
    clip_input,
    compare_rows,
    comparison_markdown,
    evaluate_motions,
    evaluation_noise,
    report_markdown,
    synthetic_motion,
)
from inference.features.codec import features_from_motion
from inference.features.layout import SL_CONTACT, observation_mask
from inference.metrics.errors import ClipMetrics

KEYS = {"clips", "frames", "ga_deg", "la_deg", "jpe_cm", "jitter_ratio", "re2_m", "re5_m", "re10_m"}



def test_noise_free_inputs_equal_training_features():
    m = synthetic_motion(seconds=2.0, seed=4)
    inp = clip_input(m, SIX, insoles=True, noise=None, align=False)
    x = features_from_motion(m)
    mask = observation_mask(SIX, insoles=True)
    assert inp.features.shape == x.shape and np.array_equal(inp.mask[0], mask)
    np.testing.assert_allclose(inp.features[:, mask], x[:, mask], atol=1e-5)
    assert np.all(inp.features[:, ~mask] == 0)
    np.testing.assert_array_equal(inp.features[:, SL_CONTACT], x[:, SL_CONTACT])


def test_noise_model_is_calibrated_and_small():
    nz = evaluation_noise()
    assert nz.mounting_deg == 0 and nz.heading_deg == 0 and nz.acc_white > 0 and nz.ori_white_deg > 0
    m = synthetic_motion(seconds=2.0, seed=4)
    clean = clip_input(m, SIX, noise=None)
    noisy = clip_input(m, SIX, noise=nz, seed=1)
    d = np.abs(noisy.features - clean.features)[:, clean.mask[0]]
    assert 0 < d.max() < 0.5  # noise, not a different frame of reference


def test_floor_evaluation_and_short_clip_nulls():
    motions = [synthetic_motion(seconds=3.0, seed=1, name="a"), synthetic_motion(seconds=6.5, seed=2, name="b")]
    s, clips = evaluate_motions(motions, None, SIX, noise=evaluation_noise(), progress=False, keep=True)
    assert KEYS <= set(s)
    assert s["clips"] == 2 and s["frames"] == 61 + 131
    assert s["re2_m"] is not None and s["re5_m"] is not None and s["re10_m"] is None
    assert 0 < s["ga_deg"] < 60 and s["jpe_cm"] > 0
    # the floor holds the root, the truth walks 1 m/s: RE2 is about 2 m
    assert 1.7 < s["re2_m"] < 2.3
    assert clips[0].recon is not None and clips[0].recon.rot.shape == (61, 24, 3, 3)
    text = report_markdown([{"label": "6 sites", "model": "floor", "steps": 0, **s}])
    assert "| 6 sites | floor | 0 | 2 | 192 |" in text and "n/a" in text


def test_face_forward_turns_the_start_to_plus_x():
    from inference.evaluation.runner import face_forward

    m = synthetic_motion(seconds=1.0, seed=3, turn_deg_per_s=50.0)
    from dataclasses import replace

    from inference.body.rotations import matrix_about_axis

    Rz = matrix_about_axis(np.array([0.0, 0.0, 1.0]), 2.5)
    turned = replace(m, rot=Rz @ m.rot, root=m.root @ Rz.T + [4.0, -3.0, 0.0])
    back = face_forward(turned)
    fwd = back.rot[0, 0] @ [1.0, 0.0, 0.0]
    assert abs(np.arctan2(fwd[1], fwd[0])) < 1e-9
    np.testing.assert_allclose(back.root[0, :2], 0.0, atol=1e-12)
    np.testing.assert_allclose(back.joints(), face_forward(m).joints(), atol=1e-9)


def test_comparisons_pair_the_model_with_each_baseline_scored_on_the_same_set():
    def clips(ga):
        return [ClipMetrics(f"c{k}", 40, g * 40, 0.0, 0.0, 0.0, 0.0, 0) for k, g in enumerate(ga)]

    rng = np.random.default_rng(1)
    hard = rng.uniform(10, 40, 30)
    per_clip = {
        ("6 sites", "diffusion"): clips(hard), ("6 sites", "regressor"): clips(hard + 1 + rng.normal(0, 0.2, 30)),
        ("6 sites", "floor"): clips(hard + 20),
        ("2 sites", "diffusion"): clips(hard + 5), ("2 sites", "floor"): clips(hard + 5 + rng.normal(0, 3, 30)),
    }  # the regressor's 2-site weights are missing: no row for it
    rows = compare_rows(per_clip)
    assert [(r["label"], r["baseline"]) for r in rows] == [("6 sites", "regressor"), ("6 sites", "floor"),
                                                           ("2 sites", "floor")]
    assert rows[0]["decided"] and rows[0]["high"] < 0 and rows[0]["model_lower"] == 30
    assert rows[1]["difference"] == pytest.approx(-20.0)
    assert rows[2]["low"] < rows[2]["difference"] < rows[2]["high"]
    text = comparison_markdown(rows)
    assert "| 6 sites | diffusion | floor | ga_deg | -20.00 | [-20.00, -20.00] | 30 of 30 |" in text
    assert ("(not settled)" in text) == (not rows[2]["decided"])
    assert comparison_markdown([]) == ""
