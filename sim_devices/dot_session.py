"""A Movella DOT session as people record it, synthesized: several trials, one folder each.

Why: a lab does not record one log that starts with a still stand. It records an N-pose
trial, a leg-cycle trial per leg (the functional calibration of OpenSense's and Xsens's
workflows), then walk trials that start with the subject already walking; and each DOT
starts every trial with its own heading reference. ``imucap import --calibration-trial``
and the session import are tested on exactly that shape.

What is written, per trial ``<session>/<trial>/<Tag>_<address>_<date>_<time>.csv``: the
DOT app's preamble, columns ``PacketCounter, SampleTimeFine, Quat_W..Z, Acc_X..Z,
Gyr_X..Z (deg/s), Mag_X..Z, Status`` with a trailing comma on every line, at 120 Hz. Seven
sensors (pelvis, thighs, shanks, feet) mounted +X up and +Z lateral (left and right
mirrored; the pelvis sensor's +Z points back), each with a random mounting error on top
(the same in every trial: the straps stay on) and a random heading reference per trial.
The motions are ``sim_devices.motions`` (N-pose, ``leg_cycle``) and
``sim_devices.xsens_export.stand_walk_stand`` cut so that the walk has no still start;
the signals are ``inference.signals.synthesis.synthesize``'s.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from inference.body.conventions import from_scipy, quat_z, rot_z, to_scipy
from inference.body.motion import Motion
from inference.body.rotations import quat_multiply, quat_to_matrix
from inference.signals.site_signals import SiteSignals
from inference.signals.synthesis import NoiseModel, synthesize

from .motions import generate, leg_cycle
from .xsens_export import MAG_EARTH, stand_walk_stand

SITES = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")
TAGS = {"pelvis": "Pelvis", "l_thigh": "LeftUpperLeg", "r_thigh": "RightUpperLeg", "l_shank": "LeftLowerLeg",
        "r_shank": "RightLowerLeg", "l_foot": "LeftFoot", "r_foot": "RightFoot"}
ADDRESSES = {s: f"D4CA6EF172{0x30 + k:02X}" for k, s in enumerate(SITES)}
RATE_HZ = 120.0
COLUMNS = ("Quat_W", "Quat_X", "Quat_Y", "Quat_Z", "Acc_X", "Acc_Y", "Acc_Z", "Gyr_X", "Gyr_Y", "Gyr_Z",
           "Mag_X", "Mag_Y", "Mag_Z")


def nominal_mounting(site: str) -> np.ndarray:
    """(3,3) R_BS of a DOT strapped +X up, +Z lateral (pelvis: +Z back), in the bone frame of
    our T-pose (X forward, Y left, Z up)."""
    x = np.array([0.0, 0.0, 1.0])
    z = {"l": np.array([0.0, 1.0, 0.0]), "r": np.array([0.0, -1.0, 0.0])}.get(site[0] if site[1:2] == "_" else "",
                                                                          np.array([-1.0, 0.0, 0.0]))
    return np.stack([x, np.cross(z, x), z], axis=1)


@dataclass
class TrialTruth:
    """What the synthesis drew for one trial: its motion (60 Hz), each sensor's R_WG (the
    trial's heading reference) and R_SB (the same in every trial)."""

    name: str
    kind: str  # "npose", "leg_cycle", "walk"
    motion: Motion
    R_WG: np.ndarray  # (S,3,3)
    R_SB: np.ndarray  # (S,3,3)
    folder: Path
    files: list[Path] = field(default_factory=list)


def _at_120(sig: SiteSignals) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t, quat, specific force, gyro) on a 120 Hz grid: slerp and linear interpolation of
    the 60 Hz synthesis (the DOT's rate; the import puts it back on 60 Hz)."""
    t = np.arange(0.0, sig.t[-1] + 1e-9, 1.0 / RATE_HZ)
    S = len(sig.sites)
    quat = np.stack([from_scipy(Slerp(sig.t, to_scipy(sig.quat[:, k]))(t)) for k in range(S)], axis=1)

    def lin(v: np.ndarray) -> np.ndarray:
        return np.stack([[np.interp(t, sig.t, v[:, k, j]) for j in range(3)] for k in range(S)]).transpose(2, 0, 1)

    return t, quat, lin(sig.specific_force), lin(sig.gyro)


def write_dot_trial(folder: str | os.PathLike, t: np.ndarray, quat: np.ndarray, acc: np.ndarray, gyro: np.ndarray,
                    mag: np.ndarray, sites: tuple[str, ...] = SITES, stamp: str = "20240502_100000",
                    t0_us: int = 2**32 - 2_000_000) -> list[Path]:
    """One DOT app export per sensor (the columns of the module docstring, trailing commas);
    gyro in rad/s (written in deg/s, as the DOT does)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    fine = (t0_us + np.rint(t * 1e6).astype(np.int64)) % 2**32
    paths = []
    for k, site in enumerate(sites):
        pad = "," * (len(COLUMNS) + 2)
        text = ["sep=,", f"DeviceTag:,{TAGS[site]}{pad}", f"FirmwareVersion:,2.0.0{pad}", f"AppVersion:,2022.0{pad}",
                f"SyncStatus:,Synced{pad}", f"OutputRate:,{RATE_HZ:g}Hz{pad}", f"FilterProfile:,General{pad}",
                f"Measurement Mode:,Custom mode 4{pad}", f"StartTime: ,{stamp}_000 GMT+1{pad}",
                "\u00a9 Xsens Technologies B. V. 2005-2024", "", ",".join(["PacketCounter", "SampleTimeFine",
                                                                          *COLUMNS, "Status", ""])]
        values = np.concatenate([quat[:, k], acc[:, k], np.degrees(gyro[:, k]), mag[:, k]], axis=1)
        text += [f"{i + 1},{int(fine[i])}," + ",".join(f"{v:.6f}" for v in row) + ",0," for i, row in enumerate(values)]
        path = folder / f"{TAGS[site]}_{ADDRESSES[site]}_{stamp}.csv"
        path.write_text("\n".join(text) + "\n", encoding="utf-8")
        paths.append(path)
    return paths


def synthesize_trial(motion: Motion, folder: str | os.PathLike, name: str, kind: str, seed: int, trial_seed: int,
                     noise: NoiseModel, stamp: str = "20240502_100000") -> TrialTruth:
    """One trial of the session: ``motion``'s signals with the session's mounting (drawn
    from ``seed``, so the same in every trial) and a heading reference per sensor drawn
    from ``trial_seed``, written as DOT exports in ``folder``."""
    sig = synthesize(motion, replace(noise, heading_deg=0.0), rng=seed, sites=SITES)
    nominal = np.stack([nominal_mounting(s) for s in SITES])
    heading = np.random.default_rng(trial_seed).uniform(-np.pi, np.pi, len(SITES))
    R_WS = quat_to_matrix(sig.quat) @ nominal  # the heading reference of the synthesis is the world
    q_nom = from_scipy(Rotation.from_matrix(nominal))
    quat = quat_multiply(quat_z(-heading)[None], quat_multiply(sig.quat, q_nom[None]))
    f = np.einsum("sji,tsj->tsi", nominal, sig.specific_force)
    g = np.einsum("sji,tsj->tsi", nominal, sig.gyro)
    mag = np.einsum("tsji,j->tsi", R_WS, MAG_EARTH)
    sig = replace(sig, quat=quat, specific_force=f, gyro=g)
    t, q120, f120, g120 = _at_120(sig)
    m120 = np.stack([[np.interp(t, sig.t, mag[:, k, j]) for j in range(3)] for k in range(len(SITES))])
    m120 = m120.transpose(2, 0, 1)
    files = write_dot_trial(Path(folder) / name, t, q120, f120, g120, m120, stamp=stamp)
    R_SB = np.swapaxes(nominal, -1, -2) @ np.asarray(sig.meta["R_SB"])
    return TrialTruth(name, kind, motion, rot_z(heading), R_SB, Path(folder) / name, files)


@dataclass
class DotSession:
    folder: Path
    trials: dict[str, TrialTruth]

    def files(self, name: str) -> list[Path]:
        return self.trials[name].files


def walk_without_still_start(seed: int, walk_s: float = 7.0, cut_s: float = 1.5, end_s: float = 0.7) -> Motion:
    """A walk trial as recorded when the recording starts after the first steps: the walk of
    ``stand_walk_stand`` from ``cut_s`` into its walking, to a short stop (``end_s``, under
    the 1 s a still stand needs)."""
    m = stand_walk_stand(walk_s=walk_s, stand_s=1.0, end_s=end_s, seed=seed)
    start = int(round((1.0 + 0.5 + cut_s) * m.fps))
    return m.slice(start, m.n_frames)


def synthesize_dot_session(folder: str | os.PathLike, seed: int = 0, walks: int = 1, leg_cycles: bool = True,
                           noise: NoiseModel | None = None, walk_s: float = 7.0) -> DotSession:
    """A whole session in ``folder``: ``npose``, ``legcycle_left`` and ``legcycle_right``
    (when ``leg_cycles``), ``walk_001``... (no still start); ``noise`` default MTw-class with
    10 deg mounting errors. Every trial's sensors have their own heading reference."""
    noise = noise or replace(NoiseModel.typical(), mounting_deg=10.0)
    folder = Path(folder)
    trials: dict[str, TrialTruth] = {}
    plan: list[tuple[str, str, Motion]] = [("npose", "npose", generate("npose", seconds=4.0))]
    if leg_cycles:
        plan += [(f"legcycle_{w}", "leg_cycle", leg_cycle(s, seed=seed)) for s, w in (("l", "left"), ("r", "right"))]
    plan += [(f"walk_{i + 1:03d}", "walk", walk_without_still_start(seed * 10 + i, walk_s=walk_s))
             for i in range(walks)]
    for n, (name, kind, motion) in enumerate(plan):
        trials[name] = synthesize_trial(motion, folder, name, kind, seed, 1000 * seed + n, noise,
                                        stamp=f"20240502_10{n:02d}00")
    return DotSession(folder, trials)


__all__ = ["ADDRESSES", "DotSession", "SITES", "TAGS", "TrialTruth", "nominal_mounting", "synthesize_dot_session",
           "synthesize_trial", "walk_without_still_start", "write_dot_trial"]
