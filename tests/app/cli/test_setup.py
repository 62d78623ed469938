"""`imucap setup new` and `imucap setup check` as a user runs them: in their own process,
answers on the standard input, against simulated devices at real ports and sockets."""

from __future__ import annotations

import json
import queue
import re
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from app.capture.setup_file import load_setup
from app.cli.main import main
from sim_devices.devices import make_sim_device, spinning_signals

REPO = Path(__file__).resolve().parents[3]
IMUCAP = [sys.executable, "-m", "app.cli.main"]


def sim(protocol: str, site: str, rate_dps: float = 0.0, **kw):
    return make_sim_device(protocol, spinning_signals((site,), seconds=30.0, rate_dps=rate_dps), site, **kw).start()


@pytest.fixture
def devices():
    started: list = []

    def start(*args, **kw):
        started.append(sim(*args, **kw))
        return started[-1]

    yield start
    for d in started:
        d.stop()


class Session:
    """A running `imucap` whose output is read line by line while the test types."""

    def __init__(self, args: list[str]) -> None:
        self.proc = subprocess.Popen(IMUCAP + args, cwd=REPO, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE, text=True, bufsize=1)
        self.lines: queue.Queue[str] = queue.Queue()
        self.seen: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        for line in self.proc.stdout:
            self.lines.put(line)

    def expect(self, text: str, timeout: float = 30.0) -> str:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            try:
                line = self.lines.get(timeout=0.1)
            except queue.Empty:
                continue
            self.seen.append(line)
            if text in line:
                return line
        raise AssertionError(f"{text!r} never came; output so far:\n{''.join(self.seen)}")

    def type(self, text: str) -> None:
        self.proc.stdin.write(text)
        self.proc.stdin.flush()

    def finish(self, timeout: float = 30.0) -> tuple[int, str, str]:
        self.proc.stdin.close()
        rc = self.proc.wait(timeout)
        rest = []
        while not self.lines.empty():
            rest.append(self.lines.get())
        return rc, "".join(self.seen + rest), self.proc.stderr.read()


def test_new_assigns_the_moved_device_and_enter_skips(devices, tmp_path):
    still = devices("bno08x-rvc", "pelvis", 0.0)
    moved = devices("bno08x-rvc", "l_wrist", 180.0)
    insoles = make_sim_device("moticon-udp", spinning_signals(("l_foot",), seconds=5.0), "insoles")  # its URL only
    out = tmp_path / "lab.toml"
    s = Session(["setup", "new", str(out), "--url", still.url, "--url", moved.url,
                 "--sites", "l_wrist,r_wrist,pelvis", "--seconds-per-site", "3"])
    try:
        s.type("P014\n1.72\nleft knee brace\n")
        assert moved.url in s.expect("l_wrist ->")
        s.expect("move the sensor for r_wrist now (Enter to skip)")
        s.type("\n")
        s.expect("r_wrist: skipped")
        # only the still one is left to choose from, and it does not move: the site times out
        s.expect("pelvis: no sensor moved within 3 s")
        s.type("xbus:///dev/ttyUSB9\n")  # not insoles: asked again
        s.type(insoles.url + "\n")
        rc, stdout, stderr = s.finish()
    finally:
        s.proc.kill()
    assert rc == 0, stderr
    assert "is an IMU, not insoles" in stdout and f"wrote {out}" in stdout
    setup = load_setup(out)
    assert setup.subject.id == "P014" and setup.subject.height_m == 1.72 and setup.subject.notes == "left knee brace"
    assert setup.urls() == {"l_wrist": moved.url, "insoles": insoles.url}


def test_new_with_every_answer_piped_never_assigns_a_device_twice(devices, tmp_path):
    moved = devices("bno08x-rvc", "r_wrist", 200.0)
    out = tmp_path / "lab.toml"
    r = subprocess.run(IMUCAP + ["setup", "new", str(out), "--url", moved.url, "--sites", "r_wrist,l_wrist",
                                 "--seconds-per-site", "3"],
                       cwd=REPO, input="S2\n1.8\n", capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "r_wrist -> " in r.stdout
    assert "every open device has a site; l_wrist left without one" in r.stdout
    setup = load_setup(out)
    assert setup.urls() == {"r_wrist": moved.url} and setup.subject.notes == ""


def test_new_refuses_to_replace_a_file_and_bad_sites(tmp_path, capsys):
    out = tmp_path / "lab.toml"
    out.write_text("keep me")
    assert main(["setup", "new", str(out), "--url", "dualsense://unix/x"]) == 2
    assert "exists" in capsys.readouterr().err and out.read_text() == "keep me"
    assert main(["setup", "new", str(tmp_path / "n.toml"), "--sites", "pelvis,l_wirst", "--url", "dualsense://"]) == 2
    assert "did you mean l_wrist?" in capsys.readouterr().err


def write_setup(path: Path, sensors: dict[str, str], insoles: str | None = None) -> Path:
    lines = ["[subject]", 'id = "P1"', "height = 1.75", "", "[sensors]"]
    lines += [f"{site} = {value}" for site, value in sensors.items()]
    if insoles:
        lines += ["", "[insoles]", f'url = "{insoles}"']
    path.write_text("\n".join(lines) + "\n")
    return path


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_check_reports_rates_battery_and_insoles(devices, tmp_path):
    pelvis = devices("bno08x-rvc", "pelvis")
    wrist = devices("dualsense", "r_wrist")
    # the insoles' app streams from elsewhere: a process of its own, as `imucap devices simulate` runs
    insoles = subprocess.Popen(IMUCAP + ["devices", "simulate", "--protocol", "moticon-udp", "--motion", "spin",
                                         "--port", str(free_udp_port()), "--seconds", "30"],
                               cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        insoles_url = insoles.stdout.readline().strip()
        f = write_setup(tmp_path / "lab.toml", {"pelvis": f'"{pelvis.url}"',
                                                "r_wrist": f'{{ url = "{wrist.url}", serial = "A1B2" }}'},
                        insoles_url)
        r = subprocess.run(IMUCAP + ["setup", "check", str(f), "--seconds", "1.5", "--json"], cwd=REPO,
                           capture_output=True, text=True, timeout=60)
    finally:
        insoles.kill()
        insoles.wait()
    out = json.loads(r.stdout)
    assert r.returncode == (0 if out["ok"] else 1), r.stderr
    assert set(out["devices"]) == {"pelvis", "r_wrist", "insoles"}
    pel, ds, ins = (out["devices"][k] for k in ("pelvis", "r_wrist", "insoles"))
    assert pel["ok"] and ds["ok"], out
    assert 80 <= pel["rate_hz"] <= 120 and pel["samples"] > 100 and pel["errors"] == 0
    assert pel["battery_pct"] is None  # the RVC stream has no battery
    assert ds["battery_pct"] == 85.0 and ds["rate_hz"] > 200
    assert ds["serial_expected"] == "A1B2" and ds["serial_match"] is None  # this protocol reports none
    # the simulated insoles stamp their stream with the wall clock, so on a loaded machine a
    # late packet reads as a lost one: tolerated here, anything else is not
    assert ins["samples"] > 50 and ins["rate_hz"] > 50
    assert all(p.startswith("lost") for p in ins["problems"]), ins["problems"]


def test_check_names_a_dead_url_and_a_slow_device(devices, tmp_path):
    pelvis = devices("bno08x-rvc", "pelvis")
    slow = devices("bno08x-rvc", "head", rate=20.0)
    nobody = tmp_path / "ttyNOBODY"
    f = write_setup(tmp_path / "lab.toml", {"pelvis": f'"{pelvis.url}"', "head": f'"{slow.url}"',
                                            "l_shank": f'"bno08x-rvc://{nobody}"'})
    r = subprocess.run(IMUCAP + ["setup", "check", str(f), "--seconds", "1.5"], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1, r.stdout + r.stderr
    blocks = r.stdout.split("\n")
    shank = next(i for i, line in enumerate(blocks) if line.startswith("l_shank"))
    assert "does not answer (check power/cable/URL)" in blocks[shank + 2]
    head = next(i for i, line in enumerate(blocks) if line.startswith("head"))
    # the rate on the host's clock: a loaded machine reads a 20 Hz device at 18-22 Hz
    rate = re.search(r"rate (\d+) Hz, expected >= 50", blocks[head + 2])
    assert rate and 15 <= int(rate.group(1)) <= 25, blocks[head + 2]
    pel = next(i for i, line in enumerate(blocks) if line.startswith("pelvis"))
    assert blocks[pel + 1].endswith(": ok")
    assert "2 of 3 device(s) with a problem" in r.stdout


def test_check_on_a_broken_file_is_one_line_and_exit_2(tmp_path, capsys):
    f = write_setup(tmp_path / "lab.toml", {"l_wirst": '"dualsense://"'})
    assert main(["setup", "check", str(f)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"{f}:6: unknown site 'l_wirst'") and "\n" not in err
