"""The simulated VR rig (``sim_devices/devices/vr_rig.py``) in a process of its own, as a
VR-to-VMC bridge runs beside imucap::

    python -m sim_devices.vr_rig_process --port P --motion walk --seconds S \\
        [--serials head=SIM-HMD,l_hand=SIM-CON-L,r_hand=SIM-CON-R] [--sites head,l_hand,r_hand,pelvis] \\
        [--rate 72] [--truth TRUTH.npz]

It prints one JSON line when it starts (``url``, ``started_at`` on time.monotonic, the
clock every process of the machine shares, the noise figures) and one when it stops
(``sent`` bundles, ``messages`` device messages). ``--truth`` writes the clean poses it
played (before latency and noise). With ``--seconds 0`` it runs until stdin closes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from drivers.vmc.device import DEFAULT_PORT
from inference.body.motion import Motion
from sim_devices.devices.base import DeviceFaults
from sim_devices.devices.vr_rig import (
    DEFAULT_SITES,
    NO_NOISE,
    ROLES,
    SimVrRig,
    TrackedSource,
    TrackingNoise,
)
from sim_devices.motions import KINDS, generate


def load_rig_motion(spec: str, seconds: float, height: float, seed: int) -> Motion:
    """A procedural motion kind (``sim_devices.motions.KINDS``, one clip as long as the run
    and at least 4 s) or a motion file."""
    if spec in KINDS:
        return generate(spec, height=height, seconds=max(4.0, seconds + 1.0), seed=seed)
    from inference.loaders import load_motion

    return load_motion(spec)


def parse_serials(text: str) -> dict[str, str]:
    """``head=A,l_hand=B`` -> {"head": "A", "l_hand": "B"}; a ValueError names what is wrong."""
    out = {}
    for item in filter(None, (x.strip() for x in text.split(","))):
        site, sep, serial = item.partition("=")
        if not sep or not serial or site not in ROLES:
            raise ValueError(f"--serials: {item!r} is not SITE=SERIAL with SITE one of {', '.join(ROLES)}")
        out[site] = serial
    return out


def write_truth(path: Path, source: TrackedSource, rig: SimVrRig) -> None:
    """The clean poses played (``<site>_pos`` (T, 3), ``<site>_quat`` (T, 4)), their frame
    times, the rig's start on time.monotonic, its serials and noise figures."""
    arrays = {f"{s}_{k}": v for s, (P, Q) in source.points.items() for k, v in (("pos", P), ("quat", Q))}
    np.savez(path, t=np.arange(source.n) / source.fps, fps=source.fps, started_at=rig.started_at,
             height=source.height, sites=np.array(source.sites), serials=json.dumps(rig.serials),
             noise=json.dumps(asdict(rig.noise)), **arrays)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m sim_devices.vr_rig_process", description=__doc__.split("\n\n")[0])
    ap.add_argument("--port", type=int, default=DEFAULT_PORT, help="UDP port of the vmc-in receiver")
    ap.add_argument("--host", default="127.0.0.1", help="loopback address of the receiver")
    ap.add_argument("--motion", default="walk", help="a motion kind (walk, jog, squat, ...) or a motion file")
    ap.add_argument("--seconds", type=float, default=0.0, help="how long to send (0: until stdin closes)")
    ap.add_argument("--sites", default=",".join(DEFAULT_SITES), help="head,l_hand,r_hand[,pelvis]")
    ap.add_argument("--serials", default="", help="SITE=SERIAL,... (defaults: SIM-HMD, SIM-CON-L, ...)")
    ap.add_argument("--rate", type=float, default=72.0, help="bundles per second, 60-120")
    ap.add_argument("--height", type=float, default=1.75, help="body height of a procedural motion, m")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--no-noise", action="store_true", help="send the clean poses, without latency")
    ap.add_argument("--truth", type=Path, help="write the clean poses played to this .npz")
    a = ap.parse_args(argv)
    try:
        sites = tuple(x.strip() for x in a.sites.split(",") if x.strip())
        unknown = [s for s in sites if s not in ROLES]
        if unknown or not sites:
            raise ValueError(f"--sites: {', '.join(unknown) or 'none given'}; known: {', '.join(ROLES)}")
        serials = parse_serials(a.serials)
        source = TrackedSource(load_rig_motion(a.motion, a.seconds, a.height, a.seed), sites)
        rig = SimVrRig(source, a.rate, DeviceFaults(seed=a.seed), host=a.host, port=a.port, serials=serials,
                       noise=NO_NOISE if a.no_noise else TrackingNoise())
    except (ValueError, OSError) as exc:
        print(f"vr_rig: {exc}", file=sys.stderr)
        return 2
    rig.start()
    try:
        if a.truth is not None:
            write_truth(a.truth, source, rig)
        print(json.dumps({"url": rig.url, "started_at": rig.started_at, "rate": rig.rate,
                          "noise": asdict(rig.noise)}), flush=True)
        if a.seconds > 0:
            time.sleep(a.seconds)
        else:
            sys.stdin.read()
    except KeyboardInterrupt:
        pass
    finally:
        rig.stop()
    print(json.dumps({"sent": rig.stats["sent"], "skipped": rig.stats["skipped"],
                      "messages": rig.stats["sent"] * len(sites)}), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
