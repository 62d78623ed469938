"""`imucap bench --end-to-end`: sensor-to-pose latency of the live path, per latency mode
(``app.live.latency``), measured in one run so both modes share the machine's load.

What is timed: from the moment a sample's packet leaves its simulated device (the device
logs the monotonic time right after writing each packet to its transport, by packet
counter: ``SimDevice.log_sends``) to the moment the pose it went into is handed to the
pipeline's sinks. For each pose the sample is the *newest* one that went into it: the hub
frame that completed the pose says, per site, which sample it used last (``HubFrame.
sample_t`` / ``sample_counter``), and the newest of those is matched back to the device's
send log through its wire counter. Everything between is the real thing: the demo's
simulated suit over its real transports (ptys for Xbus at 100 Hz), the drivers, the hub,
calibration, the resampler, the poser with the shipped model, the sinks.

Also reported per mode: ``age``, from the time the pose stands for (its 20 Hz frame's grid
time on the session clock, which the hub's clock fit puts at the sample's send time plus
the transport's least delay) to the same emission: the centred moving average's look-ahead
shows here, not in the newest-sample figure, because the newest sample of a centred pose is
the one 5 samples *after* the time it stands for. And ``model``: the poser's time per frame.

Rounds alternate the modes (centred, low, centred, low, ...), each a fresh session
(calibration included, not timed), so a load change during the run hits both.

Each round is an ``imucap demo`` session (``app.capture.demo``): the devices live in another
process (``imucap devices simulate --setup``, its send log written to a file on exit; the
monotonic clock is the machine's, so the times compare), and this process runs the capture
session that opens their URLs and calibrates with the guided walk, as a user has it.
"""

from __future__ import annotations

import os
import tempfile
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.capture.setup_file import DEFAULT_MODEL
from app.live import LivePose, Sink

WARMUP_POSES = 20  # the first poses after calibration also pay for the model's first calls
# a round runs past its seconds until this many poses after the warm-up (at most
# POSE_PATIENCE_S more): a busy machine makes fewer poses a second, and a round with none
# timed says nothing about latency
MIN_TIMED_POSES = 10
POSE_PATIENCE_S = 60.0


@dataclass
class _PoseRecord:
    emitted: float  # monotonic
    site: str  # the site whose sample was the newest in the pose
    counter: int  # its wire packet counter
    age_ms: float  # emission minus the pose's own grid time (session clock = monotonic)


@dataclass
class LatencyProbe(Sink):
    """Notes, for every pose, when it left and which sample was the newest in it. Must be
    the pipeline's first sink, so that the emission time is taken before any other sink's
    work."""

    sites: tuple[str, ...]
    records: list[_PoseRecord] = field(default_factory=list)
    unmatched: int = 0
    _frames: deque = field(default_factory=lambda: deque(maxlen=4))

    def on_frame(self, frame) -> None:
        self._frames.append(frame)

    def on_pose(self, pose: LivePose) -> None:
        now = time.monotonic()
        frame = self._frames[-1] if self._frames else None
        if frame is None or frame.sample_t is None or frame.sample_counter is None:
            self.unmatched += 1
            return
        st = np.where(frame.present, frame.sample_t, np.nan)
        if not np.isfinite(st).any():
            self.unmatched += 1  # a pose completed by a frame filled in for a gap
            return
        k = int(np.nanargmax(st))
        c = frame.sample_counter[k]
        if not np.isfinite(c):
            self.unmatched += 1
            return
        self.records.append(_PoseRecord(now, self.sites[k], int(c), (now - pose.t) * 1e3))


def _send_time(log: list[tuple[int, float]], counter: int, modulus: int | None, before: float) -> float | None:
    """Send time of the packet with wire counter ``counter`` that left last before ``before``
    (counters wrap: at 100 Hz an 8-bit one every 2.56 s)."""
    if not log:
        return None
    sends = np.fromiter((s for _, s in log), float, len(log))
    i = int(np.searchsorted(sends, before, side="right")) - 1
    while i >= 0:
        full, t = log[i]
        if (full % modulus if modulus else full) == counter:
            return t
        i -= 1
        if before - sends[i + 1] > 5.0:
            break
    return None


def _pct(values: list[float], q: float) -> float | None:
    return round(float(np.percentile(values, q)), 2) if values else None


def _summarise(mode: str, probe: LatencyProbe, logs: dict[str, list[tuple[int, float]]], hub: Any, stats: Any,
               causal: bool, model_label: str, runtime: str, warning: str | None) -> dict[str, Any]:
    """Per pose after the warm-up: newest sample's send (from the device's log) -> emission."""
    moduli = {site: hub.tracks[site].device.counter_modulus for site in probe.sites}
    e2e, age, missing = [], [], 0
    for rec in probe.records[WARMUP_POSES:]:
        sent = _send_time(logs[rec.site], rec.counter, moduli[rec.site], rec.emitted)
        if sent is None:
            missing += 1
            continue
        e2e.append((rec.emitted - sent) * 1e3)
        age.append(rec.age_ms)
    return {
        "mode": mode, "e2e_ms": e2e, "age_ms": age, "model_ms": list(stats.step_ms)[WARMUP_POSES:],
        "poses": len(probe.records), "timed": len(e2e), "unmatched": probe.unmatched + missing,
        "dropped": stats.dropped, "hub_frames_skipped": hub.stats.frames_skipped, "hub_wait_ms": hub.latency * 1e3,
        "acc_filter": "causal" if causal else "centred", "model": model_label,
        "runtime": runtime, "warning": warning,
    }


def _read_send_logs(path: str, names: tuple[str, ...]) -> dict[str, list[tuple[int, float]]]:
    with np.load(path) as z:
        return {n: list(zip(z[f"{n}/counter"].tolist(), z[f"{n}/t"].tolist())) for n in names}


def measure_mode(mode: str, seconds: float, model: str = DEFAULT_MODEL, sensors: tuple[str, ...] | None = None,
                 seed: int = 0, threads: int = 1) -> dict[str, Any]:
    """One demo session in ``mode`` (its Xbus devices in their own process): calibrate
    (the guided walk, untimed), then ``seconds`` timed."""
    from pathlib import Path

    from app.capture.demo import DEFAULT_SENSORS, DemoConfig, DemoRun, demo_spec

    sites = tuple(sensors or DEFAULT_SENSORS)
    cfg = DemoConfig(motion="walk", sensors=sites, protocol="xbus", seconds=seconds, model=model, seed=seed,
                     threads=threads, latency=mode)
    with tempfile.TemporaryDirectory(prefix="imucap-bench-") as folder:
        spec = demo_spec(cfg, folder=Path(folder))
        log_path = os.path.join(folder, "sends.npz")
        spec.simulator.args += ["--log-sends", log_path]
        spec.options.countdown = 1.0  # nobody to get into place
        demo = DemoRun(cfg, spec)
        probe = LatencyProbe(sites)
        demo.pipeline.sinks.insert(0, probe)  # first: the emission time before any other sink's work
        try:
            demo.start()
            if not demo.run_for(seconds, WARMUP_POSES + MIN_TIMED_POSES, timeout=seconds + POSE_PATIENCE_S) \
                    and demo.session.calibration is None:
                raise RuntimeError(f"the bench's capture did not calibrate: {demo.session.guided.status()}")
        finally:
            demo.stop()  # the simulator writes its send log on the way out
        logs = _read_send_logs(log_path, sites)
    s = demo.session
    assert s.hub is not None
    return _summarise(mode, probe, logs, s.hub, s.pipeline.stats, s.pipeline.causal, s.model_label,
                      s.poser.runtime, s.warning)


def run_end_to_end(seconds: float = 10.0, rounds: int = 2, model: str = DEFAULT_MODEL, seed: int = 0,
                   threads: int = 1, modes: tuple[str, ...] = ("centred", "low")) -> dict[str, Any]:
    """The `imucap bench --end-to-end` measurement; returns its JSON object: per mode
    ``<mode>_p50_ms``, ``<mode>_p99_ms`` (newest sample leaving its device -> pose to the
    sinks), ``<mode>_age_p50_ms``/``_p99_ms`` (from the time the pose stands for),
    ``<mode>_model_p50_ms``, and ``model_p50_ms``/``model_p99_ms`` over both modes."""
    import torch

    from app.live.latency import latency_settings

    for m in modes:
        latency_settings(m)
    if rounds < 1 or seconds <= 0:
        raise ValueError("--rounds must be at least 1 and --seconds positive")
    runs: dict[str, list[dict[str, Any]]] = {m: [] for m in modes}
    t0 = time.monotonic()
    for _ in range(rounds):
        for m in modes:
            runs[m].append(measure_mode(m, seconds, model, seed=seed, threads=threads))
    out: dict[str, Any] = {}
    all_model: list[float] = []
    for m, rs in runs.items():
        e2e = [v for r in rs for v in r["e2e_ms"]]
        age = [v for r in rs for v in r["age_ms"]]
        mod = [v for r in rs for v in r["model_ms"]]
        all_model += mod
        out.update({
            f"{m}_p50_ms": _pct(e2e, 50), f"{m}_p99_ms": _pct(e2e, 99),
            f"{m}_age_p50_ms": _pct(age, 50), f"{m}_age_p99_ms": _pct(age, 99),
            f"{m}_model_p50_ms": _pct(mod, 50), f"{m}_model_p99_ms": _pct(mod, 99),
            f"{m}_poses": sum(r["timed"] for r in rs), f"{m}_unmatched": sum(r["unmatched"] for r in rs),
            f"{m}_dropped": sum(r["dropped"] for r in rs),
            f"{m}_hub_frames_skipped": sum(r["hub_frames_skipped"] for r in rs),
            f"{m}_hub_wait_ms": rs[0]["hub_wait_ms"], f"{m}_acc_filter": rs[0]["acc_filter"],
            f"{m}_model": rs[0]["model"],
        })
    out["model_p50_ms"] = _pct(all_model, 50)
    out["model_p99_ms"] = _pct(all_model, 99)
    first = runs[modes[0]][0]
    warnings = sorted({r["warning"] for rs in runs.values() for r in rs if r["warning"]})
    out.update({
        "runtime": first["runtime"], "threads": torch.get_num_threads(), "protocol": "xbus", "suit": "process",
        "rounds": rounds, "seconds_per_round": seconds, "wall_s": round(time.monotonic() - t0, 1),
        "load_avg_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(),
        **({"warnings": warnings} if warnings else {}),
    })
    return out


__all__ = ["LatencyProbe", "measure_mode", "run_end_to_end"]
