"""A tracked device's positions on the hub's grid (``HubFrame.position``): held or
interpolated as the free acceleration is, NaN at IMU sites and where a site is missing,
None from a hub without tracked devices. Deterministic: samples pushed, the clock given."""

from __future__ import annotations

import numpy as np
import pytest

import drivers
from drivers.base import Sample
from drivers.hub import Hub, Interpolation
from inference.signals.resample import slerp_unit

RATE = 90.0  # the rig's bundles


def _rig():
    return drivers.make_device("vmc-in://127.0.0.1:1?head=HMD&r_hand=CON-R&id=vr")  # built, not opened


def _imu():
    return drivers.make_device("bno08x-rvc:///dev/null-shank")


def right_hand(t: float) -> np.ndarray:
    return np.array([0.2 + t, 0.5 - 2.0 * t, 1.0 + 0.5 * t])  # linear: interpolation is exact


def _pose(t: float, site: str, pos: np.ndarray) -> Sample:
    return Sample(t, None, "vr", None, np.array([1.0, 0, 0, 0]), np.zeros(3), np.array([0, 0, 9.81]), np.zeros(3),
                  extra={"site": site, "position": pos, "serial": site, "kind": "con"})


def _imu_sample(t: float) -> Sample:
    return Sample(t, None, "shank", None, np.array([1.0, 0, 0, 0]), np.zeros(3), np.array([0, 0, 9.81]), np.zeros(3))


def feed(hub: Hub, seconds: float = 1.5, drop_hand: tuple[float, float] | None = None) -> list:
    hub.poll(now=1.0)  # the grid starts here
    for k in range(int(seconds * RATE)):
        t = 1.0 + (k + 0.3) / RATE  # never on a grid time: which sample is held is then clear
        if drop_hand is None or not drop_hand[0] <= t < drop_hand[1]:
            hub.push("vr", _pose(t, "r_hand", right_hand(t)))
        hub.push("vr", _pose(t, "head", np.array([0.0, 0.0, 1.64])))
        if "l_shank" in hub.tracks:
            hub.push("l_shank", _imu_sample(t))
    return hub.poll(now=1.0 + seconds - 0.05)


@pytest.mark.parametrize("interpolate", [False, True], ids=["hold", "interpolate"])
def test_positions_reach_the_grid_like_the_other_channels(interpolate):
    hub = Hub({"l_shank": _imu(), "vr": _rig()}, latency=0.0, max_backlog=5,
              interpolation=Interpolation(slerp_unit) if interpolate else None)
    frames = feed(hub)
    assert hub.sites == ("l_shank", "head", "r_wrist")
    live = [f for f in frames if f.present.all()]
    assert len(live) > 60
    for f in live:
        assert f.position.shape == (3, 3)
        assert np.isnan(f.position[0]).all()  # the IMU site has none
        np.testing.assert_allclose(f.position[1], [0.0, 0.0, 1.64])
        # interpolated: the position at the grid time itself; held: the sample at or before it
        t_src = f.t if interpolate else 1.0 + (np.floor((f.t - 1.0) * RATE - 0.3) + 0.3) / RATE
        np.testing.assert_allclose(f.position[2], right_hand(t_src), atol=1e-9)


def test_a_missing_site_has_no_position():
    hub = Hub({"vr": _rig()}, latency=0.0, staleness=0.03, fill_gap=0.03, max_backlog=5,
              interpolation=Interpolation(slerp_unit, max_gap=0.03))
    frames = feed(hub, drop_hand=(1.5, 1.8))
    gone = [f for f in frames if 1.55 < f.t < 1.75]
    assert gone and all(not f.present[1] and np.isnan(f.position[1]).all() for f in gone)
    assert all(f.present[0] and np.isfinite(f.position[0]).all() for f in gone)
    back = [f for f in frames if f.t > 1.9]
    assert back and all(np.isfinite(f.position).all() for f in back)


def test_a_hub_without_tracked_devices_gives_no_positions():
    hub = Hub({"l_shank": _imu()}, latency=0.0, max_backlog=5)
    hub.poll(now=1.0)
    for k in range(90):
        hub.push("l_shank", _imu_sample(1.0 + k / RATE))
    hub.poll(now=1.0)
    frames = hub.poll(now=1.9)
    assert frames and all(f.position is None for f in frames)
