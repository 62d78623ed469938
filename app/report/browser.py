"""Headless Chromium (Debian's ``chromium`` package) for the report's PDF, and for looking at a report as
a reader's browser shows it (a screenshot, the DOM after layout).

Each run gets a fresh profile folder and the flags that keep it from reaching out (no background
networking, component updates or sync): the page is a local file with its images inlined.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run")
NAMES = ("chromium", "chromium-browser", "google-chrome")
TIMEOUT_S = 180.0


def find_chromium() -> str | None:
    override = os.environ.get("IMUCAP_CHROMIUM")
    if override:
        return override
    for n in NAMES:
        p = shutil.which(n)
        if p:
            return p
    return None


def _run(args: list[str], timeout: float = TIMEOUT_S) -> subprocess.CompletedProcess:
    exe = find_chromium()
    if exe is None:
        raise FileNotFoundError("no chromium found (apt-get install chromium); the HTML report needs none, "
                                "--pdf does")
    with tempfile.TemporaryDirectory(prefix="imucap-chromium-") as profile:
        cmd = [exe, *FLAGS, f"--user-data-dir={profile}", *args]
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    return res


def print_pdf(html_path: str | Path, pdf_path: str | Path) -> Path:
    pdf = Path(pdf_path).resolve()
    if pdf.exists():
        pdf.unlink()
    res = _run(["--no-pdf-header-footer", f"--print-to-pdf={pdf}", Path(html_path).resolve().as_uri()])
    if not pdf.exists() or pdf.stat().st_size == 0:
        raise OSError(f"chromium wrote no PDF (exit {res.returncode}): {res.stderr.strip()[-400:]}")
    return pdf


def screenshot(html_path: str | Path, png_path: str | Path, width: int = 1100, height: int = 4000) -> Path:
    png = Path(png_path).resolve()
    if png.exists():
        png.unlink()
    res = _run([f"--screenshot={png}", f"--window-size={width},{height}", "--hide-scrollbars",
                Path(html_path).resolve().as_uri()])
    if not png.exists() or png.stat().st_size == 0:
        raise OSError(f"chromium took no screenshot (exit {res.returncode}): {res.stderr.strip()[-400:]}")
    return png


def dump_dom(html_path: str | Path) -> str:
    """The page's DOM as the browser built it (serialised HTML)."""
    res = _run(["--dump-dom", Path(html_path).resolve().as_uri()])
    if res.returncode != 0 or "<html" not in res.stdout:
        raise OSError(f"chromium dumped no DOM (exit {res.returncode}): {res.stderr.strip()[-400:]}")
    return res.stdout
