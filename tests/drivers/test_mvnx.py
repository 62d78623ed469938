"""Reading an MVN take's MVNX export: each sensor's orientation and specific force as the
file holds them, the calibration frames left out, damage counted or named."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.xsens_export import G
from drivers.xsens_export.mvnx import MVN_SITES, MvnxError, is_mvnx, read_mvnx
from inference.signals.synthesis import NoiseModel, synthesize
from sim_devices.motions import generate
from sim_devices.xsens_export import write_mvnx

SITES = ("pelvis", "torso", "l_wrist", "r_shank")
LABELS = {"pelvis": "Pelvis", "torso": "T8", "l_wrist": "LeftForeArm", "r_shank": "RightLowerLeg"}


@pytest.fixture(scope="module")
def sig():
    return synthesize(generate("walk", seconds=3.0), NoiseModel(), rng=2, sites=SITES)


def test_every_sensor_reads_back_as_written(sig, tmp_path):
    path = write_mvnx(sig, tmp_path / "take.mvnx", LABELS, extra={"LeftHand": "l_wrist"}, drop=[30, 31], bad=[40])
    assert is_mvnx(path)
    take = read_mvnx(path)
    assert [d.name for d in take.logs] == ["Pelvis", "T8", "LeftForeArm", "RightLowerLeg", "LeftHand"]
    assert take.frame_rate == 60.0 and take.info["mvn_version"] == "2022.0.0"
    assert take.skipped == {"malformed": 1}  # the short frame; the dropped ones are simply absent
    keep = np.setdiff1d(np.arange(len(sig.t)), [30, 31, 40])
    for site, label in LABELS.items():
        d, k = take.log(label), SITES.index(site)
        assert d.info["site"] == MVN_SITES[label] == site
        assert len(d.t) == len(keep) and np.allclose(d.t, sig.t[keep], atol=1e-9)  # index / frameRate, not the ms
        assert np.allclose(d.quat, sig.quat[keep, k], atol=1e-5)
        assert np.allclose(d.acc, sig.specific_force[keep, k], atol=1e-3)  # gravity put back, sensor frame
        assert np.isnan(d.gyro).all()  # MVNX has no sensor rate
    assert take.log("LeftHand").info["site"] == ""


def test_a_take_cut_short_keeps_the_frames_before_the_cut(sig, tmp_path):
    take = read_mvnx(write_mvnx(sig, tmp_path / "cut.mvnx", LABELS, cut_at=100))
    assert take.skipped == {"truncated": 1} and "ends early" in take.info["truncated"]
    assert all(len(d.t) == 100 for d in take.logs)
    assert take.logs[0].skipped["truncated"] == 1


@pytest.mark.parametrize("content, said", [
    ("", "not an MVNX file"),
    ("<?xml version='1.0'?><bvh><frames/></bvh>", "its root element is <bvh>"),
    ("Frame,Time\n1,0.0\n", "not an MVNX file (not XML"),
    ("<?xml version='1.0' encoding='WTF-8'?><mvnx/>", "unknown encoding"),  # found by benchmarks/fuzz.py mvnx
    ("<?xml version='1.0' encoding='cp932'?><mvnx/>", "multi-byte encodings"),  # so was this
    ("<mvnx version='4'><subject frameRate='60'><frames>", "damaged MVNX file, no frames before the damage"),
    ("<mvnx version='4'><subject frameRate='60'><frames></frames></subject></mvnx>", "no <sensors>"),
    ("<mvnx version='4'><subject frameRate='60'><sensors><sensor label='Pelvis'/></sensors><frames>"
     "<frame time='0' type='normal'><orientation>1 0 0 0</orientation></frame></frames></subject></mvnx>",
     "no sensor data in the frames (export with 'Sensor orientation'"),
])
def test_what_is_not_a_take_is_named_in_one_line(tmp_path, content, said):
    path = tmp_path / "x.mvnx"
    path.write_text(content)
    assert not is_mvnx(path) or "mvnx" in content
    with pytest.raises(MvnxError) as exc:
        read_mvnx(path)
    assert said in str(exc.value) and str(path) in str(exc.value) and "\n" not in str(exc.value)


def test_frames_without_an_index_keep_their_ms_and_an_xml_name_is_still_a_take(tmp_path):
    frames = "".join(f"<frame time='{ms}' type='normal'><sensorOrientation>1 0 0 0</sensorOrientation>"
                     f"<sensorFreeAcceleration>0 0 1</sensorFreeAcceleration></frame>" for ms in (0, 17, 33, 33))
    path = tmp_path / "take.xml"
    path.write_text("<mvnx xmlns='http://www.xsens.com/mvn/mvnx' version='3'><subject frameRate='60'><sensors>"
                    f"<sensor label='Head'/></sensors><frames>{frames}</frames></subject></mvnx>")
    assert is_mvnx(path)
    take = read_mvnx(path)
    head = take.log("Head")
    assert np.allclose(head.t, [0.0, 0.017, 0.033]) and take.skipped == {"duplicate": 1}
    assert np.allclose(head.acc, [[0.0, 0.0, 1.0 + G]] * 3)  # the gravity MVN took out, put back


def test_a_sensor_listed_after_the_frames_began_is_not_taken(tmp_path):
    """Was an IndexError (fuzz target mvnx): frames under a misspelt <frames> read before a
    third <sensor> came, which made the sensor list longer than the frames' lists."""
    frame = ("<frame time='{ms}' index='{i}' type='normal'><sensorOrientation>1 0 0 0 1 0 0 0</sensorOrientation>"
             "<sensorFreeAcceleration>0 0 0 0 0 0</sensorFreeAcceleration></frame>")
    path = tmp_path / "take.mvnx"
    path.write_text("<mvnx version='4'><subject frameRate='60'><sensors><sensor label='Pelvis'/><sensor label='T8'/>"
                    f"</sensors><fram>{frame.format(ms=0, i=0)}{frame.format(ms=17, i=1)}</fram>"
                    "<sensors><sensor label='Head'/></sensors></subject></mvnx>")
    take = read_mvnx(path)
    assert [d.name for d in take.logs] == ["Pelvis", "T8"] and len(take.logs[0].t) == 2
