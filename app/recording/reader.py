"""Reading a recording whole (``read_recording``), chunk by chunk where it must: a chunk
that fails its checksum, a part cut off or never written costs its own rows, which
``Recording.damage`` lists, never the dataset, the group or the file."""

from __future__ import annotations

import json
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from app.recording.format import (
    EVENT_FIELDS,
    HDF5_SIGNATURE,
    INSOLE_FIELDS,
    POSITION_FIELD,
    RECON_FIELDS,
    RECON_NEWER,
    SITE_FIELDS,
    calibration_fields,
    fault_text,
    fill_value,
)
from app.recording.header import RecordingError, in_heap, open_recording_header
from calibration import Calibration
from drivers.hub import HubFrame
from inference.body.rotations import quat_to_matrix
from inference.body.skeleton import N_SEGMENTS

# a chunk of a file still (or last) open for writing that fails its read is tried again
# twice after this pause, in case the writer was rewriting it
IN_FLIGHT_RETRY_S = 0.01


@dataclass
class Recording:
    """A recording in memory. raw: ``t``, ``index`` and per site dicts (quat, free_acc,
    acc, gyro, present, and ``position`` at a tracked device's sites) plus ``insoles``;
    calibrations: (t, Calibration) in order;
    recon: arrays as in the file, ``rot`` also as matrices under ``R``.

    damage: one line per stretch that could not be read (a chunk whose checksum failed,
    a part cut off, rows never written), e.g. ``raw/l_wrist/quat frames 1024-1279
    (t 17.1-21.3 s): checksum failed, skipped``, t in seconds from the first raw frame as
    in exports. What it names is not in the arrays: raw frames without a readable time
    are dropped, a site's damaged samples are not ``present`` (NaN), damaged poses,
    calibrations and events are dropped. checksums: every dataset carried Fletcher32
    (recordings from before the checksums did not, and were read unverified)."""

    path: Path
    sites: tuple[str, ...]
    metadata: dict[str, Any]
    raw: dict[str, Any]
    calibrations: list[tuple[float, Calibration]]
    recon: dict[str, np.ndarray]
    attrs: dict[str, Any] = field(default_factory=dict)
    events: list[tuple[float, str, str]] = field(default_factory=list)
    damage: list[str] = field(default_factory=list)
    checksums: bool = True

    def markers(self) -> list[tuple[float, str]]:
        return [(t, d) for t, k, d in self.events if k == "marker"]

    @property
    def n_frames(self) -> int:
        return int(len(self.raw["t"]))

    @property
    def position_sites(self) -> tuple[str, ...]:
        """The sites whose positions were kept (a VR rig's; none in older recordings)."""
        return tuple(s for s in self.sites if "position" in self.raw.get(s, {}))

    def positions(self) -> np.ndarray | None:
        """(N, S, 3) the kept positions over ``sites`` (NaN at the others), or None when the
        recording kept none: what the hub's frames held (``HubFrame.position``)."""
        if not self.position_sites:
            return None
        out = np.full((self.n_frames, len(self.sites), 3), np.nan)
        for k, s in enumerate(self.sites):
            if "position" in self.raw[s]:
                out[:, k] = self.raw[s]["position"]
        return out

    def hub_frames(self) -> list[HubFrame]:
        """The raw stream as hub frames, to replay through a ``Pipeline``."""
        S = len(self.sites)
        r = self.raw
        out = []
        pos = self.positions()
        for i in range(self.n_frames):
            quat = np.stack([r[s]["quat"][i] for s in self.sites]).astype(np.float64) if S else np.zeros((0, 4))
            vec = {n: np.stack([r[s][n][i] for s in self.sites]).astype(np.float64) if S else np.zeros((0, 3))
                   for n in ("free_acc", "acc", "gyro")}
            present = np.array([bool(r[s]["present"][i]) for s in self.sites])
            ins = r["insoles"]
            out.append(HubFrame(t=float(r["t"][i]), index=int(r["index"][i]), sites=self.sites, quat=quat,
                                free_acc=vec["free_acc"], acc=vec["acc"], gyro=vec["gyro"], present=present,
                                insole_force=ins["force"][i].astype(np.float64), contacts=ins["contacts"][i].copy(),
                                insole_present=bool(ins["present"][i]),
                                position=None if pos is None else pos[i]))
        return out


CHECKSUM_FAILED = "checksum failed"
UNREADABLE = "unreadable"
CUT_OFF = "beyond the end of the file (truncated)"
NEVER_WRITTEN = "never written"
MISSING = "missing"
ZEROED = "zeroed on disk"
# datasets in which a whole chunk of zeros cannot be data (times, indices, rotations): a
# block the disk zeroed passes Fletcher32, whose sums start at zero, and is caught here
NEVER_ZERO = frozenset({"t", "index", "quat", "rot", "R_WG", "R_SB"})


@dataclass
class _Column:
    """One dataset as read: its rows (fill values where lost) and the stretches lost."""

    name: str
    data: np.ndarray | None
    lost: list[tuple[int, int, str]]

    def fit(self, n: int, tail: tuple[int, ...], dtype: str) -> None:
        """Cut to the group's common length; a dataset that could not be opened stands in
        as n lost rows."""
        if self.data is None:
            self.data = np.full((n,) + tail, fill_value(dtype), dtype=dtype)
            self.lost = [(0, n, self.lost[0][2] if self.lost else UNREADABLE)]
            return
        self.data = self.data[:n]
        self.lost = [(a, min(b, n), why) for a, b, why in self.lost if a < n]

    def bad(self) -> np.ndarray:
        assert self.data is not None
        m = np.zeros(len(self.data), bool)  # a (0, 0) entry: could not be opened, no rows to mark
        for a, b, _ in self.lost:
            m[a:b] = True
        return m


def _runs(spans: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for a, b in spans:
        if out and out[-1][1] == a:
            out[-1] = (out[-1][0], b)
        else:
            out.append((a, b))
    return out


def _stretches(mask: np.ndarray) -> list[tuple[int, int]]:
    """[a, b) runs of True."""
    if not mask.any():
        return []
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist()))


def _chunk_places(ds: h5py.Dataset) -> dict[int, tuple[int, int]] | None:
    """First row of each chunk on disk -> (byte offset, size); None when HDF5 cannot list
    them (the chunk index itself damaged)."""
    places: dict[int, tuple[int, int]] = {}

    def visit(info: Any) -> None:
        places[int(info.chunk_offset[0])] = (int(info.byte_offset), int(info.size))

    try:
        ds.id.chunk_iter(visit)
    except (AttributeError, NotImplementedError):  # HDF5 older than 1.12.3: the slow way
        try:
            for i in range(ds.id.get_num_chunks()):
                visit(ds.id.get_chunk_info(i))
        except (OSError, RuntimeError):
            return None
    except (OSError, RuntimeError):
        return None
    return places


class _Reader:
    """Reads a recording chunk by chunk where it must, so that one bad chunk costs its own
    rows and not the dataset, the group or the file."""

    def __init__(self, f: h5py.File, path: Path) -> None:
        self.f = f
        self.size = os.path.getsize(path)
        flags, self.stored_eof = _superblock(path)
        # a writer has it open, or died with it open: the rows at the end of a dataset that
        # are not on disk yet were in flight, not lost from a finished file
        self.in_flight = bool(flags)
        self.checksums = True
        self.fields: dict[str, int] = {}  # group -> how many datasets it has
        # (group, dataset, first row, end row, why, unit, times of the first and last row)
        self.entries: list[tuple[str, str, int, int, str, str, float | None, float | None]] = []

    def column(self, name: str, tail: tuple[int, ...], dtype: str) -> _Column:
        try:
            ds = self.f.get(name)  # one lookup where the dataset is there (most of a read's time was lookups)
            if ds is None:  # absent, or linked but its object unreadable
                return _Column(name, None, [(0, 0, UNREADABLE if name in self.f else MISSING)])
            # a type in the global heap is never what the Recorder writes, and a damaged heap
            # can hang HDF5 (root_attributes)
            if not isinstance(ds, h5py.Dataset) or ds.shape[1:] != tail or in_heap(ds.id.get_type()):
                return _Column(name, None, [(0, 0, UNREADABLE)])
            return _Column(name, *self._read(ds))
        except (OSError, RuntimeError, KeyError, ValueError):
            return _Column(name, None, [(0, 0, UNREADABLE)])

    def _read(self, ds: h5py.Dataset) -> tuple[np.ndarray, list[tuple[int, int, str]]]:
        shape, dtype = ds.shape, ds.dtype  # each a call into HDF5
        L = shape[0]
        out = np.full(shape, fill_value(dtype), dtype=dtype)
        if L == 0:
            return out, []
        if ds.chunks is None:  # not written by the Recorder; nothing to go by but HDF5's word
            try:
                out[...] = ds[...]
                return out, []
            except (OSError, RuntimeError):
                return out, [(0, L, UNREADABLE)]
        checked = bool(ds.fletcher32)
        self.checksums &= checked
        rows = ds.chunks[0]
        places = _chunk_places(ds)
        lost: list[tuple[int, int, str]] = []
        good: list[tuple[int, int]] = []
        # only chunks known to lie inside the file are read: past a cut, HDF5 reads zeros,
        # and zeros pass Fletcher32 (its sums start at 0)
        for a in range(0, L, rows):
            b = min(a + rows, L)
            if places is not None:
                place = places.get(a)
            else:  # the index cannot be walked whole (cut or damaged): ask chunk by chunk
                try:
                    info = ds.id.get_chunk_info_by_coord((a,) + (0,) * (ds.ndim - 1))
                except (OSError, RuntimeError, ValueError):
                    lost.append((a, b, UNREADABLE))
                    continue
                place = None if info.byte_offset is None else (int(info.byte_offset), int(info.size))
            if place is None:
                lost.append((a, b, NEVER_WRITTEN))
            elif place[0] + place[1] > self.size:
                lost.append((a, b, CUT_OFF))
            else:
                good.append((a, b))
        why = CHECKSUM_FAILED if checked else UNREADABLE
        for ra, rb in _runs(good):
            try:
                out[ra:rb] = ds[ra:rb]
                continue
            except (OSError, RuntimeError):
                pass
            for a in range(ra, rb, rows):  # find the bad chunk(s) in the run
                b = min(a + rows, rb)
                for attempt in range(3 if self.in_flight else 1):  # a live writer may be rewriting it
                    try:
                        out[a:b] = ds[a:b]
                        break
                    except (OSError, RuntimeError):
                        if attempt == (2 if self.in_flight else 0):
                            lost.append((a, b, why))
                        else:
                            time.sleep(IN_FLIGHT_RETRY_S)
        if ds.name.rsplit("/", 1)[-1] in NEVER_ZERO:
            bad = {(a, b) for a, b, _ in lost}
            for a, b in good:
                if (a, b) not in bad and not np.any(out[a:b]):
                    out[a:b] = fill_value(ds.dtype)
                    lost.append((a, b, ZEROED))
        return out, sorted(lost)

    def group(self, group: str, fields: Sequence[tuple[str, tuple[int, ...], str]], optional: bool = False,
              newer: Sequence[str] = ()) -> tuple[dict[str, _Column], int]:
        """Every field of ``group`` cut to their common length (a killed writer leaves them
        a few rows apart). optional: the group may be absent altogether; newer: fields
        that recordings made before they existed lack (no damage, fill values)."""
        cols = {name: self.column(f"{group}/{name}", tail, dt) for name, tail, dt in fields}
        self.fields[group] = len(cols)
        absent = {name for name, c in cols.items() if c.data is None and c.lost[0][2] == MISSING}
        if optional and len(absent) == len(cols):
            return {}, 0
        lengths = [self._written(name, c) for name, c in cols.items() if c.data is not None]
        n = min(lengths) if lengths else 0
        for (name, tail, dt), c in zip(fields, cols.values()):
            c.fit(n, tail, dt)
            if name in absent and name in newer:
                c.lost = []
        return cols, n

    def _written(self, name: str, c: _Column) -> int:
        """Rows of ``c`` to take: all of them, but in a file still (or last) open for
        writing not the ones at the end that have not reached the disk yet (no chunk, a
        chunk past the end of the file, times and indices still the fill value)."""
        assert c.data is not None
        n = len(c.data)
        if not self.in_flight:
            return n
        for a, b, why in sorted(c.lost, reverse=True):
            if b != n or why not in (CUT_OFF, NEVER_WRITTEN):
                break
            n = a
        if name in ("t", "index"):
            ok = np.flatnonzero(np.isfinite(c.data[:n]) if name == "t" else c.data[:n] >= 0)
            n = int(ok[-1]) + 1 if len(ok) else 0
        return n

    def note(self, cols: dict[str, _Column], group: str, unit: str, times: np.ndarray) -> None:
        """Remember the lost stretches of ``cols``, timed by ``times`` (NaN where unknown,
        estimated from the neighbours)."""
        t = np.asarray(times, dtype=np.float64)
        ok = np.flatnonzero(np.isfinite(t))
        step = float(np.median(np.diff(t[ok]) / np.diff(ok))) if len(ok) > 1 else 0.0

        def at(i: int) -> float:
            if i < ok[0]:
                return float(t[ok[0]] - (ok[0] - i) * step)
            if i > ok[-1]:
                return float(t[ok[-1]] + (i - ok[-1]) * step)
            return float(np.interp(i, ok, t[ok]))

        for c in cols.values():
            for a, b, why in c.lost:
                ta = tb = None
                if len(ok) and b > a:
                    ta, tb = at(a), at(b - 1)
                self.entries.append((group, c.name, a, b, why, unit, ta, tb))

    def damage(self, origin: float) -> list[str]:
        """One line per damaged stretch: the same stretch lost in several datasets of a
        group (a cut-off file, a bad block across interleaved chunks) is one line."""
        out = []
        keyed: dict[tuple[str, str, str], list] = {}
        for g, name, a, b, why, unit, ta, tb in self.entries:
            keyed.setdefault((g, why, unit), []).append([a, b, {name}, ta, tb])
        for (g, why, unit), items in keyed.items():
            items.sort(key=lambda it: (it[0], it[1]))
            merged: list[list] = []
            for a, b, names, ta, tb in items:
                m = merged[-1] if merged else None
                if m is not None and a <= m[1]:
                    m[1] = max(m[1], b)
                    m[2] |= names
                    m[3] = ta if m[3] is None else (m[3] if ta is None else min(m[3], ta))
                    m[4] = tb if m[4] is None else (m[4] if tb is None else max(m[4], tb))
                else:
                    merged.append([a, b, set(names), ta, tb])
            for a, b, names, ta, tb in merged:
                line = _damage_line(g, sorted(names), self.fields.get(g, 0), a, b, why, unit, ta, tb, origin)
                out.append((_GROUP_ORDER.index(g) if g in _GROUP_ORDER else 9, a, line))
        return [line for *_, line in sorted(out)]


_GROUP_ORDER = ("raw", "calibration", "events", "recon")


def _damage_line(group: str, names: list[str], total: int, a: int, b: int, why: str, unit: str,
                 ta: float | None, tb: float | None, origin: float) -> str:
    parents = {n.rsplit("/", 1)[0] for n in names}
    if len(names) == 1:
        what = names[0]
    elif len(names) == total:
        what = group
    elif len(parents) == 1:
        what = f"{parents.pop()}/{','.join(n.rsplit('/', 1)[1] for n in names)}"
    else:
        what = f"{group} ({len(names)} of {total} datasets)"
    rows = f"{unit[:-1]} {a}" if b - a == 1 else f"{unit} {a}-{b - 1}"
    when = ""
    if ta is not None and tb is not None:
        ta, tb = ta - origin, tb - origin
        when = f" (t {ta:.1f} s)" if f"{ta:.1f}" == f"{tb:.1f}" else f" (t {ta:.1f}-{tb:.1f} s)"
    if why == MISSING:
        return f"{what}: missing from the file, skipped"
    if b <= a:  # could not even be opened: how many rows it had is not known
        return f"{what}: {why}, skipped"
    return f"{what} {rows}{when}: {why}, skipped"


def _superblock(path: Path) -> tuple[int, int | None]:
    """(file consistency flags, file length) as HDF5's superblock (version 2 or 3, what
    the Recorder writes) states them: flags are non-zero while a writer has the file open
    and stay so if it dies. (0, None) for other superblocks."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(36)
    except OSError:
        return 0, None
    if len(head) < 36 or head[:8] != HDF5_SIGNATURE or head[8] not in (2, 3) or head[9] != 8:
        return 0, None
    return head[11], int.from_bytes(head[28:36], "little")


def _never_written(cols: dict[str, _Column], mask: np.ndarray, names: Sequence[str] = ("t",)) -> None:
    """Rows that read as the fill value (NaN time, index -1) were allocated but never
    reached the disk (the writer failed or died mid-flush): lost like a bad chunk, and
    charged to ``names[0]`` unless one of ``names`` lost them already."""
    bad = np.zeros(len(mask), bool)
    for name in names:
        bad |= cols[name].bad()
    extra = mask & ~bad
    cols[names[0]].lost += [(a, b, NEVER_WRITTEN) for a, b in _stretches(extra)]


def _has(f: h5py.File, name: str) -> bool:
    """Whether the file links ``name`` (a damaged link reads as there: the read then says so)."""
    try:
        return name in f
    except (OSError, RuntimeError, KeyError, ValueError):
        return True


def read_recording(path: str | os.PathLike) -> Recording:
    """Everything flushed so far (a live or killed file included), minus what cannot be
    trusted: a chunk that fails its checksum, a part cut off or never written is skipped
    and listed in ``Recording.damage`` (see there for what becomes of those rows), so one
    bad block costs seconds of a session, not the session."""
    path = Path(path)
    f, attrs = open_recording_header(path)
    with f:
        rd = _Reader(f, path)
        try:
            sites = tuple(json.loads(attrs["sites"]))
            meta = json.loads(attrs.get("metadata", "{}"))
        except (KeyError, ValueError, TypeError) as exc:
            raise RecordingError(path, f"damaged: its root attributes cannot be read ({fault_text(exc)})") from None
        S = len(sites)

        # raw: a frame without a readable time or index is dropped, a site's damaged samples
        # are marked not present
        raw_fields = [("t", (), "f8"), ("index", (), "i8")]
        # a site's position only where the writer kept one (a tracked device's site)
        site_fields = {s: SITE_FIELDS + ((POSITION_FIELD,) if _has(f, f"raw/{s}/{POSITION_FIELD[0]}") else ())
                       for s in sites}
        raw_fields += [(f"{s}/{k}", tail, dt) for s in sites for k, tail, dt in site_fields[s]]
        raw_fields += [(f"insoles/{k}", tail, dt) for k, tail, dt in INSOLE_FIELDS]
        cols, n = rd.group("raw", raw_fields)
        t_raw = cols["t"].data.astype(np.float64)
        idx = cols["index"].data.astype(np.int64)
        _never_written(cols, ~np.isfinite(t_raw) | (idx < 0), ("t", "index"))
        drop = cols["t"].bad() | cols["index"].bad()
        t_raw[cols["t"].bad()] = np.nan
        rd.note(cols, "raw", "frames", t_raw)
        keep = ~drop
        raw: dict[str, Any] = {"t": t_raw[keep], "index": idx[keep]}
        for s, fields in [(s, site_fields[s]) for s in sites] + [("insoles", INSOLE_FIELDS)]:
            sub = {k: cols[f"{s}/{k}"] for k, _, _ in fields}
            hurt = np.zeros(n, bool)
            for c in sub.values():
                hurt |= c.bad()
            out = {}
            for k, c in sub.items():
                a = c.data
                if hurt.any():
                    a = a.copy()
                    a[hurt] = fill_value(a.dtype)
                out[k] = a[keep]
            raw[s] = out

        # calibrations: a damaged row is dropped (replay then keeps the one before); a
        # damaged protocol/quality report alone costs only the report
        cols, k_cal = rd.group("calibration", calibration_fields(S), newer=("meta",))
        t_cal = cols["t"].data.astype(np.float64)
        _never_written(cols, ~np.isfinite(t_cal))
        meta_bad = cols["meta"].bad()
        drop_cal = np.zeros(k_cal, bool)
        for name, c in cols.items():
            if name != "meta":
                drop_cal |= c.bad()
        rd.note(cols, "calibration", "rows", t_cal)
        cals = []
        for i in np.flatnonzero(~drop_cal):
            cal_meta: dict[str, Any] = {}
            if not meta_bad[i]:
                try:
                    cal_meta = json.loads(cols["meta"].data[i].decode("utf-8") or "{}")
                except (UnicodeDecodeError, ValueError):
                    cal_meta = {}
            c = {name: col.data[i] for name, col in cols.items()}
            cals.append((float(c["t"]), Calibration(
                sites=sites, R_WG=c["R_WG"], R_SB=c["R_SB"], acc_offset=c["acc_offset"], valid=c["valid"],
                residual_world_deg=c["residual_world_deg"], residual_tpose_deg=c["residual_tpose_deg"],
                meta=cal_meta)))

        # events (recordings from before events had none)
        events = []
        cols, k_ev = rd.group("events", EVENT_FIELDS, optional=True)
        if cols:
            t_ev = cols["t"].data.astype(np.float64)
            _never_written(cols, ~np.isfinite(t_ev))
            drop_ev = np.zeros(k_ev, bool)
            for c in cols.values():
                drop_ev |= c.bad()
            rd.note(cols, "events", "rows", t_ev)
            events = [(float(t_ev[i]), cols["kind"].data[i].decode("utf-8", "replace"),
                       cols["detail"].data[i].decode("utf-8", "replace")) for i in np.flatnonzero(~drop_ev)]

        # recon: a damaged pose is dropped whole (export shows it as a gap)
        cols, m = rd.group("recon", RECON_FIELDS, newer=RECON_NEWER)
        t_rec = cols["t"].data.astype(np.float64)
        _never_written(cols, ~np.isfinite(t_rec))
        drop_rec = np.zeros(m, bool)
        for c in cols.values():
            drop_rec |= c.bad()
        rd.note(cols, "recon", "frames", t_rec)
        recon = {k: c.data[~drop_rec] for k, c in cols.items()}

        finite = raw["t"][np.isfinite(raw["t"])]
        origin = float(finite[0]) if len(finite) else (float(recon["t"][0]) if len(recon["t"]) else 0.0)
        damage = rd.damage(origin)
        eof = rd.stored_eof
        if eof is not None and rd.size < eof and not rd.in_flight:
            damage.insert(0, f"file truncated: {rd.size} of its {eof} bytes are there, what was in the rest is lost")
        checksums = rd.checksums
    m = len(recon["t"])
    recon["R"] = quat_to_matrix(recon["rot"].astype(np.float64)) if m else np.zeros((0, N_SEGMENTS, 3, 3))
    return Recording(path, sites, meta, raw, cals, recon, attrs, events, damage, checksums)
