"""The hub's batched interpolation (``Hub._interp_all``, what the live centred mode runs)
against the per-site reference (``Hub._per_site`` given inference's ``to_grid`` as the
per-stream resampler): the same grid values, presence, free accelerations and newest-sample stamps for
streams at different rates with jitter, lost bursts, long gaps, a device that only just
started and one that reports no orientation. Deterministic: samples pushed, grids given."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers.base import Sample
from drivers.hub import Hub, Interpolation

resample = pytest.importorskip("inference.signals.resample")
rotations = pytest.importorskip("inference.body.rotations")

SITES = ("pelvis", "head", "l_wrist", "r_wrist")


def _to_grid(t, q, a, grid):
    """Inference's ``to_grid`` as the hub's per-stream resampler."""
    tg, qg, ag, valid = resample.to_grid(t, q, a, fps=60.0, max_gap=0.1, t0=float(grid[0]))
    G, n = grid.size, min(grid.size, len(tg))
    quat, acc, ok = np.full((G, 4), np.nan), np.full((G, 3), np.nan), np.zeros(G, bool)
    quat[:n], acc[:n], ok[:n] = qg[:n], ag[:n], valid[:n]
    return quat, acc, ok


def _hub(interpolation: Interpolation) -> Hub:
    devs = {s: drivers.make_device(f"bno08x-rvc:///dev/null-interp-{s}") for s in SITES}
    return Hub(devs, latency=0.0, staleness=0.05, max_backlog=5, queue_size=4096, interpolation=interpolation)


def _fill(hub: Hub, rng: np.random.Generator) -> None:
    plans = {  # rate (Hz), jitter (s), lost burst starts, whether quats are sent, start time
        "pelvis": (100.0, 0.002, [50, 51, 52, 200], True, 1.0),
        "head": (60.0, 0.004, list(range(90, 110)), True, 1.0),  # a 0.33 s gap: stays a gap
        "l_wrist": (120.0, 0.001, [], False, 1.0),  # acc only: held, not interpolated
        "r_wrist": (100.0, 0.002, [], True, 3.5),  # starts late: nothing before it
    }
    for site, (rate, jit, lost, quat, start) in plans.items():
        n = int((5.0 - start) * rate)
        t = start + np.arange(n) / rate + rng.uniform(-jit, jit, n)
        run = 0
        for k in range(n):
            if k in lost:
                run += 1
                continue
            q = rotations.quat_normalize(rng.normal(size=4) * 0.05 + np.array([np.cos(t[k]), 0, np.sin(t[k]), 0]))
            s = Sample(float(t[k]), None, "x", k & 0xFF, q if quat else None,
                       rng.normal(size=3) if quat else None, rng.normal(size=3), rng.normal(size=3))
            if run:
                s.extra["lost_before"] = run
                run = 0
            hub.push(site, s)
    hub._drain()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_batched_interpolation_equals_the_per_site_reference(seed):
    batch = Interpolation(resample.slerp_unit)
    hub = _hub(Interpolation(per_stream=_to_grid))
    _fill(hub, np.random.default_rng(seed))
    assert hub.tracks["l_wrist"].ring.has["quat"] is False and len(hub.tracks["pelvis"].ring) > 300
    for first in (61, 150, 205, 240, 296, 298):  # before, inside, after the gaps; the late start; the end
        grid = (first + np.arange(4)) / 60.0
        batched = hub._interp_all(SITES, grid, batch)
        reference = hub._per_site(SITES, grid)
        names = ("quat", "free", "acc", "gyro", "present", "newest")
        for name, a, b in zip(names, batched, reference):
            assert a.shape == b.shape, name
            if name == "quat":  # q and -q are one orientation
                a, b = a * np.sign(a[..., :1]), b * np.sign(b[..., :1])
            np.testing.assert_allclose(a, b, atol=1e-9, err_msg=f"{name} at grid index {first}")
    present = hub._interp_all(SITES, (150 + np.arange(4)) / 60.0, batch)[4]
    assert not present[:, 1].any()  # head's long gap is no bridge
    assert present[:, 0].all() and present[:, 2].all()


def test_the_hub_takes_the_batched_path_when_given_a_slerp(monkeypatch):
    hub = _hub(Interpolation(resample.slerp_unit))
    _fill(hub, np.random.default_rng(0))
    monkeypatch.setattr(Hub, "_per_site", lambda *a: pytest.fail("the per-site path ran"))
    hub._next_index = 200
    frames = hub.poll(now=4.0)
    assert frames and all(f.present[0] for f in frames)
