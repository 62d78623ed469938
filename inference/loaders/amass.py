"""AMASS .npz reader (SMPL-H `poses` axis-angle, `trans`, `mocap_framerate`, Z-up).

No SMPL model file is used (its license forbids it here), so the body's bone lengths come
from the height: the `imucap_height_m` field our generator writes, else 1.75 m. The
pelvis path is `trans`; SMPL's constant pelvis offset disappears in floor alignment.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from inference.body.body import Body
from inference.body.motion import Motion, MotionFormatError
from inference.loaders.amass_frames import amass_poses_to_global


def load_amass(path: str | Path, height: float | None = None) -> Motion:
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: no such motion file") from None
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise MotionFormatError(str(path), f"not a readable .npz ({exc})") from None
    missing = [k for k in ("poses", "trans") if k not in data]
    if missing:
        raise MotionFormatError(str(path), f"AMASS file lacks {missing}; has {sorted(data)}")
    fps_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in data), None)
    if fps_key is None:
        raise MotionFormatError(str(path), "AMASS file has no mocap_framerate")
    poses = np.asarray(data["poses"], dtype=np.float64)
    trans = np.asarray(data["trans"], dtype=np.float64)
    fps = float(data[fps_key])
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
        height = float(data["imucap_height_m"]) if "imucap_height_m" in data else 1.75
    rot = amass_poses_to_global(poses)
    name = path.name.removesuffix(".npz")
    return Motion(rot=rot, root=trans, fps=fps, body=Body.from_height(height), name=name, source=str(path),
                  meta={"format": "amass"}).floor_aligned()
