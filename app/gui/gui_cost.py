"""What the window itself costs, measured from inside it: the GUI thread's CPU time, the
time each pose takes to hand to the view, how often the view is redrawn and how late the
view timer arrives. ``--window-stats FILE`` on the commands that open a window writes it at
``--quit-after``; ``benchmarks/window_live.py`` sets it beside the headless demo's figures."""

from __future__ import annotations

import json
import os
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np


@dataclass
class GuiCost:
    """Counters kept by the window on its own (GUI) thread."""

    wall0: float = field(default_factory=time.monotonic)
    thread0: float = field(default_factory=time.thread_time)  # the GUI thread's CPU time at start
    process0: float = field(default_factory=time.process_time)
    draw_ms: deque[float] = field(default_factory=lambda: deque(maxlen=20_000))
    status_ms: deque[float] = field(default_factory=lambda: deque(maxlen=20_000))
    lag_ms: deque[float] = field(default_factory=lambda: deque(maxlen=20_000))
    first_draw: float | None = None
    last_draw: float | None = None

    def drew(self, t: float, ms: float) -> None:
        self.draw_ms.append(ms)
        if self.first_draw is None:
            self.first_draw = t
        self.last_draw = t

    def summary(self, frames_shown: int) -> dict[str, Any]:
        """Call on the GUI thread (its CPU time is read there)."""
        wall = max(time.monotonic() - self.wall0, 1e-9)

        def pct(values: deque[float], q: float) -> float | None:
            return round(float(np.percentile(values, q)), 2) if values else None

        # the rate while the live view was drawing (not over the start-up and the calibration)
        span = (self.last_draw - self.first_draw) if self.first_draw is not None and self.last_draw else 0.0
        n = len(self.draw_ms)
        return {
            "wall_s": round(wall, 2), "frames_shown": frames_shown,
            "draws_per_s": round((n - 1) / span, 2) if n > 1 and span > 0 else None,
            "gui_thread_cores": round((time.thread_time() - self.thread0) / wall, 3),
            "process_cores": round((time.process_time() - self.process0) / wall, 3),
            "draw_p50_ms": pct(self.draw_ms, 50), "draw_p99_ms": pct(self.draw_ms, 99),
            "status_p50_ms": pct(self.status_ms, 50), "status_p99_ms": pct(self.status_ms, 99),
            "timer_lag_p50_ms": pct(self.lag_ms, 50), "timer_lag_p99_ms": pct(self.lag_ms, 99),
            "cpus": os.cpu_count(), "load_avg_1min": round(os.getloadavg()[0], 2),
        }

    def write(self, path: str | Path, frames_shown: int, extra: dict[str, Any] | None = None) -> None:
        Path(path).write_text(json.dumps({**self.summary(frames_shown), **(extra or {})}))
