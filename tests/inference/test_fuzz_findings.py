"""Motion files the coverage-guided fuzzer (benchmarks/fuzz.py) found that made a loader
raise something other than MotionFormatError (the CLI's one-line ``path:line: problem``),
or that would have hung it."""

from __future__ import annotations

import gzip
import io
import zipfile
from pathlib import Path

import numpy as np
import pytest

from inference.loaders import MotionFormatError, load_motion

ASF = """:version 1.10
:name fuzz
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name lfemur
     direction 0 -1 0
     length 7.5
     axis 0 0 20 XYZ
    dof rx ry rz
  end
  begin
     id 2
     name ltibia
     direction 0 -1 0
     length 7.5
     axis 0 0 20 XYZ
    dof rx
  end
:hierarchy
  begin
    root lfemur
    lfemur ltibia
  end
"""
AMC = ":FULLY-SPECIFIED\n:DEGREES\n" + "".join(f"{k}\nroot 0 17 0 0 0 0\nlfemur 0 0 0\nltibia 0\n" for k in (1, 2))


def _asf_amc(tmp_path: Path, asf: str) -> Path:
    (tmp_path / "HDM_zz.asf").write_text(asf)
    amc = tmp_path / "HDM_zz_fuzz_001_120.amc"
    amc.write_text(AMC)
    return amc


@pytest.mark.parametrize("keyword, cut", [("angle", "  angle deg"), ("axis", "   axis XYZ"),
                                          ("name", "     name ltibia")])
def test_asf_keyword_without_its_value(tmp_path, keyword, cut):
    """Was an IndexError (fuzz target asf-amc: ``angle`` alone on its line)."""
    amc = _asf_amc(tmp_path, ASF.replace(cut, "  " + keyword))
    with pytest.raises(MotionFormatError, match=f"no value after '{keyword}'") as exc:
        load_motion(amc)
    assert exc.value.line is not None


def test_asf_hierarchy_loop_is_an_error_not_a_hang(tmp_path):
    amc = _asf_amc(tmp_path, ASF.replace("    lfemur ltibia\n", "    lfemur ltibia\n    ltibia lfemur\n"))
    with pytest.raises(MotionFormatError, match="twice"):
        load_motion(amc)


def _npz(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


GOOD = {"poses": np.zeros((3, 156)), "trans": np.zeros((3, 3)), "mocap_framerate": np.array(60.0)}


def test_amass_member_flagged_encrypted(tmp_path):
    """Was zipfile's RuntimeError (fuzz target amass)."""
    b = bytearray(_npz(**GOOD))
    b[6] |= 1  # general purpose flag, bit 0: encrypted (local header, then central directory)
    b[b.find(b"PK\x01\x02") + 8] |= 1
    p = tmp_path / "enc.npz"
    p.write_bytes(bytes(b))
    with pytest.raises(MotionFormatError, match="not a readable .npz.*encrypted"):
        load_motion(p)


def test_amass_npy_header_cut_short(tmp_path):
    """Was tokenize's TokenError from numpy's header parser (fuzz target amass-arrays)."""
    head = b"{'descr': '<f8', 'fortran_order': False, 'shape': ("
    p = tmp_path / "cut.npz"
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("poses.npy", b"\x93NUMPY\x01\x00" + len(head).to_bytes(2, "little") + head)
    with pytest.raises(MotionFormatError, match="not a readable .npz"):
        load_motion(p)


@pytest.mark.parametrize("what, arrays, match", [
    ("a member that is no .npy", None, "imucap_height_m is not a numpy array"),
    ("text for a number", {**GOOD, "mocap_framerate": np.array("sixty")}, "holds <U5 values"),
    ("several rates", {**GOOD, "mocap_framerate": np.array([60.0, 120.0])}, "should be one number"),
    ("text poses", {**GOOD, "poses": np.full((3, 156), "x")}, "poses holds"),
])
def test_amass_members_of_the_wrong_kind(tmp_path, what, arrays, match):
    """Was AttributeError / TypeError from numpy (fuzz target amass): np.load hands a
    member that is not an .npy over as bytes, and float() of a 2-element array is a
    TypeError."""
    p = tmp_path / "clip.npz"
    if arrays is None:
        p.write_bytes(_npz(**GOOD))
        with zipfile.ZipFile(p, "a") as z:
            z.writestr("imucap_height_m.npy", b"1.75")
    else:
        p.write_bytes(_npz(**arrays))
    with pytest.raises(MotionFormatError, match=match):
        load_motion(p)


def test_truncated_gzip_motion_is_a_format_error(tmp_path):
    p = tmp_path / "HDM_zz_fuzz_001_120.amc.gz"
    p.write_bytes(gzip.compress(AMC.encode())[:-9])
    (tmp_path / "HDM_zz.asf").write_text(ASF)
    with pytest.raises(MotionFormatError, match="compressed"):
        load_motion(p)


BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  End Site
  {
    OFFSET 0 10 0
  }
}
MOTION
Frames: FRAMES
Frame Time: 0.0333
0 90 0 0 0 0
0 90 0 5 0 0
"""


@pytest.mark.parametrize("frames", ["0", "-1"])
def test_bvh_that_declares_no_frames(tmp_path, frames):
    """'Frames: 0' reached the forward kinematics with an empty, one-dimensional array
    (IndexError); a negative count would have sliced the data from its end."""
    p = tmp_path / "clip.bvh"
    p.write_text(BVH.replace("FRAMES", frames))
    with pytest.raises(MotionFormatError, match=f"header says {frames} frames"):
        load_motion(p)


@pytest.mark.parametrize("line, match", [
    ("   order TX TY TZ RX RY R", "root order 'TX TY TZ RX RY R'"),  # fuzz target asf-amc: an IndexError
    ("   order TX TY RX RY RZ", "each of TX TY TZ once"),
    ("   order TX TY TZ RX RX RZ", "each of TX TY TZ once"),
])
def test_asf_root_order_with_a_channel_that_is_not_one(tmp_path, line, match):
    """Was an IndexError (``R`` taken as a rotation whose axis is its second letter), or a
    ValueError without a line for a missing translation."""
    amc = _asf_amc(tmp_path, ASF.replace("   order TX TY TZ RX RY RZ", line))
    with pytest.raises(MotionFormatError, match=match) as exc:
        load_motion(amc)
    assert exc.value.line is not None


@pytest.mark.parametrize("old, new", [("   axis XYZ", "   axis XQZ"), ("axis 0 0 20 XYZ", "axis 0 0 20 XY")])
def test_asf_axis_order_that_is_not_one(tmp_path, old, new):
    amc = _asf_amc(tmp_path, ASF.replace(old, new, 1))
    with pytest.raises(MotionFormatError, match="X, Y and Z once each") as exc:
        load_motion(amc)
    assert exc.value.line is not None
