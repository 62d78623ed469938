"""A pseudo-terminal that looks like a USB serial port, with a stable path.

The driver opens a symlink (as udev's /dev/serial/by-id links work); unplugging
closes the pty and removes the link (as udev removes a by-id link), plugging back
in makes a new pty and a new link, so the driver's reconnect sees exactly what it
sees with real hardware: EIO on the old port, no such file while unplugged, then
the same path working again. (A link left pointing at the closed pty would be a
trap no real port sets: the kernel hands its number to the next pty opened on the
machine, and a reconnecting driver would open someone else's device.)
"""

from __future__ import annotations

import os
import pty
import tempfile
import tty


class PtyPort:
    def __init__(self, link_path: str | None = None) -> None:
        if link_path is None:
            d = tempfile.mkdtemp(prefix="imucap-sim-")
            link_path = os.path.join(d, "tty")
        self.link_path = link_path
        self.master: int | None = None
        self._slave: int | None = None

    def open(self) -> None:
        master, slave = pty.openpty()
        tty.setraw(slave)
        os.set_blocking(master, False)
        name = os.ttyname(slave)
        tmp = f"{self.link_path}.{os.getpid()}.tmp"
        if os.path.lexists(tmp):
            os.unlink(tmp)
        os.symlink(name, tmp)
        os.replace(tmp, self.link_path)
        self.master, self._slave = master, slave

    def close(self) -> None:
        if self.master is not None:
            try:
                os.unlink(self.link_path)
            except OSError:
                pass
        for fd in (self.master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self.master = self._slave = None

    def write(self, data: bytes) -> None:
        if self.master is None:
            raise OSError("pty closed")
        n = os.write(self.master, data)
        if n < len(data):
            raise BlockingIOError("pty buffer full")

    def read(self) -> bytes:
        if self.master is None:
            return b""
        try:
            return os.read(self.master, 4096)
        except (BlockingIOError, OSError):
            return b""

    def remove(self) -> None:
        self.close()
        try:
            os.unlink(self.link_path)
        except OSError:
            pass
