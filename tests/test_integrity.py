"""What a capture went through before the decoder (``simbench.decode.integrity``): JPEG's 8x8
blocks and clipped channels, which bias the decoded phase at a confidence above the operating
point, are measured and warned of by `simbench decode`."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from simbench.cli import main
from simbench.io import save_png
from simbench.decode import DecoderParams, robust_params
from simbench.decode.integrity import (
    BLOCK_RATIO_WARN,
    CLIPPED_SHARE_WARN,
    block_artifacts,
    clipped_share,
    clipping_doubt,
    compression_doubt,
)
from simbench.systems import get_system

from .conftest import bare_files

SYSTEM = get_system("proposed")
RAW, CAL, SCENE = SYSTEM.bench_inputs(scene="plane", frames=True)


def _jpeg(img: np.ndarray, quality: int) -> np.ndarray:
    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(img[..., ::-1]), [cv2.IMWRITE_JPEG_QUALITY, quality])
    assert ok
    return np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])


def test_jpeg_blocks_are_told_from_an_uncompressed_capture():
    """The benchmark plane (camera noise, no compression) reads ~1 whatever its dtype; re-encoded
    by OpenCV's JPEG it reads past the warning's 1.1 from quality 95 down (measured 2.5 at 95, 5.3
    at 90, inf at 75 and below: its blocks' rows flat), also cut by a few rows and columns (the
    grid found at any offset); a flat image or one under two blocks tall is not judged."""
    clean = block_artifacts(RAW)
    assert abs(clean - 1.0) < 0.03, clean
    assert block_artifacts(RAW.astype(np.float32) / 255) == pytest.approx(clean, rel=1e-5)
    assert block_artifacts(RAW.astype(np.uint16) * 257) == pytest.approx(clean, rel=1e-9)
    ratios = [block_artifacts(_jpeg(RAW, q)) for q in (95, 90, 75, 50)]
    assert all(r >= BLOCK_RATIO_WARN for r in ratios), ratios
    assert ratios == sorted(ratios)  # the harder the compression, the plainer its blocks
    assert block_artifacts(_jpeg(RAW, 90)[3:, 5:]) >= BLOCK_RATIO_WARN
    assert np.isnan(block_artifacts(np.full((40, 40, 3), 7, np.uint8)))
    assert np.isnan(block_artifacts(RAW[:16]))


def test_a_jpeg_capture_decodes_off_the_uncompressed_ones_depth():
    """Why the warning: the colour-robust decoder's columns of the JPEG-encoded benchmark plane
    move from the clean capture's by more the harder it is compressed (measured RMS 0.010, 0.016,
    0.029 and 0.056 projector px at quality 95, 90, 75 and 50; the rendered hard scenes' phase
    moved 0.6-1.5 px over whole blocks at 75, simbench/decode/integrity.py), while their
    confidence stays above the operating point on > 99 % of the plane."""
    p = robust_params(DecoderParams(mode="calibrated"))
    base = SYSTEM.decode(RAW, CAL, scene=SCENE, params=p).detail
    rms = []
    for q in (95, 75, 50):
        r = SYSTEM.decode(_jpeg(RAW, q), CAL, scene=SCENE, params=p).detail
        both = r.valid & base.valid
        assert both.mean() > 0.99
        rms.append(float(np.sqrt(np.mean((r.column_px - base.column_px)[both] ** 2))))
    assert rms == sorted(rms) and rms[-1] > 4 * rms[0], rms


def test_the_clipped_share_counts_pixels_with_any_channel_at_full_scale():
    img = np.zeros((4, 5, 3), np.uint8)
    img[0, 0, 0] = 255
    img[1, 1] = 255
    img[2, 2, 2] = 254
    assert clipped_share(img) == pytest.approx(2 / 20)
    assert clipped_share(img, saturation_level=254 / 255) == pytest.approx(3 / 20)
    assert clipped_share(img.astype(np.uint16) * 257) == pytest.approx(2 / 20)
    assert clipped_share(img.astype(np.float32) / 255) == pytest.approx(2 / 20)
    assert clipped_share(img[..., 0]) == pytest.approx(2 / 20)
    assert clipped_share(np.zeros((0, 3, 3), np.uint8)) == 0.0


def test_the_doubts_name_what_they_measured_from_their_thresholds_on():
    assert compression_doubt(BLOCK_RATIO_WARN - 0.01) == "" and compression_doubt(float("nan")) == ""
    assert "JPEG's 8x8 blocks (steps at the blocks' edges 1.50x" in compression_doubt(1.5)
    assert "flat within them" in compression_doubt(float("inf"), what="reference capture")
    assert clipping_doubt(CLIPPED_SHARE_WARN - 0.001) == ""
    told = clipping_doubt(0.21, what="reference capture")
    assert told.startswith("21.0 % of the reference capture's pixels are clipped") and "Expose shorter" in told


def test_decode_warns_of_a_jpeg_and_a_clipped_capture(tmp_path, caplog):
    """As a user meets it: a capture saved as JPEG (then as PNG: the blocks stay) and one exposed
    3x (49 % of it clipped) are warned of by `simbench decode`, the clean one not; a JPEG reference
    capture too."""
    ref = CAL.image
    files = [*bare_files(tmp_path, RAW, ref, SCENE.rig), "--z0", "1.0", "--out", str(tmp_path / "d.npy")]
    assert main(["decode", *files]) == 0
    assert "JPEG" not in caplog.text and "clipped" not in caplog.text
    cv2.imwrite(str(tmp_path / "capture.jpg"), RAW[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, 90])
    caplog.clear()
    assert main(["decode", str(tmp_path / "capture.jpg"), *files[1:]]) == 0
    assert "capture.jpg: the capture shows JPEG's 8x8 blocks" in caplog.text
    bright = np.clip(RAW.astype(np.int32) * 3, 0, 255).astype(np.uint8)
    files = [*bare_files(tmp_path, bright, _jpeg(ref, 90), SCENE.rig), "--z0", "1.0", "--out", str(tmp_path / "d.npy")]
    caplog.clear()
    main(["decode", *files])
    assert "capture.png: " in caplog.text and "of the capture's pixels are clipped in a colour channel" in caplog.text
    assert "reference.png: the reference capture shows JPEG's 8x8 blocks" in caplog.text


def test_a_capture_saturated_all_over_is_told_of_once(tmp_path, caplog):
    """A capture at 255 everywhere: the nothing-decoded warning names its saturation, without the
    clipping doubt about the phase beside clipped runs before it (a new user's audit, 2026-11-29:
    there are no kept pixels for it to be about); at 50 % clipped that doubt stands
    (test_decode_warns_of_a_jpeg_and_a_clipped_capture)."""
    from simbench.decode.pipeline import CAPTURE_CLIPPED_UNDECODABLE
    from simbench.systems.files import NOTHING_DECODED_SHARE

    assert CAPTURE_CLIPPED_UNDECODABLE == pytest.approx(1.0 - NOTHING_DECODED_SHARE)
    white = np.full_like(RAW, 255)
    files = [*bare_files(tmp_path, white, CAL.image, SCENE.rig), "--z0", "1.0", "--out", str(tmp_path / "d.npy")]
    assert main(["decode", *files]) == 0
    assert "clipped in a colour channel" not in caplog.text, caplog.text
    assert "no pixel decoded: 100 % of the capture's pixels are saturated in every channel" in caplog.text


def test_decode_refuses_clipped_calibration_frames_in_one_line(tmp_path, capsys):
    """The colour-robust decoder's coupling matrix is the median of each primary's frame over the
    plane: frames exposed 3x (each primary's own channel at full scale over the plane) would give
    the clipping level's matrix and unmix every capture wrongly - refused, naming the frame."""
    files = [*bare_files(tmp_path, RAW, CAL.image, SCENE.rig), "--z0", "1.0", "--out", str(tmp_path / "d.npy")]
    frames = tmp_path / "cal"
    frames.mkdir()
    for name, frame in CAL.frames.items():
        bright = frame if name == "dark" else np.clip(frame.astype(np.int32) * 3, 0, 255).astype(np.uint8)
        save_png(frames / f"calibration_{name}.png", bright)
    rc = main(["decode", *files, "--robust", "--calibration", str(frames)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert "the calibration capture under projector primary R is clipped" in err[0], err
    assert f"the calibration frames in {frames}/" in err[0] and "calibration_dark.png" in err[0], err


def test_decode_refuses_calibration_frames_in_the_wrong_order(tmp_path, capsys):
    """A new user's audit (2026-11-30): the green and blue frames renamed decoded a chart with 8 % of
    its depths > 5 mm wrong, exit 0, without a word; refused now, in one line naming the folder."""
    files = [*bare_files(tmp_path, RAW, CAL.image, SCENE.rig), "--z0", "1.0", "--out", str(tmp_path / "d.npy")]
    frames = tmp_path / "cal"
    frames.mkdir()
    swap = {"green": "blue", "blue": "green"}
    for name, frame in CAL.frames.items():
        save_png(frames / f"calibration_{swap.get(name, name)}.png", frame)
    rc = main(["decode", *files, "--robust", "--calibration", str(frames)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert f"the calibration frames in {frames}/" in err[0], err
    assert "named green looks blue" in err[0] and "named blue looks green" in err[0], err
    assert not (tmp_path / "d.npy").exists()


def test_calibration_frames_may_be_tiff_as_a_labs_camera_writes_them(tmp_path, capsys):
    """A lab user's audit (2026-11-30): `--calibration` with TIFF frames failed on "needs
    calibration_*.png" while the docs advise PNG or TIFF.  TIFF frames decode as their PNGs do (the
    same depth, bit for bit); a frame in two formats is refused (which one was meant?)."""
    import cv2

    files = [*bare_files(tmp_path, RAW, CAL.image, SCENE.rig), "--z0", "1.0"]
    depth = {}
    for kind in ("png", "tiff"):
        frames = tmp_path / kind
        frames.mkdir()
        for name, frame in CAL.frames.items():
            if kind == "png":
                save_png(frames / f"calibration_{name}.png", frame)
            else:
                assert cv2.imwrite(str(frames / f"calibration_{name}.tiff"), frame[..., ::-1])
        out = tmp_path / f"{kind}.npy"
        assert main(["decode", *files, "--out", str(out), "--robust", "--calibration", str(frames)]) == 0
        depth[kind] = np.load(out)
    assert np.array_equal(depth["png"], depth["tiff"], equal_nan=True) and np.isfinite(depth["png"]).mean() > 0.5
    save_png(tmp_path / "tiff" / "calibration_red.png", CAL.frames["red"])
    capsys.readouterr()
    rc = main(["decode", *files, "--out", str(tmp_path / "x.npy"), "--robust", "--calibration", str(tmp_path / "tiff")])
    assert (
        rc == 2
        and "holds 2 calibration_red frames (calibration_red.png, calibration_red.tiff)" in capsys.readouterr().err
    )
