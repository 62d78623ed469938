"""benchmarks/mirror_real_log.py: an MT Manager export mirrored through the vertical x-z plane."""

import numpy as np
from scipy.spatial.transform import Rotation

from benchmarks.mirror_real_log import SWAP, mirror_text

HEADER = "PacketCounter\tSampleTimeFine\tAcc_X\tAcc_Y\tAcc_Z\t" + "\t".join(
    f"Mat[{i}][{j}]" for j in (1, 2, 3) for i in (1, 2, 3))


def export(R: np.ndarray, acc: np.ndarray) -> str:
    rows = [f"{k:05d}\t\t" + "\t".join(f"{v:.6f}" for v in (*a, *r.T.ravel())) for k, (r, a) in enumerate(zip(R, acc))]
    return "\n".join(["// Update Rate: 100.0Hz", HEADER, *rows]) + "\n"


def parse(text: str) -> tuple[np.ndarray, np.ndarray]:
    rows = [ln.split("\t") for ln in text.splitlines()[2:]]
    acc = np.array([[float(v) for v in r[2:5]] for r in rows])
    R = np.array([np.array([float(v) for v in r[5:14]]).reshape(3, 3).T for r in rows])
    return R, acc


def test_each_orientation_becomes_M_R_M_and_the_acceleration_M_a():
    R = Rotation.random(5, random_state=1).as_matrix()
    acc = np.random.default_rng(2).normal(size=(5, 3))
    M = np.diag([1.0, -1.0, 1.0])
    Rm, am = parse(mirror_text(export(R, acc)))
    np.testing.assert_allclose(Rm, M @ R @ M, atol=2e-6)
    np.testing.assert_allclose(am, acc @ M, atol=2e-6)
    assert np.allclose(np.linalg.det(Rm), 1.0, atol=1e-4)  # still a rotation
    # twice is the original, to the text
    text = export(R, acc)
    assert mirror_text(mirror_text(text)) == text


def test_left_and_right_twins_swap_ids():
    assert all(SWAP[SWAP[k]] == k for k in SWAP) and len(SWAP) == 6


def test_a_real_mt_manager_export_mirrors_to_M_R_M():
    """On the OpenSense walk's own export (MT Manager wrote it): each row's matrix comes back as
    M R M, a rotation, the other columns untouched."""
    import pytest

    from benchmarks.mirror_real_log import LOG
    from inference.training.data import data_root

    files = sorted((data_root() / LOG).glob("*.txt"))
    if not files:
        pytest.skip(f"no real log under {data_root() / LOG}")
    text = files[0].read_text()
    out = mirror_text(text)

    def rows(t: str) -> tuple[list[str], list[list[str]]]:
        lines = [ln for ln in t.splitlines() if ln.strip() and not ln.startswith("//")]
        return lines[0].split("\t"), [ln.split("\t") for ln in lines[1:201]]

    cols, a = rows(text)
    _, b = rows(out)
    mat = [cols.index(f"Mat[{i}][{j}]") for i in (1, 2, 3) for j in (1, 2, 3)]
    acc = [cols.index(f"Acc_{c}") for c in "XYZ"]
    M = np.diag([1.0, -1.0, 1.0])
    for ra, rb in zip(a, b):
        R = np.array([float(ra[k]) for k in mat]).reshape(3, 3)
        Rm = np.array([float(rb[k]) for k in mat]).reshape(3, 3)
        np.testing.assert_allclose(Rm, M @ R @ M, atol=1e-9)
        assert abs(np.linalg.det(Rm) - 1.0) < 1e-3
        np.testing.assert_allclose([float(rb[k]) for k in acc], M @ [float(ra[k]) for k in acc])
        kept = [k for k in range(len(ra)) if k not in mat + acc]
        assert [rb[k] for k in kept] == [ra[k] for k in kept]
