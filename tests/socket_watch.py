"""Where processes send: every socket destination of a command, read off ``strace``.

Why strace and not a Python hook: what leaves the machine is often sent by a compiled
library on a thread of its own (ONNX Runtime's telemetry resolved Microsoft's event host
that way), which no Python-level hook sees. ``strace -f`` records every ``connect``,
``sendto``, ``sendmsg`` and ``sendmmsg`` of the process and all its threads and children;
a destination is any internet address in those calls. Loopback (127.0.0.0/8, ::1, and
IPv4-mapped loopback) is this machine; anything else, multicast and the resolver
included, is traffic that leaves it.

Tracing slows the traced process, so a test that watches must not also judge real-time
behaviour. ``--seccomp-bpf`` keeps the slowdown to the four calls watched: without it strace
stops the process at every system call (each futex, poll and read) and drops the others
itself, and a traced capture read the CAN bus at a fraction of its rate. strace proceeds
without the filter where the kernel refuses it.
"""

from __future__ import annotations

import ipaddress
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

STRACE = shutil.which("strace")
CALLS = "connect,sendto,sendmsg,sendmmsg"
_CALL = re.compile(r"^(?:\d+\s+)?(?:[\d:.]+\s+)?(?P<call>connect|sendto|sendmsg|sendmmsg)\(")
_V4 = re.compile(r"sa_family=AF_INET, sin_port=htons\((?P<port>\d+)\), sin_addr=inet_addr\(\"(?P<addr>[^\"]+)\"\)")
_V6 = re.compile(r"sa_family=AF_INET6, sin6_port=htons\((?P<port>\d+)\).*?inet_pton\(AF_INET6, \"(?P<addr>[^\"]+)\"")


@dataclass(frozen=True)
class Destination:
    call: str
    address: str
    port: int

    @property
    def on_this_machine(self) -> bool:
        ip = ipaddress.ip_address(self.address)
        if isinstance(ip, ipaddress.IPv6Address) and ip.ipv4_mapped is not None:
            ip = ip.ipv4_mapped
        return ip.is_loopback

    def __str__(self) -> str:
        return f"{self.call} to {self.address} port {self.port}"


def watched(cmd: list[str], log: Path) -> list[str]:
    """``cmd`` run under strace, every thread and child followed, its socket calls written to ``log``."""
    if STRACE is None:
        raise RuntimeError("strace is not installed (scripts/test.sh installs it)")
    return [STRACE, "-f", "--seccomp-bpf", "-qq", "-e", f"trace={CALLS}", "-e", "signal=none", "-o", str(log), *cmd]


def destinations(text: str) -> list[Destination]:
    """Every internet destination in an strace log of ``CALLS`` (local sockets, netlink and
    calls on connected sockets, which name no address, are not destinations)."""
    out = []
    for line in text.splitlines():
        m = _CALL.match(line)
        if m is None:
            continue
        for pat in (_V4, _V6):
            for d in pat.finditer(line):
                out.append(Destination(m["call"], d["addr"], int(d["port"])))
    return out


def off_machine(text: str) -> list[Destination]:
    return [d for d in destinations(text) if not d.on_this_machine]
