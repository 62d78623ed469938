"""What the report's first page says about a recording: subject, date, sensor set, model, where the poses
came from, the calibration's quality, and every warning the recording carries (the import's calibration
warnings, devices lost, damaged stretches)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

WARN_EVENTS = ("device_lost", "device_silent", "recording_error", "recalibration", "gap")


@dataclass
class SessionInfo:
    path: Path
    subject: str
    date: str
    sensors: tuple[str, ...]
    insoles: bool
    model: str
    source: str
    duration_s: float
    calibration: list[dict[str, Any]] = field(default_factory=list)  # per site: residuals (deg)
    calibration_summary: str = ""
    warnings: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {"file": str(self.path), "subject": self.subject, "date": self.date, "sensors": list(self.sensors),
                "insoles": self.insoles, "model": self.model, "source": self.source,
                "duration_s": round(self.duration_s, 2), "calibration": self.calibration,
                "calibration_summary": self.calibration_summary, "warnings": self.warnings}


def _text(v: Any) -> str:
    if isinstance(v, bytes):
        return v.decode("utf-8", "replace")
    return "" if v is None else str(v)


def _subject(meta: dict[str, Any]) -> str:
    s = meta.get("subject")
    if isinstance(s, dict):
        parts = [str(s.get("id") or "").strip()]
        if s.get("height_m"):
            parts.append(f"height {float(s['height_m']):.2f} m")
        if s.get("notes"):
            parts.append(str(s["notes"]))
        text = ", ".join(p for p in parts if p)
        if text:
            return text
    elif s:
        return str(s)
    h = meta.get("body_height_m")
    return f"not named (body height {float(h):.2f} m)" if h else "not named"


def _calibration(rec) -> tuple[list[dict[str, Any]], str, list[str]]:
    """Per-site rows of the last calibration that took effect, a one-line summary and its warnings."""
    warnings: list[str] = []
    meta_cal = rec.metadata.get("calibration")
    found = rec.metadata.get("calibration_warnings") or (meta_cal.get("warnings") if isinstance(meta_cal, dict)
                                                         else None)
    if not found and rec.calibrations and isinstance(rec.calibrations[-1][1].meta, dict):
        found = rec.calibrations[-1][1].meta.get("warnings")
    warnings += [f"calibration: {w}" for w in (found or []) if w]
    if not rec.calibrations:
        return [], "no calibration in the recording", warnings + ["no calibration took effect"]
    t, cal = rec.calibrations[-1]
    rows = []
    for k, site in enumerate(cal.sites):
        w = None if cal.residual_world_deg is None else float(cal.residual_world_deg[k])
        p = None if cal.residual_tpose_deg is None else float(cal.residual_tpose_deg[k])
        rows.append({"site": site, "valid": bool(cal.valid[k]),
                     "still_deg": None if w is None or not np.isfinite(w) else round(w, 2),
                     "pose_deg": None if p is None or not np.isfinite(p) else round(p, 2)})
        if not cal.valid[k]:
            warnings.append(f"{site}: not calibrated")
    protocol = cal.meta.get("protocol") if isinstance(cal.meta, dict) else None
    method = meta_cal.get("method") if isinstance(meta_cal, dict) else meta_cal
    res = cal.residual_deg
    summary = ", ".join(x for x in (
        f"{len(rec.calibrations)} calibration(s), the last at {t - float(rec.raw['t'][0]):.1f} s"
        if len(rec.raw.get("t", [])) else f"{len(rec.calibrations)} calibration(s)",
        f"protocol {protocol}" if protocol else "", f"method {method}" if method else "",
        f"mean residual {res:.2f} deg" if res is not None and np.isfinite(res) else "") if x)
    return rows, summary, warnings


def session_info(rec) -> SessionInfo:
    meta = rec.metadata or {}
    rows, summary, warnings = _calibration(rec)
    for _t, kind, detail in rec.events:
        if kind in WARN_EVENTS:
            warnings.append(f"{kind.replace('_', ' ')}: {detail}")
    warnings += [f"damaged: {d}" for d in rec.damage]
    recon_t = rec.recon.get("t", np.zeros(0))
    duration = float(recon_t[-1] - recon_t[0]) if len(recon_t) > 1 else 0.0
    sensors = tuple(meta.get("sensors") or rec.sites)
    model = meta.get("model") or "unknown"
    if meta.get("steps"):
        model = f"{model}, {meta['steps']} steps"
    return SessionInfo(
        path=Path(rec.path), subject=_subject(meta), date=_text(rec.attrs.get("created")) or "unknown",
        sensors=sensors, insoles=bool(meta.get("insoles")), model=str(model),
        source=_text(meta.get("source")) or "unknown", duration_s=duration, calibration=rows,
        calibration_summary=summary, warnings=warnings)
