# ruff: noqa: E501 (strace lines are kept as strace prints them)
"""The socket watch tells this machine from the network, on strace lines as strace prints them."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.socket_watch import STRACE, destinations, off_machine, watched

LOG = r"""
4986  connect(30, {sa_family=AF_UNIX, sun_path="/var/run/nscd/socket"}, 110) = -1 ENOENT (No such file or directory)
4986  connect(30, {sa_family=AF_INET, sin_port=htons(53), sin_addr=inet_addr("10.255.255.53")}, 16) = 0
4986  sendto(30, "8\270\1\0\0\1\0\0\0\0\0\0\6mobile"..., 50, MSG_NOSIGNAL, NULL, 0) = 50
2691  sendto(11, "I\1\200\200"..., 65, 0, {sa_family=AF_INET, sin_port=htons(43113), sin_addr=inet_addr("239.210.149.57")}, 16) = 65
5001  connect(7, {sa_family=AF_INET, sin_port=htons(41233), sin_addr=inet_addr("127.0.0.1")}, 16) = 0
5002  sendto(9, "a", 1, 0, {sa_family=AF_INET6, sin6_port=htons(9999), sin6_flowinfo=htonl(0), inet_pton(AF_INET6, "::1", &sin6_addr), sin6_scope_id=0}, 28) = 1
5003  sendto(9, "a", 1, 0, {sa_family=AF_INET6, sin6_port=htons(9999), sin6_flowinfo=htonl(0), inet_pton(AF_INET6, "::ffff:127.0.0.2", &sin6_addr), sin6_scope_id=0}, 28) = 1
5004  sendmsg(9, {msg_name={sa_family=AF_INET6, sin6_port=htons(5353), sin6_flowinfo=htonl(0), inet_pton(AF_INET6, "ff02::fb", &sin6_addr), sin6_scope_id=0}, msg_namelen=28}, 0) = 40
5005  connect(12, {sa_family=AF_NETLINK, nl_pid=0, nl_groups=00000000}, 12) = 0
"""


def test_loopback_is_this_machine_and_the_rest_is_not():
    found = {(d.call, d.address, d.port) for d in destinations(LOG)}
    assert found == {("connect", "10.255.255.53", 53), ("sendto", "239.210.149.57", 43113),
                     ("connect", "127.0.0.1", 41233), ("sendto", "::1", 9999), ("sendto", "::ffff:127.0.0.2", 9999),
                     ("sendmsg", "ff02::fb", 5353)}
    assert {d.address for d in off_machine(LOG)} == {"10.255.255.53", "239.210.149.57", "ff02::fb"}


@pytest.mark.skipif(STRACE is None, reason="strace not installed (scripts/test.sh installs it)")
def test_a_datagram_sent_elsewhere_is_seen(tmp_path):
    """A real traced process: a datagram to loopback, and a UDP socket connected to a
    documentation address (TEST-NET-1), which sends nothing: connecting a UDP socket only
    sets its default destination, so the watch is tested without any traffic leaving."""
    code = ("import socket; s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM); s.sendto(b'x', ('127.0.0.1', 9))\n"
            "u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
            "try: u.connect(('192.0.2.1', 9))\n"
            "except OSError: pass\n")
    log = tmp_path / "t.strace"
    subprocess.run(watched([sys.executable, "-c", code], log), check=True, timeout=60)
    text = log.read_text()
    assert {(d.call, d.address) for d in destinations(text)} == {("sendto", "127.0.0.1"), ("connect", "192.0.2.1")}
    assert [d.address for d in off_machine(text)] == ["192.0.2.1"]
