"""The simulated serial port behaves like a USB serial adapter under udev."""

from __future__ import annotations

import os
import select

import pytest
import serial

from sim_devices.devices.pty_port import PtyPort


def test_unplugged_port_has_no_link_and_replug_points_to_a_new_pty(tmp_path):
    """While unplugged the path must not exist: the kernel reuses pty numbers, so a
    link left on the closed pty could lead a reconnecting driver to another
    process's device (this happened under pytest-xdist)."""
    port = PtyPort(str(tmp_path / "tty"))
    port.open()
    try:
        with serial.Serial(port.link_path, timeout=0) as ser:
            port.write(b"abc")
            assert ser.read(3) == b"abc"
        port.close()
        assert not os.path.lexists(port.link_path)
        with pytest.raises(serial.SerialException):
            serial.Serial(port.link_path)
        port.open()
        assert os.path.exists(port.link_path)
        with serial.Serial(port.link_path, timeout=0) as ser:
            ser.write(b"xy")
            ser.flush()
            got = b""
            while len(got) < 2 and select.select([port.master], [], [], 5.0)[0]:
                got += port.read()
            assert got == b"xy"
        assert os.path.realpath(port.link_path).startswith("/dev/pts/")
    finally:
        port.remove()
    assert not os.path.lexists(port.link_path)
