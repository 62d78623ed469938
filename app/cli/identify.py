"""`imucap devices identify [URL...]`: move a sensor and see which device it is.

    imucap devices identify [URL ...] [--seconds S] [--threshold DEG_S] [--json]

Without URLs it listens to every device `imucap devices list` finds. Live, one line per
update: each device's angular speed, and "<- moving" after the one being moved (on a
terminal the line is rewritten in place; piped, a line per change and once a second).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Iterable
from typing import Any, TextIO
from urllib.parse import parse_qs, urlsplit


def short_label(url: str) -> str:
    """A few characters that tell devices apart on one terminal line."""
    u = urlsplit(url)
    q = parse_qs(u.query)
    if q.get("id"):
        return q["id"][0]
    if u.scheme == "xsens-can":
        return f"{u.path.strip('/')}{'+' + q['id_offset'][0] if q.get('id_offset') else ''}"
    if u.scheme == "dualsense":
        return "dualsense" + (f":{q['serial'][0][-6:]}" if q.get("serial") else "")
    if u.scheme == "moticon-udp":
        return f"insoles:{u.netloc.rpartition(':')[2]}"
    return (u.netloc + u.path).rstrip("/").rsplit("/", 1)[-1] or u.scheme


def unique_labels(urls: list[str]) -> dict[str, str]:
    labels: dict[str, str] = {}
    for url in urls:
        label = short_label(url)
        n = 2
        base = label
        while label in labels.values():
            label, n = f"{base}#{n}", n + 1
        labels[url] = label
    return labels


class LiveLine:
    """Prints speeds: one rewritten line on a terminal, plain lines (on change, else once a
    second) when the output is piped into a file or another program."""

    def __init__(self, labels: dict[str, str], out: TextIO, every_s: float = 1.0) -> None:
        self.labels, self.out = labels, out
        self.tty = out.isatty()
        self.every_s = every_s
        self._last_winner: str | None = None
        self._last_print = 0.0
        self._width = 0

    def update(self, speeds: dict[str, float], winner: str | None, failed: Iterable[str] = ()) -> None:
        gone = set(failed)
        parts = [f"{self.labels[u]} " + ("not open" if u in gone else f"{speeds.get(u, 0.0):4.0f} deg/s")
                 + (" <- moving" if u == winner else "") for u in self.labels]
        line = " | ".join(parts)
        now = time.monotonic()
        if self.tty:
            self.out.write("\r" + line.ljust(self._width))
            self._width = len(line)
            self.out.flush()
        elif winner != self._last_winner or now - self._last_print >= self.every_s:
            print(line, file=self.out, flush=True)
            self._last_print = now
        self._last_winner = winner

    def end(self) -> None:
        if self.tty and self._width:
            self.out.write("\n")
            self.out.flush()


def discovered_urls(discover: Callable[[], list[dict[str, Any]]]) -> list[str]:
    """The URLs of what ``discover`` (``imucap devices list``'s search) found and can open."""
    return [d["url"] for d in discover() if d.get("url")]


def cmd_identify(args: argparse.Namespace) -> int:
    from app.capture.identify import watch_devices

    urls = list(args.urls) or discovered_urls(args.discover)
    if not urls:
        print("imucap devices identify: no devices found; connect them, or give their URLs", file=sys.stderr)
        return 1
    labels = unique_labels(urls)
    errors: dict[str, str] = {}
    peaks: dict[str, float] = dict.fromkeys(urls, 0.0)
    last: dict[str, float] = dict.fromkeys(urls, 0.0)
    live = None if args.json else LiveLine(labels, sys.stdout)
    if live is not None:
        for url, label in labels.items():
            print(f"{label:>12} = {url}")
        print(f"listening for {args.seconds:g} s: move one sensor (Ctrl-C to stop)", flush=True)

    def on_update(speeds: dict[str, float], winner: str | None) -> None:
        last.update(speeds)
        for k, v in speeds.items():
            peaks[k] = max(peaks.get(k, 0.0), v)
        if live is not None:
            live.update(speeds, winner, errors)

    def on_error(url: str, why: str) -> None:
        errors[url] = why
        if live is not None:
            print(f"\n{labels[url]}: cannot open ({why})", file=sys.stderr, flush=True)

    winner = None
    try:
        winner = watch_devices(urls, args.seconds, on_update, threshold_dps=args.threshold, on_error=on_error)
    except KeyboardInterrupt:
        pass
    finally:
        if live is not None:
            live.end()
    if args.json:
        print(json.dumps(_summary(urls, labels, last, peaks, errors, winner)))
    else:
        print(f"moving: {winner}" if winner else "no device was moved")
    return 0


def _summary(urls: list[str], labels: dict[str, str], last: dict[str, float], peaks: dict[str, float],
             errors: dict[str, str], winner: str | None) -> dict[str, Any]:
    return {
        "moving": winner,
        "devices": [{"url": u, "label": labels[u], "speed_dps": round(last.get(u, 0.0), 1),
                     "peak_dps": round(peaks.get(u, 0.0), 1), "error": errors.get(u)} for u in urls],
    }


def add_parser(sub: argparse._SubParsersAction, discover: Callable[[], list[dict[str, Any]]]) -> None:
    """Registered by ``imucap devices``, which hands over its device search (so this module
    does not import its caller back)."""
    pi = sub.add_parser("identify", help="move a sensor and see which device (URL) it is")
    pi.add_argument("urls", nargs="*", metavar="URL", help="devices to listen to (default: every one found)")
    pi.add_argument("--seconds", type=float, default=30.0, help="listen this long")
    pi.add_argument("--threshold", type=float, default=60.0, help="deg/s above which a device counts as moving")
    pi.add_argument("--json", action="store_true", help="no live lines: one JSON object at the end")
    pi.set_defaults(func=cmd_identify, discover=discover)
