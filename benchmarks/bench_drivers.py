"""Driver benchmarks (not tests): decode throughput per protocol, and the CPU cost of
13 sensors at 100 Hz through the real drivers and the hub.

    .venv/bin/python benchmarks/bench_drivers.py [--seconds 10] [--json]

CPU figures use time.process_time() (this process only, all threads) against
time.perf_counter(), so other jobs on the machine do not inflate them. For the
live measurement the 13 simulated MTis run in a child process and this process
does only what the app does: read 13 ptys, decode, merge on the 60 Hz grid.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import time
from typing import Any

import numpy as np

from drivers.base import Unwrapper
from drivers.bno08x import protocol as rvc
from drivers.bno08x.driver import rvc_to_sample
from drivers.dualsense import protocol as ds
from drivers.dualsense.driver import DualSenseDevice
from drivers.moticon import protocol as mot
from drivers.moticon.driver import MoticonUdpDevice
from drivers.xbus import protocol as xb
from drivers.xbus.driver import mtdata2_to_sample
from drivers.xsens_can import protocol as xcan
from drivers.xsens_can.driver import group_to_sample

N = 20000


def _rate(fn, n: int) -> float:
    t0 = time.process_time()
    fn()
    return n / max(1e-9, time.process_time() - t0)


def decode_rates() -> dict[str, float]:
    rng = np.random.default_rng(0)
    out: dict[str, float] = {}

    frames = b"".join(
        xb.encode(
            0x36,
            xb.encode_mtdata2(
                xb.MTData2(
                    k & 0xFFFF,
                    k * 100,
                    tuple(rng.normal(size=4)),
                    tuple(rng.normal(size=3)),
                    tuple(rng.normal(size=3)),
                    tuple(rng.normal(size=3)),
                    3,
                )
            ),
        )
        for k in range(N)
    )

    def xbus() -> None:
        p, u = xb.XbusStreamParser(), Unwrapper(1 << 32, 1e-4)
        for i in range(0, len(frames), 4096):
            for m in p.feed(frames[i : i + 4096]):
                mtdata2_to_sample(xb.decode_mtdata2(m.data), "x", u)

    out["xbus"] = _rate(xbus, N)

    rframes = b"".join(rvc.encode(rvc.RvcFrame(k & 0xFF, 10.0, 5.0, -3.0, (10.0, -20.0, 990.0))) for k in range(N))

    def bno() -> None:
        p, u = rvc.RvcStreamParser(), Unwrapper(256, 0.01)
        for i in range(0, len(rframes), 4096):
            for f in p.feed(rframes[i : i + 4096]):
                rvc_to_sample(f, "x", u)

    out["bno08x-rvc"] = _rate(bno, N)

    group = xcan.CanGroup(123, 1, 3, (1.0, 0, 0, 0), (0.1, 0.2, 0.3), (0, 0, 9.8), (0.1, 0, 0))
    cframes = xcan.encode(group) * (N // 4)

    def can() -> None:
        asm, u = xcan.GroupAssembler(), Unwrapper(1 << 32, 1e-6)
        for fid, data in cframes:
            g = asm.push(*xcan.decode(fid, data))
            if g is not None:
                group_to_sample(g, "x", u)

    out["xsens-can"] = _rate(can, N // 4)

    cal = ds.DsCalibration()
    reports = [
        ds.encode_input_report(ds.DsInput(k & 0xFF, (10, -5, 3), (0, 0, 8192), k * 12000, 80.0, False))
        for k in range(N // 4)
    ]

    class _Hid:
        def get_feature_report(self, rid: int, size: int) -> bytes:
            return ds.encode_calibration(cal)

        def close(self) -> None:
            pass

    dev = DualSenseDevice(lambda: _Hid())
    dev._open()  # noqa: SLF001 - calibration and AHRS set up as on a real open

    def dualsense() -> None:
        for r in reports:
            dev._to_sample(ds.decode_input_report(r))  # noqa: SLF001

    out["dualsense"] = _rate(dualsense, N // 4)

    f = mot.InsoleFrame(
        1.0,
        rng.normal(size=(2, 3)),
        rng.normal(size=(2, 3)),
        rng.normal(size=(2, 2)),
        np.abs(rng.normal(size=(2, 16))),
        np.array([400.0, 300.0]),
    )
    grams = [
        mot.encode(mot.InsoleFrame(k / 100, f.acc_g, f.gyro_dps, f.cop, f.pressure, f.total_force))
        for k in range(N // 4)
    ]
    mdev = MoticonUdpDevice("127.0.0.1", 0)

    def moticon() -> None:
        for g in grams:
            mdev._to_sample(mot.decode(g))  # noqa: SLF001

    out["moticon-udp"] = _rate(moticon, N // 4)
    return out


def _suit_child(conn, seconds: float, protocol: str = "xbus") -> None:
    from sim_devices.devices import spinning_signals
    from sim_devices.suit import SimulatedSuit

    sites = (
        "pelvis",
        "torso",
        "head",
        "l_upperarm",
        "r_upperarm",
        "l_wrist",
        "r_wrist",
        "l_thigh",
        "r_thigh",
        "l_shank",
        "r_shank",
        "l_foot",
        "r_foot",
    )
    sig = spinning_signals(sites, seconds=30)
    # CAN twins on a bus served on 127.0.0.1 (python-can's remote interface), as across processes in the app
    with SimulatedSuit(sig, {s: protocol for s in sites}, can_interface="remote") as suit:
        conn.send(suit.urls())
        conn.recv()  # until the parent is done
        conn.send({s: d.sim.stats for s, d in suit.devices.items()})


def live_cost(seconds: float, protocol: str = "xbus", **hub_kw: Any) -> dict[str, Any]:
    """One run: 13 MTi twins in a child process (``xbus`` on ptys, or ``xsens-can``: MTi-600s
    on one CAN bus served on loopback), this process reads them through the real drivers and
    the hub and consumes 60 Hz frames. ``hub_kw`` goes to ``Hub`` (``selector``,
    ``read_interval``) so each lever can be measured on its own."""
    import drivers
    from drivers.hub import Hub

    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=_suit_child, args=(child, seconds, protocol), daemon=True)
    proc.start()
    urls = parent.recv()
    devs = {s: drivers.make_device(u) for s, u in urls.items()}
    with Hub(devs, **hub_kw) as hub:
        time.sleep(1.0)  # configuration handshakes done, steady state
        decoded0 = sum(d.stats.decoded for d in devs.values())
        c0, w0 = time.process_time(), time.perf_counter()
        frames = 0
        present = 0.0
        for f in hub.frames(duration=seconds):
            frames += 1
            present += float(f.present.mean())
        c1, w1 = time.process_time(), time.perf_counter()
        decoded = sum(d.stats.decoded for d in devs.values()) - decoded0
        lost = sum(d.stats.lost_packets for d in devs.values())
    parent.send("done")
    sim_stats = parent.recv()
    proc.join(timeout=5)
    return {
        "sensors": len(urls),
        "seconds": round(w1 - w0, 2),
        "samples_per_s": round(decoded / (w1 - w0), 1),
        "frames_per_s": round(frames / (w1 - w0), 1),
        "present_fraction": round(present / max(1, frames), 4),
        "cpu_fraction_of_one_core": round((c1 - c0) / (w1 - w0), 4),
        "lost_packets": lost,
        "sim_sent": sum(s["sent"] for s in sim_stats.values()),
    }


def live_repeated(seconds: float, repeat: int, protocol: str = "xbus", **hub_kw: Any) -> dict[str, Any]:
    """``repeat`` runs; the ratio of one core is reported per run and as the median,
    because other jobs on the machine make single runs noisy."""
    runs = [live_cost(seconds, protocol, **hub_kw) for _ in range(repeat)]
    ratios = [r["cpu_fraction_of_one_core"] for r in runs]
    out = dict(runs[-1])
    out["cpu_fraction_of_one_core"] = float(np.median(ratios))
    out["runs"] = ratios
    return out


def to_grid_per_stream(to_grid: Any, max_gap: float = 0.1) -> Any:
    """Inference's ``to_grid(t, quat, acc, fps, max_gap, t0)`` as the hub's per-stream
    resampler (``drivers.hub.StreamResampler``): one site's samples onto the grid times."""

    def resample(t: np.ndarray, q: np.ndarray, a: np.ndarray, grid: np.ndarray):
        tg, qg, ag, valid = to_grid(t, q, a, fps=60.0, max_gap=max_gap, t0=float(grid[0]))
        G = grid.size
        quat, acc, ok = np.full((G, 4), np.nan), np.full((G, 3), np.nan), np.zeros(G, bool)
        n = min(G, len(tg))
        quat[:n], acc[:n], ok[:n] = qg[:n], ag[:n], valid[:n]
        return quat, acc, ok

    return resample


def interpolation_cost(seconds: float, repeat: int, **hub_kw: Any) -> dict[str, Any]:
    """The hub's share of a core with the 13 twins when it interpolates each site to the
    grid (the centred mode): one batched slerp over all sites (``Hub._interp_all``) against
    ``to_grid`` per site (``Hub._per_site``), and the hold, taken in turn in each repeat
    so the machine's load falls on all three."""
    from drivers.hub import Interpolation
    from inference.signals.resample import slerp_unit, to_grid

    modes = {"hold": None, "batched": Interpolation(slerp_unit),
             "per_site": Interpolation(per_stream=to_grid_per_stream(to_grid))}
    ratios: dict[str, list[float]] = {m: [] for m in modes}
    present: dict[str, list[float]] = {m: [] for m in modes}
    for _ in range(repeat):
        for m, rs in modes.items():
            r = live_cost(seconds, interpolation=rs, **hub_kw)
            ratios[m].append(r["cpu_fraction_of_one_core"])
            present[m].append(r["present_fraction"])
    med = {m: float(np.median(v)) for m, v in ratios.items()}
    return {f"{m}_fraction_of_one_core": round(v, 4) for m, v in med.items()} | {
        "per_site_over_batched": round(med["per_site"] / med["batched"], 2),
        "present_fraction": {m: round(float(np.median(v)), 4) for m, v in present.items()},
        "runs": ratios, "sensors": 13, "seconds": seconds}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3, help="live runs; the median ratio is reported")
    ap.add_argument("--live-only", action="store_true", help="skip the decode throughput part")
    ap.add_argument("--no-selector", action="store_true", help="one reader thread per device (batched reads)")
    ap.add_argument("--read-interval", type=float, default=None, help="selector sleep between drains, s")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--protocol", choices=["xbus", "xsens-can"], default="xbus",
                    help="the 13 twins of the live part: Xbus on ptys, or MTi-600 on one CAN bus served on loopback")
    ap.add_argument("--interpolation", action="store_true",
                    help="also the hub of the centred latency mode (slerp to the grid), batched over the sites and "
                         "per site, alternating with the hold in each repeat")
    args = ap.parse_args()
    hub_kw: dict[str, Any] = {"selector": not args.no_selector}
    if args.read_interval is not None:
        hub_kw["read_interval"] = args.read_interval
    rates = {} if args.live_only else decode_rates()
    if args.interpolation:
        result = interpolation_cost(args.seconds, args.repeat, **hub_kw)
        print(json.dumps(result) if args.json else "\n".join(f"{k}: {v}" for k, v in result.items()))
        return
    live = live_repeated(args.seconds, args.repeat, args.protocol, **hub_kw)
    budget = {k: round(1300 / v, 4) for k, v in rates.items()}  # 13 sensors x 100 Hz, decode only
    result = {
        "decoded_packets_per_s": {k: round(v) for k, v in rates.items()},
        "decode_cost_13x100Hz_fraction_of_core": budget,
        f"live_13_{args.protocol.replace('-', '_')}_100Hz_with_hub": live,
        "live_ratio_of_one_core": live["cpu_fraction_of_one_core"],
        "live_under_10_percent": live["cpu_fraction_of_one_core"] < 0.10,
    }
    if args.json:
        print(json.dumps(result))
    else:
        for k, v in rates.items():
            print(f"{k:12s} {v:10.0f} packets/s   13x100 Hz decode = {100 * budget[k]:.2f}% of a core")
        print(f"live, 13 {args.protocol} twins at 100 Hz through drivers + hub:", json.dumps(live))
        print(
            f"live ratio of one core (13 x 100 Hz, median of {args.repeat}): "
            f"{live['cpu_fraction_of_one_core']:.4f} (budget 0.10)"
        )


if __name__ == "__main__":
    main()
