"""A 60 s capture over wireless twins against one over wired twins, on the same walk.

Each setup has six sensors and insoles, simulated in their own process by `imucap devices
simulate --setup` (the walk calibration, then the walk) and captured by `imucap capture
--headless --record` in another; `imucap replay --truth` scores each recording. Wireless: two
Movella DOTs (BLE seam), two x-IMU3s (UDP), an Xbus MTi and an MTi-600 on CAN; wired: Xbus,
BNO08x and MTi-600s only.

    python benchmarks/wireless_capture.py [--seconds 60]    # one line per setup, then the JSON
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.capture.twins import free_udp_port  # noqa: E402
from sim_devices.devices.can_loopback import loopback_channel  # noqa: E402
from sim_devices.devices.wireless_twins import dot_address  # noqa: E402

CLI = [sys.executable, "-m", "app.cli.main"]


def sensors(kind: str, tmp: Path) -> str:
    def x3() -> str:
        return f'"ximu3://udp/{free_udp_port()}?ip=127.0.0.1&send_port={free_udp_port()}"'

    can = loopback_channel()
    if kind == "wireless":
        ble = tmp / "ble"
        rows = {"pelvis": f'"xbus://{tmp}/{kind}-pelvis-tty?baud=115200"',
                "head": f'"movella-dot://{dot_address("head")}?ble={ble}"', "l_wrist": x3(),
                "r_wrist": f'"xsens-can://remote/{can}?id_offset=0x100"',
                "l_shank": f'"movella-dot://{dot_address("l_shank")}?ble={ble}"', "r_shank": x3()}
    else:
        rows = {"pelvis": f'"xbus://{tmp}/{kind}-pelvis-tty?baud=115200"', "head": f'"bno08x-rvc://{tmp}/{kind}-head-tty"',
                "l_wrist": f'"xsens-can://remote/{can}?id_offset=0x100"',
                "r_wrist": f'"xsens-can://remote/{can}?id_offset=0x200"',
                "l_shank": f'"bno08x-rvc://{tmp}/{kind}-l_shank-tty"',
                "r_shank": f'"xbus://{tmp}/{kind}-r_shank-tty?baud=115200"'}
    return "\n".join(f"{k} = {v}" for k, v in rows.items())


def run(kind: str, tmp: Path, motion: Path) -> dict:
    setup = tmp / f"{kind}.toml"
    setup.write_text(f'[subject]\nid = "sim-60"\nheight = 1.75\n\n[sensors]\n{sensors(kind, tmp)}\n\n[insoles]\n'
                     f'url = "moticon-udp://127.0.0.1:{free_udp_port()}"\n\n[calibration]\nprotocol = "walk"\n')
    truth, rec = tmp / f"{kind}-truth.npz", tmp / f"{kind}.h5"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    sim = subprocess.Popen([*CLI, "devices", "simulate", "--setup", str(setup), "--motion", str(motion), "--truth",
                            str(truth), "--lead-in", "15", "--seed", "1"], stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True, env=env)
    try:
        lines = []
        for line in sim.stdout:  # type: ignore[union-attr]
            lines.append(line)
            if line.startswith("simulating"):
                break
        duration = float(lines[-1].split()[1])
        cap = subprocess.run([*CLI, "capture", "--setup", str(setup), "--headless", "--record", str(rec),
                              "--seconds", f"{duration - 4.0:.1f}", "--json", "--countdown", "1"], input="",
                             capture_output=True, text=True, env=env)
    finally:
        sim.terminate()
        sim.wait(10)
    if cap.returncode != 0:
        return {"error": cap.stderr[-1500:]}
    rep = subprocess.run([*CLI, "replay", str(rec), "--truth", str(truth), "--json", "--no-progress"],
                         capture_output=True, text=True)
    if rep.returncode != 0:
        return {"error": rep.stderr[-1500:]}
    r = json.loads(rep.stdout)
    return {"duration_s": duration, "ga_deg": r.get("ga_deg"), "recorded_ga_deg": r.get("recorded_ga_deg")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=60.0, help="length of the walk after the calibration")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="imucap-wireless-"))
    motion = tmp / "walk.npz"
    subprocess.run([*CLI, "data", "generate", "walk", "--seconds", f"{args.seconds:g}", "--seed", "3", "--out",
                    str(motion)], check=True, capture_output=True)
    out = {}
    for kind in ("wireless", "wired"):
        out[kind] = run(kind, tmp, motion)
        print(kind, out[kind], flush=True)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
