"""Where a pipeline's hub frames come from besides a live hub: synthesized signals
(``frames_from_signals``, device-less tests and replay) and a list released in real time or
at once (``ListSource``). Anything with ``poll() -> list[HubFrame]`` is a ``FrameSource``;
the hub is one, and ``LivePipeline`` also uses its ``due_in`` when it has one."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from drivers.hub import HubFrame
from inference.signals.site_signals import SiteSignals


class FrameSource(Protocol):
    def poll(self) -> list[HubFrame]: ...


def frames_from_signals(sig: SiteSignals, t0: float = 0.0, insoles: bool = False,
                        drop: dict[str, list[tuple[float, float]]] | None = None) -> list[HubFrame]:
    """Hub frames straight from synthesized signals (no devices): raw free acceleration
    (``meta['free_acc_raw']``, as a device streams it), specific force, gyro, quaternion;
    ``drop`` marks sites absent over (start, stop) second spans. For tests and replay."""
    raw = sig.meta.get("free_acc_raw", sig.free_acc) if sig.meta else sig.free_acc
    S = len(sig.sites)
    out = []
    for i in range(len(sig)):
        t = t0 + i / sig.fps
        present = np.ones(S, bool)
        for site, spans in (drop or {}).items():
            k = sig.sites.index(site)
            if any(a <= t - t0 < b for a, b in spans):
                present[k] = False
        q, fa = sig.quat[i].copy(), raw[i].copy()
        acc, gyro = sig.specific_force[i].copy(), sig.gyro[i].copy()
        for arr in (q, fa, acc, gyro):
            arr[~present] = np.nan
        force = sig.insole_force[i] if insoles else np.full(2, np.nan)
        out.append(HubFrame(t=t, index=i, sites=tuple(sig.sites), quat=q, free_acc=fa, acc=acc, gyro=gyro,
                            present=present, insole_force=force, contacts=sig.contacts[i].copy(),
                            insole_present=insoles))
    return out


class ListSource:
    """Frames from a list, released at the pace of ``clock`` (real time) or all at once
    (``realtime=False``): a FrameSource for tests and offline replay."""

    def __init__(self, frames: Sequence[HubFrame], realtime: bool = False,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.frames = list(frames)
        self.realtime = realtime
        self.clock = clock
        self._i = 0
        self._start: float | None = None

    @property
    def exhausted(self) -> bool:
        return self._i >= len(self.frames)

    def poll(self) -> list[HubFrame]:
        if self.exhausted:
            return []
        if not self.realtime:
            out, self._i = self.frames[self._i:], len(self.frames)
            return out
        if self._start is None:
            self._start = self.clock() - self.frames[0].t
        now = self.clock() - self._start
        j = self._i
        while j < len(self.frames) and self.frames[j].t <= now:
            j += 1
        out, self._i = self.frames[self._i:j], j
        return out
