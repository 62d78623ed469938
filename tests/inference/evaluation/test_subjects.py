"""Per-subject figures: which person a clip shows, and pooling by subject."""

from __future__ import annotations

import pytest

from inference.evaluation.subjects import per_subject, per_subject_markdown, subject_of
from inference.metrics.errors import ClipMetrics


@pytest.mark.parametrize("name,subject", [
    ("HDM_dg_squat3Reps_001_120", "hdm05 dg"), ("hdm05/bd/HDM_bd_kick_002_120", "hdm05 bd"),
    ("02_05", "cmu 02"), ("005_13", "cmu 05"), ("cmu/bvh_cgspeed/16_01", "cmu 16"),
    ("dataset-1_walk_sad_001", "bandai"), ("walk", "walk"),
])
def test_subject_of(name, subject):
    assert subject_of(name) == subject


def clip(name: str, frames: int, ga: float) -> ClipMetrics:
    return ClipMetrics(name, frames, ga * frames, 0.0, 0.0, 0.0, 0.0, 0)


def test_per_subject_pools_by_frames():
    t = per_subject([clip("02_01", 100, 10.0), clip("02_02", 300, 20.0), clip("HDM_dg_x_001_120", 50, 5.0)])
    assert t["cmu 02"]["clips"] == 2 and t["cmu 02"]["frames"] == 400
    assert t["cmu 02"]["ga_deg"] == pytest.approx(17.5)
    assert t["hdm05 dg"]["ga_deg"] == pytest.approx(5.0)
    md = per_subject_markdown({"new": t, "old": per_subject([clip("02_01", 100, 12.0)])})
    assert "| cmu 02 | 2 | 400 | 17.5 | 12.0 |" in md and "| hdm05 dg | 1 | 50 | 5.0 | - |" in md
