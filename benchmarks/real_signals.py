"""Where the real x-IMU3 walk differs from signals synthesized on a Bandai walk: the figures
and tables of docs/real_signals.md.

    .venv/bin/python benchmarks/real_signals.py [--log DIR] [--walk BVH] [--json OUT.json] [--figures docs]

The real log is imported as ``imucap import`` does (standing start, each sensor's heading
from the gait) and its calibrated bone orientations R_WB and world free accelerations are
compared, per lower-body site, with ``synthesize`` on the walk (the evaluation's sensor
noise, no mounting or heading error: what the model is scored on). Both at 60 Hz.

Measures (walking part only: real from 2 s after the standing start, synthesized whole):
- sagittal swing of each segment (its long axis in the pelvis's heading frame), range 5-95 %;
- swing axis: the principal axis of the bone-frame angular rate, its angle from the bone's
  lateral axis (Y), split into heading (about Z) and tilt: a residual mounting error;
- placement along the segment: slope of the acceleration along the segment's long axis on
  the squared swing rate (centripetal, a = w^2 r, r = distance from the proximal joint);
- acceleration spectra (Welch) and the share of power above 5 Hz, which the 11-frame
  moving average of the model's input removes;
- heel-strike impacts: per step, the peak |a| of shank and foot, raw and as the model sees it;
- strap/skin motion: RMS of the orientation about its 11-frame moving average (deg);
- timing between sensors: lag of the cross-correlation of high-passed |a| of foot, shank and
  thigh of one leg (a heel strike reaches them at the same instant).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

LOWER = ("pelvis", "l_thigh", "r_thigh", "l_shank", "r_shank", "l_foot", "r_foot")
FPS = 60.0


def _data() -> Path:
    from inference.training.data import data_root

    return data_root()


def real_signals(log: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(R_WB (T,S,3,3), a_W (T,S,3), t (T,)) of the imported log after calibration, from
    the moment its calibration takes effect; sites in LOWER order."""
    from app.cli.importing import import_paths
    from app.recording import read_recording

    with tempfile.TemporaryDirectory() as tmp:
        import_paths([log], Path(tmp) / "s.h5", reconstruct=False)
        rec = read_recording(Path(tmp) / "s.h5")
    t_cal, cal = rec.calibrations[-1]
    raw = rec.raw
    quat = np.stack([raw[s]["quat"] for s in LOWER], axis=1)
    free = np.stack([raw[s]["free_acc"] for s in LOWER], axis=1)
    acc = np.stack([raw[s]["acc"] for s in LOWER], axis=1)
    R, a = cal.apply(quat, free, acc, sites=LOWER)
    t = np.asarray(raw["t"], float)
    keep = t >= t_cal + 2.0
    R, a, t = R[keep], a[keep], t[keep]
    ok = np.all(np.isfinite(a), axis=(1, 2)) & np.all(np.isfinite(R), axis=(1, 2, 3))
    return R[ok], a[ok], t[ok]


def synth_signals(walk: Path, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(R_WB, raw free acceleration) of ``synthesize`` on ``walk`` with the evaluation noise."""
    from inference.body.rotations import quat_to_matrix
    from inference.evaluation.runner import evaluation_noise
    from inference.loaders import load_motion
    from inference.signals.synthesis import synthesize

    sig = synthesize(load_motion(walk), evaluation_noise(), seed, sites=LOWER)
    return quat_to_matrix(sig.quat), sig.meta["free_acc_raw"]


def body_rate(R: np.ndarray) -> np.ndarray:
    from inference.signals.synthesis import angular_velocity

    return angular_velocity(R, FPS)


def sagittal_angle(R: np.ndarray) -> np.ndarray:
    """(T,S) deg: each segment's long axis (bone -Z, down at standing) in the sagittal plane
    of the pelvis's heading, 0 = vertical, + = distal end forward."""
    fwd = R[:, 0, :, 0].copy()
    fwd[:, 2] = 0.0
    fwd /= np.linalg.norm(fwd, axis=-1, keepdims=True)
    down = -R[:, :, :, 2]
    along = np.einsum("tk,tsk->ts", fwd, down)
    return np.degrees(np.arctan2(along, -down[..., 2]))


def swing_axis(w: np.ndarray) -> tuple[float, float, float]:
    """(total, heading, tilt) deg of the principal axis of bone-frame rates w (T,3) from +Y."""
    c = w.T @ w
    vals, vecs = np.linalg.eigh(c)
    ax = vecs[:, -1]
    ax = ax if ax[1] >= 0 else -ax
    total = float(np.degrees(np.arccos(np.clip(ax[1], -1, 1))))
    heading = float(np.degrees(np.arctan2(-ax[0], ax[1])))
    tilt = float(np.degrees(np.arctan2(ax[2], ax[1])))
    return total, heading, tilt


def placement(R: np.ndarray, a: np.ndarray, w: np.ndarray) -> float:
    """Slope (m) of the long-axis (bone +Z) acceleration on the squared rate about the
    other two axes: the sensor's distance from the segment's proximal joint."""
    a_B = np.einsum("tji,tj->ti", R, a)
    w2 = w[:, 0] ** 2 + w[:, 1] ** 2
    use = w2 > 4.0  # swing, not stance
    if use.sum() < 20:
        return float("nan")
    A = np.stack([w2[use], np.ones(use.sum())], axis=1)
    return float(np.linalg.lstsq(A, a_B[use, 2], rcond=None)[0][0])


def high_share(x: np.ndarray, cut: float = 5.0) -> tuple[np.ndarray, np.ndarray, float]:
    from scipy.signal import welch

    f, p = welch(x - x.mean(), fs=FPS, nperseg=min(256, len(x)))
    return f, p, float(p[f > cut].sum() / p.sum())


def impacts(a: np.ndarray, w_shank: np.ndarray) -> dict[str, float]:
    """Median per-step peak |a| (m/s^2), raw and after the model's moving average; steps
    cut at the shank's swing-rate peaks."""
    from scipy.signal import find_peaks

    from inference.signals.resample import moving_average

    mag = np.linalg.norm(a, axis=-1)
    smooth = np.linalg.norm(moving_average(a[:, None])[:, 0], axis=-1)
    peaks, _ = find_peaks(np.abs(w_shank), height=3.0, distance=int(0.6 * FPS))
    if len(peaks) < 3:
        return {"steps": int(len(peaks)), "raw": float("nan"), "smoothed": float("nan")}
    raw = [mag[p:q].max() for p, q in zip(peaks[:-1], peaks[1:])]
    sm = [smooth[p:q].max() for p, q in zip(peaks[:-1], peaks[1:])]
    return {"steps": int(len(peaks) - 1), "raw": float(np.median(raw)), "smoothed": float(np.median(sm))}


def strap_motion(R: np.ndarray) -> float:
    """RMS deg of each orientation about its 11-frame moving average (what is too fast to
    be the segment moving: skin, strap, sensor fusion jitter)."""
    from inference.body.rotations import matrix_angle_between
    from inference.signals.resample import moving_average

    Rs = moving_average(R.reshape(len(R), -1)).reshape(R.shape)
    u, _, vt = np.linalg.svd(Rs)
    Rs = u @ vt
    return float(np.degrees(np.sqrt(np.mean(matrix_angle_between(R, Rs)[5:-5] ** 2))))


def lag_ms(x: np.ndarray, y: np.ndarray, max_lag: int = 12) -> float:
    """Lag (ms) of y behind x maximising the cross-correlation of the high-passed signals."""
    from inference.signals.resample import moving_average

    def hp(v):
        return v - moving_average(v[:, None, None])[:, 0, 0]

    x, y = hp(x), hp(y)
    best, arg = -np.inf, 0
    for k in range(-max_lag, max_lag + 1):
        c = np.dot(x[max_lag:-max_lag], np.roll(y, -k)[max_lag:-max_lag])
        if c > best:
            best, arg = c, k
    return 1000.0 * arg / FPS


TURN_RATE = 0.5  # rad/s: frames whose pelvis turns faster are left out of the swing-axis and placement fits


def analyse(R: np.ndarray, a: np.ndarray) -> dict:
    w = body_rate(R)
    ang = sagittal_angle(R)
    # the log turns on the spot twice: a turn's rate about the vertical is no swing axis
    yaw_rate = np.einsum("tij,tj->ti", R[:, 0], w[:, 0])[:, 2]
    straight = np.abs(yaw_rate) < TURN_RATE
    out: dict = {"seconds": round(len(R) / FPS, 2), "sites": {}}
    out["straight_seconds"] = round(float(straight.sum()) / FPS, 2)
    for k, s in enumerate(LOWER):
        lo, hi = np.percentile(ang[:, k], [5, 95])
        _, _, share = high_share(np.linalg.norm(a[:, k], axis=-1))
        total, heading, tilt = swing_axis(w[straight, k])
        shank = LOWER.index(("l_" if s.startswith("l_") else "r_") + "shank") if s != "pelvis" else 3
        out["sites"][s] = {
            "swing_range_deg": round(float(hi - lo), 1),
            "swing_axis_deg": round(total, 1), "swing_axis_heading_deg": round(heading, 1),
            "swing_axis_tilt_deg": round(tilt, 1),
            "placement_m": round(placement(R[straight, k], a[straight, k], w[straight, k]), 3),
            "acc_rms": round(float(np.sqrt(np.mean(np.sum((a[:, k] - a[:, k].mean(0)) ** 2, -1)))), 2),
            "acc_power_above_5hz": round(share, 3),
            "impact": {k2: round(v, 2) for k2, v in impacts(a[:, k], w[:, shank, 1]).items()},
            "strap_motion_deg": round(strap_motion(R[:, k]), 2),
        }
    mags = np.linalg.norm(a, axis=-1)
    out["lag_ms"] = {f"{side}_{b}_vs_{side}_foot": round(lag_ms(mags[:, LOWER.index(f"{side}_foot")],
                                                                 mags[:, LOWER.index(f"{side}_{b}")]), 1)
                     for side in ("l", "r") for b in ("shank", "thigh")}
    out["lag_ms"]["pelvis_vs_l_foot"] = round(lag_ms(mags[:, LOWER.index("l_foot")], mags[:, 0]), 1)
    return out


def figures(real: tuple, synth: tuple, out_dir: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    (Rr, ar), (Rs, as_) = real, synth
    names = []
    fig, axes = plt.subplots(2, 4, figsize=(13, 5.5), sharex="row")
    for col, s in enumerate(("pelvis", "l_thigh", "l_shank", "l_foot")):
        k = LOWER.index(s)
        for R, a, lab, c in ((Rr, ar, "real x-IMU3", "C3"), (Rs, as_, "synthesized (Bandai walk)", "C0")):
            f, p, _ = high_share(np.linalg.norm(a[:, k], axis=-1))
            axes[0, col].semilogy(f, p, c, label=lab)
            t = np.arange(min(len(R), 360)) / FPS
            axes[1, col].plot(t, sagittal_angle(R)[: len(t), k], c, label=lab)
        axes[0, col].axvline(60 / 11, color="k", ls=":", lw=0.8)
        axes[0, col].set_title(f"{s}: |a| spectrum")
        axes[0, col].set_xlabel("Hz")
        axes[1, col].set_title(f"{s}: sagittal angle (deg)")
        axes[1, col].set_xlabel("s")
    axes[0, 0].set_ylabel("(m/s^2)^2 / Hz")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    p = out_dir / "real_signals_spectra.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    names.append(str(p))

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.6))
    for ax, s in zip(axes, ("l_shank", "l_foot")):
        k = LOWER.index(s)
        for a, lab, c in ((ar, "real", "C3"), (as_, "synthesized", "C0")):
            n = min(len(a), 240)
            ax.plot(np.arange(n) / FPS, np.linalg.norm(a[:n, k], axis=-1), c, lw=0.9, label=lab)
        ax.set_title(f"{s}: |free acceleration| (m/s^2), 60 Hz, unsmoothed")
        ax.set_xlabel("s")
    axes[0].legend(fontsize=8)
    fig.tight_layout()
    p = out_dir / "real_signals_impacts.png"
    fig.savefig(p, dpi=90)
    plt.close(fig)
    names.append(str(p))
    return names


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--log", type=Path, default=None, help="x-IMU3 log folder (default: the shared lower-body log)")
    ap.add_argument("--walk", type=Path, default=None, help="motion to synthesize (default: Bandai walk normal 001)")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures as JSON here")
    ap.add_argument("--figures", type=Path, default=None, help="write the PNGs into this folder (e.g. docs)")
    args = ap.parse_args()
    log = args.log or _data() / "ximu3" / "logged_lower_body"
    walk = args.walk or _data() / "bandai" / "d1" / "dataset-1_walk_normal_001.bvh.gz"
    real = real_signals(log)[:2]
    synth = synth_signals(walk)
    res = {"real": analyse(*real), "synthesized": analyse(*synth), "log": str(log), "walk": str(walk)}
    if args.figures is not None:
        res["figures"] = figures(real, synth, args.figures)
    text = json.dumps(res, indent=1)
    if args.json is not None:
        args.json.write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
