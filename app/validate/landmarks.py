"""Joint centres and segment frames from a lab's surface markers: what a C3D or TRC of
a real session holds when it has no joint centres of its own (or has them but not the
frames).

Recognised, by label (lower-cased, without a ``Subject:`` prefix, dots, underscores and
spaces; the side as a leading or trailing ``l``/``r`` or ``left``/``right``):

- Plug-in Gait's segment axes (``PELO/PELA/PELL/PELP``, ``LFEO..``, ``LTIO..``,
  ``LFOO..``; origin, anterior, left, proximal points): the pelvis, thigh, shank and
  foot frames as Vicon Nexus computed them;
- anatomical landmarks (ISB: Wu et al. 2002, 2005; the names of Plug-in Gait, the
  CAST / Qualisys sets and OpenSim's example trials): ASIS (``LASI``, ``L_IAS``,
  ``L.ASIS``, ``ASISl``), PSIS or sacrum, femoral epicondyles (``L_FLE``/``L_FME``,
  ``L.Knee.Lat``/``.Med``), malleoli (``L_FAL``/``L_TAM``, ``L.Ankle.Lat``/``.Med``),
  heel and toe, humeral epicondyles and the styloids. From them: the hip centre by
  Harrington et al. (2007)'s regression on the pelvis width and depth, the knee, ankle,
  elbow and wrist centres as the midpoints of their two landmarks, and the pelvis,
  thigh, shank and foot frames (``frames.segment_from_axes``);
- a static trial (``with_static``): landmarks the walking trial does not carry (medial
  knee and ankle markers removed after calibration, as in OpenSim's example gait data)
  are carried along by the rigid cluster of three markers nearest to them that stays
  rigid in the walking trial (the least change of its inter-marker distances), fitted
  frame by frame (Söderkvist & Wedin 1993).
"""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass

import numpy as np

from app.validate.frames import segment_from_axes, unit

# role -> normalised names (without the side)
_SIDED: dict[str, tuple[str, ...]] = {
    "asis": ("asis", "asi", "ias"),
    "psis": ("psis", "psi", "ips"),
    "knee_lat": ("kneelat", "fle", "lfe", "kne", "latepicondyle", "lateralknee", "kneelateral"),
    "knee_med": ("kneemed", "fme", "mfe", "knm", "kneemedial", "medialknee", "medepicondyle"),
    "ankle_lat": ("anklelat", "fal", "ank", "latmalleolus", "lateralmalleolus", "anklelateral"),
    "ankle_med": ("anklemed", "tam", "anm", "medmalleolus", "medialmalleolus", "anklemedial"),
    "heel": ("heel", "hee", "fcc", "cal"),
    "toe": ("toetip", "toe", "fm2", "mt2", "tt"),
    "mt1": ("fm1", "mt1", "fmh", "mth1"),  # first and fifth metatarsal heads: the toe between them
    "mt5": ("fm5", "mt5", "vmh", "mth5"),
    "elbow_lat": ("hle", "elbowlat", "elb", "elbow", "epicl", "lateralelbow"),
    "elbow_med": ("hme", "elbowmed", "epicm", "medialelbow"),
    "wrist_rad": ("rsp", "wristlat", "wra", "stylr", "radialstyloid"),
    "wrist_uln": ("usp", "wristmed", "wrb", "stylu", "ulnarstyloid"),
}
_UNSIDED: dict[str, tuple[str, ...]] = {"sacrum": ("vsacral", "sacral", "sacrum", "sacr", "sacrm", "sac")}
PIG_SEGMENTS = {"pel": "pelvis", "lfe": "l_thigh", "rfe": "r_thigh", "lti": "l_shank", "rti": "r_shank",
                "lfo": "l_foot", "rfo": "r_foot"}


def normalise(label: str) -> str:
    return re.sub(r"[\s._\-]", "", label.split(":")[-1]).lower()


def _split_side(key: str) -> list[tuple[str, str]]:
    """Possible (side, rest) readings of a normalised label."""
    out = []
    for side, words in (("l", ("left", "l")), ("r", ("right", "r"))):
        for w in words:
            if key.startswith(w) and len(key) > len(w):
                out.append((side, key[len(w):]))
            if key.endswith(w) and len(key) > len(w):
                out.append((side, key[:-len(w)]))
    return out


def find_landmarks(labels: list[str]) -> dict[str, int]:
    """'{side}_{role}' (or an unsided role) -> index into ``labels``; the first label wins."""
    out: dict[str, int] = {}
    for i, lab in enumerate(labels):
        key = normalise(lab)
        for role, names in _UNSIDED.items():
            if key in names:
                out.setdefault(role, i)
        for side, rest in _split_side(key):
            for role, names in _SIDED.items():
                if rest in names:
                    out.setdefault(f"{side}_{role}", i)
    return out


def pig_axes(labels: list[str]) -> dict[str, dict[str, int]]:
    """segment -> {'o','a','l','p'} -> index: Plug-in Gait's segment axis points."""
    idx = {normalise(lab): i for i, lab in enumerate(labels)}
    out: dict[str, dict[str, int]] = {}
    for prefix, seg in PIG_SEGMENTS.items():
        pts = {k: idx.get(f"{prefix}{k}") for k in "oalp"}
        if all(v is not None for v in pts.values()):
            out[seg] = {k: int(v) for k, v in pts.items() if v is not None}
    return out


@dataclass
class Anatomy:
    """What the landmarks give, in the file's axes (converted by the caller): joint
    centres by our names (T, 3) and segment frames as (proximal, right) axis pairs, or
    (anterior, left, proximal) for Plug-in Gait's axes."""

    centres: dict[str, np.ndarray]
    axes: dict[str, tuple[np.ndarray, np.ndarray]]  # segment -> (proximal, right)
    notes: list[str]


def harrington_hip(asis_l, asis_r, back) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) hip centres (T, 3) by Harrington et al. 2007 (J Biomech 40:595):
    in the pelvis frame (origin mid-ASIS, X anterior, Y superior, Z right; metres)
    x = -0.24 PD - 0.0099, y = -0.30 PW - 0.0109, z = +-(0.33 PW + 0.0073), PW the
    ASIS distance, PD the depth from mid-ASIS to ``back`` (mid-PSIS or the sacrum)."""
    mid = 0.5 * (asis_l + asis_r)
    z = unit(asis_r - asis_l)
    x0 = mid - back
    x = unit(x0 - np.sum(x0 * z, axis=-1, keepdims=True) * z)
    y = np.cross(z, x)
    pw = np.linalg.norm(asis_r - asis_l, axis=-1, keepdims=True)
    pd = np.linalg.norm(x0, axis=-1, keepdims=True)
    base = mid + x * (-0.24 * pd - 0.0099) + y * (-0.30 * pw - 0.0109)
    off = z * (0.33 * pw + 0.0073)
    return base - off, base + off


def anatomy(pos: np.ndarray, labels: list[str], scale_to_m: float) -> Anatomy:
    """Joint centres and segment axes from the landmarks in ``pos`` (T, N, 3), in the file's
    axes, metres (``scale_to_m`` already applied)."""
    lm = find_landmarks(labels)
    P = {k: pos[:, i] for k, i in lm.items()}
    for s in "lr":
        if f"{s}_toe" not in P and f"{s}_mt1" in P and f"{s}_mt5" in P:
            P[f"{s}_toe"] = 0.5 * (P[f"{s}_mt1"] + P[f"{s}_mt5"])
    centres: dict[str, np.ndarray] = {}
    axes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    notes: list[str] = []
    if "l_asis" in P and "r_asis" in P:
        back = (0.5 * (P["l_psis"] + P["r_psis"]) if "l_psis" in P and "r_psis" in P else P.get("sacrum"))
        if back is not None:
            centres["l_hip"], centres["r_hip"] = harrington_hip(P["l_asis"], P["r_asis"], back)
            right = P["r_asis"] - P["l_asis"]
            anterior = 0.5 * (P["l_asis"] + P["r_asis"]) - back
            axes["pelvis"] = (np.cross(right, anterior), right)
            notes.append("hip centres from the ASIS and PSIS/sacrum (Harrington et al. 2007)")
    for s in "lr":
        sign = 1.0 if s == "r" else -1.0  # lateral minus medial points right on the right side
        for joint, lat, med in (("knee", "knee_lat", "knee_med"), ("ankle", "ankle_lat", "ankle_med"),
                                ("elbow", "elbow_lat", "elbow_med"), ("wrist", "wrist_rad", "wrist_uln")):
            a, b = P.get(f"{s}_{lat}"), P.get(f"{s}_{med}")
            if a is not None and b is not None:
                centres[f"{s}_{joint}"] = 0.5 * (a + b)
        hip, knee, ankle = centres.get(f"{s}_hip"), centres.get(f"{s}_knee"), centres.get(f"{s}_ankle")
        if hip is not None and knee is not None:
            axes[f"{s}_thigh"] = (hip - knee, sign * (P[f"{s}_knee_lat"] - P[f"{s}_knee_med"]))
        if knee is not None and ankle is not None:
            axes[f"{s}_shank"] = (knee - ankle, sign * (P[f"{s}_ankle_lat"] - P[f"{s}_ankle_med"]))
        if ankle is not None and f"{s}_heel" in P and f"{s}_toe" in P and f"{s}_shank" in axes:
            anterior = P[f"{s}_toe"] - P[f"{s}_heel"]
            right = axes[f"{s}_shank"][1]
            axes[f"{s}_foot"] = (np.cross(right, anterior), right)
    return Anatomy(centres, axes, notes)


def pig_frames(pos: np.ndarray, labels: list[str]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """segment -> (proximal, right) from Plug-in Gait's axis points (``pig_axes``). The
    foot's own axes are the odd ones: its "proximal" runs along the foot from toe to heel
    and its "anterior" points up, out of the sole, so the latter is our proximal axis."""
    out = {}
    for seg, k in pig_axes(labels).items():
        o = pos[:, k["o"]]
        up = pos[:, k["a"]] - o if seg.endswith("foot") else pos[:, k["p"]] - o
        out[seg] = (up, o - pos[:, k["l"]])
    return out


def frames_in_world(axes: dict[str, tuple[np.ndarray, np.ndarray]], W: np.ndarray) -> dict[str, np.ndarray]:
    """segment -> (T, 3, 3) our orientation, the axes turned into our world by ``W``."""
    return {seg: segment_from_axes(p @ W.T, r @ W.T, seg) for seg, (p, r) in axes.items()}


# ------------------------------------------------------------------------------ static trial


def _kabsch(A: np.ndarray, B: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotations R (T, 3, 3) and translations t (T, 3) with B[t] ~ R A + t, A (K, 3) fixed
    and B (T, K, 3)."""
    ca, cb = A.mean(axis=0), B.mean(axis=1)
    H = np.einsum("ki,tkj->tij", A - ca, B - cb[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros_like(H)
    D[:, 0, 0] = D[:, 1, 1] = 1.0
    D[:, 2, 2] = d
    R = np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)
    return R, cb - np.einsum("tij,j->ti", R, ca)


def with_static(pos: np.ndarray, labels: list[str], static_pos: np.ndarray, static_labels: list[str],
                nearest: int = 6) -> tuple[np.ndarray, list[str], list[str]]:
    """(positions (T, N + M, 3), labels, mapping lines): the walking trial with the static
    trial's M landmarks it lacks, each carried by its most rigid nearby cluster (module
    docstring). Both in the same units and axes."""
    have = {lab: i for i, lab in enumerate(labels) if np.isfinite(pos[:, i]).any()}
    ref = np.nanmean(static_pos, axis=0)  # (M, 3): the static pose
    new_pos, new_labels, lines = [], [], []
    for j, lab in enumerate(static_labels):
        if lab in have or not np.all(np.isfinite(ref[j])):
            continue
        shared = [(static_labels.index(o), have[o]) for o in have if o in static_labels
                  and np.all(np.isfinite(ref[static_labels.index(o)]))]
        if len(shared) < 3:
            continue
        shared.sort(key=lambda p: np.linalg.norm(ref[p[0]] - ref[j]))
        best, best_cost = None, np.inf
        for tri in itertools.combinations(shared[:nearest], 3):
            S = ref[[p[0] for p in tri]]
            area = np.linalg.norm(np.cross(S[1] - S[0], S[2] - S[0]))
            if area < 1e-4 * max(np.linalg.norm(S[1] - S[0]) ** 2, 1e-12):
                continue
            D = pos[:, [p[1] for p in tri]]
            change = [np.nanstd(np.linalg.norm(D[:, a] - D[:, b], axis=-1)) for a, b in ((0, 1), (0, 2), (1, 2))]
            cost = max(change) + 0.01 * np.mean(np.linalg.norm(S - ref[j], axis=-1))
            if np.isfinite(cost) and cost < best_cost:
                best, best_cost = tri, cost
        if best is None:
            continue
        A = ref[[p[0] for p in best]]
        B = pos[:, [p[1] for p in best]]
        ok = np.all(np.isfinite(B), axis=(1, 2))
        out = np.full((len(pos), 3), np.nan)
        if ok.any():
            R, t = _kabsch(A, B[ok])
            out[ok] = np.einsum("tij,j->ti", R, ref[j]) + t
        new_pos.append(out)
        new_labels.append(lab)
        lines.append(f"{lab} <- static trial, carried by {', '.join(static_labels[p[0]] for p in best)}")
    if not new_pos:
        return pos, list(labels), lines
    return np.concatenate([pos, np.stack(new_pos, axis=1)], axis=1), [*labels, *new_labels], lines


__all__ = ["find_landmarks", "pig_axes", "Anatomy", "anatomy", "harrington_hip", "pig_frames", "frames_in_world",
           "with_static", "normalise"]
