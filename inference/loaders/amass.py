"""AMASS .npz reader (SMPL-H `poses` axis-angle, `trans`, `mocap_framerate`, Z-up).

No SMPL model file is used (its license forbids it here), so the body's bone lengths come
from the height: the `imucap_height_m` field our generator writes, else 1.75 m. The
pelvis path is `trans`; SMPL's constant pelvis offset disappears in floor alignment.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from inference.body.body import Body
from inference.body.motion import Motion, MotionFormatError
from inference.loaders.amass_frames import amass_poses_to_global


def _numbers(path: Path, data: dict[str, np.ndarray], key: str) -> np.ndarray:
    """A member as float64; text, object or record arrays are a wrong file, and numpy's
    TypeError for them would name neither the file nor the member."""
    a = data[key]
    if not isinstance(a, np.ndarray):  # np.load gives a member that is no .npy as raw bytes
        raise MotionFormatError(str(path), f"{key} is not a numpy array")
    if a.dtype.kind not in "biuf":
        raise MotionFormatError(str(path), f"{key} holds {a.dtype} values, not numbers")
    return np.asarray(a, dtype=np.float64)


def _scalar(path: Path, data: dict[str, np.ndarray], key: str) -> float:
    a = _numbers(path, data, key)
    if a.size != 1:
        raise MotionFormatError(str(path), f"{key} should be one number, has shape {a.shape}")
    return float(a.reshape(()))


def load_amass(path: str | Path, height: float | None = None) -> Motion:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such motion file") from None
    except Exception as exc:  # noqa: BLE001
        # a damaged .npz fails in zipfile, zlib, numpy's header parser (tokenize) or its
        # reader, each with its own exception types (RuntimeError for an "encrypted"
        # member, TokenError for a cut header...): all of them mean the same to the user
        raise MotionFormatError(str(path), f"not a readable .npz ({type(exc).__name__}: {exc})") from None
    missing = [k for k in ("poses", "trans") if k not in data]
    if missing:
        raise MotionFormatError(str(path), f"AMASS file lacks {missing}; has {sorted(data)}")
    fps_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in data), None)
    if fps_key is None:
        raise MotionFormatError(str(path), "AMASS file has no mocap_framerate")
    poses = _numbers(path, data, "poses")
    trans = _numbers(path, data, "trans")
    fps = _scalar(path, data, fps_key)
    if poses.ndim != 2 or poses.shape[1] < 66 or poses.shape[1] % 3:
        raise MotionFormatError(str(path), f"poses must be (T, 3*J) with J >= 22, got {poses.shape}")
    if trans.shape != (poses.shape[0], 3):
        raise MotionFormatError(str(path), f"trans {trans.shape} does not match poses {poses.shape}")
    if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(trans))):
        bad = int(np.where(~(np.isfinite(poses).all(1) & np.isfinite(trans).all(1)))[0][0])
        raise MotionFormatError(str(path), f"frame {bad} contains NaN or infinite values")
    if not fps > 0:
        raise MotionFormatError(str(path), f"bad mocap_framerate {fps}")
    if height is None:
        height = _scalar(path, data, "imucap_height_m") if "imucap_height_m" in data else 1.75
    rot = amass_poses_to_global(poses)
    name = path.name.removesuffix(".npz")
    return Motion(rot=rot, root=trans, fps=fps, body=Body.from_height(height), name=name, source=str(path),
                  meta={"format": "amass"}).floor_aligned()
