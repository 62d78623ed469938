"""Simulated CAN buses that another process reaches over loopback TCP.

Why: python-can's ``virtual`` bus lives inside one process, and its ``udp_multicast``
bus sends every frame to a multicast group, which the kernel routes out of the network
interface (loopback carries no multicast). A simulator must not put traffic on the
machine's network. So the simulated MTi-600s of a process send on an in-process
``virtual`` channel, and python-can-remote's server (a maintained python-can bridge,
``interface="remote"`` on the client side) serves that channel on 127.0.0.1: imucap opens
``xsens-can://remote/127.0.0.1:PORT`` and receives every frame, as a node on a real bus
would. The server binds loopback only; anything else is refused.

One server per port per process, shared by every twin on it, started by the first twin
and stopped when the last one is stopped for good (an unplugged twin only stops sending,
as a sensor pulled off a real bus does; the bus stays).
"""

from __future__ import annotations

import ipaddress
import socket
import socketserver
import threading
import uuid
from dataclasses import dataclass

from can_remote.server import RemoteServer

REMOTE_INTERFACE = "remote"


def split_host_port(channel: str) -> tuple[str, int]:
    """``127.0.0.1:54701`` -> (host, port); a ``ws://`` prefix is allowed (the client takes it)."""
    text = channel.split("://", 1)[-1].rstrip("/")
    host, sep, port = text.rpartition(":")
    host = host.strip("[]")
    if not sep or not host or not port.isdigit():
        raise ValueError(f"a loopback CAN channel is HOST:PORT, e.g. 127.0.0.1:54701, not {channel!r}")
    return host, int(port)


def free_loopback_port(kind: int = socket.SOCK_STREAM) -> int:
    """A port free on 127.0.0.1 now, TCP or (``socket.SOCK_DGRAM``) UDP: whoever serves it
    binds it a moment later."""
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def loopback_channel(channel: str | None = None) -> str:
    """``HOST:PORT`` with a free port in place of a missing or zero one."""
    host, port = split_host_port(channel) if channel else ("127.0.0.1", 0)
    return f"{host}:{port or free_loopback_port()}"


def is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a name would need resolving: not ours to serve


class _LoopbackRemoteServer(RemoteServer):
    """python-can-remote's server without the reverse name lookup ``HTTPServer.server_bind``
    makes (``socket.getfqdn``): a simulator resolves no names."""

    def server_bind(self) -> None:
        socketserver.TCPServer.server_bind(self)
        host, port = self.server_address[:2]
        self.server_name, self.server_port = str(host), int(port)


@dataclass
class _Served:
    server: _LoopbackRemoteServer
    thread: threading.Thread
    virtual_channel: str
    users: int = 0


class LoopbackCanServers:
    """The servers of this process, by (host, port)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._served: dict[tuple[str, int], _Served] = {}

    def acquire(self, channel: str) -> str:
        """Serve ``channel`` (HOST:PORT on a loopback address) if not yet served; returns the
        in-process ``virtual`` channel whose frames it carries."""
        host, port = split_host_port(channel)
        if not is_loopback(host):
            raise ValueError(f"simulated CAN is served on a loopback address (127.0.0.1, ::1), not {host!r}")
        with self._lock:
            served = self._served.get((host, port))
            if served is None:
                virtual = f"imucap-served-{port}-{uuid.uuid4().hex[:6]}"
                try:
                    server = _LoopbackRemoteServer(host, port, interface="virtual", channel=virtual,
                                                   receive_own_messages=False)
                except OSError as exc:
                    raise OSError(f"cannot serve simulated CAN on {host}:{port}: {exc.strerror or exc}") from exc
                thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1},
                                          name=f"can-server-{port}", daemon=True)
                thread.start()
                served = self._served[(host, port)] = _Served(server, thread, virtual)
            served.users += 1
            return served.virtual_channel

    def release(self, channel: str) -> None:
        host, port = split_host_port(channel)
        with self._lock:
            served = self._served.get((host, port))
            if served is None:
                return
            served.users -= 1
            if served.users > 0:
                return
            del self._served[(host, port)]
        served.server.shutdown()
        for client in list(served.server.clients):  # the bus is gone: its nodes hear so at once
            try:
                client.close()
            except OSError:
                pass
        served.server.server_close()
        served.thread.join(2.0)


SERVERS = LoopbackCanServers()
