"""The sensor-placement advisor: a set that holds the task's segments ranks ahead of one
that does not, searches cover every set up to 3 then grow a beam, and the fast scoring
keeps the order the live poser gives."""

from __future__ import annotations

import pytest

from inference.evaluation.advisor import TASKS, Advisor, advisor_clips, ranked, sets_of_size, table
from inference.poser.models import DEFAULT_WEIGHTS, resolve_model
from sim_devices.motions import generate

pytestmark = pytest.mark.skipif(not DEFAULT_WEIGHTS["diffusion"].exists(), reason="shipped weights not installed")


@pytest.fixture(scope="module")
def advisor():
    motions = [generate("walk", seconds=3.0, seed=0), generate("arm_raises", seconds=3.0, seed=1)]
    return Advisor(resolve_model("diffusion"), advisor_clips(motions), frame_step=4)


@pytest.mark.parametrize("task, holds, lacks", [
    ("legs", ("l_thigh", "r_thigh"), ("l_wrist", "r_wrist")),
    ("arms", ("l_upperarm", "r_upperarm"), ("l_shank", "r_shank")),
])
def test_a_set_on_the_tasks_segments_ranks_ahead_of_one_off_them(advisor, task, holds, lacks):
    advisor.score([holds, lacks], [task])
    order = [r.sites for r in ranked(advisor.scored.values(), task) if r.sites in (holds, lacks)]
    assert order == [holds, lacks]
    assert advisor.scored[holds].error(task) < advisor.scored[lacks].error(task)


def test_every_small_set_is_counted_once():
    assert [len(sets_of_size(k)) for k in (1, 2, 3)] == [13, 78, 286]
    assert all(s == tuple(sorted(s, key=lambda x: sets_of_size(1).index((x,)))) for s in sets_of_size(3))


def test_search_grows_a_beam_past_three(monkeypatch):
    import inference.evaluation.advisor as adv

    monkeypatch.setattr(adv, "EXHAUSTIVE", 1)  # keep the test small: singles, then the beam
    advisor = Advisor(resolve_model("diffusion"), advisor_clips([generate("walk", seconds=2.0, seed=3)]),
                      frame_step=8)
    rows = advisor.search("legs", max_sensors=2, beam=2)
    pairs = [r for r in rows if len(r.sites) == 2]
    singles = ranked([r for r in advisor.scored.values() if len(r.sites) == 1], "legs")
    assert 0 < len(pairs) <= 2 * 12 and all(set(p.sites) & {s.sites[0] for s in singles[:2]} for p in pairs)
    assert rows == sorted(rows, key=lambda r: (r.error("legs"), len(r.sites), r.sites))
    assert "1" in table(rows, "legs", top=3).splitlines()[1]


def test_root_task_scores_the_root_error():
    motions = [generate("walk", seconds=3.0, seed=2)]
    adv = Advisor(resolve_model("diffusion"), advisor_clips(motions), frame_step=4)
    pelvis, head = adv.score([("pelvis",), ("head",)], ["root"])
    assert TASKS["root"] is None
    assert pelvis.error("root") < head.error("root")  # the pelvis sensor walks the root (odometry)
