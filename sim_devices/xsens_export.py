"""Synthesized signals written as Xsens exports (the layouts ``drivers.xsens_export``
reads), so importing a lab's MT Manager or DOT session is tested end to end without the
sensors.

Like the real files (see the readers' docstrings for the public samples they follow):
one file per sensor; MT Manager's ``//`` preamble, tab- or comma-separated, PacketCounter
wrapping at 2^16 and SampleTimeFine in 10 kHz ticks, Gyr_* in rad/s, file named
``MT_<station>_<take>_<device id>.txt``; the DOT app's ``sep=,`` and ``Key:,value``
preamble, SampleTimeFine in microseconds, Gyr_* in deg/s, Euler in degrees, file named
``<tag>_<address>_<date>_<time>.csv``. The sensors of one session share one clock, which
starts close enough to 2^32 ticks to wrap during the session. A dropped packet is a row
missing from every file; a blanked cell is written empty.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from drivers.xsens_export import DOT, MTMANAGER, G
from inference.body.motion import Motion
from inference.body.rotations import quat_conjugate, quat_rotate, quat_to_euler, quat_to_matrix
from inference.signals.site_signals import SiteSignals

WRAP = 2**32
MAG_EARTH = np.array([0.0, 0.45, -0.89])  # a.u.: north along +Y (ENU), dipping down
Values = Callable[[SiteSignals, int], np.ndarray]  # (signals, site index) -> (T, n) one site's columns


def _free_acc(sig: SiteSignals, k: int) -> np.ndarray:
    """What an Xsens reports as free acceleration: its own specific force turned to Earth
    by its own orientation, gravity removed (unsmoothed, unlike ``sig.free_acc``)."""
    return quat_rotate(sig.quat[:, k], sig.specific_force[:, k]) - np.array([0.0, 0.0, G])


def _euler_deg(sig: SiteSignals, k: int) -> np.ndarray:
    """(roll, pitch, yaw) in degrees, Xsens's order R = Rz(yaw) Ry(pitch) Rx(roll)."""
    return np.degrees(quat_to_euler(sig.quat[:, k], "ZYX"))[:, ::-1]


def _matrix_columns(sig: SiteSignals, k: int) -> np.ndarray:
    """Mat[1][1], Mat[2][1], Mat[3][1], Mat[1][2], ...: R_GS column by column."""
    return np.swapaxes(quat_to_matrix(sig.quat[:, k]), -1, -2).reshape(-1, 9)


def _mag(sig: SiteSignals, k: int) -> np.ndarray:
    return quat_rotate(quat_conjugate(sig.quat[:, k]), np.broadcast_to(MAG_EARTH, sig.quat[:, k, 1:].shape))


# a column group -> (its column names, its values)
MT_GROUPS: dict[str, tuple[tuple[str, ...], Values]] = {
    "acc": (("Acc_X", "Acc_Y", "Acc_Z"), lambda s, k: s.specific_force[:, k]),
    "freeacc": (("FreeAcc_X", "FreeAcc_Y", "FreeAcc_Z"), _free_acc),
    "gyr": (("Gyr_X", "Gyr_Y", "Gyr_Z"), lambda s, k: s.gyro[:, k]),
    "mag": (("Mag_X", "Mag_Y", "Mag_Z"), _mag),
    "quat": (("Quat_q0", "Quat_q1", "Quat_q2", "Quat_q3"), lambda s, k: s.quat[:, k]),
    "matrix": (tuple(f"Mat[{r}][{c}]" for c in (1, 2, 3) for r in (1, 2, 3)), _matrix_columns),
    "euler": (("Roll", "Pitch", "Yaw"), _euler_deg),
}
DOT_GROUPS: dict[str, tuple[tuple[str, ...], Values]] = {
    "quat": (("Quat_W", "Quat_X", "Quat_Y", "Quat_Z"), lambda s, k: s.quat[:, k]),
    "euler": (("Euler_X", "Euler_Y", "Euler_Z"), _euler_deg),
    "freeacc": (("FreeAcc_X", "FreeAcc_Y", "FreeAcc_Z"), _free_acc),
    "acc": (("Acc_X", "Acc_Y", "Acc_Z"), lambda s, k: s.specific_force[:, k]),
    "gyr": (("Gyr_X", "Gyr_Y", "Gyr_Z"), lambda s, k: np.degrees(s.gyro[:, k])),
}
MT_DEFAULT = ("acc", "gyr", "mag", "quat")
DOT_DEFAULT = ("quat", "freeacc")


def _table(sig: SiteSignals, k: int, groups: Mapping[str, tuple[tuple[str, ...], Values]],
           chosen: Sequence[str]) -> tuple[list[str], np.ndarray]:
    """(column names, (T, n) values) of one site for the chosen groups."""
    names: list[str] = []
    values = []
    for g in chosen:
        cols, fn = groups[g]
        names += cols
        values.append(np.asarray(fn(sig, k), dtype=np.float64).reshape(len(sig.t), -1))
    return names, np.concatenate(values, axis=1)


def _lines(counter: np.ndarray, fine: np.ndarray | None, values: np.ndarray, delimiter: str, counter_width: int,
           blank: set[tuple[int, int]]) -> list[str]:
    """Data lines; ``blank`` holds (row, value column) cells left empty."""
    out = []
    for i, (c, row) in enumerate(zip(counter, values)):
        cells = [f"{int(c):0{counter_width}d}"] + ([] if fine is None else [str(int(fine[i]))])
        cells += ["" if (i, j) in blank else f"{v:.6f}" for j, v in enumerate(row)]
        out.append(delimiter.join(cells))
    return out


def _blank_cells(names: list[str], blank: Sequence[tuple[int, str]]) -> set[tuple[int, int]]:
    return {(row, names.index(col)) for row, col in blank}


def write_mtmanager_exports(sig: SiteSignals, folder: str | os.PathLike, ids: Mapping[str, str],
                            columns: Sequence[str] = MT_DEFAULT, delimiter: str = "\t", time: bool = True,
                            t0_ticks: int = WRAP - 20_000, counter0: int = 65_400, drop: Sequence[int] = (),
                            blank: Sequence[tuple[int, str]] = (), long_header: bool = False) -> list[Path]:
    """One MT Manager export per site of ``sig`` (ids: site -> device id) in ``folder``.
    columns: groups of ``MT_GROUPS`` after PacketCounter (and SampleTimeFine unless
    ``time`` is False: time by counter and rate, as the OpenSim example files do);
    drop: sample indices lost from every file; blank: (row, column name) cells left empty."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    keep = np.setdiff1d(np.arange(len(sig.t)), np.asarray(drop, dtype=int))
    counter = (counter0 + keep) % MTMANAGER.counter_wrap
    fine = (t0_ticks + np.rint(sig.t[keep] / MTMANAGER.tick_s).astype(np.int64)) % WRAP if time else None
    ext = ".txt" if delimiter == "\t" else ".csv"
    paths = []
    for k, site in enumerate(sig.sites):
        names, values = _table(sig, k, MT_GROUPS, columns)
        head = ["PacketCounter"] + (["SampleTimeFine"] if time else []) + names
        path = folder / f"MT_012005D6_000-000_{ids[site]}{ext}"
        text = _mt_preamble(ids[site], sig.fps, long_header) + [delimiter.join(head)]
        text += _lines(counter, fine, values[keep], delimiter, 5, _blank_cells(names, blank))
        path.write_text("\n".join(text) + "\n")
        paths.append(path)
    return paths


def _mt_preamble(device_id: str, rate: float, long_header: bool) -> list[str]:
    """MT Manager's preamble: the short one of older versions (no device id; the file name
    carries it) or the grouped one of newer versions."""
    if not long_header:
        return ["// Start Time: Unknown", f"// Update Rate: {rate:.1f}Hz", "// Filter Profile: human (46.1)",
                "// Option Flags: AHS Disabled ICC Disabled ", "// Firmware Version: 4.0.2"]
    return ["// General information: ", "//  MT Manager version: 2022.2.0", "// Device information: ",
            f"//  DeviceId: {device_id}", "//  ProductCode: MTW2-3A7G6", "//  Firmware Version: 4.4.0",
            "// Device settings: ", "//  Filter Profile: human(46.1)", f"//  Update Rate: {rate:.1f}Hz",
            "// Coordinate system: ENU"]


def write_dot_exports(sig: SiteSignals, folder: str | os.PathLike, tags: Mapping[str, str],
                      columns: Sequence[str] = DOT_DEFAULT, t0_us: int = WRAP - 3_000_000,
                      drop: Sequence[int] = (), blank: Sequence[tuple[int, str]] = ()) -> list[Path]:
    """One DOT app export per site of ``sig`` (tags: site -> the tag the user gave the
    sensor) in ``folder``; columns: groups of ``DOT_GROUPS`` after PacketCounter and
    SampleTimeFine (default the app's Quat + FreeAcc); drop, blank as for MT Manager."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    keep = np.setdiff1d(np.arange(len(sig.t)), np.asarray(drop, dtype=int))
    fine = (t0_us + np.rint(sig.t[keep] / DOT.tick_s).astype(np.int64)) % WRAP
    paths = []
    for k, site in enumerate(sig.sites):
        names, values = _table(sig, k, DOT_GROUPS, columns)
        address = f"D4CA6EF1{0x7200 + k:04X}"
        pad = "," * (len(names) + 1)
        text = ["sep=,", f"DeviceTag:,{tags[site]}{pad}", f"FirmwareVersion:,2.0.0{pad}", f"AppVersion:,2021.0{pad}",
                f"SyncStatus:,Synced{pad}", f"OutputRate:,{sig.fps:g}Hz{pad}", f"FilterProfile:,General{pad}",
                f"StartTime: ,2024-05-02_10:00:00_000 GMT+1{pad}", "\u00a9 Xsens Technologies B. V. 2005-2024", "",
                ",".join(["PacketCounter", "SampleTimeFine", *names])]
        text += _lines(keep + 1, fine, values[keep], ",", 1, _blank_cells(names, blank))
        path = folder / f"{tags[site]}_{address}_20240502_100000.csv"
        path.write_text("\n".join(text) + "\n", encoding="utf-8")
        paths.append(path)
    return paths


def _mvnx_numbers(rows: np.ndarray) -> str:
    return " ".join(f"{v:.6f}" for v in rows.ravel())


# MVN's segments as written here: label -> (our segment its orientation and origin come
# from, the joint point MVN names at its origin). L3 sits halfway between spine1 and spine2.
MVN_SEGMENTS: dict[str, tuple[str, str]] = {
    "Pelvis": ("pelvis", ""), "L5": ("spine1", "jL5S1"), "L3": ("spine1", "jL4L3"), "T12": ("spine2", "jL1T12"),
    "T8": ("spine3", "jT9T8"), "Neck": ("neck", "jT1C7"), "Head": ("head", "jC1Head"),
    **{k: v for side, s in (("Right", "r"), ("Left", "l")) for k, v in (
        (f"{side}Shoulder", (f"{s}_collar", f"j{side}T4Shoulder")),
        (f"{side}UpperArm", (f"{s}_upperarm", f"j{side}Shoulder")),
        (f"{side}ForeArm", (f"{s}_forearm", f"j{side}Elbow")), (f"{side}Hand", (f"{s}_hand", f"j{side}Wrist")))},
    **{k: v for side, s in (("Right", "r"), ("Left", "l")) for k, v in (
        (f"{side}UpperLeg", (f"{s}_thigh", f"j{side}Hip")), (f"{side}LowerLeg", (f"{s}_shank", f"j{side}Knee")),
        (f"{side}Foot", (f"{s}_foot", f"j{side}Ankle")), (f"{side}Toe", (f"{s}_toes", f"j{side}BallFoot")))},
}
MVN_TREE: dict[str, str] = {
    "L5": "Pelvis", "L3": "L5", "T12": "L3", "T8": "T12", "Neck": "T8", "Head": "Neck",
    **{k: v for side in ("Right", "Left") for k, v in (
        (f"{side}Shoulder", "T8"), (f"{side}UpperArm", f"{side}Shoulder"), (f"{side}ForeArm", f"{side}UpperArm"),
        (f"{side}Hand", f"{side}ForeArm"), (f"{side}UpperLeg", "Pelvis"), (f"{side}LowerLeg", f"{side}UpperLeg"),
        (f"{side}Foot", f"{side}LowerLeg"), (f"{side}Toe", f"{side}Foot"))},
}


def _mvn_body(motion: Motion) -> tuple[dict[str, np.ndarray], np.ndarray, np.ndarray]:
    """(segment -> its points {label: pos_b}, orientations (T, 23, 4), origins (T, 23, 3))
    of ``motion`` as MVN would store them: at zero rotation a T-pose in our axes."""
    from inference.body.rotations import matrix_to_quat
    from inference.body.skeleton import SEGMENT_INDEX

    rest, joints = motion.body.rest_joints(), motion.joints()
    labels = list(MVN_SEGMENTS)
    spine1, spine2 = SEGMENT_INDEX["spine1"], SEGMENT_INDEX["spine2"]

    def origin(label: str, at: np.ndarray) -> np.ndarray:
        if label == "L3":
            return (at[..., spine1, :] + at[..., spine2, :]) / 2
        return at[..., SEGMENT_INDEX[MVN_SEGMENTS[label][0]], :]

    points: dict[str, dict[str, np.ndarray]] = {label: {} for label in labels}
    for label in labels:
        joint = MVN_SEGMENTS[label][1]
        if joint:
            points[label][joint] = np.zeros(3)
            parent = MVN_TREE[label]
            points[parent][joint] = origin(label, rest) - origin(parent, rest)
    for label, point, tip in (("Head", "pTopOfHead", (0.0, 0.0, 0.2)), ("RightToe", "pRightToe", (0.05, 0.0, 0.0)),
                              ("LeftToe", "pLeftToe", (0.05, 0.0, 0.0))):
        points[label][point] = np.array(tip)
    for side, s in (("Right", "r"), ("Left", "l")):
        hand, fingers = SEGMENT_INDEX[f"{s}_hand"], SEGMENT_INDEX[f"{s}_fingers"]
        points[f"{side}Hand"][f"p{side}TopOfHand"] = rest[fingers] - rest[hand]
    quat = np.stack([matrix_to_quat(motion.rot[:, SEGMENT_INDEX[MVN_SEGMENTS[label][0]]]) for label in labels], 1)
    pos = np.stack([origin(label, joints) for label in labels], axis=1)
    return points, quat, pos


def write_mvnx(sig: SiteSignals, path: str | os.PathLike, labels: Mapping[str, str],
               extra: Mapping[str, str] | None = None, drop: Sequence[int] = (), bad: Sequence[int] = (),
               cut_at: int | None = None, motion: Motion | None = None) -> Path:
    """A take of ``sig`` as MVN writes it to MVNX (``drivers.xsens_export.mvnx`` for the
    layout): labels: site -> MVN sensor label; extra: more sensors, label -> the site whose
    signals they carry (a hand sensor beside the forearm's), which imucap has no site for.
    With ``motion`` (the one ``sig`` was synthesized from), MVN's 23 segments carry its
    body and posture (``inference.loaders.mvnx`` reads them); else each sensor's segment
    stands alone. The calibration frames (identity, T-pose) come first; drop: samples
    missing (MVN skips a frame it could not solve); bad: frames written with a short sensor
    list; cut_at: the file ends mid-frame there, unclosed, as a copy that stopped would."""
    path = Path(path)
    sensors = [(label, sig.sites.index(site)) for site, label in labels.items()]
    sensors += [(label, sig.sites.index(site)) for label, site in (extra or {}).items()]
    idx = [k for _, k in sensors]
    free = np.stack([_free_acc(sig, k) for k in idx], axis=1)  # (T, S, 3)
    quat = sig.quat[:, idx]
    if motion is not None:
        points, seg_quat, seg_pos = _mvn_body(motion)
    else:
        points = {label: {f"p{label}Origin": np.zeros(3)} for label, _ in sensors}
        seg_quat, seg_pos = quat, np.zeros((len(sig.t), len(sensors), 3))
    ms0 = 1_714_640_400_000
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             '<mvnx xmlns="http://www.xsens.com/mvn/mvnx" version="4">',
             '\t<mvn version="2022.0.0" build="simulated"/>', "\t<comment></comment>",
             f'\t<subject label="sim subject" torsoColor="#ea6852" frameRate="{sig.fps:g}" '
             f'segmentCount="{len(points)}" recDate="Thu May 02 10:00:00.000 2024" configuration="FullBody" '
             'userScenario="singleLevel">',
             "\t\t<comment></comment>", "\t\t<segments>"]
    for n, (label, pts) in enumerate(points.items(), 1):
        lines += [f'\t\t\t<segment label="{label}" id="{n}">', "\t\t\t\t<points>"]
        for name, v in pts.items():
            lines += [f'\t\t\t\t\t<point label="{name}">', f"\t\t\t\t\t\t<pos_b>{_mvnx_numbers(v)}</pos_b>",
                      "\t\t\t\t\t</point>"]
        lines += ["\t\t\t\t</points>", "\t\t\t</segment>"]
    lines += ["\t\t</segments>", "\t\t<sensors>"] + [f'\t\t\t<sensor label="{label}"/>' for label, _ in sensors]
    lines += ["\t\t</sensors>",
              f'\t\t<frames segmentCount="{len(points)}" sensorCount="{len(sensors)}" jointCount="0">']
    unit = np.tile([1.0, 0.0, 0.0, 0.0], len(points))
    for kind in ("identity", "tpose", "tpose-isb"):
        lines += [f'\t\t\t<frame time="0" tc="00:00:00:00" ms="{ms0}" type="{kind}">',
                  f"\t\t\t\t<orientation>{_mvnx_numbers(unit)}</orientation>",
                  f"\t\t\t\t<position>{_mvnx_numbers(np.zeros(3 * len(points)))}</position>", "\t\t\t</frame>"]
    dropped = set(int(i) for i in drop)
    for i in range(len(sig.t)):
        if i in dropped:
            continue
        ms = int(round(sig.t[i] * 1000.0))
        q, a = quat[i], free[i]
        if i in bad:
            q = q[:-1]
        frame = [f'\t\t\t<frame time="{ms}" index="{i}" tc="00:00:{ms // 1000:02d}:{i % 60:02d}" ms="{ms0 + ms}" '
                 'type="normal">',
                 f"\t\t\t\t<orientation>{_mvnx_numbers(seg_quat[i])}</orientation>",
                 f"\t\t\t\t<position>{_mvnx_numbers(seg_pos[i])}</position>",
                 f"\t\t\t\t<sensorFreeAcceleration>{_mvnx_numbers(a)}</sensorFreeAcceleration>",
                 f"\t\t\t\t<sensorOrientation>{_mvnx_numbers(q)}</sensorOrientation>", "\t\t\t</frame>"]
        if cut_at is not None and i == cut_at:
            lines += frame[:3]
            lines.append(frame[3][: len(frame[3]) // 2])
            path.write_text("\n".join(lines), encoding="utf-8")
            return path
        lines += frame
    lines += ["\t\t</frames>", "\t</subject>", '\t<securityCode code="0"/>', "</mvnx>"]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


# ------------------------------------------------------------------ a logged walk with its truth


def stand_walk_stand(walk_s: float = 6.0, stand_s: float = 2.0, end_s: float = 2.0, seed: int = 0,
                     heading_deg: float = 0.0, blend_s: float = 0.5) -> Motion:
    """What a lab logs for a calibrated trial: standing still in the N-pose, blending into a
    walk straight ahead, blending back into standing still where the walk ended. Still at
    both ends, so each sensor's path over the walk can be integrated (``calibration.gait_heading``).
    Faces +X turned by ``heading_deg``; 60 Hz."""
    from inference.body.rotations import matrix_to_quat, quat_slerp

    from .motions import generate

    walk = generate("walk", seconds=walk_s, seed=seed)
    hold = generate("npose", seconds=max(stand_s, end_s))
    nb = max(int(round(blend_s * 60.0)), 1)
    w = (np.arange(nb) + 1.0) / (nb + 1.0)
    w = w * w * (3.0 - 2.0 * w)

    def blend(R0: np.ndarray, R1: np.ndarray, p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        q0, q1 = matrix_to_quat(R0), matrix_to_quat(R1)
        q = quat_slerp(np.broadcast_to(q0, (nb,) + q0.shape), np.broadcast_to(q1, (nb,) + q1.shape),
                       w.reshape(-1, 1))
        return quat_to_matrix(q), p0 + w[:, None] * (p1 - p0)

    n0, n1 = int(round(stand_s * 60.0)), int(round(end_s * 60.0))
    start_root = hold.root[:n0] + (walk.root[0] - hold.root[0]) * [1, 1, 0]
    end_root = hold.root[:n1] + (walk.root[-1] - hold.root[0]) * [1, 1, 0]
    r_in, p_in = blend(hold.rot[0], walk.rot[0], start_root[-1], walk.root[0])
    r_out, p_out = blend(walk.rot[-1], hold.rot[0], walk.root[-1], end_root[0])
    rot = np.concatenate([hold.rot[:n0], r_in, walk.rot, r_out, hold.rot[:n1]])
    root = np.concatenate([start_root, p_in, walk.root, p_out, end_root])
    if heading_deg:
        from .motions import rz

        Rh = rz(np.deg2rad(heading_deg))
        rot, root = Rh @ rot, root @ Rh.T
    return Motion(rot=rot, root=root, fps=60.0, body=hold.body, name="stand_walk_stand",
                  meta={"still_frames": n0, "walk_seed": seed})


__all__ = ["DOT_GROUPS", "MT_GROUPS", "stand_walk_stand", "write_dot_exports", "write_mtmanager_exports",
           "write_mvnx"]
