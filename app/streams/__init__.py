"""Sinks that stream the live body to other programs: LSL (lab recorders), VMC (avatar
apps), VRChat OSC trackers. Layouts, frames and ports: docs/streams.md.

Every session (demo, capture, replay) builds them the same way, from the CLI's
``--stream lsl,vmc,vrchat`` and ``--stream-host``::

    from app.streams import add_stream_arguments, sinks_from_args
    add_stream_arguments(parser)                  # when building the parser
    for s in sinks_from_args(args):               # when building the pipeline
        pipeline.add_sink(s)

A name may carry its port (``vmc:39540``) and repeat (two VMC receivers). Sends go to
127.0.0.1 unless a host is named; LSL then announces its streams on this machine only.
The modules are imported when a stream is asked for, so ``--stream vmc`` needs no liblsl.
"""

from __future__ import annotations

import argparse
import ipaddress
from collections.abc import Callable, Sequence
from typing import Any

from app.live import Sink

STREAM_KINDS: tuple[str, ...] = ("lsl", "vmc", "vrchat")
DEFAULT_PORTS: dict[str, int] = {"vmc": 39539, "vrchat": 9000}
LOOPBACK = "127.0.0.1"
STREAM_HELP = ("send the body to other programs as it is reconstructed, comma separated: lsl (Lab Streaming "
               "Layer), vmc (VMC protocol, port 39539), vrchat (VRChat OSC trackers, port 9000); NAME:PORT for "
               "another port")


def parse_stream_spec(spec: str | Sequence[str] | None) -> list[tuple[str, int | None]]:
    """``"lsl,vmc:39540"`` -> ``[("lsl", None), ("vmc", 39540)]``; a ValueError names what is wrong."""
    if spec is None:
        return []
    items = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec)]
    out: list[tuple[str, int | None]] = []
    for item in filter(None, items):
        name, _, port = item.partition(":")
        name = name.strip().lower()
        if name not in STREAM_KINDS:
            raise ValueError(f"unknown stream {name!r}; valid: {', '.join(STREAM_KINDS)}")
        if port and name == "lsl":
            raise ValueError("lsl takes no port (LSL finds its streams by name)")
        try:
            p = int(port) if port else None
        except ValueError:
            raise ValueError(f"--stream {item!r}: the port must be a number") from None
        if p is not None and not 0 < p < 65536:
            raise ValueError(f"--stream {item!r}: {p} is not a UDP port")
        if (name, p) in out or (name == "lsl" and any(n == "lsl" for n, _ in out)):
            raise ValueError(f"--stream {item!r} is given twice")
        out.append((name, p))
    return out


def is_loopback(host: str) -> bool:
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def make_stream_sinks(spec: str | Sequence[str] | None, host: str = LOOPBACK, *,
                      clock_map: Callable[[float], float] | None = None, lsl_prefix: str = "imucap") -> list[Sink]:
    """The sinks for ``spec`` (see ``parse_stream_spec``), sending to ``host``.

    clock_map: takes pipeline times to ``time.monotonic()`` for LSL time stamps when they
    are on another clock (a replay: ``Pacer.to_monotonic``); live sessions need none.
    lsl_prefix: the LSL stream names' first word (tests use their own, so they cannot
    pick up another process's streams).
    """
    wanted = parse_stream_spec(spec)
    sinks: list[Sink] = []
    try:
        for name, port in wanted:
            if name == "lsl":
                from app.streams.lsl import LslSink

                sinks.append(LslSink(prefix=lsl_prefix, local_only=is_loopback(host), clock_map=clock_map))
            elif name == "vmc":
                from app.streams.vmc import VmcSink

                sinks.append(VmcSink(host, port or DEFAULT_PORTS["vmc"]))
            else:
                from app.streams.vrchat import VrchatSink

                sinks.append(VrchatSink(host, port or DEFAULT_PORTS["vrchat"]))
    except Exception:
        for s in sinks:
            s.close()
        raise
    return sinks


def add_stream_arguments(parser: argparse.ArgumentParser, replay: bool = False) -> None:
    """``--stream``, ``--stream-host`` (and for replays ``--stream-speed``)."""
    parser.add_argument("--stream", default=None, metavar="LIST", help=STREAM_HELP)
    parser.add_argument("--stream-host", default=LOOPBACK, metavar="HOST",
                        help="where vmc/vrchat send to (default 127.0.0.1, this machine only); a host other than "
                             "this machine also makes the LSL streams visible on the network")
    if replay:
        parser.add_argument("--stream-speed", type=float, default=1.0, metavar="X",
                            help="with --stream: replay at X times real time (default 1 = as recorded; "
                                 "0 = as fast as it goes)")


def sinks_from_args(args: argparse.Namespace, clock_map: Callable[[float], float] | None = None) -> list[Sink]:
    """The sinks ``add_stream_arguments``' options ask for (none without ``--stream``)."""
    return make_stream_sinks(getattr(args, "stream", None), getattr(args, "stream_host", LOOPBACK),
                             clock_map=clock_map)


def stream_summary(sinks: Sequence[Any]) -> list[dict[str, Any]]:
    """What each stream sent, for a session's JSON summary."""
    return [s.summary() for s in sinks if hasattr(s, "summary")]


__all__ = ["STREAM_KINDS", "DEFAULT_PORTS", "parse_stream_spec", "make_stream_sinks", "add_stream_arguments",
           "sinks_from_args", "stream_summary", "is_loopback"]
