"""The demo session: a simulated suit replaying a synthesized motion through the real
drivers and transports, calibrated from its own protocol and reconstructed live. What
`imucap demo` runs headless and the window drives; below both, so neither imports the
other."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app import APP_VERSION
from app.live import LivePipeline, LivePose, Pipeline, Sink, close_sink
from app.model_choice import choose_model, set_torch_threads
from app.replay import poser_metadata
from drivers.hub import Hub

FRAMES_PATIENCE = 20.0  # --frames: wait at most this many times --seconds for the poses

PROTOCOL_CHOICES = ("xbus", "bno08x-rvc", "xsens-can", "dualsense", "movella-dot", "ximu3", "mixed")


MIXED_ORDER = ("xbus", "xsens-can", "bno08x-rvc", "dualsense")


DEFAULT_SENSORS = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")  # the paper's six




SUIT_PLACES = ("process", "thread")


@dataclass
class DemoConfig:
    """Everything a demo session is made of (the CLI's options)."""

    motion: str = "walk"
    file: str | None = None
    sensors: tuple[str, ...] = DEFAULT_SENSORS
    insoles: bool = False
    protocol: str = "xbus"
    seconds: float = 20.0
    frames: int = 0  # headless: run on past ``seconds`` until this many poses (run_for)
    model: str = "diffusion"
    steps: str | None = None
    seed: int = 0
    record: str | None = None
    noise: bool = True
    headless: bool = True
    threads: int = 1  # one window per step: 1 intra-op thread is fastest and leaves a core to the drivers/GUI
    latency: str = "centred"  # app.latency.LATENCY_MODES: "low" waits for no future sample
    runtime: str = "auto"  # the live model call: ONNX Runtime when installed (faster), else torch
    confidence: bool = False  # each pose with its per-segment spread (inference/poser/confidence.py)
    # where the simulated suit runs: "process", a child process as real sensors are outside
    # imucap (sim_devices/suit_process.py), or "thread", inside this one (its packet writing
    # then competes with the model for the interpreter)
    suit: str = "process"
    calibration_protocol: Any = None  # a calibration.Protocol overriding the default timings
    # sinks streaming the body to other programs (--stream: app.streams.make_stream_sinks builds
    # them, above this module); the session adds them to its pipeline, which closes them
    streams: list[Any] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)


def assignment_for(sensors: tuple[str, ...], protocol: str, insoles: bool) -> dict[str, str]:
    """Site -> protocol for the simulated suit (``mixed``: protocols in turn)."""
    if protocol not in PROTOCOL_CHOICES:
        raise ValueError(f"unknown protocol {protocol!r}; choose from {', '.join(PROTOCOL_CHOICES)}")
    out = {s: (MIXED_ORDER[k % len(MIXED_ORDER)] if protocol == "mixed" else protocol)
           for k, s in enumerate(sensors)}
    if insoles:
        out["insoles"] = "moticon-udp"
    return out


def load_activity(cfg: DemoConfig, seconds: float):
    """The activity motion at 60 Hz facing +X at its start: generated, or read from a file."""
    from inference.evaluation.runner import face_forward

    if cfg.file:
        from inference.loaders import load_motion

        m = face_forward(load_motion(cfg.file)).resample(60.0)
        return m
    from sim_devices.motions import generate

    return generate(cfg.motion, seconds=max(seconds, 1.0), seed=cfg.seed)


class TruthSink(Sink):
    """Global angle error of each pose against the synthesized truth (the demo knows what
    the subject did), over the activity part of the session only (not the calibration)."""

    def __init__(self, truth, origin: float, activity_start: float) -> None:
        from inference.metrics.errors import global_angle_error

        self._ga = global_angle_error
        self.rot = truth.rot
        self.fps = truth.fps
        self.n = truth.n_frames
        self.origin = origin
        self.activity_start = activity_start
        self.duration = self.n / self.fps
        self.ga: list[float] = []

    def on_pose(self, pose: LivePose) -> None:
        tau = (pose.t - self.origin) % self.duration
        if tau < self.activity_start:
            return
        i = min(int(round(tau * self.fps)), self.n - 1)
        self.ga.append(float(self._ga(pose.pose.rot[None], self.rot[i:i + 1])[0]))


class LoopSink(Sink):
    """The simulated suit loops its clip (table, strap, T-pose, activity, table, ...): at
    every loop the pipeline calibrates again, as with a subject who re-dons the sensors."""

    def __init__(self, pipeline: Pipeline, origin: float, duration: float) -> None:
        self.pipeline, self.origin, self.duration = pipeline, origin, duration
        self.loops = 0

    def on_frame(self, frame) -> None:
        k = int((frame.t - self.origin) // self.duration)
        if k > self.loops:
            self.loops = k
            self.pipeline.recalibrate(self.origin + k * self.duration)


class DemoSession:
    """Builds and runs one demo: suit -> drivers -> hub -> pipeline (threads) -> sinks.

    ``start()`` returns at once (the session runs on its own threads); ``result()`` is the
    headless JSON object; ``stop()`` ends everything it started.
    """

    def __init__(self, cfg: DemoConfig) -> None:
        from calibration import Calibrator, Protocol, synthesize_session
        from inference.body.skeleton import parse_sites
        from inference.poser.poser import Poser
        from inference.signals.synthesis import NoiseModel

        self.cfg = cfg
        cfg.sensors = tuple(parse_sites(list(cfg.sensors)))
        if not cfg.sensors:
            raise ValueError("--sensors: give at least one site")
        if not cfg.seconds > 0:
            raise ValueError("--seconds must be positive")
        if cfg.suit not in SUIT_PLACES:
            raise ValueError(f"--suit must be one of {', '.join(SUIT_PLACES)}, not {cfg.suit!r}")
        set_torch_threads(cfg.threads)
        if cfg.calibration_protocol is not None:
            self.protocol = cfg.calibration_protocol
        else:
            self.protocol = Protocol.fitted(cfg.seconds) if cfg.headless else Protocol()
        activity_s = cfg.seconds - self.protocol.prefix + 2.0 if cfg.headless else cfg.seconds
        choice = choose_model(cfg.model, cfg.latency, fallback=True)
        self.model, self.model_label, self.causal, self.warning = (choice.model, choice.label, choice.causal,
                                                                   choice.warning)
        self.activity = load_activity(cfg, activity_s)
        sites = tuple(cfg.sensors)
        if cfg.insoles:
            sites += tuple(s for s in ("l_foot", "r_foot") if s not in sites)
        noise = NoiseModel.typical() if cfg.noise else None
        self.signals, self.truth = synthesize_session(self.activity, self.protocol, noise=noise, rng=cfg.seed,
                                                      sites=sites)
        self.assignment = assignment_for(cfg.sensors, cfg.protocol, cfg.insoles)
        # the poser keeps confidence for a diffusion model only (the others draw nothing)
        self.poser = Poser(self.model, body=self.truth.body, steps=cfg.steps, seed=cfg.seed, runtime=cfg.runtime,
                           confidence=cfg.confidence)
        self.calibrator = Calibrator(cfg.sensors, schedule=self.protocol.schedule())
        self.pipeline = Pipeline(self.poser, cfg.sensors, calibrator=self.calibrator, insoles=cfg.insoles,
                                 clock=time.monotonic, causal=self.causal)
        self.suit = None  # SimulatedSuit (suit "thread") or SuitProcess ("process")
        self.hub: Hub | None = None
        self.live: LivePipeline | None = None
        self.recorder = None
        self.origin = 0.0
        self.truth_sink: TruthSink | None = None
        self.calibrated_at: float | None = None
        self.started = False
        for sink in cfg.streams:
            self.pipeline.add_sink(sink)

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> DemoSession:
        import drivers
        from app.latency import hub_options
        from sim_devices.suit import SimulatedSuit
        from sim_devices.suit_process import SuitProcess

        if self.cfg.suit == "process":
            self.suit = SuitProcess(self.signals, self.assignment, seed=self.cfg.seed).start()
            t0s = list(self.suit.t0s.values())
        else:
            self.suit = SimulatedSuit(self.signals, self.assignment, seed=self.cfg.seed).start()
            t0s = [d.sim.started_at for d in self.suit.devices.values()]
        self.started = True
        # the clip's time zero on the session clock (each twin starts its clock as it starts;
        # CLOCK_MONOTONIC is one clock for every process of the machine)
        self.origin = float(np.mean(t0s)) if t0s else time.monotonic()
        self.calibrator.reset(self.origin)
        self.truth_sink = TruthSink(self.truth, self.origin, self.signals.meta["activity_start"])
        self.pipeline.add_sink(self.truth_sink)
        self.pipeline.add_sink(CalibrationWatch(self))
        if not self.cfg.headless:
            self.pipeline.add_sink(LoopSink(self.pipeline, self.origin, len(self.signals) / self.signals.fps))
        if self.cfg.record:
            self.start_recording(self.cfg.record)
        devices = {site: drivers.make_device(url) for site, url in self.suit.urls().items()}
        self.hub = Hub(devices, **hub_options(self.cfg.latency))
        self.hub.start()
        self.live = LivePipeline(self.pipeline, self.hub).start()
        return self

    def start_recording(self, path: str | Path):
        """Record from now on (a sink added on the pipeline thread)."""
        from app.recording import Recorder

        rec = Recorder(path, sites=self.cfg.sensors, metadata=self.metadata())
        self.recorder = rec
        if self.live is not None:
            self.live.call(lambda p: p.add_sink(rec))
        else:
            self.pipeline.add_sink(rec)
        return rec

    def stop_recording(self) -> Path | None:
        rec, self.recorder = self.recorder, None
        if rec is None:
            return None
        close_sink(self.live, self.pipeline, rec)
        return rec.path

    def stop(self) -> None:
        if self.live is not None:
            self.live.stop()
        if self.recorder is not None:
            self.stop_recording()
        if self.hub is not None:
            self.hub.stop()
        if self.suit is not None:
            self.suit.stop()
        self.pipeline.close()

    def __enter__(self) -> DemoSession:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def session_time(self) -> float:
        return time.monotonic() - self.origin

    def run_for(self, seconds: float, poses: int = 0, timeout: float | None = None) -> bool:
        """Block for ``seconds`` of session time (the pipeline runs on its threads), and on
        until ``poses`` poses were made, up to ``timeout`` s of session time in all (default
        FRAMES_PATIENCE times ``seconds``): a busy machine makes fewer poses a second, and a
        script that needs N of them gets them however slow it runs. False when the poses
        were not reached."""
        assert self.live is not None
        self.live.wait_for(lambda: self.session_time() >= seconds, seconds + 5.0)
        if poses > 0:
            limit = FRAMES_PATIENCE * seconds if timeout is None else timeout
            self.live.wait_for(lambda: self.pipeline.stats.poses >= poses, max(limit - self.session_time(), 0.0))
        if self.live.error is not None:
            raise RuntimeError(f"the pipeline stopped: {self.live.error!r}") from self.live.error
        return self.pipeline.stats.poses >= poses

    # ------------------------------------------------------------------ reporting
    def metadata(self) -> dict[str, Any]:
        c = self.cfg
        return {
            "app_version": APP_VERSION, "model": self.model_label,
            # how the poser ran, from the poser built: a replay with no options runs it so again
            **poser_metadata(self.poser, c.latency), "sensors": list(c.sensors), "insoles": c.insoles,
            "protocol": c.protocol,
            "assignment": self.assignment, "motion": c.file or c.motion, "seed": c.seed,
            "source": "imucap demo (simulated suit)", "body_height_m": float(self.truth.body.height),
            # the exact bones the poser used, so `imucap replay/export` rebuild the same body
            "body_offsets": np.round(self.truth.body.offsets, 6).tolist(),
        }

    def steps_count(self) -> int:
        p = self.poser
        return len(p.steps) if p.kind == "diffusion" else (1 if p.kind == "regressor" else 0)

    def sensor_status(self) -> dict[str, dict[str, Any]]:
        """Per site: protocol, packets, rate_hz, errors, gaps, battery."""
        if self.hub is None:
            return {}
        el = max(self.session_time(), 1e-6)
        out = {}
        for name, st in self.hub.status().items():
            st = dict(st)
            st["protocol"] = self.assignment.get(name, "")
            st["rate_hz"] = round(st["packets"] / el, 1)
            out[name] = st
        return out

    def calibration_error_deg(self) -> float | None:
        """Mean angle between the recovered sensor-to-bone rotations and the ones synthesis
        drew: a check of calibration *and* of every driver's frame conventions."""
        from inference.body.rotations import matrix_angle_between

        cal = self.pipeline.calibration
        if cal is None:
            return None
        sig_sites = list(self.signals.sites)
        idx = [sig_sites.index(s) for s in cal.sites]
        err = np.rad2deg(matrix_angle_between(cal.R_SB, self.signals.meta["R_SB"][idx]))
        return round(float(np.mean(err[cal.valid])), 3) if cal.valid.any() else None

    def result(self) -> dict[str, Any]:
        """The headless JSON object."""
        stats = self.pipeline.stats.summary()
        cal = self.pipeline.calibration
        ts = self._pose_times
        fps = (len(ts) - 1) / (ts[-1] - ts[0]) if len(ts) > 2 and ts[-1] > ts[0] else None
        ga = self.truth_sink.ga if self.truth_sink else []
        out: dict[str, Any] = {
            "frames": stats["poses"], "fps": None if fps is None else round(fps, 2),
            "latency_p50_ms": stats["latency_p50_ms"], "latency_p99_ms": stats["latency_p99_ms"],
            "compute_p50_ms": stats["compute_p50_ms"], "compute_p99_ms": stats["compute_p99_ms"],
            "step_p50_ms": stats["step_p50_ms"], "step_p99_ms": stats["step_p99_ms"],
            "sites": self.sensor_status(),
            "calibration_residual_deg": None if cal is None or cal.residual_deg is None else round(cal.residual_deg, 3),
            "calibration_error_deg": self.calibration_error_deg(),
            "calibration_status": self.pipeline.status,
            "calibrated_at_s": None if self.calibrated_at is None else round(self.calibrated_at, 3),
            "ga_deg": round(float(np.mean(ga)), 3) if ga else None, "ga_frames": len(ga),
            "model": self.model_label, "steps": self.steps_count(),
            "sensors": list(self.cfg.sensors), "insoles": self.cfg.insoles, "protocol": self.cfg.protocol,
            "motion": self.cfg.file or self.cfg.motion, "seconds": self.cfg.seconds, "suit": self.cfg.suit,
            "hub_frames": stats["frames_in"], "dropped": stats["dropped"], "poses_skipped": stats["poses_skipped"],
            "hub_frames_skipped": self.hub.stats.frames_skipped if self.hub else 0,
            "frames_filled": stats["frames_filled"], "resampler_restarts": stats["resampler_restarts"],
            "stride": self.pipeline.stride_status(),
        }
        if self.cfg.streams:
            out["streams"] = [s.summary() for s in self.cfg.streams if hasattr(s, "summary")]
        w = getattr(self, "_watch", None)
        if self.poser.confidence is not None and w is not None and w.spread_n:
            from inference.body.skeleton import SEGMENTS

            out["spread_mean_deg"] = {s: round(float(v), 2) for s, v in zip(SEGMENTS, w.spread_sum / w.spread_n)}
        out["latency_mode"] = self.cfg.latency
        out["runtime"] = self.poser.runtime
        out["acc_filter"] = "causal" if self.pipeline.causal else "centred"
        if self.warning:
            out["warning"] = self.warning
        if self.recorder is not None or self.cfg.record:
            out["record"] = str(self.cfg.record)
        return out

    @property
    def _pose_times(self) -> list[float]:
        w = getattr(self, "_watch", None)
        return w.times if w is not None else []


class CalibrationWatch(Sink):
    """Notes when calibration took effect, the wall time of every pose (for fps) and the
    per-segment spread when the poses carry one."""

    def __init__(self, session: DemoSession) -> None:
        self.session = session
        self.times: list[float] = []
        self.spread_sum = np.zeros(24)
        self.spread_n = 0
        session._watch = self

    def on_calibration(self, calibration, t: float) -> None:
        self.session.calibrated_at = t - self.session.origin

    def on_pose(self, pose: LivePose) -> None:
        self.times.append(time.monotonic())
        spread = pose.pose.spread_deg
        if spread is not None and np.all(np.isfinite(spread)):
            self.spread_sum += spread
            self.spread_n += 1
