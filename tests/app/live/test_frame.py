"""The typed live frame: its named fields, what an absent input leaves (NaN, no flag), and that
the optional inputs write only their own field at the one stage that builds the frame."""

from __future__ import annotations

import dataclasses

import numpy as np

from app.live.frame import LIVE_FRAME, FrameBuilder, InsoleInput, empty_frame, observation
from app.live.tracked import RigPoints
from inference.body.skeleton import SITE_INDEX
from inference.features.layout import SL_CONTACT
from tests.app.rig_frames import SITES, rig_walk


def test_the_frame_has_named_fields_and_nothing_observed_when_empty():
    assert LIVE_FRAME.names == ("orientations", "accelerations", "flags", "contacts", "positions")
    f = empty_frame()
    assert not f["flags"].any()
    for name in ("orientations", "accelerations", "contacts", "positions"):
        assert np.isnan(f[name]).all(), name
    obs = observation(f)
    assert not obs.mask.any() and obs.points is None and not obs.insoles


def test_each_input_writes_its_own_field_once():
    rig = rig_walk(seconds=0.5)
    hub = rig.frames[10]
    hub = dataclasses.replace(hub, insole_present=True, contacts=np.array([1, 0, 0, 1], bool))
    active = np.ones(len(SITES), bool)
    bare = FrameBuilder(SITES).build(hub, rig.calibration, active)
    assert bare["flags"][[SITE_INDEX[s] for s in SITES]].all() and bare["flags"].sum() == len(SITES)
    assert np.isnan(bare["contacts"]).all() and np.isnan(bare["positions"]).all()

    insoles = InsoleInput(enabled=True)
    full = FrameBuilder(SITES, [insoles, RigPoints(SITES)]).build(hub, rig.calibration, active)
    np.testing.assert_array_equal(full["orientations"], bare["orientations"])
    np.testing.assert_array_equal(full["contacts"], [1.0, 0.0, 0.0, 1.0])
    assert np.isfinite(full["positions"][:3]).all() and np.isnan(full["positions"][3]).all()  # no waist tracker
    obs = observation(full)
    assert obs.insoles and obs.mask[SL_CONTACT].all() and obs.points is not None

    insoles.enabled = False  # the pipeline's insoles switched off live
    off = FrameBuilder(SITES, [insoles]).build(hub, rig.calibration, active)
    assert np.isnan(off["contacts"]).all()

    some = active.copy()
    some[SITES.index("head")] = False
    part = FrameBuilder(SITES).build(hub, rig.calibration, some)
    assert not part["flags"][SITE_INDEX["head"]] and np.isnan(part["orientations"][SITE_INDEX["head"]]).all()
