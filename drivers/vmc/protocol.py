"""The VMC protocol's device messages (https://protocol.vmc.info), pure functions.

What VR-to-VMC bridges send from SteamVR, one OSC message per tracked device, usually
several in one OSC bundle with ``/VMC/Ext/T`` (sender's relative time, s) and
``/VMC/Ext/OK``::

    /VMC/Ext/Hmd/Pos        (string){serial} (float){p.x} {p.y} {p.z} {q.x} {q.y} {q.z} {q.w}   V2.2
    /VMC/Ext/Con/Pos        same, a hand controller
    /VMC/Ext/Tra/Pos        same, a tracker
    /VMC/Ext/Hmd/Pos/Local  same, V2.3 (also Con, Tra)

in Unity's frame (left-handed, Y up, metres), ``serial`` the OpenVR serial number. The
spec's words on the two forms: ``Pos`` is "avatar scale", ``Pos/Local`` "device raw
scale"; a performer that does not scale its devices to an avatar (a bridge) sends the
same pose in both. Both are read; ``TrackedSample.local`` says which form a pose came in,
and the device prefers one (``device.py``).

``decode`` parses with python-osc (``OscPacket``: messages and nested bundles alike) and
converts to our frame; ``encode`` builds with python-osc's builders from our frame. Anything
other than device messages and ``/VMC/Ext/T`` (bones, blend shapes, ``OK``) is not ours
and is passed over. A datagram that is not OSC, or a device message whose arguments are not
(string, 7 numbers), whose numbers are not finite or whose quaternion is not near unit
length, is malformed: ``ValueError`` with a one-line reason, and nothing of that datagram
is used (a half-read frame would mix two instants).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.osc_packet import OscPacket, ParseError

KINDS: tuple[str, ...] = ("hmd", "con", "tra")
_ADDRESS_KIND = {"Hmd": "hmd", "Con": "con", "Tra": "tra"}
_KIND_ADDRESS = {v: k for k, v in _ADDRESS_KIND.items()}
TIME_ADDRESS = "/VMC/Ext/T"
OK_ADDRESS = "/VMC/Ext/OK"

# Unity (X right, Y up, Z forward; left-handed) -> ours (X forward, Y left, Z up; right-handed):
# our x = Unity z, our y = -Unity x, our z = Unity y. Rows: our axes in Unity components.
UNITY_TO_WORLD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@dataclass(frozen=True, slots=True)
class TrackedSample:
    """One device pose from one datagram, in our frame: ``position`` (3,) m, ``quat`` (4,)
    (w, x, y, z) device -> world. ``sender_time``: the datagram's ``/VMC/Ext/T`` (s, the
    sender's own clock), ``None`` without one."""

    serial: str
    kind: str  # "hmd", "con" or "tra"
    position: np.ndarray
    quat: np.ndarray
    local: bool = False
    sender_time: float | None = None


def address(kind: str, local: bool = False) -> str:
    if kind not in _KIND_ADDRESS:
        raise ValueError(f"VMC device kind {kind!r}: one of {', '.join(KINDS)}")
    return f"/VMC/Ext/{_KIND_ADDRESS[kind]}/Pos" + ("/Local" if local else "")


def unity_to_world(position: np.ndarray, quat_xyzw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A Unity pose in our frame: position (..., 3) and quaternion (..., 4) in Unity's
    (x, y, z, w) order -> position (..., 3) and quaternion (..., 4) as our (w, x, y, z).

    Unity: X right, Y up, Z forward, left-handed. Ours (DESIGN.md): X forward, Y left, Z up,
    right-handed. Vectors go across by ``v = A u`` with::

        A = [[ 0, 0, 1],     our x (forward) =  Unity z
             [-1, 0, 0],     our y (left)    = -Unity x
             [ 0, 1, 0]]     our z (up)      =  Unity y

    ``det A = -1``: that sign is the change of handedness and cannot be avoided by any
    relabelling, since the two frames have opposite handedness. Rotations do not take that
    sign: a device's orientation goes across by conjugation, ``R = A R_U A^T``, which is a
    proper rotation (det +1) in our right-handed frame for every proper ``R_U``. Unity's
    quaternions use the same algebra as ours (Hamilton product, column vectors: its
    ``AngleAxis(90, up) * forward`` is ``right``), so in components the conjugation is:
    the vector part ``(x, y, z)_U`` is an axial vector and goes across as ``det A * A v``,
    the scalar part stays::

        (w, x, y, z) = (w_U, -z_U, x_U, -y_U)

    A yaw of +90 deg about Unity's up turns forward to the right; in ours that is -90 deg
    about Z. The inverse is ``world_to_unity`` (and app/streams/unity.py's map, its transpose).
    """
    u = np.asarray(position, dtype=np.float64)
    q = np.asarray(quat_xyzw, dtype=np.float64)
    p = u @ UNITY_TO_WORLD.T
    out = np.stack([q[..., 3], -q[..., 2], q[..., 0], -q[..., 1]], axis=-1)
    return p, out


def world_to_unity(position: np.ndarray, quat_wxyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The inverse of ``unity_to_world``: our position (..., 3) and (w, x, y, z) quaternion
    -> Unity position (..., 3) and quaternion (..., 4) in Unity's (x, y, z, w) order."""
    p = np.asarray(position, dtype=np.float64)
    q = np.asarray(quat_wxyz, dtype=np.float64)
    u = p @ UNITY_TO_WORLD  # A is orthogonal: A^-1 = A^T, and (A^T p) as a row is p @ A
    out = np.stack([q[..., 2], -q[..., 3], -q[..., 1], q[..., 0]], axis=-1)
    return u, out


# --- encode ---------------------------------------------------------------------------------------------
def message(kind: str, serial: str, position: Sequence[float], quat: Sequence[float], *,
            local: bool = False) -> OscMessage:
    """One device message from a pose in OUR frame (position m, quat w x y z)."""
    u, qu = world_to_unity(np.asarray(position, dtype=float), np.asarray(quat, dtype=float))
    b = OscMessageBuilder(address=address(kind, local))
    b.add_arg(str(serial), OscMessageBuilder.ARG_TYPE_STRING)
    for v in (*u, *qu):
        b.add_arg(float(v), OscMessageBuilder.ARG_TYPE_FLOAT)
    return b.build()


def encode(kind: str, serial: str, position: Sequence[float], quat: Sequence[float], *,
           local: bool = False) -> bytes:
    """One device message as a datagram, from a pose in our frame."""
    return message(kind, serial, position, quat, local=local).dgram


@dataclass(frozen=True, slots=True)
class DevicePose:
    """What ``encode_frame`` sends of one device: a pose in our frame."""

    kind: str
    serial: str
    position: np.ndarray
    quat: np.ndarray


def frame_bundle(poses: Iterable[DevicePose], sender_time: float | None = None, *, local: bool = False,
                 ok: bool = True) -> OscBundle:
    """One OSC bundle as a bridge sends it per frame: ``/VMC/Ext/T`` (when ``sender_time``
    is given), a device message per pose, ``/VMC/Ext/OK 1``."""
    b = OscBundleBuilder(IMMEDIATELY)
    if sender_time is not None:
        t = OscMessageBuilder(address=TIME_ADDRESS)
        t.add_arg(float(sender_time), OscMessageBuilder.ARG_TYPE_FLOAT)
        b.add_content(t.build())
    for p in poses:
        b.add_content(message(p.kind, p.serial, p.position, p.quat, local=local))
    if ok:
        m = OscMessageBuilder(address=OK_ADDRESS)
        m.add_arg(1, OscMessageBuilder.ARG_TYPE_INT)
        b.add_content(m.build())
    return b.build()


def encode_frame(poses: Iterable[DevicePose], sender_time: float | None = None, *, local: bool = False,
                 ok: bool = True) -> bytes:
    """``frame_bundle`` as a datagram."""
    return frame_bundle(poses, sender_time, local=local, ok=ok).dgram


# --- decode ---------------------------------------------------------------------------------------------
def _device_kind(addr: str) -> tuple[str, bool] | None:
    """(kind, local) for a device message's address, None for any other address."""
    parts = addr.split("/")
    # "", "VMC", "Ext", "Hmd", "Pos"[, "Local"]
    if len(parts) not in (5, 6) or parts[1:3] != ["VMC", "Ext"] or parts[4] != "Pos":
        return None
    kind = _ADDRESS_KIND.get(parts[3])
    if kind is None or (len(parts) == 6 and parts[5] != "Local"):
        return None
    return kind, len(parts) == 6


def _is_number(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def decode(datagram: bytes) -> list[TrackedSample]:
    """Every device pose in one datagram (a message or a bundle, bundles nested or not),
    converted to our frame; ``[]`` for a datagram with none. Malformed: ``ValueError``."""
    try:
        timed = OscPacket(bytes(datagram)).messages
    except (ParseError, ValueError, IndexError, TypeError) as exc:
        raise ValueError(f"not an OSC packet ({len(datagram)} bytes): {exc}") from None
    sender_time: float | None = None
    raw: list[tuple[str, str, bool, tuple[float, ...]]] = []
    for tm in timed:
        msg = tm.message
        addr = msg.address
        args = list(msg.params)
        if addr == TIME_ADDRESS:
            if len(args) >= 1 and _is_number(args[0]) and math.isfinite(float(args[0])):
                sender_time = float(args[0])
            else:
                raise ValueError(f"{TIME_ADDRESS}: expected a time in seconds, got {args!r}")
            continue
        dk = _device_kind(addr)
        if dk is None:
            continue
        if len(args) < 8 or not isinstance(args[0], str) or not all(_is_number(a) for a in args[1:8]):
            types = " ".join(type(a).__name__ for a in args)
            raise ValueError(f"{addr}: expected (serial string, 7 numbers), got ({types})")
        nums = tuple(float(a) for a in args[1:8])
        if not all(math.isfinite(v) for v in nums):
            raise ValueError(f"{addr} {args[0]!r}: non-finite position or rotation")
        n = math.sqrt(sum(v * v for v in nums[3:7]))
        if not 0.5 < n < 1.5:
            raise ValueError(f"{addr} {args[0]!r}: rotation quaternion has norm {n:.3g}, not 1")
        raw.append((args[0], dk[0], dk[1], nums))
    out = []
    for serial, kind, local, nums in raw:
        p, q = unity_to_world(np.array(nums[0:3]), np.array(nums[3:7]))
        q = q / np.linalg.norm(q)
        if q[0] < 0:
            q = -q
        out.append(TrackedSample(serial, kind, p, q, local, sender_time))
    return out
