"""A 10- or 12-bit camera's images - uint16 holding its digital numbers, 0 to 2^bits - 1 - decode
against that camera's full scale: in memory, from a recording folder, and from bare image files
with ``--bits`` (a new user's audit, 2026-11-28: a 12-bit recording did not decode at all, and a
bare 12-bit capture decoded 49 % of its pixels without a word, read 16 times too dark)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simbench.cli import main
from simbench.io import adc_full_scale, narrow_uint16_hint
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.rig import paper_rig
from simbench.sim.camera import simple_camera
from simbench.sim.projector import transfer_curve
from simbench.sim.sensor import get_sensor
from simbench.sim.synthetic import synthetic_plane_capture

from .conftest import SCENES, bare_files

RIG = paper_rig()


def test_adc_full_scale_reads_digital_numbers_against_their_own_range():
    dn = np.array([[0, 1, 4095]], np.uint16)
    assert adc_full_scale(dn, bits=12, where="x").tolist() == [[0.0, np.float32(1 / 4095), 1.0]]
    assert adc_full_scale(dn, bits=16, where="x") is dn and adc_full_scale(dn, bits=None, where="x") is dn
    f = np.zeros((1, 1), np.float32)
    assert adc_full_scale(f, bits=12, where="x") is f  # floats are full scale already
    with pytest.raises(ValueError, match=r"x: values up to 4095, above a 10-bit camera's largest digital number 1023"):
        adc_full_scale(dn, bits=10, where="x")
    with pytest.raises(ValueError, match="an 8-bit image, not the 12-bit camera's"):
        adc_full_scale(np.zeros((1, 1), np.uint8), bits=12, where="x")
    # a 14-bit camera (common in scientific cameras; a new user's audit found it refused)
    assert adc_full_scale(dn, bits=14, where="x").tolist() == [[0.0, np.float32(1 / 16383), np.float32(4095 / 16383)]]
    with pytest.raises(ValueError, match="bits must be one of"):
        adc_full_scale(dn, bits=15, where="x")
    assert "give --bits 12" in narrow_uint16_hint(dn) and "16 times darker" in narrow_uint16_hint(dn)
    assert "give --bits 14" in narrow_uint16_hint(np.array([[10000]], np.uint16))
    assert narrow_uint16_hint(np.array([[60000]], np.uint16)) == "" and narrow_uint16_hint(dn.astype(np.uint8)) == ""


def _plane_pair(bits: int, seed: int = 3):
    """The decoder benchmark's plane (capture at 1.1 m, reference at 1.0 m) through the minimal
    camera with a ``bits``-bit ADC."""
    cam = dataclasses.replace(get_sensor("minimal").camera, bits=bits)
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    rng = np.random.default_rng(seed)
    cap = simple_camera(synthetic_plane_capture(drive, RIG, point_m=(0, 0, 1.1))[0] / 1.21, camera=cam, rng=rng)
    ref = simple_camera(synthetic_plane_capture(drive, RIG, point_m=(0, 0, 1.0))[0], camera=cam, rng=rng)
    return cap, ref


def test_a_twelve_bit_camera_decodes_in_memory_as_an_eight_bit_one_does():
    from simbench.sim.scene import SceneSpec
    from simbench.systems import SystemOptions, get_system
    from simbench.systems.proposed import ReferenceCalibration

    scene = SceneSpec(name="plane", rig=RIG, objects=(), reference_depth_m=1.0)
    minimal = get_sensor("minimal")
    out = {}
    for bits in (8, 12, 14):
        cap, ref = _plane_pair(bits)
        assert cap.dtype == np.uint8 if bits == 8 else (cap.dtype == np.uint16 and cap.max() > 1023)
        assert bits != 14 or 4095 < cap.max() <= 16383
        sensor = dataclasses.replace(minimal, camera=dataclasses.replace(minimal.camera, bits=bits))
        system = get_system("proposed", SystemOptions(sensor=sensor))
        cal = ReferenceCalibration(rig=RIG, image=ref, adc_bits=bits)
        out[bits] = system.decode(cap, cal, scene=scene)
    for bits, r in out.items():
        assert r.valid.mean() > 0.97, bits
        assert np.nanmedian(r.depth_m) == pytest.approx(1.1, abs=5e-4), bits
    # the control: the same 12-bit images read at the 16-bit range (what the decoder did before)
    cap, ref = _plane_pair(12)
    system = get_system("proposed", SystemOptions(sensor=minimal))
    with pytest.raises(ValueError, match="the reference capture decodes at only"):
        system.decode(cap, ReferenceCalibration(rig=RIG, image=ref), scene=scene)


def _bare_files(tmp_path, bits: int) -> list[str]:
    return bare_files(tmp_path, *_plane_pair(bits), RIG)


def test_bare_twelve_bit_files_decode_with_bits_and_warn_without(tmp_path, capsys, caplog):
    args = _bare_files(tmp_path, 12)
    out = tmp_path / "d.npy"
    assert main(["decode", *args, "--out", str(out), "--bits", "12"]) == 0
    depth = np.load(out)
    assert np.isfinite(depth).mean() > 0.97 and np.nanmedian(depth) == pytest.approx(1.1, abs=5e-4)
    # without --bits: read as 16-bit, and told so for each image (here the reference then fails its
    # check, whose one-line error names the warning's advice: an audit, 2026-12-05)
    assert main(["decode", *args, "--out", str(tmp_path / "e.npy")]) == 2
    told = caplog.text + capsys.readouterr().err
    for name in ("capture.png", "reference.png"):
        assert f"{name}: a 16-bit image whose largest value is" in told and "give --bits 12" in told
    assert "the reference capture decodes at only" in told
    assert "as warned above, the images hold fewer bits than their type: give --bits 12" in told
    # bits the values exceed: one line naming the file
    assert main(["decode", *args, "--out", str(tmp_path / "f.npy"), "--bits", "10"]) == 2
    err = capsys.readouterr().err
    assert "capture.png: values up to" in err and "above a 10-bit camera's largest digital number 1023" in err


def test_bits_is_refused_for_a_float_capture_and_named_in_its_range_advice(tmp_path, capsys):
    """A docs audit (2026-11-30): ``--bits 12`` was ignored for a float .npy capture without a word,
    and one holding 12-bit digital numbers as floats was told "16-bit values? divide by 65535"."""
    from simbench.io import load_image, save_npy

    args = _bare_files(tmp_path, 12)
    dn = load_image(tmp_path / "capture.png").astype(np.float32)
    save_npy(tmp_path / "dn.npy", dn)  # 0 .. 4095 as floats
    save_npy(tmp_path / "unit.npy", dn / 4095)  # full scale
    for name, told in [
        ("dn.npy", "12-bit digital numbers? divide by 4095, or save them as uint16 with --bits 12"),
        ("unit.npy", "--bits 12: " + str(tmp_path / "unit.npy") + " is a float image, read as full scale"),
    ]:
        argv = ["decode", str(tmp_path / name), *args[1:], "--out", str(tmp_path / "d.npy"), "--bits", "12"]
        assert main(argv) == 2
        assert told in capsys.readouterr().err, name
    argv = ["decode", str(tmp_path / "dn.npy"), *args[1:], "--out", str(tmp_path / "d.npy")]
    assert main(argv) == 2 and "16-bit values? divide by 65535" in capsys.readouterr().err  # not told the bits


@pytest.mark.slow
def test_a_twelve_bit_recording_decodes_as_recorded(tmp_path, variant, capsys):
    """`simbench render --sensor` with a 12-bit camera, then `simbench decode FOLDER`: the folder's
    manifest gives the bits; a --bits that contradicts it is refused."""
    from simbench.io import load_image
    from simbench.systems import get_system

    sensor = tmp_path / "b12.toml"
    text = (SCENES.parent / "simbench" / "presets" / "paper.toml").read_text()
    assert "\nbits = 8\n" in text
    sensor.write_text(text.replace("\nbits = 8\n", "\nbits = 12\n"))
    rec = tmp_path / "rec"
    argv = ["render", str(SCENES / "white_plane.toml"), "--out", str(rec), "--spp", "1", "--sensor", str(sensor)]
    assert main([*argv, "--no-cache"]) == 0
    raw = load_image(rec / "capture.png")
    assert raw.dtype == np.uint16 and 1023 < raw.max() <= 4095
    out = tmp_path / "d.npy"
    assert main(["decode", str(rec), "--out", str(out)]) == 0
    depth, gt = np.load(out), np.load(rec / "gt_depth.npy")
    assert np.isfinite(depth).mean() > 0.97 and np.nanmedian(np.abs(depth - gt)) < 5e-4
    assert main(["decode", str(rec), "--out", str(tmp_path / "e.npy"), "--bits", "10"]) == 2
    assert "whose camera recorded 12-bit digital numbers" in capsys.readouterr().err
    # read_recording gives the capture at full scale and the calibration its bits
    capture, cal, _ = get_system("proposed").read_recording(rec)
    assert capture.dtype == np.float32 and cal.adc_bits == 12


@pytest.mark.slow
def test_a_twelve_bit_camera_serves_the_phase_shifting_reference_too(tmp_path, variant):
    """The review's find: the phase-shifting system's grey frames (and the calibration's, the
    same path) read a 12-bit camera's uint16 as /65535, 16 times too dark for its modulation
    threshold."""
    sensor = tmp_path / "b12.toml"
    sensor.write_text(
        (SCENES.parent / "simbench" / "presets" / "paper.toml").read_text().replace("\nbits = 8\n", "\nbits = 12\n")
    )
    rec = tmp_path / "ps"
    argv = ["render", str(SCENES / "white_plane.toml"), "--system", "phase_shift", "--out", str(rec)]
    assert main([*argv, "--spp", "1", "--sensor", str(sensor), "--no-cache"]) == 0
    assert main(["decode", str(rec), "--out", str(tmp_path / "d.npy")]) == 0
    depth, gt = np.load(tmp_path / "d.npy"), np.load(rec / "gt_depth.npy")
    ok = np.isfinite(gt)
    assert np.isfinite(depth[ok]).mean() > 0.97 and np.nanmedian(np.abs(depth - gt)) < 1e-3
