"""Captures whose values encode light non-linearly (sRGB, a camera's gamma), linearised before the
decoder reads them (``simbench decode --encoding``): an sRGB camera's frames decoded as if linear
bend the fringe (the benchmark plane: the colour-robust decoder 55 % complete, the paper's decoder
0.92 mm MAE by triangulation, against 99.9 % and 0.21 mm linearised first)."""

from __future__ import annotations

import colour
import numpy as np
import pytest

from simbench.cli import main
from simbench.io import check_encoding, linearize, save_png
from simbench.systems import get_system

from .conftest import bare_files


def test_the_srgb_decoding_is_the_standards_and_a_gamma_a_power_law():
    ramp = np.arange(256, dtype=np.uint8)
    # IEC 61966-2-1, as colour-science implements it
    np.testing.assert_allclose(
        linearize(ramp, encoding="srgb"), colour.cctf_decoding(ramp / 255.0, function="sRGB"), rtol=1e-6, atol=1e-7
    )
    wide = np.arange(0, 65536, 257, dtype=np.uint16)
    np.testing.assert_allclose(linearize(wide, encoding="gamma=2.2"), (wide / 65535.0) ** 2.2, atol=1e-6)
    floats = np.linspace(0.0, 1.0, 11, dtype=np.float32)
    np.testing.assert_allclose(linearize(floats, encoding="gamma=2"), floats**2, atol=1e-7)
    assert linearize(ramp, encoding="linear") is ramp
    assert linearize(ramp, encoding="sRGB").dtype == np.float32


@pytest.mark.parametrize(
    "text, name", [("linear", "linear"), (" sRGB ", "srgb"), ("gamma=2.20", "gamma=2.2"), ("GAMMA=1", "gamma=1")]
)
def test_encodings_are_named_one_way(text, name):
    assert check_encoding(text) == name


@pytest.mark.parametrize("text", ["", "gamma", "gamma=0.45", "gamma=5", "gamma=nan", "rec709", "log"])
def test_other_encodings_are_refused_naming_the_valid_ones(text):
    with pytest.raises(ValueError, match="linear, srgb, gamma=G|from 1 to 4"):
        check_encoding(text)


def test_an_srgb_cameras_frames_decode_when_linearised(tmp_path):
    system = get_system("proposed")
    raw, cal, scene = system.bench_inputs(scene="plane", frames=True)

    def encoded(a):
        return np.round(255 * colour.cctf_encoding(a / 255.0, function="sRGB")).astype(np.uint8)

    files = [*bare_files(tmp_path, encoded(raw), encoded(cal.image), scene.rig), "--z0", "1.0"]
    frames = tmp_path / "cal"
    frames.mkdir()
    for name, frame in cal.frames.items():
        save_png(frames / f"calibration_{name}.png", encoded(frame))
    out = tmp_path / "d.npy"
    got = {}
    for encoding in ("linear", "srgb"):
        for robust in (False, True):
            extra = ["--robust", "--calibration", str(frames)] if robust else []
            argv = ["decode", *files, "--mode", "calibrated", "--encoding", encoding, "--out", str(out), *extra]
            assert main(argv) == 0
            z = np.load(out)
            got[encoding, robust] = (float(np.isfinite(z).mean()), float(np.nanmean(np.abs(z - 1.1))) * 1e3)
    # measured: linear 100 % / 0.92 mm (paper), 55 % / 0.56 mm (robust); srgb 100 % / 0.21 mm, 99.85 % / 0.21 mm
    assert got["linear", False][1] > 0.6 and got["linear", True][0] < 0.7, got
    assert got["srgb", False][1] < 0.3 and got["srgb", True][0] > 0.99 and got["srgb", True][1] < 0.3, got


def test_an_encoded_capture_and_reference_read_as_linear_are_warned_of(tmp_path, caplog):
    """The fringe's second harmonic against its first (simbench.decode.registration): ~0 for a
    linear capture of the pattern, -0.13 to -0.17 for sRGB-encoded rendered scenes and -0.24 for
    this darker synthetic plane; over 0.05 the decode names it, for the capture and the
    reference, and not once linearised."""
    from simbench.decode.registration import fringe_harmonic_ratio

    system = get_system("proposed")
    raw, cal, scene = system.bench_inputs(scene="plane")
    t = system.decoder.camera_period(scene.rig)
    srgb = np.round(255 * colour.cctf_encoding(raw / 255.0, function="sRGB")).astype(np.uint8)
    assert abs(fringe_harmonic_ratio(raw, order=[0, 1, 2], period_px=t)) < 0.01
    assert fringe_harmonic_ratio(srgb, order=[0, 1, 2], period_px=t) < -0.1
    assert abs(fringe_harmonic_ratio(linearize(srgb, encoding="srgb"), order=[0, 1, 2], period_px=t)) < 0.01
    ref = np.round(255 * colour.cctf_encoding(cal.image / 255.0, function="sRGB")).astype(np.uint8)
    files = [*bare_files(tmp_path, srgb, ref, scene.rig), "--z0", "1.0", "--out", str(tmp_path / "d.npy")]
    assert main(["decode", *files]) == 0
    assert "capture.png: the capture's fringe holds a second harmonic -0.2" in caplog.text
    assert "reference.png: the reference capture's fringe holds a second harmonic" in caplog.text
    assert "give --encoding srgb" in caplog.text
    caplog.clear()
    assert main(["decode", *files, "--encoding", "srgb"]) == 0
    assert "second harmonic" not in caplog.text


def test_no_fringe_no_linearity_to_judge():
    from simbench.decode.registration import encoding_doubt, fringe_harmonic_ratio

    noise = np.random.default_rng(3).integers(0, 256, (480, 640, 3), dtype=np.uint8)
    for img in (noise, np.zeros((480, 640, 3), np.uint8), np.full((480, 640, 3), 255, np.uint8)):
        ratio = fringe_harmonic_ratio(img, order=[0, 1, 2], period_px=10.9)
        assert np.isnan(ratio) and encoding_doubt(ratio) == ""


def test_the_warning_reads_the_bends_sign_against_the_encoding_given():
    from simbench.decode.registration import encoding_doubt

    assert encoding_doubt(0.04) == encoding_doubt(-0.04) == ""
    assert "give --encoding srgb" in encoding_doubt(-0.2)
    assert "--encoding srgb leaves it compressed" in encoding_doubt(-0.2, encoding="srgb")
    # a linear image read as sRGB expands (+0.27 on the benchmark's plane)
    assert "was the image linear already (then leave --encoding out)?" in encoding_doubt(0.27, encoding="srgb")
    assert "not linear" in encoding_doubt(0.27)
