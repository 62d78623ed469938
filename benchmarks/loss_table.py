"""What packet loss and sensor dropouts cost the reconstruction, measured end to end.

    .venv/bin/python benchmarks/loss_table.py [--clips N] [--json OUT.json] [--markdown]

For each clip of the held-out HDM05 actor dg: the clip is played forwards and backwards
until it lasts a session (``SESSION`` s; the clips are 0.6-5 s, a 10 s dropout needs
more), its signals synthesized with the evaluation's sensor noise, and six simulated
devices (Xbus, BNO08x RVC and Xsens CAN twins, two of each) sample it at 100 Hz and
encode every packet in their real wire format. Packets are lost in bursts
(Gilbert-Elliott, mean burst 3 packets) at a given rate, or one sensor goes silent for
1, 3 or 10 s. The rest are decoded by the real drivers (``read_many`` over an in-memory
transport, counter gaps and all), stamped on a simulated arrival clock (2 ms plus
exponential jitter of 3 ms mean, in order per device), merged by the hub with the app's
slerp resampler and pushed through the live ``Pipeline`` with an exact calibration;
the features and masks the pipeline hands the poser go to the shipped diffusion model
(``reconstruct_many``: each clip's answer is its frame-by-frame one). No real time
passes anywhere.

GA (deg, mean over all segments and 20 Hz frames, pooled over clips as ``imucap
evaluate`` pools) at 6 sites (pelvis, head, wrists, shanks) and 3 sites (pelvis, wrists;
the same streams, the other sensors inactive). For dropouts the table also gives GA over
the dropout and the second after it against the same frames without a dropout. The site that drops
rotates over pelvis, l_wrist, r_wrist from clip to clip (one stream serves both sets).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import can  # noqa: E402

from app.live import Pipeline  # noqa: E402
from calibration import Calibration  # noqa: E402
from drivers.bno08x.driver import Bno08xRvcDevice  # noqa: E402
from drivers.hub import Hub, Interpolation  # noqa: E402
from drivers.xbus.driver import XbusDevice  # noqa: E402
from drivers.xsens_can.driver import XsensCanDevice  # noqa: E402
from inference.body.motion import Motion  # noqa: E402
from inference.loaders import find_motion_files, load_motion  # noqa: E402
from inference.metrics.errors import evaluate_clip, global_angle_error, summarize  # noqa: E402
from inference.signals.resample import FPS_MODEL, slerp_unit  # noqa: E402
from inference.signals.synthesis import kinematics, synthesize  # noqa: E402
from sim_devices.devices import DeviceFaults, SignalSource, SimBno08xRvc, SimXbus, SimXsensCan  # noqa: E402

SIX = ("pelvis", "head", "l_wrist", "r_wrist", "l_shank", "r_shank")
THREE = ("pelvis", "l_wrist", "r_wrist")
SETS = {"6 sites": SIX, "3 sites": THREE}
PROTOCOL = {"pelvis": "xbus", "head": "bno08x-rvc", "l_wrist": "xsens-can", "r_wrist": "xbus",
            "l_shank": "bno08x-rvc", "r_shank": "xsens-can"}
LOSSES = (0.0, 0.05, 0.10, 0.20, 0.40)
BURST = 3.0  # mean packets per loss burst
DROPOUTS = (1.0, 3.0, 10.0)
SESSION = 16.0  # s of motion per clip and condition
DROP_AT = 3.0  # s into the session when a dropout starts
T0 = 1.0  # session clock at the first sample
RATE = 100.0  # device packets per second
DELAY, JITTER = 0.002, 0.003  # transport: fixed delay, mean of the exponential jitter (s)
POLL = 1 / 60  # s between hub polls (the live ingest thread polls once per grid frame)


def data_root() -> Path:
    return Path(os.environ.get("IMUCAP_DATA", REPO.parent / "shared" / "data"))


def session_motion(motion: Motion, seconds: float) -> Motion:
    """The clip forwards, backwards, forwards... until it lasts ``seconds``: continuous
    poses and paths (a reversal is a turn-around, not a jump), unlike a loop."""
    idx = np.arange(motion.n_frames)
    cycle = np.concatenate([idx, idx[-2:0:-1]]) if motion.n_frames > 2 else idx
    need = int(math.ceil(seconds * motion.fps)) + 1
    order = np.resize(cycle, need)
    return dataclasses.replace(motion, rot=motion.rot[order], root=motion.root[order])


def burst_entry(loss: float, burst: float = BURST) -> float:
    """Per-packet chance of entering a burst that gives a long-run loss fraction ``loss``
    when a burst ends with chance 1/``burst`` per packet (Gilbert-Elliott)."""
    q = 1.0 / burst
    return 0.0 if loss <= 0 else loss * q / (1.0 - loss)


class _FakeBus:
    """python-can's ``recv`` over the frames delivered so far."""

    def __init__(self) -> None:
        self.queue: list[can.Message] = []

    def recv(self, timeout: float | None = None) -> can.Message | None:
        return self.queue.pop(0) if self.queue else None

    def shutdown(self) -> None:
        pass


class Link:
    """One site: a simulated device making packets, the transport between, and the real
    driver decoding them."""

    def __init__(self, site: str, k: int, source: SignalSource, faults: DeviceFaults,
                 clock: Callable[[], float]) -> None:
        self.site = site
        self.protocol = PROTOCOL[site]
        self.rx: list = []  # delivered, not yet read
        if self.protocol == "xbus":
            self.twin = SimXbus(source, RATE, faults, site, link_path=f"/nonexistent/{site}")
            self.dev = XbusDevice(f"/dev/null-{site}", configure=False, reconnect=False, clock=clock, device_id=site)
        elif self.protocol == "bno08x-rvc":
            self.twin = SimBno08xRvc(source, RATE, faults, site, link_path=f"/nonexistent/{site}")
            self.dev = Bno08xRvcDevice(f"/dev/null-{site}", reconnect=False, clock=clock, device_id=site)
        else:
            self.twin = SimXsensCan(source, RATE, faults, site, id_offset=0x100 * (k + 1))
            self.dev = XsensCanDevice("virtual", site, id_offset=0x100 * (k + 1), reconnect=False, clock=clock,
                                      device_id=site)
        if self.protocol == "xsens-can":
            bus = _FakeBus()
            self.dev._open = lambda: setattr(self.dev, "_bus", bus)
            self._bus = bus
        else:
            self.dev._open = self.dev._reset_parser
            self.dev._read_bytes = self._read_bytes
        self.dev.open()

    def _read_bytes(self, timeout: float | None) -> bytes:
        data, self.rx = b"".join(self.rx), []
        return data

    def deliver(self, packet) -> None:  # type: ignore[no-untyped-def]
        if self.protocol == "xsens-can":
            self._bus.queue.extend(can.Message(arbitration_id=i, data=d, is_extended_id=False) for i, d in packet)
        else:
            self.rx.append(packet)

    def read(self) -> list:
        """Everything delivered so far (the CAN driver takes one frame per zero-timeout
        read when it does not complete a group, so keep asking while frames wait)."""
        out = self.dev.read_many(0.0)
        while self.protocol == "xsens-can" and self._bus.queue:
            out += self.dev.read_many(0.0)
        return out


class BurstLoss:
    """Gilbert-Elliott loss: a delivered packet starts a burst with chance ``enter``; a
    lost one ends it with chance 1/``burst``, so bursts last ``burst`` packets on average
    and the long-run loss is ``loss`` (``burst_entry``)."""

    def __init__(self, loss: float, rng: np.random.Generator, burst: float = BURST) -> None:
        self.enter = burst_entry(loss, burst)
        self.leave = 1.0 / burst
        self.rng = rng
        self.bad = False

    def lost(self) -> bool:
        was = self.bad
        self.bad = self.rng.random() >= self.leave if was else self.rng.random() < self.enter
        return was


def simulate_frames(sig, sites: tuple[str, ...], loss: float, dropout: tuple[str, float, float] | None,
                    seed: int, fill_gap: float = 0.1) -> tuple[list, dict]:
    """Hub frames of one session (module docstring) and what the links did."""
    now = [0.0]
    clock = lambda: now[0]  # noqa: E731
    rng = np.random.default_rng(seed)
    links = []
    for k, site in enumerate(sites):
        faults = DeviceFaults(clock_offset=100.0 * (k + 1), drift_ppm=20.0 * (k - 2), seed=seed * 31 + k)
        links.append(Link(site, k, SignalSource(sig, site), faults, clock))
    losses = [BurstLoss(loss, np.random.default_rng(seed * 31 + k)) for k in range(len(links))]
    hub = Hub({ln.site: ln.dev for ln in links}, clock=clock, interpolation=Interpolation(slerp_unit),
              fill_gap=fill_gap)
    duration = (len(sig) - 1) / sig.fps
    events: list[tuple[float, int, object]] = []
    sent = lost = 0
    for k, ln in enumerate(links):
        phase = rng.uniform(0, 1 / RATE)
        t = np.arange(phase, duration, 1 / RATE)
        arrival = np.maximum.accumulate(T0 + t + DELAY + rng.exponential(JITTER, t.size))
        for tt, at in zip(t, arrival, strict=True):
            tw = ln.twin
            counter = tw.counter
            tw.counter += 1
            if losses[k].lost():
                lost += 1
                continue
            if dropout is not None and dropout[0] == ln.site and dropout[1] <= tt < dropout[1] + dropout[2]:
                lost += 1
                continue
            sent += 1
            events.append((float(at), k, tw._make_packet(float(tt), tw.device_time(float(tt)), counter)))
    events.sort(key=lambda e: (e[0], e[1]))
    frames = []
    j = 0
    reads = np.arange(T0 + 0.01, T0 + duration + 0.2, 0.01)  # the readers drain every 10 ms
    next_poll = T0 + POLL
    for step in reads:
        now[0] = float(step)
        touched = set()
        while j < len(events) and events[j][0] <= step:
            links[events[j][1]].deliver(events[j][2])
            touched.add(events[j][1])
            j += 1
        for k in sorted(touched):
            batch = links[k].read()
            if batch:
                hub.push_many(links[k].site, batch)
        if step >= next_poll:
            frames += hub.poll()
            next_poll += POLL
    return frames, {"sent": sent, "lost": lost, "loss": lost / max(1, sent + lost)}


class _Tap:
    """Stands in for the poser inside the Pipeline: keeps the features and masks the
    pipeline would feed it (the shipped poser then runs on them batched)."""

    stride = None
    pelvis_odometry = None

    def __init__(self) -> None:
        self.x: list[np.ndarray] = []
        self.mask: list[np.ndarray] = []

    def reset(self) -> None:
        pass

    def step(self, x: np.ndarray, mask: np.ndarray):  # type: ignore[no-untyped-def]
        self.x.append(np.array(x))
        self.mask.append(np.array(mask))
        return None


def pipeline_features(frames: list, sites: tuple[str, ...], active: tuple[str, ...]
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(features (T, 190), masks (T, 190), session times (T,)) of the 20 Hz frames the
    pipeline makes from hub frames, with an exact calibration (the synthesized sensors
    sit on their bones, world-aligned)."""
    S = len(sites)
    cal = Calibration(sites=sites, R_WG=np.tile(np.eye(3), (S, 1, 1)), R_SB=np.tile(np.eye(3), (S, 1, 1)),
                      acc_offset=np.zeros((S, 3)), valid=np.ones(S, bool))
    tap = _Tap()
    pipe = Pipeline(tap, sites, calibration=cal, active_sites=active)  # type: ignore[arg-type]
    times = []
    for f in frames:
        times += [lp.t for lp in pipe.push(f)]
    return np.array(tap.x), np.array(tap.mask), np.array(times)


def truth_index(times: np.ndarray) -> np.ndarray:
    """60 Hz frame of the session motion a pipeline time stands for (the hub's clock puts a
    sample at its capture time plus the transport's least delay)."""
    return np.rint((times - T0 - DELAY) * 60.0).astype(int)


def run(clips: list[Path], steps=None, lanes: int = 8, log=print,  # type: ignore[no-untyped-def]
        losses: tuple[float, ...] = LOSSES, dropouts: tuple[float, ...] = DROPOUTS, fill_gap: float = 0.1,
        checkpoint: Callable[[dict], None] | None = None, session: float = SESSION) -> dict:
    from inference.evaluation.runner import ClipInput, clip_poser, clip_seed, evaluation_noise, face_forward
    from inference.poser.batched import reconstruct_many
    from inference.poser.models import resolve_model

    model = resolve_model("diffusion")
    if dropouts and 0.0 not in losses:
        losses = (0.0, *losses)  # the dropout window is compared with the same frames at no loss
    conditions: list[tuple[str, str, float]] = [("loss", f"{p:.0%}", p) for p in losses]
    conditions += [("dropout", f"{d:g} s", d) for d in dropouts]
    rows: dict[tuple[str, str, str], list] = {}
    window_rows: dict[tuple[str, str, str], list[tuple[float, float]]] = {}
    measured_loss: dict[str, list[float]] = {}
    for ci, path in enumerate(clips):
        t_clip = time.monotonic()
        motion = face_forward(load_motion(path))
        long = session_motion(motion, session)
        seed = clip_seed(0, motion.name)
        sig = synthesize(long, evaluation_noise(), rng=seed, sites=SIX)
        kin = kinematics(long)
        inputs, posers, keys = [], [], []
        for kind, label, value in conditions:
            streams = []
            if kind == "loss":
                frames, st = simulate_frames(sig, SIX, value, None, seed, fill_gap)
                measured_loss.setdefault(label, []).append(st["loss"])
                streams = [(name, frames, None) for name in SETS]
            else:  # one stream for both sets: the site that drops is one of the three
                site = THREE[ci % len(THREE)]
                frames, _ = simulate_frames(sig, SIX, 0.0, (site, DROP_AT, value), seed, fill_gap)
                streams = [(name, frames, (site, DROP_AT, value)) for name in SETS]
            for set_name, frames, drop in streams:
                x, m, times = pipeline_features(frames, SIX, SETS[set_name])
                idx = truth_index(times)
                ok = (idx >= 0) & (idx < len(kin.rot))
                x, m, times, idx = x[ok], m[ok], times[ok], idx[ok]
                inp = ClipInput(name=f"{motion.name}|{set_name}|{label}", body=long.body, features=x, mask=m,
                                rot=kin.rot[idx], root=kin.root[idx], joints=kin.joints[idx])
                inputs.append((inp, times, drop))
                posers.append(clip_poser(model, inp, steps, seed))
                keys.append((set_name, kind, label))
        recs = reconstruct_many(posers, [(i.features, i.mask) for i, _, _ in inputs], lanes=lanes)
        per_frame: dict[tuple[str, str, str], tuple[np.ndarray, np.ndarray]] = {}
        for (inp, times, _), rec, key in zip(inputs, recs, keys, strict=True):
            cm = evaluate_clip(inp.name, rec.rot, rec.root, rec.joints, inp.rot, inp.root, inp.joints, FPS_MODEL)
            rows.setdefault(key, []).append(cm)
            per_frame[key] = (times, global_angle_error(rec.rot, inp.rot))
        for (set_name, kind, label), (times, ga) in per_frame.items():
            if kind != "dropout":
                continue
            d = float(label.split()[0])
            bt, bga = per_frame[(set_name, "loss", "0%")]
            lo, hi = T0 + DROP_AT, T0 + DROP_AT + d + 1.0
            w = (times >= lo) & (times < hi)
            wb = (bt >= lo) & (bt < hi)
            window_rows.setdefault((set_name, kind, label), []).append((float(ga[w].sum()), float(bga[wb].sum()),
                                                                        int(w.sum())))
        log(f"[{ci + 1}/{len(clips)}] {motion.name}: {motion.n_frames / motion.fps:.1f} s clip, "
            f"{time.monotonic() - t_clip:.0f} s")
        if checkpoint is not None:
            checkpoint(_table(rows, window_rows, measured_loss, ci + 1))
    return _table(rows, window_rows, measured_loss, len(clips))


def _table(rows: dict, window_rows: dict, measured_loss: dict, n_clips: int) -> dict:
    table = []
    for (set_name, kind, label), cms in rows.items():
        s = summarize(cms)
        row = {"sensors": set_name, "condition": kind, "level": label, "clips": s["clips"], "frames": s["frames"],
               "ga_deg": round(float(s["ga_deg"]), 2)}
        if kind == "loss":
            row["measured_loss"] = round(float(np.mean(measured_loss[label])), 4)
        if (set_name, kind, label) in window_rows:
            w = window_rows[(set_name, kind, label)]
            n = sum(c for *_, c in w)
            row["window_ga_deg"] = round(sum(a for a, _, _ in w) / max(1, n), 2)
            row["window_base_ga_deg"] = round(sum(b for _, b, _ in w) / max(1, n), 2)
        table.append(row)
    base = {r["sensors"]: r["ga_deg"] for r in table if r["condition"] == "loss" and r["level"] == "0%"}
    for r in table:
        r["cost_deg"] = round(r["ga_deg"] - base[r["sensors"]], 2) if r["sensors"] in base else None
    return {"clips": n_clips, "rows": table}


def markdown(result: dict) -> str:
    lines = ["| sensors | condition | GA deg | cost deg | measured loss | GA in dropout +1 s "
             "| same frames, no dropout |",
             "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        cond = f"{r['level']} loss" if r["condition"] == "loss" else f"{r['level']} dropout"
        ml = f"{r['measured_loss']:.1%}" if "measured_loss" in r else ""
        w = f"{r['window_ga_deg']:.1f}" if "window_ga_deg" in r else ""
        wb = f"{r['window_base_ga_deg']:.1f}" if "window_base_ga_deg" in r else ""
        cost = "" if r["cost_deg"] is None else f"{r['cost_deg']:+.2f}"
        lines.append(f"| {r['sensors']} | {cond} | {r['ga_deg']:.2f} | {cost} | {ml} | {w} | {wb} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(data_root() / "hdm05" / "dg"))
    ap.add_argument("--clips", type=int, default=0, help="every k-th clip so that N are used (0: all)")
    ap.add_argument("--json", help="write the result here")
    ap.add_argument("--lanes", type=int, default=8)
    ap.add_argument("--losses", default=",".join(f"{p:g}" for p in LOSSES), help="loss fractions, comma-separated")
    ap.add_argument("--dropouts", default=",".join(f"{d:g}" for d in DROPOUTS), help="dropout seconds ('' for none)")
    ap.add_argument("--session", type=float, default=SESSION, help="seconds of motion per clip and condition")
    ap.add_argument("--fill-gap", type=float, default=0.1,
                    help="the hub's fill_gap (0: every lost packet's stretch marked missing, as before)")
    args = ap.parse_args(argv)
    losses = tuple(float(v) for v in args.losses.split(",") if v)
    dropouts = tuple(float(v) for v in args.dropouts.split(",") if v)
    import torch

    torch.set_num_threads(1)
    files = find_motion_files(args.data)
    if args.clips and args.clips < len(files):
        files = [files[int(i)] for i in np.linspace(0, len(files) - 1, args.clips).round()]
    t0 = time.monotonic()

    def save(result: dict) -> None:
        result.update(seconds=round(time.monotonic() - t0), data=args.data, fill_gap=args.fill_gap,
                      session_s=args.session, clip_names=[f.name for f in files[:result["clips"]]])
        if args.json:
            Path(args.json).write_text(json.dumps(result, indent=1))
        print(markdown(result), file=sys.stderr, flush=True)

    result = run(files, lanes=args.lanes, log=lambda s: print(s, file=sys.stderr, flush=True), losses=losses,
                 dropouts=dropouts, fill_gap=args.fill_gap, checkpoint=save, session=args.session)
    save(result)
    print(markdown(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
