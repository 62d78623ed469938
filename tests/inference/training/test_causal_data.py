"""Training data through the low-latency mode's trailing filter: TrainConfig.causal reaches
the features, keys the cache apart, and the model file says which filter it expects."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from inference.features.codec import features_from_kinematics
from inference.features.layout import SL_ACC
from inference.model.config import ModelConfig
from inference.model.files import load_model
from inference.signals.resample import STEP, acc_filter_of, moving_average
from inference.signals.synthesis import kinematics
from inference.training.config import TrainConfig
from inference.training.data import load_dataset, synthetic_dataset
from inference.training.dataset import build_dataset
from inference.training.loop import export_model, train
from sim_devices.motions import generate

CALLS: list[dict] = []


def record_factory(**kwargs):
    """A dataset factory that notes what it was asked for."""
    CALLS.append(kwargs)
    return synthetic_dataset(2, 70, seed=0)


def test_features_take_the_trailing_filter_on_acceleration_only():
    kin = kinematics(generate("walk", seconds=2.0, seed=1))
    centred, causal = features_from_kinematics(kin), features_from_kinematics(kin, causal=True)
    T = centred.shape[0]
    want = moving_average(kin.site_acc_raw, STEP, causal=True).reshape(T, -1).astype(np.float32)
    np.testing.assert_array_equal(causal[:, SL_ACC], want)
    rest = np.ones(centred.shape[1], bool)
    rest[SL_ACC] = False
    np.testing.assert_array_equal(causal[:, rest], centred[:, rest])
    assert not np.array_equal(causal[:, SL_ACC], centred[:, SL_ACC])


def test_load_dataset_passes_causal_to_the_factory_and_refuses_a_contradiction():
    spec = {"factory": f"{__name__}:record_factory", "kwargs": {"progress": False}}
    CALLS.clear()
    load_dataset(spec, causal=True)
    load_dataset(spec)
    assert CALLS == [{"progress": False, "causal": True}, {"progress": False}]
    with pytest.raises(ValueError, match="causal"):
        load_dataset({**spec, "kwargs": {"causal": True}}, causal=False)
    with pytest.raises(ValueError, match="causal"):
        load_dataset({"synthetic": {"clips": 2, "frames": 70}}, causal=True)  # its filter cannot be told


def test_build_dataset_caches_the_causal_features_apart(tmp_path):
    files = [tmp_path / "a.bvh", tmp_path / "b.bvh"]
    for i, f in enumerate(files):
        f.write_text(f"motion {i}")
    motions = {f.name: generate("walk", seconds=1.5, seed=i) for i, f in enumerate(files)}

    def build(causal):
        return build_dataset(files, tmp_path / "cache", loader=lambda f: motions[Path(f).name],
                             finder=lambda paths: list(paths), progress=False, causal=causal)

    a, b = build(False), build(True)
    assert len(list((tmp_path / "cache").glob("dataset-*.npz"))) == 2
    assert not np.array_equal(a.clips[0][:, SL_ACC], b.clips[0][:, SL_ACC])
    np.testing.assert_array_equal(build(True).clips[0], b.clips[0])  # read back from its own cache


def test_model_file_says_which_filter_it_was_trained_on(tmp_path):
    tiny = ModelConfig.tiny().to_dict()
    d = {"kind": "diffusion", "model": tiny, "steps": 1, "batch": 2, "warmup": 1, "log_every": 1, "ckpt_every": 1,
         "val_every": 100, "causal": True, "data": {"train": {"npz": "given below, never read"}}}
    cfg = TrainConfig.from_dict(json.loads(json.dumps(d)))
    ds = synthetic_dataset(2, 70, seed=0)
    train(cfg, tmp_path / "run", train_set=ds, val_set=None, progress=False)
    assert acc_filter_of(load_model(tmp_path / "run" / "model.pt").meta) == "causal"
    export_model(tmp_path / "run" / "last.pt", tmp_path / "out.pt")
    assert load_model(tmp_path / "out.pt").meta["acc_filter"] == "causal"
    assert TrainConfig().causal is False
