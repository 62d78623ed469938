"""The shank contact detector: heading invariance, that it learns stance from real
kinematics, its file format, and that the poser uses it only when both shanks are measured
and the insoles are not."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from inference.body.conventions import rot_z
from inference.evaluation.runner import SIX, synthetic_motion
from inference.features.codec import features_from_motion
from inference.features.layout import SL_CONTACT, observation_mask
from inference.poser.contact_detector import (
    CONTEXT,
    SHANK_INDEX,
    ContactDetector,
    DetectorTraining,
    clip_windows,
    contact_accuracy,
    heading_frame_inputs,
    load_detector,
    save_detector,
    train_detector,
)
from inference.poser.poser import Poser
from inference.training.augment import rotate_yaw


def _walks(seeds, **kw):
    return [features_from_motion(synthetic_motion(seconds=6.0, seed=s, **kw)).astype(np.float32) for s in seeds]


def test_inputs_do_not_depend_on_heading():
    x = torch.as_tensor(_walks([0])[0])[None]
    turned = rotate_yaw(x, torch.tensor([2.1]))[0]
    a = heading_frame_inputs(x[0][:, torch.as_tensor(SHANK_INDEX)])
    b = heading_frame_inputs(turned[:, torch.as_tensor(SHANK_INDEX)])
    assert torch.allclose(a, b, atol=1e-5)
    assert not torch.allclose(x[0][:, torch.as_tensor(SHANK_INDEX)], turned[:, torch.as_tensor(SHANK_INDEX)], atol=1e-2)


@pytest.mark.data
def test_learns_stance_from_real_walks(shared_data):
    """Trained briefly on six real walk styles, it classifies a held-out style's walk far
    better than always answering the most common label."""
    from inference.loaders import load_motion

    d1 = shared_data / "bandai" / "d1"
    styles = ("active", "angry", "childish", "feminine", "happy", "normal")
    train = [features_from_motion(load_motion(d1 / f"dataset-1_walk_{s}_001.bvh.gz")) for s in styles]
    held = [features_from_motion(load_motion(d1 / "dataset-1_walk_sad_001.bvh.gz"))]
    cfg = DetectorTraining(steps=800, batch=256)
    det = train_detector(train, {"held": held}, cfg, progress=None)
    X, Y = clip_windows(held)
    acc = np.array(contact_accuracy(det, X, Y))
    majority = np.maximum(Y.mean(0).numpy(), 1 - Y.mean(0).numpy())
    assert (0.2 < Y.mean(0)).all() and (Y.mean(0) < 0.8).all()  # the held-out walk has stance and swing
    assert (acc > majority + 0.1).all() and (acc > 0.8).all(), (acc, majority)
    assert cfg.log[-1]["acc_held"] == pytest.approx(acc.tolist(), abs=1e-3)


def test_file_round_trip(tmp_path):
    det = ContactDetector()
    torch.nn.init.normal_(det.net[0].weight)
    save_detector(tmp_path / "d.pt", det, {"note": "x"})
    back = load_detector(tmp_path / "d.pt")
    w = torch.randn(3, CONTEXT * len(SHANK_INDEX))
    assert torch.equal(back(w), det(w)) and back.meta == {"note": "x"}
    torch.save({"format": "something else"}, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="not an imucap contact detector"):
        load_detector(tmp_path / "bad.pt")


def _biased(value: float) -> ContactDetector:
    """A detector that answers ``value`` logit for every point, whatever it sees."""
    det = ContactDetector()
    with torch.no_grad():
        det.net[-1].weight.zero_()
        det.net[-1].bias.fill_(value)
    return det.eval()


@pytest.mark.parametrize("sites, insoles, expect_detector", [
    (SIX, False, True),  # both shanks measured: the detector decides
    (("l_shank", "r_shank"), False, True),
    (("pelvis", "l_wrist", "r_wrist"), False, False),  # no shanks: the model's own contacts
    (("pelvis", "l_shank"), False, False),  # one shank is not enough
    (SIX, True, False),  # insoles measure the contacts
])
def test_poser_uses_the_detector_only_when_both_shanks_are_measured(sites, insoles, expect_detector):
    x = _walks([3])[0]
    mask = observation_mask(list(sites), insoles)
    never = Poser(None, contact_detector=_biased(-20.0))
    assert never.contact_detector is None  # the floor keeps the standing pose's contacts
    from inference.model.config import ModelConfig
    from inference.model.files import LoadedModel, build_model

    cfg = ModelConfig(layers=1, d_model=32, heads=2, ff=64, mask_input=True)
    torch.manual_seed(0)
    model = LoadedModel(build_model("diffusion", cfg), "diffusion", cfg, np.zeros(190, np.float32),
                        np.ones(190, np.float32), meta={"contact_threshold": 0.5})
    outs = {}
    for name, logit in (("never", -20.0), ("always", 20.0)):
        p = Poser(model, steps="1000,0", contact_detector=_biased(logit), smoothing=False)
        outs[name] = np.array([p.step(f, mask).contacts for f in x[:15]])
    if expect_detector:
        assert not outs["never"].any() and outs["always"].all()
    else:
        assert np.array_equal(outs["never"], outs["always"])  # the detector was not asked
        if insoles:
            assert np.array_equal(outs["never"], x[:15, SL_CONTACT] > 0.5)


def test_heading_frame_keeps_the_shanks_relative_yaw():
    """Turning one shank against the other changes the inputs (the turn is information)."""
    x = torch.as_tensor(_walks([0])[0][:, SHANK_INDEX])
    a = heading_frame_inputs(x)
    from inference.body.rotations import matrix_to_rot6d, rot6d_to_matrix

    Rl = rot6d_to_matrix(x[:, :6])
    Rz = torch.as_tensor(rot_z(0.5), dtype=torch.float32)
    y = x.clone()
    y[:, :6] = matrix_to_rot6d(Rz @ Rl)
    assert not torch.allclose(heading_frame_inputs(y), a, atol=1e-3)


def test_missing_shipped_detector_warns_and_keeps_the_models_contacts(monkeypatch, tmp_path):
    from inference.poser import models as poser

    monkeypatch.setattr(poser, "CONTACT_DETECTOR_WEIGHTS", tmp_path / "nope.pt")
    with pytest.warns(UserWarning, match="nope.pt is missing"):
        assert poser.resolve_detector("default") is None
    assert poser.resolve_detector(None) is None
