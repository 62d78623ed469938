"""`imucap devices`: list attached devices, probe one by URL, run a simulated one."""

from __future__ import annotations

import argparse
import gc
import json
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from app.capture.discovery import KNOWN_USB, discover  # noqa: F401 (the CLI's names)


def cmd_list(args: argparse.Namespace) -> int:
    found = discover()
    if args.json:
        print(json.dumps({"devices": found}, indent=2))
        return 0
    if not [f for f in found if "error" not in f]:
        print("no devices found (serial, HID, USB, CAN); try `imucap devices simulate`")
    for f in found:
        if "error" in f:
            print(f"[{f['kind']}] not available: {f['error']}", file=sys.stderr)
        else:
            url = f.get("url") or f.get("note") or "no backend"
            battery = f"  battery {f['battery']:.0f}%" if f.get("battery") is not None else ""
            print(f"[{f['kind']}] {f['path']}  {f.get('usb') or ''}  {f['what']}{battery}  -> {url}")
    # say what was looked at and came back empty, so "nothing listed" is not ambiguous
    for kind in ("serial", "hid", "usb", "can", "ble"):
        if not any(f["kind"] == kind for f in found):
            print(f"[{kind}] none found")
    return 0


def probe(url: str, seconds: float) -> dict[str, Any]:
    """Open ``url``, read for ``seconds``, summarise (the DESIGN.md contract)."""
    import drivers

    dev = drivers.open_device(url)
    n = 0
    first = None
    t_first = t_last = None
    try:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            s = dev.read(min(0.2, max(0.0, end - time.monotonic())))
            if s is None:
                continue
            n += 1
            if first is None:
                first = s.as_json()
                t_first = s.t
            t_last = s.t
    finally:
        dev.close()
    rate = (n - 1) / (t_last - t_first) if n > 1 and t_last and t_first is not None and t_last > t_first else 0.0
    st = dev.stats
    return {
        "url": url,
        "samples": n,
        "rate_hz": round(rate, 2),
        "errors": st.errors,
        "first": first,
        "stats": st.as_dict(),
        "events": [{"t": e.t, "kind": e.kind, "detail": e.detail} for e in dev.events],
    }


def cmd_probe(args: argparse.Namespace) -> int:
    out = probe(args.url, args.seconds)
    if args.json:
        print(json.dumps(out))
    else:
        print(f"{out['samples']} samples at {out['rate_hz']} Hz, {out['errors']} errors")
        if out["first"]:
            print("first:", json.dumps(out["first"]))
    return 0 if out["samples"] > 0 else 1


def _signals(args: argparse.Namespace, sites: list[str]):
    if args.motion != "spin":
        try:
            from inference.signals.synthesis import NoiseModel, synthesize
            from sim_devices.motions import generate
        except ImportError as exc:
            print(f"motion synthesis unavailable ({exc}); using the analytic spinning signals", file=sys.stderr)
        else:
            motion = generate(args.motion, seconds=max(6.0, min(args.seconds or 30.0, 60.0)), seed=args.seed)
            noise = NoiseModel.typical() if args.noise == "typical" else None
            return synthesize(motion, noise=noise, rng=args.seed, sites=tuple(sites))
    from sim_devices.devices import spinning_signals

    return spinning_signals(sites, seconds=30.0)


def cmd_simulate_setup(args: argparse.Namespace) -> int:
    """A whole setup's devices, worn by one simulated subject, until the session ends or Ctrl-C."""
    from app.capture.setup_file import SetupError, load_setup
    from app.capture.simulate import SimulatedSetup, SimulatedSubject, Unplug
    from inference.signals.synthesis import NoiseModel

    try:
        setup = load_setup(args.setup)
        if args.twin_setup:
            setup = _write_twin_setup(setup, Path(args.twin_setup))
        else:
            _check_simulatable(setup)
        unplug = [Unplug.parse(u) for u in args.unplug]
        activity = _activity(args.motion, args.activity_seconds, args.seed, setup.subject.height_m)
        noise = NoiseModel.typical() if args.noise == "typical" else NoiseModel()
        subject = SimulatedSubject(setup, activity, lead_in=args.lead_in, seed=args.seed, noise=noise)
        sim = SimulatedSetup(subject, unplug)
        if args.log_sends:
            for d in sim.devices.values():
                d.log_sends()
        _freeze_setup_objects()
        sim.start()
    except (SetupError, ValueError, OSError) as exc:
        print(f"imucap devices simulate: {exc}", file=sys.stderr)
        return 2
    # a terminate (a service manager, a test harness) ends the session as Ctrl-C does: the devices
    # are stopped (ptys closed, sockets released) and the send logs written
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        if args.truth:
            sim.write_truth(args.truth)
        for name, d in sim.devices.items():
            print(f"{name} {d.url}", flush=True)
        print(f"simulating {sim.duration:.1f} s ({setup.calibration} calibration, then {args.motion})", flush=True)
        sim.run(args.seconds or None, stop=_stdin_closed() if args.while_stdin_open else None)
    except KeyboardInterrupt:
        pass
    finally:
        # a terminate that comes while the devices stop (a harness closes standard input, then
        # terminates) must not cut the stop short and lose the send logs: it is ignored until
        # they are written; a stop that hangs is still ended by a kill
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        try:
            sim.stop()
        finally:
            if args.log_sends:
                sim.write_send_logs(args.log_sends)
            signal.signal(signal.SIGTERM, previous)
    print(json.dumps(sim.stats()), file=sys.stderr)
    return 0


def _raise_interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _freeze_setup_objects() -> None:
    """Take what the set-up made (the synthesis, torch, the modules) out of the collector's full passes.

    A full pass holds the interpreter while it walks every tracked object, and with it every device's
    thread: one came ~13 s into a wireless capture's activity and no device sent for 140-160 ms
    (``tests/app/capture/test_capture_wireless.py`` saw the gap in two runs of two; none once frozen). The
    capture freezes its own objects after the model's warm-up (``app/live/pipeline.py``)."""
    gc.collect()
    gc.freeze()


def _check_simulatable(setup) -> None:
    from app.capture.twins import EXAMPLE, simulation_problem

    for name, url in setup.urls().items():
        problem = simulation_problem(url)
        if problem is not None:
            raise ValueError(f"{name} = {url}: {problem}; to simulate this setup add --twin-setup SIM.toml "
                             f"(the same setup over simulated devices, for imucap capture --setup SIM.toml), "
                             f"or start from {EXAMPLE}")


def _write_twin_setup(setup, path: Path):
    """Write ``setup`` over simulated devices to ``path`` and return it as loaded from there."""
    import tempfile

    from app.capture.setup_file import load_setup, save_setup
    from app.capture.twins import twin_setup

    twin = twin_setup(setup, Path(tempfile.mkdtemp(prefix="imucap-sim-")))
    save_setup(twin, path)
    print(f"wrote {path}: this setup over simulated devices; capture with imucap capture --setup {path}",
          flush=True)
    return load_setup(path)


def _stdin_closed() -> threading.Event:
    """Set when standard input closes: the parent that started this simulator ended it, or died."""
    closed = threading.Event()

    def watch() -> None:
        try:
            while sys.stdin.read(4096):
                pass
        finally:
            closed.set()

    threading.Thread(target=watch, name="stdin-watch", daemon=True).start()
    return closed


def _activity(motion: str, seconds: float, seed: int, height: float):
    """A procedural motion kind, or a motion file (BVH, ASF/AMC, AMASS) facing forward."""
    from sim_devices.motions import KINDS, generate

    if motion in KINDS:
        return generate(motion, seconds=seconds, seed=seed, height=height)
    from inference.evaluation.runner import face_forward
    from inference.loaders import load_motion

    return face_forward(load_motion(motion))


def cmd_simulate(args: argparse.Namespace) -> int:
    from sim_devices.devices import INSOLE_PROTOCOLS, DeviceFaults, make_sim_device

    if args.setup:
        return cmd_simulate_setup(args)
    if not args.protocol:
        print("imucap devices simulate: give --protocol (one device) or --setup FILE (a whole setup)",
              file=sys.stderr)
        return 2

    site = "insoles" if args.protocol in INSOLE_PROTOCOLS else args.site
    sites = ["l_foot", "r_foot"] if site == "insoles" else [site]
    sig = _signals(args, sites)
    disconnects = [(float(a), float(b)) for a, b in (x.split(":") for x in args.disconnect)]
    faults = DeviceFaults(
        loss_rate=args.loss, loss_burst=args.burst, corrupt_rate=args.corrupt, disconnects=disconnects, seed=args.seed
    )
    kw: dict[str, Any] = {}
    if args.protocol in ("xbus", "bno08x-rvc") and args.link:
        kw["link_path"] = args.link
    if args.protocol == "xsens-can":
        kw.update(interface=args.can_interface, channel=args.can_channel)
    if args.protocol in ("moticon-udp", "ximu3") and args.port:
        kw["port"] = args.port
    if args.protocol == "movella-dot":
        from app.capture.discovery import SIM_BLE_FOLDER

        kw["folder"] = args.ble_folder or SIM_BLE_FOLDER  # where `imucap devices list` looks for simulated DOTs
    sim = make_sim_device(args.protocol, sig, site, faults=faults, **kw)
    _freeze_setup_objects()
    sim.start()
    print(sim.url, flush=True)
    if args.protocol == "xsens-can" and args.can_interface == "virtual":
        print(
            "note: python-can's virtual bus is per process; to reach another process use "
            "--can-interface remote --can-channel 127.0.0.1:PORT (served here on loopback), "
            "or socketcan with a vcan device",
            file=sys.stderr,
        )
    try:
        end = None if not args.seconds else time.monotonic() + args.seconds
        while end is None or time.monotonic() < end:
            time.sleep(0.2)
    except KeyboardInterrupt:
        pass
    finally:
        sim.stop()
    print(json.dumps({"url": sim.url, **sim.stats}), file=sys.stderr)
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("devices", help="list, probe and simulate IMU devices")
    sub = p.add_subparsers(dest="devices_command", required=True)

    pl = sub.add_parser("list", help="find serial, HID, USB and CAN devices we know how to open")
    pl.add_argument("--json", action="store_true")
    pl.set_defaults(func=cmd_list)

    pp = sub.add_parser("probe", help="open a device URL, read for a while, report")
    pp.add_argument("url", help="e.g. xbus:///dev/ttyUSB0?baud=115200")
    pp.add_argument("--seconds", type=float, default=2.0)
    pp.add_argument("--json", action="store_true")
    pp.set_defaults(func=cmd_probe)

    from app.cli.identify import add_parser as add_identify_parser

    add_identify_parser(sub, discover)

    ps = sub.add_parser("simulate", help="run a simulated device; prints the URL to open")
    ps.add_argument("--protocol", choices=["xbus", "bno08x-rvc", "xsens-can", "dualsense", "moticon-udp",
                                           "movella-dot", "ximu3"],
                    help="one device of this protocol (or --setup for all of a setup file's devices)")
    ps.add_argument("--setup", help="make every device of this setup file appear at its URL, worn by a simulated "
                                    "subject who follows the setup's calibration protocol, then --motion")
    ps.add_argument("--truth", help="with --setup: write the motion played here (.npz), for imucap replay --truth")
    ps.add_argument("--twin-setup", metavar="SIM.toml",
                    help="with --setup: write the same setup over simulated devices (for a setup of real "
                         "devices' URLs) and serve that; capture with imucap capture --setup SIM.toml")
    ps.add_argument("--log-sends", metavar="FILE.npz",
                    help="with --setup: on exit, write when each device sent each packet (for imucap bench "
                         "--end-to-end, which runs the suit in its own process)")
    ps.add_argument("--lead-in", type=float, default=8.0,
                    help="with --setup: seconds the subject waits in the first pose before the protocol")
    ps.add_argument("--activity-seconds", type=float, default=20.0,
                    help="with --setup: length of a procedural --motion")
    ps.add_argument("--unplug", action="append", default=[], metavar="DEVICE:AT:SECONDS",
                    help="with --setup: unplug DEVICE AT s into the activity for SECONDS (repeatable)")
    ps.add_argument("--site", default="pelvis", help="sensor site whose signals are replayed")
    ps.add_argument("--motion", default="walk", help="procedural motion kind, or 'spin' (analytic)")
    ps.add_argument("--noise", choices=["none", "typical"], default="typical")
    ps.add_argument("--seconds", type=float, default=0.0, help="stop after this long (0 = until Ctrl-C)")
    ps.add_argument("--while-stdin-open", action="store_true",
                    help="with --setup: run, looping the motion, until standard input closes (a parent process "
                         "that started the simulator ends it so, and its death does too)")
    ps.add_argument("--loss", type=float, default=0.0, help="probability per packet of a loss burst")
    ps.add_argument("--burst", type=float, default=3.0, help="mean loss burst length, packets")
    ps.add_argument("--corrupt", type=float, default=0.0, help="probability per packet of a flipped byte")
    ps.add_argument(
        "--disconnect", action="append", default=[], metavar="AT:FOR", help="unplug at AT s for FOR s (repeatable)"
    )
    ps.add_argument("--link", help="path of the serial port link to create (xbus, bno08x-rvc)")
    ps.add_argument("--port", type=int, help="UDP port to send to (moticon-udp, ximu3)")
    ps.add_argument("--ble-folder", help="movella-dot: folder of the simulated DOTs' seam sockets "
                                         "(default /tmp/imucap-sim/ble, where `imucap devices list` looks)")
    ps.add_argument("--can-interface", default="virtual",
                    help="virtual (this process only), remote (served on --can-channel HOST:PORT, loopback), "
                         "or a python-can interface")
    ps.add_argument("--can-channel", default="imucap")
    ps.add_argument("--seed", type=int, default=0)
    ps.set_defaults(func=cmd_simulate)
