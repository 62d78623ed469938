"""Which URLs a simulator serves, a setup's simulated twin, and the CLI around them:
`devices simulate --setup` on real devices' URLs says what to do, `--twin-setup` does it,
`setup example` writes the simulated suit, `capture --wait` waits for late devices."""

from __future__ import annotations

import subprocess
import sys
import time

import pytest

from app.capture.setup_file import load_setup
from app.capture.twins import simulation_problem, twin_setup
from app.capture.waiting import wait_for_devices
from tests.conftest import REPO

CLI = [sys.executable, "-m", "app.cli.main"]
REAL = REPO / "examples" / "setup_example.toml"
SIMULATED = REPO / "examples" / "simulated_suit.toml"


@pytest.mark.parametrize("url, why", [
    ("xbus:///dev/ttyUSB0?baud=115200", "real serial port"),
    ("dualsense://", "real DualSense"),
    ("xsens-can://socketcan/can0?id_offset=0x100", "real CAN bus"),
    ("xsens-can://virtual/imucap", "does not cross processes"),
    ("xsens-can://udp_multicast/239.1.2.3", "leaves this machine"),
    ("xsens-can://remote/192.0.2.7:54701", "not a loopback address"),
    ("moticon-udp://192.0.2.7:9999", "not a loopback address"),
])
def test_urls_a_simulator_cannot_serve_say_why(url, why):
    assert why in (simulation_problem(url) or "")


@pytest.mark.parametrize("url", ["xbus:///tmp/x/pelvis-tty", "bno08x-rvc:///tmp/x/head-tty",
                                 "xsens-can://remote/127.0.0.1:54701?id_offset=0x100", "dualsense://unix/tmp/x/p.sock",
                                 "moticon-udp://127.0.0.1:9999", "xsens-can://remote/[::1]:54701"])
def test_urls_on_this_machine_can_be_served(url):
    assert simulation_problem(url) is None


def test_the_example_setups(tmp_path):
    sim = load_setup(SIMULATED)
    assert all(simulation_problem(u) is None for u in sim.urls().values())
    protocols = {u.split(":")[0] for u in sim.urls().values()}
    assert protocols == {"xbus", "bno08x-rvc", "xsens-can", "dualsense", "moticon-udp"}  # every one served across
    real = load_setup(REAL)
    assert [n for n, u in real.urls().items() if simulation_problem(u)] == ["pelvis", "head", "l_wrist", "r_wrist",
                                                                            "l_shank", "r_shank"]
    twin = twin_setup(real, tmp_path)
    assert all(simulation_problem(u) is None for u in twin.urls().values()), twin.urls()
    assert (twin.subject, twin.model, twin.steps, twin.calibration) == (real.subject, real.model, real.steps,
                                                                        real.calibration)
    for site in real.sites():  # the same protocol at every site; CAN devices keep their identifier blocks
        assert twin.sensors[site].url.split(":")[0] == real.sensors[site].url.split(":")[0]
        assert twin.sensors[site].label == real.sensors[site].label
    assert twin.sensors["l_shank"].url.endswith("?id_offset=0x200")
    assert twin.insoles == real.insoles  # already on loopback


def test_simulating_real_urls_says_what_to_do_and_twin_setup_does_it(tmp_path):
    out = subprocess.run([*CLI, "devices", "simulate", "--setup", str(REAL), "--motion", "walk"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "pelvis = xbus:///dev/ttyUSB0" in out.stderr and "--twin-setup" in out.stderr
    sim_toml = tmp_path / "sim.toml"
    out = subprocess.run([*CLI, "devices", "simulate", "--setup", str(REAL), "--twin-setup", str(sim_toml),
                          "--motion", "walk", "--lead-in", "1", "--activity-seconds", "2", "--seconds", "1"],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    twin = load_setup(sim_toml)
    assert all(simulation_problem(u) is None for u in twin.urls().values())
    served = dict(line.split(" ", 1) for line in out.stdout.splitlines() if line.split(" ", 1)[0] in twin.urls())
    for name, url in twin.urls().items():  # it served what it wrote
        assert served[name].split("?")[0] == url.split("?")[0]



def test_a_terminated_simulator_stops_its_devices_and_writes_its_send_log(tmp_path):
    """SIGTERM (a test harness, a service manager) ends a simulated session as Ctrl-C does: exit 0,
    the statistics printed and ``--log-sends`` written, with every device's packets up to then."""
    import numpy as np

    from tests.app.capture.live_capture import start_simulator

    sim_toml = tmp_path / "sim.toml"
    subprocess.run([*CLI, "devices", "simulate", "--setup", str(REAL), "--twin-setup", str(sim_toml), "--motion",
                    "walk", "--lead-in", "1", "--activity-seconds", "2", "--seconds", "0.1"],
                   capture_output=True, text=True, timeout=300, check=True)
    sends = tmp_path / "sends.npz"
    sim = start_simulator(["--setup", str(sim_toml), "--motion", "walk", "--lead-in", "30",
                           "--activity-seconds", "2", "--log-sends", str(sends)])
    time.sleep(1.0)
    sim.proc.stdin.close()
    sim.proc.terminate()
    assert sim.proc.wait(30) == 0, sim.proc.stderr.read()[-2000:]
    assert '"packets"' in sim.proc.stderr.read()  # the statistics, as after Ctrl-C
    log = np.load(sends)
    counts = {k.split("/")[0]: len(log[k]) for k in log.files if k.endswith("/counter")}
    served = {line.split(" ", 1)[0] for line in sim.lines[:-1]}  # "name url" per device, then "simulating"
    assert set(counts) == served, (counts, served)
    assert max(counts.values()) > 20, counts  # ~1 s at 100 Hz: a device that sends without a reader

def test_setup_example_writes_the_simulated_suit_and_keeps_an_existing_file(tmp_path):
    target = tmp_path / "suit.toml"
    out = subprocess.run([*CLI, "setup", "example", str(target)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and target.read_text() == SIMULATED.read_text()
    target.write_text("mine")
    out = subprocess.run([*CLI, "setup", "example", str(target)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "exists" in out.stderr and target.read_text() == "mine"


def test_waiting_for_devices_names_the_one_that_never_came(tmp_path):
    said: list[str] = []
    with pytest.raises(OSError, match=r"pelvis \(xbus://.*\) did not appear within 0.6 s"):
        wait_for_devices({"pelvis": f"xbus://{tmp_path}/none-tty"}, 0.6, say=said.append)
    assert said == ["waiting up to 0.6 s for pelvis"]
