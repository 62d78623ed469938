"""What the window tests share: settings in a temporary file, setup files for simulated
suits, the simulator in its own process, waiting with a useful failure message, and the
pixels of a grabbed view."""

from __future__ import annotations

import socket
import sys
from pathlib import Path

import numpy as np

from app.capture.simulator_process import SimulatorProcess
from sim_devices.devices.can_loopback import loopback_channel

CLI = [sys.executable, "-m", "app.cli.main"]
SKELETON_RGB = ((77, 179, 255), (219, 224, 235))  # colours.MEASURED and colours.INFERRED


def settings(tmp: Path):
    from PySide6 import QtCore

    return QtCore.QSettings(str(tmp / "imucap-settings.ini"), QtCore.QSettings.Format.IniFormat)


def shown_window(qtbot, tmp: Path):
    """The main window with its settings in ``tmp``, shown and exposed, closed with the test."""
    from app.gui.main import MainWindow

    win = MainWindow(settings(tmp))
    qtbot.addWidget(win)
    win.show()
    qtbot.waitExposed(win)
    return win


def choose_preset(win, name: str) -> None:
    """Pick the Setup tab's sensor preset whose name starts with ``name``, as a click does."""
    sp = win.setup_panel
    i = next(k for k in range(sp.preset.count()) if (sp.preset.itemData(k) or "").startswith(name))
    sp.preset.setCurrentIndex(i)
    sp.preset.activated.emit(i)


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def suit_urls(tmp: Path, can: bool = True) -> dict[str, str]:
    """The classic six over three wire protocols, as a lab might have them (``can=False``:
    serial ones only, Xbus and BNO08x on pseudo-terminals)."""
    can_bus = loopback_channel()  # the simulator serves the CAN bus on 127.0.0.1
    wrists = ((f"xsens-can://remote/{can_bus}?id_offset=0x100", f"xsens-can://remote/{can_bus}?id_offset=0x200")
              if can else (f"bno08x-rvc://{tmp}/l_wrist-tty", f"xbus://{tmp}/r_wrist-tty?baud=115200"))
    return {
        "pelvis": f"xbus://{tmp}/pelvis-tty?baud=115200",
        "head": f"bno08x-rvc://{tmp}/head-tty",
        "l_wrist": wrists[0],
        "r_wrist": wrists[1],
        "l_shank": f"bno08x-rvc://{tmp}/l_shank-tty",
        "r_shank": f"xbus://{tmp}/r_shank-tty?baud=115200",
    }


def write_setup(path: Path, urls: dict[str, str], insoles: str | None = None, subject: str = "sim-01",
                model: str = "diffusion") -> Path:
    lines = ["[subject]", f'id = "{subject}"', "height = 1.75", "", "[sensors]"]
    lines += [f'{site} = "{url}"' for site, url in urls.items()]
    if insoles:
        lines += ["", "[insoles]", f'url = "{insoles}"']
    lines += ["", "[model]", f'name = "{model}"', "", "[calibration]", 'protocol = "walk"', "",
              "[recording]", 'folder = "recordings"', ""]
    path.write_text("\n".join(lines))
    return path


class Simulator(SimulatorProcess):
    """``imucap devices simulate --setup`` in its own process, as a user runs it (walk after
    the protocol; started by ``wait_ready``)."""

    def __init__(self, setup: Path, lead_in: float = 20.0, truth: Path | None = None, unplug: str | None = None,
                 seed: int = 1) -> None:
        args = (["--truth", str(truth)] if truth is not None else []) + (["--unplug", unplug] if unplug else [])
        super().__init__(setup, "walk", seconds=40.0, seed=seed, lead_in=lead_in, args=args)

    def wait_ready(self, timeout: float = 180.0) -> float:
        """Until the devices are up; returns the simulation's length (s)."""
        self.start(timeout)
        assert self.duration is not None
        return self.duration


def wait(qtbot, cond, timeout_s: float, what: str, state=None) -> None:
    """qtbot.waitUntil with a message that says what was awaited and what the window shows."""
    try:
        qtbot.waitUntil(cond, timeout=int(timeout_s * 1000))
    except qtbot.TimeoutError as exc:
        extra = "" if state is None else f"; {state()}"
        raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}{extra}") from exc


def window_state(win) -> str:
    """What the window shows, for failure messages."""
    live = win.session
    bar = win.messages
    out = [f"message={bar.level}:{bar.label.text()!r}", f"session_label={win.session_label.text()!r}"]
    if live is not None:
        g = live.session.guided
        out += [f"calibration={g.status()!r}", f"perf={live.perf()}",
                f"devices={[(r.name, r.state, r.packets) for r in live.device_rows()]}"]
    return " ".join(out)


def image_array(img) -> np.ndarray:
    """(H, W, 3) uint8 of a QImage."""
    from PySide6 import QtGui

    img = img.convertToFormat(QtGui.QImage.Format.Format_RGB888)
    w, h, bpl = img.width(), img.height(), img.bytesPerLine()
    buf = np.frombuffer(img.constBits(), dtype=np.uint8, count=bpl * h).reshape(h, bpl)
    return buf[:, : 3 * w].reshape(h, w, 3).copy()


def skeleton_pixels(rgb: np.ndarray, tol: int = 40) -> int:
    """How many pixels have one of the skeleton's colours (bones measured or inferred)."""
    n = 0
    for c in SKELETON_RGB:
        n += int(np.sum(np.all(np.abs(rgb.astype(int) - np.array(c)) <= tol, axis=-1)))
    return n


def grab_view(view) -> np.ndarray:
    img = view.grabFramebuffer() if hasattr(view, "grabFramebuffer") else view.grab().toImage()
    return image_array(img)
