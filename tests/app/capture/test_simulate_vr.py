"""`imucap devices simulate --setup` serving a VR rig (``[tracked]`` vmc-in URL) beside an
IMU, from one motion and one clock, in its own process: the rig's poses reach a hub in
this process in the rig's own frame, in step with the truth the simulator wrote."""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from app.capture.setup_file import load_setup
from app.capture.simulate import VR_FRAME_ORIGIN, VR_FRAME_YAW_DEG, read_truth
from app.capture.simulator_process import SimulatorProcess
from app.capture.twins import free_udp_port
from drivers import make_device
from drivers.hub import Hub
from inference.body.body import Body
from inference.body.motion import Motion
from inference.body.rotations import axis_angle_to_matrix, matrix_angle_between, quat_to_matrix
from inference.body.skeleton import SITE_INDEX, SITE_SEGMENT_INDEX
from sim_devices.devices.vr_rig import tracked_points


def test_the_rig_is_served_from_the_truths_motion_in_its_own_frame(tmp_path):
    port = free_udp_port()
    setup_path = tmp_path / "vr.toml"
    setup_path.write_text(f"""[subject]
id = "sim-vr"
height = 1.75

[sensors]
l_shank = "xbus://{tmp_path}/l_shank-tty?baud=115200"

[tracked]
vr = "vmc-in://127.0.0.1:{port}?head=HMD&l_hand=CL&r_hand=CR"
""")
    setup = load_setup(setup_path)
    truth_path = tmp_path / "truth.npz"
    got: list = []
    frames: list = []
    with SimulatorProcess(setup_path, "walk", seconds=6.0, lead_in=1.0, args=["--truth", str(truth_path)]) as sim:
        assert set(sim.urls) == {"l_shank", "vr"}
        hub = Hub({n: make_device(u) for n, u in setup.urls().items()}, latency=0.08)
        assert hub.sites == setup.sites() == ("l_shank", "head", "l_wrist", "r_wrist")
        hub.start()
        try:
            end = time.monotonic() + 30.0  # a deadline far past the 2 s wanted
            while time.monotonic() < end and len(frames) < 150:
                frames += hub.poll()
                time.sleep(0.02)
            got = [s for s in hub.tracks["vr"].ring.rows(-np.inf)]  # every vr sample held
        finally:
            hub.stop()
    assert len(frames) >= 150
    present = np.array([f.present for f in frames[30:]])
    assert present.mean(axis=0).min() > 0.7, present.mean(axis=0)  # a busy machine delays some samples
    assert len(got) > 100

    truth = read_truth(truth_path)
    assert truth.sites == setup.sites() and truth.R_SB is not None
    body = dataclasses.replace(Body.from_height(truth.height), offsets=truth.offsets)
    motion = Motion(rot=truth.rot, root=truth.root, fps=truth.fps, body=body)
    clean = tracked_points(motion, ("head",))["head"]
    # the rig's frame: turned by VR_FRAME_YAW_DEG about the vertical, its origin moved
    Rz = axis_angle_to_matrix(np.array([0.0, 0.0, -math.radians(VR_FRAME_YAW_DEG)]))
    head_vr = (clean[0] - np.asarray(VR_FRAME_ORIGIN)) @ Rz.T
    # the hub's head quaternion against the truth's head segment turned into the rig's frame
    hq = np.array([f.quat[1] for f in frames[30:] if f.present[1]])
    ht = np.array([f.t for f in frames[30:] if f.present[1]])
    R_true = Rz @ truth.rot[truth.frame_at(ht - 0.015), SITE_SEGMENT_INDEX[SITE_INDEX["head"]]]
    err = np.rad2deg(matrix_angle_between(quat_to_matrix(hq), R_true))
    print("head orientation error in the rig frame, deg p50 p90:", np.percentile(err, [50, 90]))
    assert np.median(err) < 3.0, np.percentile(err, [50, 90])
    # the head's height in the rig's frame is the truth's (the floor is shared)
    assert abs(np.median(head_vr[:, 2]) - 0.936 * 1.75) < 0.08
    # the IMU and the rig's implied channels both reach the frames (the subject stands in the
    # N-pose here: the head's implied free acceleration is the tracking noise's, ~1 m/s^2 at most)
    fa = np.array([f.free_acc for f in frames[30:]])
    assert np.isfinite(fa[:, 0]).mean() > 0.8 and np.isfinite(fa[:, 1]).mean() > 0.8
    head_fa = fa[np.isfinite(fa[:, 1, 0]), 1]
    assert np.median(np.linalg.norm(head_fa, axis=-1)) < 2.5
