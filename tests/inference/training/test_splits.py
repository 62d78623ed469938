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


def test_three_sources_get_their_shares():
    from inference.training.splits import balance_shares

    names = ["/d/bandai/d1/walk_1.bvh", "/d/bandai/d2/run_2.bvh", "/d/hdm05/bd/HDM_bd_squat_001_120.amc",
             "/d/hdm05/bd/HDM_bd_squat_001_120.amc@x1.25", "/d/cmu/asf_amc/01/01_01.amc.gz",
             "/d/cmu/bvh_iclone/005_02.bvh.gz"]
    ds = balance_shares(_ds(names), {"bandai": 0.3, "hdm05": 0.35, "cmu": 0.35})
    assert ds.weights[:2].sum() == pytest.approx(0.3) and ds.weights[2:4].sum() == pytest.approx(0.35)
    assert ds.weights[4:].sum() == pytest.approx(0.35)
    # a source that is absent gives its share to the others in proportion
    ds = balance_shares(_ds(names[:4]), {"bandai": 0.3, "hdm05": 0.35, "cmu": 0.35})
    assert ds.weights[:2].sum() == pytest.approx(0.3 / 0.65)


def test_cmu_subject_from_every_layout():
    from inference.training.splits import cmu_subject

    assert cmu_subject("cmu/asf_amc/07/07_01.amc.gz") == "07"
    assert cmu_subject("cmu/bvh_cgspeed/16_02.bvh.gz") == "16"
    assert cmu_subject("cmu/bvh_iclone/005_13.bvh.gz") == "05"


@pytest.mark.data
def test_cmu_split_is_by_subject(shared_data):
    from inference.training.splits import CMU_VAL_SUBJECTS, cmu_subject, cmu_train_files, cmu_val_files

    if not (shared_data / "cmu").is_dir():
        pytest.skip("no CMU data")
    train, val = cmu_train_files(shared_data), cmu_val_files(shared_data)
    assert train and val
    assert {cmu_subject(f) for f in val} == set(CMU_VAL_SUBJECTS)
    assert not {cmu_subject(f) for f in train} & set(CMU_VAL_SUBJECTS)
    assert not any(f.name.startswith("09_10") for f in train + val)


def test_real_motion_copies_get_their_share():
    from inference.training.splits import is_variant, is_walk, share_variants

    names = ["/d/bandai/d1/dataset-1_walk_normal_001.bvh", "/d/bandai/d2/dataset-2_run_active_002.bvh",
             "/d/bandai/d2/dataset-2_walk-turn-left_active_003.bvh@x0.6",
             "/d/bandai/d1/dataset-1_walk-back_normal_001.bvh@hold3",
             "/d/hdm05/bd/HDM_bd_squat_001_120.amc@hold3", "/d/hdm05/bd/HDM_bd_squat_001_120.amc@x1.25"]
    assert [is_walk(n.split("@")[0]) for n in names] == [True, False, True, True, False, False]
    # a slowed walk and a held stand are copies; HDM05's tempo copies are not
    assert [is_variant(n) for n in names] == [False, False, True, True, True, False]
    ds = share_variants(balance_sources(_ds(names), 0.5), 0.25)
    assert ds.weights[[2, 3, 4]].sum() == pytest.approx(0.25)
    assert ds.weights.sum() == pytest.approx(1.0)
    # without copies nothing moves
    plain = balance_sources(_ds(names[:2]), 0.5)
    np.testing.assert_allclose(share_variants(plain, 0.25).weights, plain.weights)


def test_train_set_builds_the_real_motion_copies(shared_data, tmp_path, monkeypatch):
    """The slowed walks and the held stands are built from the walks (and HDM05 for the
    stands), named apart, and drawn at the asked share."""
    from inference.training import splits

    monkeypatch.setenv("IMUCAP_CACHE", str(tmp_path))
    bandai = sorted(p for p in (shared_data / "bandai" / "d1").iterdir() if "_walk_normal" in p.name)[:2]
    bandai += sorted(p for p in (shared_data / "bandai" / "d1").iterdir() if "_run_normal" in p.name)[:1]
    hdm = sorted((shared_data / "hdm05" / "bd").glob("*.amc*"))[:1]
    monkeypatch.setattr(splits, "train_files", lambda root=None: bandai + hdm)
    ds = splits.train_set(progress=False, slow_walks=[0.6], stand_hold=2.0, variant_share=0.3)
    names = [str(n) for n in ds.names]
    assert sum(n.endswith("@x0.6") for n in names) == 2  # the two walks, not the run
    assert sum(n.endswith("@hold2") for n in names) == 3  # the two walks and the HDM05 clip
    extra = np.array([splits.is_variant(n) for n in names])
    assert ds.weights[extra].sum() == pytest.approx(0.3)
    # a held copy is 2 s longer at each end than its clip (and the settle of a walk), at 20 Hz
    base = {n: len(c) for n, c in zip(names, ds.clips) if "@" not in n}
    for n, c in zip(names, ds.clips):
        if n.endswith("@hold2"):
            assert len(c) >= base[n.removesuffix("@hold2")] + 2 * 40 - 2
