"""The training split's source balance, with and without faster/slower HDM05 copies."""

from __future__ import annotations

import numpy as np
import pytest

from inference.training.dataset import FeatureDataset
from inference.training.splits import balance_sources

from .test_dataset import moving_motion


def _ds(names: list[str]) -> FeatureDataset:
    return FeatureDataset.from_motions([moving_motion(T=120, speed=0.5 + i) for i in range(len(names))], names=names)


def test_hdm05_gets_its_share_over_all_its_speed_copies():
    names = ["bandai/d1/walk_1.bvh", "bandai/d2/run_2.bvh", "bandai/d2/dance_3.bvh",
             "hdm05/bd/HDM_bd_squat1Reps_001_120.amc.gz", "hdm05/bd/HDM_bd_squat1Reps_001_120.amc.gz@x1.25",
             "HDM_bk_kick_002_120.amc.gz@x0.8"]
    ds = balance_sources(_ds(names), hdm05_share=0.4)
    hdm = np.array([3, 4, 5])
    assert ds.weights[hdm].sum() == pytest.approx(0.4)
    assert ds.weights.sum() == pytest.approx(1.0)
    # within a source the kinetic-energy order survives the rescaling
    e = ds.energy
    assert np.argsort(ds.weights[:3]).tolist() == np.argsort(e[:3]).tolist()


def test_one_source_only_is_left_alone():
    ds = _ds(["bandai/a.bvh", "bandai/b.bvh"])
    w = ds.weights.copy()
    np.testing.assert_allclose(balance_sources(ds, 0.5).weights, w)
