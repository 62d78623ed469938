"""The simulated devices' process (``app/capture/simulator_process.py``): the devices appear at
the setup's URLs in another process and are read through the real drivers; the child ends
when it is stopped, when its parent dies, and says why when it cannot start."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from app.capture.setup_file import SetupError, load_setup
from app.capture.simulator_process import SimulatorProcess
from app.capture.twins import simulated_setup
from app.cli.devices import probe

pytestmark = pytest.mark.xdist_group("simulator_process")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie (exited, not yet reaped by its parent) counts as gone
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.parametrize("protocol", ["xbus", "xsens-can"])
def test_devices_are_read_from_the_other_process(tmp_path, protocol):
    """Serial devices on pseudo-terminals, CAN ones on a bus served on 127.0.0.1: both reach a
    driver in this process at the URLs the setup names."""
    setup = simulated_setup(("pelvis", "head"), protocol, folder=tmp_path, model="floor")
    with SimulatorProcess(setup, "walk", seconds=6.0, lead_in=1.0) as sim:
        assert sim.running and sim.proc is not None and sim.proc.pid != os.getpid()
        assert set(sim.urls) == {"pelvis", "head"}
        for name, url in setup.urls().items():  # as the child opened them (with their options)
            assert sim.urls[name].split("?")[0] == url.split("?")[0]
        assert sim.duration is not None and sim.duration > 6.0
        got = probe(setup.urls()["head"], 1.5)
    assert got["samples"] > 50, got
    assert not sim.running
    assert sim.stats is not None and '"head"' in sim.stats  # the child's packet counts, on its way out


def test_stop_ends_the_child_and_start_begins_again(tmp_path):
    setup = simulated_setup(("pelvis",), "xbus", folder=tmp_path, model="floor")
    sim = SimulatorProcess(setup, "walk", seconds=4.0, lead_in=1.0).start()
    proc = sim.proc
    assert proc is not None
    sim.stop()
    assert proc.returncode == 0  # ended by its closed input, not killed
    sim.restart()
    try:
        assert sim.running and sim.proc is not proc
        assert probe(setup.urls()["pelvis"], 1.0)["samples"] > 30
    finally:
        sim.stop()


def test_the_child_outlives_no_parent(tmp_path):
    """A window killed outright (kill -9) closes the pipe to its simulator, which then ends
    too: no devices left playing to nobody."""
    setup = simulated_setup(("pelvis",), "xbus", folder=tmp_path, model="floor")
    from app.capture.setup_file import save_setup

    path = tmp_path / "s.toml"
    save_setup(setup, path)
    parent = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from app.capture.simulator_process import SimulatorProcess
        sim = SimulatorProcess({str(path)!r}, "walk", seconds=120.0, lead_in=1.0).start()
        print(sim.proc.pid, flush=True)
        time.sleep(600)
    """)], stdout=subprocess.PIPE, text=True)
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        assert _alive(child)
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
        end = time.monotonic() + 30
        while _alive(child) and time.monotonic() < end:
            time.sleep(0.1)
        assert not _alive(child)
    finally:
        parent.kill()


def test_a_setup_the_simulator_refuses_is_one_line(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('[subject]\nid = "x"\nheight = 1.7\n\n[sensors]\npelvis = "nosuch:///dev/x"\n')
    with pytest.raises(SetupError):
        load_setup(bad)  # the setup itself is refused here already ...
    with pytest.raises(RuntimeError, match="did not start: imucap devices simulate: .*nosuch"):
        SimulatorProcess(bad, "walk", seconds=4.0).start()  # ... and by the child, in one line
