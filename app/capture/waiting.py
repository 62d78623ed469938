"""Wait for a setup's devices to appear before a capture opens them.

Why: a device that is not there when the capture starts is an error (a typo in a URL must
not become an endless reconnect loop), but sensors are often switched on, plugged in or
started a moment after the command: a simulator synthesizing its motion, a DualSense
being paired, a USB hub enumerating. ``imucap capture --wait S`` gives them S seconds.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import drivers

POLL_S = 0.5


def wait_for_devices(urls: dict[str, str], timeout: float, say: Callable[[str], None] = lambda _m: None) -> None:
    """Return once every URL opens; after ``timeout`` seconds raise what the first one
    still missing raised, naming it. ``say`` hears once which devices are waited for."""
    deadline = time.monotonic() + timeout
    waiting = dict(urls)
    told = False
    while True:
        for name, url in list(waiting.items()):
            try:
                drivers.make_device(url, reconnect=False).open().close()
            except OSError as exc:  # not there (yet); a malformed URL raises ValueError at once
                last = (name, url, exc)
                continue
            del waiting[name]
        if not waiting:
            return
        if time.monotonic() >= deadline:
            name, url, exc = last
            raise OSError(f"{name} ({url}) did not appear within {timeout:g} s: {exc}")
        if not told:
            say(f"waiting up to {timeout:g} s for {', '.join(waiting)}")
            told = True
        time.sleep(POLL_S)
