"""`imucap demo`: a capture session of a simulated setup, plus what only a simulation knows.

The demo is not a pipeline of its own. ``demo_spec`` turns the demo's options into what any
capture is made of (a setup whose URLs are simulated devices, the capture options, and the
simulated subject who wears them in a process of its own), and both front ends run exactly
that: the window through ``LiveSession`` (``app.gui.main_window.start_demo``), headless
through ``DemoRun`` here. Both calibrate with the guided steps of the setup's protocol
(the walk), as a user with real sensors does.

What a simulation adds is the truth: the simulator writes the motion it played and the
straps it drew (``--truth``), and ``DemoRun`` scores the live poses against it (``ga_deg``)
and the recovered sensor-to-bone rotations against the drawn ones
(``calibration_error_deg``, a check of calibration and of every driver's frame conventions).
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.capture.session import CaptureOptions, CaptureSession, session_spec
from app.capture.setup_file import DEFAULT_MODEL, Setup
from app.capture.simulate import Truth, read_truth
from app.capture.simulator_process import SimulatorProcess
from app.capture.twins import simulated_setup
from app.live import LivePose, Sink

FRAMES_PATIENCE = 20.0  # --frames: wait at most this many times --seconds for the poses
CALIBRATION_PATIENCE_S = 90.0  # headless: the guided calibration must be done by then
PROTOCOL_CHOICES = ("xbus", "bno08x-rvc", "xsens-can", "dualsense", "movella-dot", "ximu3", "mixed")
DEFAULT_SENSORS = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")  # the paper's six
LEAD_IN_S = 4.0  # the simulated subject stands this long before the protocol: the capture opens its devices
COUNTDOWN_S = 3.0  # before the first calibration step, as for a person in front of the window


@dataclass
class DemoConfig:
    """Everything a demo is made of (the CLI's options)."""

    motion: str = "walk"
    file: str | None = None
    sensors: tuple[str, ...] = DEFAULT_SENSORS
    insoles: bool = False
    protocol: str = "xbus"
    seconds: float = 20.0  # the activity after the calibration (the simulated subject's clip, looped)
    frames: int = 0  # headless: run on past ``seconds`` until this many poses (DemoRun.run_for)
    model: str = DEFAULT_MODEL
    steps: str | None = None
    seed: int = 0
    record: str | None = None
    noise: bool = True
    headless: bool = True
    threads: int = 1  # one window per step: 1 intra-op thread is fastest and leaves a core to the devices/GUI
    latency: str = "centred"  # app.live.latency.LATENCY_MODES: "low" waits for no future sample
    confidence: bool = False  # each pose with its per-segment spread (inference/poser/confidence.py)
    # sinks streaming the body to other programs (--stream: app.streams builds them); the
    # session adds them to its pipeline, which closes them
    streams: list[Any] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass
class DemoSpec:
    """What a demo runs: the setup and options of its capture, and its simulator."""

    setup: Setup
    options: CaptureOptions
    simulator: SimulatorProcess
    truth_path: Path | None = None

    def describe(self) -> dict[str, Any]:
        """The spec as plain data, without what differs between two builds of the same demo
        (temporary folders, free ports): for comparing front ends and for logs."""
        return {"session": session_spec(self.setup, self.options), "simulator": self.simulator.spec()}


def check_config(cfg: DemoConfig) -> None:
    from inference.body.skeleton import parse_sites
    from sim_devices.motions import KINDS

    cfg.sensors = tuple(parse_sites(list(cfg.sensors)))
    if not cfg.sensors:
        raise ValueError("--sensors: give at least one site")
    if not cfg.seconds > 0:
        raise ValueError("--seconds must be positive")
    if cfg.protocol not in PROTOCOL_CHOICES:
        raise ValueError(f"unknown protocol {cfg.protocol!r}; choose from {', '.join(PROTOCOL_CHOICES)}")
    if cfg.file is None and cfg.motion not in KINDS:
        raise ValueError(f"unknown motion {cfg.motion!r}; known: {', '.join(KINDS)}")
    if cfg.file is not None and not Path(cfg.file).exists():
        raise FileNotFoundError(f"motion file {cfg.file} not found")


def demo_spec(cfg: DemoConfig, folder: Path | None = None) -> DemoSpec:
    """The demo's capture: every front end builds its session from this and nothing else.
    ``folder`` holds the simulated devices' files and the truth (default: a new temporary
    folder)."""
    check_config(cfg)
    folder = Path(folder or tempfile.mkdtemp(prefix="imucap-demo-"))
    setup = simulated_setup(tuple(cfg.sensors), cfg.protocol, cfg.insoles, folder=folder, model=cfg.model,
                            steps=cfg.steps, recordings=Path("recordings").resolve())
    options = CaptureOptions(record=Path(cfg.record) if cfg.record else None, sinks=list(cfg.streams),
                             threads=cfg.threads, latency=cfg.latency, confidence=cfg.confidence,
                             countdown=COUNTDOWN_S,
                             metadata={"source": "imucap demo (simulated devices)", "motion": cfg.file or cfg.motion,
                                       "protocol": cfg.protocol, "seed": cfg.seed})
    truth = folder / "truth.npz"
    sim = SimulatorProcess(setup, cfg.file or cfg.motion, seconds=cfg.seconds, seed=cfg.seed, noise=cfg.noise,
                           lead_in=LEAD_IN_S, args=["--truth", str(truth)])
    return DemoSpec(setup, options, sim, truth)


class TruthSink(Sink):
    """The live poses against the motion the simulator played, over its activity (not the
    calibration before it) and its first pass (the clip loops; a recalibration would be
    needed to compare a second pass, whose session times the file does not give)."""

    def __init__(self) -> None:
        self.truth: Truth | None = None
        self.t: list[float] = []
        self.R: list[np.ndarray] = []

    def on_pose(self, pose: LivePose) -> None:
        tr = self.truth
        if tr is None:
            return
        tau = pose.t - tr.t0
        if tr.activity_start <= tau < len(tr.rot) / tr.fps:
            self.t.append(pose.t)
            self.R.append(pose.pose.rot)

    def errors(self) -> dict[str, Any]:
        from app.replay import truth_errors

        if self.truth is None or not self.t:
            return {"ga_deg": None, "truth_frames": 0}
        return truth_errors(np.array(self.t), np.stack(self.R), self.truth)


class _Spread(Sink):
    """The mean per-segment spread over the poses that carry one (``--confidence``)."""

    def __init__(self) -> None:
        self.sum = np.zeros(24)
        self.n = 0

    def on_pose(self, pose: LivePose) -> None:
        s = pose.pose.spread_deg
        if s is not None and np.all(np.isfinite(s)):
            self.sum += s
            self.n += 1


class DemoRun:
    """The headless demo: the spec's simulator, then its capture session, with the truth.

    ``start()`` returns once the devices are open (the session runs on its threads);
    ``run_for`` waits for the calibration and the activity; ``result()`` is the JSON object
    of ``imucap demo --headless``; ``stop()`` ends the session and the simulator."""

    def __init__(self, cfg: DemoConfig, spec: DemoSpec | None = None) -> None:
        self.cfg = cfg
        self.spec = spec or demo_spec(cfg)
        self.truth_sink = TruthSink()
        self.spread = _Spread()
        self.spec.options.sinks = [*self.spec.options.sinks, self.truth_sink, self.spread]
        self.session = CaptureSession(self.spec.setup, self.spec.options)
        self.warning = self.session.warning
        self.model_label = self.session.model_label
        self.started_at: float | None = None
        self.calibrated_at: float | None = None

    @property
    def pipeline(self):
        return self.session.pipeline

    def start(self) -> DemoRun:
        sim = self.spec.simulator
        try:
            # the model's first call (seconds on a busy machine) before the simulated subject's
            # clock starts: done after it, it ate the lead-in, and the guided N-pose ran into the walk
            self.session.pipeline.warm_up()
            sim.start()
            if self.spec.truth_path is not None:
                self.truth_sink.truth = read_truth(self.spec.truth_path)
            self.started_at = time.monotonic()
            self.session.start()
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self) -> None:
        try:
            self.session.stop()
        finally:
            self.spec.simulator.stop()

    def __enter__(self) -> DemoRun:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def session_time(self) -> float:
        return 0.0 if self.started_at is None else time.monotonic() - self.started_at

    def run_for(self, seconds: float, poses: int = 0, timeout: float | None = None) -> bool:
        """Wait for the calibration (at most CALIBRATION_PATIENCE_S), then ``seconds`` of
        activity, and on until ``poses`` poses were made, up to ``timeout`` s more in all
        (default FRAMES_PATIENCE times ``seconds``): a busy machine makes fewer poses a
        second, and a script that needs N of them gets them however slow it runs. False
        when the calibration failed or the poses were not reached."""
        s = self.session
        end = time.monotonic() + CALIBRATION_PATIENCE_S
        while s.calibration is None and time.monotonic() < end and s.guided.phase != "failed":
            self._check()
            s.poll()
            time.sleep(0.05)
        if s.calibration is None:
            return False
        self.calibrated_at = self.session_time()
        self._wait(lambda: False, seconds)
        if poses > 0:
            limit = FRAMES_PATIENCE * seconds if timeout is None else timeout
            self._wait(lambda: s.watch.poses >= poses, max(limit - seconds, 0.0))
        return s.watch.poses >= poses

    def _wait(self, done, seconds: float) -> None:
        end = time.monotonic() + seconds
        while not done() and time.monotonic() < end:
            self._check()
            self.session.poll()
            time.sleep(min(0.1, max(end - time.monotonic(), 0.0)))

    def _check(self) -> None:
        live = self.session.live
        if live is not None and live.error is not None:
            raise RuntimeError(f"the pipeline stopped: {live.error!r}") from live.error
        if not self.spec.simulator.running:
            raise RuntimeError(f"the simulated devices stopped: {self.spec.simulator.last_error()}")

    # ------------------------------------------------------------------ reporting
    def calibration_error_deg(self) -> float | None:
        """Mean angle between the recovered sensor-to-bone rotations and the ones the
        simulator drew."""
        by_site = self.calibration_error_by_site()
        return None if not by_site else round(float(np.mean(list(by_site.values()))), 3)

    def calibration_error_by_site(self) -> dict[str, float]:
        """Each calibrated sensor's angle between its recovered sensor-to-bone rotation and the
        one the simulator drew (deg): which sensor a poor calibration is about."""
        from inference.body.rotations import matrix_angle_between

        cal, tr = self.session.calibration, self.truth_sink.truth
        if cal is None or tr is None or tr.R_SB is None or not cal.valid.any():
            return {}
        idx = [list(tr.sites).index(s) for s in cal.sites]
        err = np.rad2deg(matrix_angle_between(cal.R_SB, tr.R_SB[idx]))
        return {s: round(float(e), 3) for s, e, ok in zip(cal.sites, err, cal.valid) if ok}

    def result(self) -> dict[str, Any]:
        """The headless JSON object: the capture's result, then what the truth says."""
        cfg, s = self.cfg, self.session
        res = s.result()
        st = s.pipeline.stats.summary()
        cal = s.calibration
        el = max(time.monotonic() - s.started_at, 1e-6) if s.started_at is not None else 1e-6
        protocols = {site: url.split(":", 1)[0] for site, url in self.spec.setup.urls().items()}
        sites = {name: {**dev, "protocol": protocols.get(name, ""), "rate_hz": round(dev.get("packets", 0) / el, 1)}
                 for name, dev in res.pop("devices").items()}
        truth = self.truth_sink.errors()
        p = s.poser
        out: dict[str, Any] = {
            "frames": res["frames"], "fps": res["fps"] or None,
            "latency_p50_ms": res["latency_p50_ms"], "latency_p99_ms": res["latency_p99_ms"],
            "compute_p50_ms": st["compute_p50_ms"], "compute_p99_ms": st["compute_p99_ms"],
            "step_p50_ms": st["step_p50_ms"], "step_p99_ms": st["step_p99_ms"],
            "sites": sites, "calibrated": res["calibrated"], "calibration_status": res["calibration_status"],
            "calibration_residual_deg": None if cal is None or cal.residual_deg is None else round(cal.residual_deg, 3),
            "calibration_error_deg": self.calibration_error_deg(),
            "calibration_error_by_site": self.calibration_error_by_site(),
            "calibrated_at_s": None if self.calibrated_at is None else round(self.calibrated_at, 3),
            "ga_deg": truth.get("ga_deg"), "ga_frames": truth.get("truth_frames", 0),
            "model": s.model_label, "steps": len(p.steps) if p.kind == "diffusion" else int(p.kind == "regressor"),
            "sensors": list(cfg.sensors), "insoles": cfg.insoles, "protocol": cfg.protocol,
            "motion": cfg.file or cfg.motion, "seconds": cfg.seconds, "suit": "process",
            "hub_frames": st["frames_in"], "dropped": st["dropped"], "poses_skipped": st["poses_skipped"],
            "hub_frames_skipped": s.hub.stats.frames_skipped if s.hub else 0,
            "hub": None if s.hub is None else s.hub.wait_status(),
            "frames_filled": st["frames_filled"], "resampler_restarts": st["resampler_restarts"],
            "stride": s.pipeline.stride_status(), "latency_mode": cfg.latency, "runtime": p.runtime,
            "acc_filter": "causal" if s.pipeline.causal else "centred",
            "events": res["events"], "spec": self.spec.describe(),
        }
        if res.get("advice"):
            out["advice"] = res["advice"]
        if cfg.streams:
            out["streams"] = [k.summary() for k in cfg.streams if hasattr(k, "summary")]
        if p.confidence is not None and self.spread.n:
            from inference.body.skeleton import SEGMENTS

            out["spread_mean_deg"] = {g: round(float(v), 2) for g, v in zip(SEGMENTS, self.spread.sum / self.spread.n)}
        if self.warning:
            out["warning"] = self.warning
        if cfg.record:
            out["record"] = str(cfg.record)
        if res.get("recording_error"):
            out["recording_error"] = res["recording_error"]
        return out


__all__ = ["DEFAULT_SENSORS", "FRAMES_PATIENCE", "PROTOCOL_CHOICES", "DemoConfig", "DemoRun", "DemoSpec",
           "TruthSink", "demo_spec"]
