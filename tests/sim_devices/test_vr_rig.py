"""The simulated VR rig: where it puts the devices on the body, and the rig in its own
process sending VMC device messages to a ``vmc-in://`` device on loopback, watched by strace."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from app.capture.twins import free_udp_port
from drivers import open_device
from inference.body.rotations import quat_angle_between, quat_to_matrix
from inference.body.skeleton import SEGMENT_INDEX
from sim_devices.devices.vr_rig import (
    EYE_HEIGHT_RATIO,
    GRIP_PITCH_DEG,
    TrackedSource,
    TrackingNoise,
    tracked_points,
)
from sim_devices.motions import generate
from sim_devices.vr_rig_process import load_rig_motion
from tests.socket_watch import STRACE, off_machine, watched

SITES = ("head", "l_hand", "r_hand", "pelvis")
SERIALS = {"head": "SIM-HMD", "l_hand": "SIM-CON-L", "r_hand": "SIM-CON-R", "pelvis": "SIM-TRK-WAIST"}


def test_devices_sit_where_a_wearer_carries_them():
    m = generate("stand", height=1.6, seconds=2.0)
    pts = tracked_points(m, SITES)
    J = m.joints()
    head_z = pts["head"][0][:, 2]
    assert np.allclose(head_z, EYE_HEIGHT_RATIO * 1.6, atol=0.02)  # standing headset height gives the body height
    for side in ("l_hand", "r_hand"):
        P, Q = pts[side]
        d = np.linalg.norm(P - J[:, SEGMENT_INDEX[side]], axis=-1)
        assert np.all((d > 0.03) & (d < 0.10))  # in the fist, beyond the wrist joint
        # the grip's rotation is the hand's turned by the grip pitch
        rel = np.swapaxes(m.rot[:, SEGMENT_INDEX[side]], -1, -2) @ quat_to_matrix(Q)
        ang = np.degrees(np.arccos(np.clip((np.trace(rel, axis1=-2, axis2=-1) - 1) / 2, -1, 1)))
        np.testing.assert_allclose(ang, GRIP_PITCH_DEG, atol=1e-6)
    assert np.allclose(pts["l_hand"][0][:, 1], -pts["r_hand"][0][:, 1], atol=0.02)  # mirrored
    assert np.linalg.norm(pts["pelvis"][0] - J[:, 0], axis=-1).max() < 0.15
    src = TrackedSource(m, SITES)
    p_half, _ = src.at(0.5 / m.fps)["head"]
    np.testing.assert_allclose(p_half, 0.5 * (pts["head"][0][0] + pts["head"][0][1]), atol=1e-12)


def _truth_at(truth, site: str, t: np.ndarray) -> np.ndarray:
    P = truth[f"{site}_pos"]
    return np.stack([np.interp(t, truth["t"], P[:, k]) for k in range(3)], axis=-1)


@pytest.mark.skipif(STRACE is None, reason="strace not installed (scripts/test.sh installs it)")
def test_rig_in_its_own_process_reaches_a_vmc_in_device(tmp_path):
    port = free_udp_port()
    query = "&".join(f"{s}={v}" for s, v in SERIALS.items())
    dev = open_device(f"vmc-in://127.0.0.1:{port}?{query}")
    truth_path, log = tmp_path / "truth.npz", tmp_path / "rig.strace"
    cmd = [sys.executable, "-m", "sim_devices.vr_rig_process", "--port", str(port), "--motion", "walk",
           "--seconds", "2", "--sites", ",".join(SITES), "--truth", str(truth_path), "--seed", "4"]
    got = []
    try:
        rig = subprocess.Popen(watched(cmd, log), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        while rig.poll() is None:
            got += dev.read_many(0.1)
        got += dev.read_many(0.3)
        out, err = rig.communicate(timeout=10)
    finally:
        dev.close()
    assert rig.returncode == 0, err
    lines = [json.loads(x) for x in out.splitlines() if x.startswith("{")]
    started, summary = lines[0], lines[-1]
    noise = TrackingNoise(**started["noise"])

    # every message sent was decoded, none was malformed or of a serial the URL does not name
    assert summary["sent"] > 100  # ~72 Hz for 2 s
    assert dev.stats.decoded == len(got) == summary["messages"] == 4 * summary["sent"]
    assert dev.stats.bad_frame == 0 and dev.unmapped == 0

    # nothing went anywhere but this machine
    away = off_machine(log.read_text())
    assert not away, "the rig sent off this machine: " + "; ".join(map(str, away[:5]))

    truth = np.load(truth_path)
    # the truth is the motion's: the same walk, rebuilt here, gives the same headset path
    again = tracked_points(load_rig_motion("walk", 2.0, 1.75, 4), ("head",))["head"][0]
    np.testing.assert_allclose(truth["head_pos"], again, atol=1e-9)

    head = [s for s in got if s.extra["site"] == "head"]
    t_sent = np.array([s.device_time for s in head])  # /VMC/Ext/T: the rig's session time at sending
    pos = np.array([s.extra["position"] for s in head])
    assert np.all(np.diff(t_sent) > 0)

    def rms(lag: float) -> float:
        return float(np.sqrt(np.mean(np.sum((pos - _truth_at(truth, "head", t_sent - lag)) ** 2, axis=-1))))

    err_m = rms(noise.latency_s)
    lags = np.arange(0.0, 0.0405, 0.0025)
    best = float(lags[int(np.argmin([rms(x) for x in lags]))])
    print(f"head: {len(head)} poses, RMS error after the {noise.latency_s * 1e3:.0f} ms latency "
          f"{err_m * 1e3:.2f} mm (stated {noise.position_rms_3d_m * 1e3:.2f} mm), without it {rms(0.0) * 1e3:.2f} mm, "
          f"best-fitting lag {best * 1e3:.1f} ms")
    assert noise.jitter_m * 1.0 < err_m < 2.0 * noise.position_rms_3d_m  # noise there, and no more than stated
    assert abs(best - noise.latency_s) <= 0.005  # the poses lag the body by the stated latency
    assert rms(0.0) > err_m  # walking at ~1.3 m/s, 15 ms is ~2 cm: the lag is real

    # orientation: within the stated jitter of the clean orientation at the same instant
    Q = truth["head_quat"]
    k = np.clip(np.round((t_sent - noise.latency_s) * float(truth["fps"])).astype(int), 0, len(Q) - 1)
    ang = np.degrees(quat_angle_between(np.array([s.quat for s in head]), Q[k]))
    print(f"head orientation error: mean {ang.mean():.2f} deg, p95 {np.percentile(ang, 95):.2f} deg")
    maxwell_mean = 2 * noise.jitter_deg * np.sqrt(2 / np.pi)  # mean angle of a 3-axis Gaussian turn
    assert 0.5 * maxwell_mean < np.mean(ang) < 2 * maxwell_mean

    for side in ("l_hand", "r_hand", "pelvis"):
        ss = [s for s in got if s.extra["site"] == side]
        p = np.array([s.extra["position"] for s in ss])
        t = np.array([s.device_time for s in ss]) - noise.latency_s
        e = np.sqrt(np.mean(np.sum((p - _truth_at(truth, side, t)) ** 2, axis=-1)))
        assert e < 2.0 * noise.position_rms_3d_m, f"{side}: {e * 1e3:.1f} mm"
