"""Lens physics (simbench.optics, simbench.sim.projector) and the decoder's undistortion."""

from __future__ import annotations

import dataclasses
import math

import cv2
import numpy as np
import pytest

from simbench.decode import DecoderParams, decode, decode_reference
from simbench.optics import (
    blur_circle_px,
    depth_varying_blur,
    distort_image,
    distort_normalized,
    undistort_image,
    undistort_normalized,
    undistort_projector_columns,
)
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.sim.projector import defocus_pattern, dmd_layout, transfer_curve
from simbench.rig import Intrinsics, paper_rig
from simbench.sim.synthetic import synthetic_plane_capture

DIST = (-0.08, 0.10, 0.001, -0.0005, 0.0)


def test_distortion_matches_opencv_both_ways():
    intr = Intrinsics(1280, 960, 2312.5, 639.5, 479.5, DIST)
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-0.28, 0.28, 200), rng.uniform(-0.21, 0.21, 200)
    xd, yd = distort_normalized(x, y, DIST)
    proj, _ = cv2.projectPoints(
        np.stack([x, y, np.ones_like(x)], -1), np.zeros(3), np.zeros(3), intr.matrix, np.array(DIST)
    )
    assert np.allclose(proj[:, 0, 0], intr.focal_px * xd + intr.cx_px, atol=1e-9)
    assert np.allclose(proj[:, 0, 1], intr.focal_px * yd + intr.cy_px, atol=1e-9)
    xu, yu = undistort_normalized(xd, yd, DIST)
    assert np.max(np.abs(xu - x)) < 1e-9 and np.max(np.abs(yu - y)) < 1e-9


def test_distort_then_undistort_image_recovers_a_smooth_image():
    intr = Intrinsics(320, 240, 578.0, 159.5, 119.5, DIST)
    yy, xx = np.mgrid[0:240, 0:320]
    img = (0.5 + 0.4 * np.sin(xx / 13.0) * np.cos(yy / 17.0)).astype(np.float32)
    back = undistort_image(distort_image(img, intr), intr)
    inner = (slice(20, -20), slice(20, -20))
    assert np.max(np.abs(back[inner] - img[inner])) < 0.01  # two bilinear resamplings
    assert not np.allclose(distort_image(img, intr)[inner], img[inner], atol=0.01)  # it did distort


def _field_image(field, fn):
    """``fn(x, y)`` of normalised coordinates at the pixel centres of ``field``, (H, W, 3) float32."""
    x, y = pixel_grid(field)
    v = fn(x, y)
    return np.ascontiguousarray(np.stack([v, 0.5 * v, 0.25 + v], -1), dtype=np.float32)


@pytest.mark.parametrize("dist", [DIST, (0.12, 0.0, 0.0, 0.0, 0.0)], ids=["barrel", "pincushion"])
@pytest.mark.parametrize("cxy", [(159.5, 119.5), (150.25, 127.0)], ids=["centred", "off-centre"])
def test_the_lens_field_gives_every_recorded_pixel_the_scene_it_sees(dist, cxy):
    """A capture renders ``lens_field`` and records it through ``camera_lens_image``: every recorded
    pixel p gets the ideal image at K D^-1(K^-1 p) - up to the image's ends, where ``distort_image``
    of a same-size pinhole image is black for a barrel lens.  Exact for an image linear in the
    normalised coordinates (bilinear interpolation reproduces it: tolerance float32 rounding of the
    maps, 1e-4 of the values' range).  The field has the same focal length, the same margin at
    opposite sides (a centred principal point stays centred, as Mitsuba's thin lens needs) and no
    distortion."""
    from simbench.optics import camera_lens_image, lens_field

    intr = Intrinsics(320, 240, 578.0, *cxy, dist)
    field = lens_field(intr)
    mx, my = (field.width_px - intr.width_px) // 2, (field.height_px - intr.height_px) // 2
    assert (field.width_px - intr.width_px, field.height_px - intr.height_px) == (2 * mx, 2 * my)
    assert (field.cx_px, field.cy_px, field.focal_px) == (intr.cx_px + mx, intr.cy_px + my, intr.focal_px)
    assert not field.has_distortion

    def linear(x, y):  # 0.5 to 1.5 over the field
        return 1.0 + x - y

    out = camera_lens_image(_field_image(field, linear), intr)
    assert out.shape == (240, 320, 3)
    xd, yd = pixel_grid(intr)
    expected = _field_image(intr, lambda x, y: linear(*undistort_normalized(xd, yd, dist)))
    assert np.max(np.abs(out - expected)) < 1e-4
    if dist[0] < 0:  # barrel: the old path's ends are black, the lens field's are not
        same_size = distort_image(_field_image(intr, linear), intr)[..., 0]
        for end in (0, -1):
            assert (same_size[:, end] < 0.5 * out[:, end, 0]).mean() > 0.5
        assert mx >= 2 and np.all(out[:, [0, -1]] > 0.1)


def test_lateral_colour_through_the_lens_field_has_no_black_rim():
    """Lateral colour pulling a channel inward (blue -0.6 px at the corner) reads beyond the recorded
    image: through the lens field that channel is the scene up to the image's ends (a uniform
    scene stays uniform to float rounding), while ``lateral_colour_image`` on the recorded grid
    darkens its end columns.  Inside the image both agree (tolerance: one more bilinear step of a
    smooth image)."""
    from simbench.optics import camera_lens_image, lateral_colour_image, lens_field

    shift = (0.6, 0.0, -0.6)
    for dist in (DIST, (0.0,) * 5):
        intr = Intrinsics(320, 240, 578.0, 159.5, 119.5, dist)
        field = lens_field(intr, lateral_colour_px=shift)
        assert field.width_px > intr.width_px
        flat = camera_lens_image(np.ones(field.size_hw + (3,), np.float32), intr, lateral_colour_px=shift)
        assert np.max(np.abs(flat - 1.0)) < 1e-5
        smooth = _field_image(field, lambda x, y: 0.5 + 0.3 * np.sin(9 * x) * np.cos(7 * y))
        out = camera_lens_image(smooth, intr, lateral_colour_px=shift)
        mx, my = (field.width_px - 320) // 2, (field.height_px - 240) // 2
        old = lateral_colour_image(
            distort_image(np.ascontiguousarray(smooth[my : my + 240, mx : mx + 320]), intr), intr, shift_px=shift
        )
        inner = (slice(20, -20), slice(20, -20))
        assert np.max(np.abs(out[inner] - old[inner])) < 2e-3
        assert old[:, -1, 2].mean() < 0.9 * out[:, -1, 2].mean()


def test_an_ideal_lens_renders_its_own_image():
    """No distortion, no lateral colour: the field is the camera itself and the image passes
    through untouched (static captures of ideal sensors keep their render keys); a wrong-size
    image is refused with the field's size in the message."""
    from simbench.optics import camera_lens_image, lens_field

    intr = Intrinsics(320, 240, 578.0, 159.5, 119.5)
    assert lens_field(intr) is intr
    img = np.zeros((240, 320, 3), np.float32)
    assert camera_lens_image(img, intr) is img
    with pytest.raises(ValueError, match="lens's field"):
        camera_lens_image(img, Intrinsics(320, 240, 578.0, 159.5, 119.5, DIST))


def pixel_grid(intr):
    """Normalised coordinates of the camera's pixel centres, float64, (H, W) each."""
    h, w = intr.size_hw
    x = (np.arange(w, dtype=np.float64) - intr.cx_px) / intr.focal_px
    y = (np.arange(h, dtype=np.float64) - intr.cy_px) / intr.focal_px
    return np.broadcast_to(x[None, :], (h, w)), np.broadcast_to(y[:, None], (h, w))


def test_remap_maps_are_cached_per_device_with_the_same_bits():
    """The undistortion and distortion maps are built once per intrinsics and reused (read-only);
    the images are bit-identical to remapping with maps built afresh from the model."""
    from simbench.optics import _distort_maps, _undistort_maps

    intr = Intrinsics(320, 240, 578.0, 159.5, 119.5, DIST)
    img = np.random.default_rng(3).integers(0, 256, (240, 320, 3), dtype=np.uint8)
    x, y = pixel_grid(intr)

    def remap(xn, yn):  # the image sampled at normalised coordinates, maps built afresh
        mx, my = (
            (xn * intr.focal_px + intr.cx_px).astype(np.float32),
            (yn * intr.focal_px + intr.cy_px).astype(np.float32),
        )
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)

    assert np.array_equal(undistort_image(img, intr), remap(*distort_normalized(x, y, DIST)))
    assert np.array_equal(distort_image(img, intr), remap(*undistort_normalized(x, y, DIST)))
    for maps in (_undistort_maps, _distort_maps):
        a, b = maps(intr), maps(dataclasses.replace(intr))
        assert a[0] is b[0] and not a[0].flags.writeable
    other = dataclasses.replace(intr, distortion=(-0.05, 0.0, 0.0, 0.0, 0.0))
    assert not np.array_equal(_undistort_maps(other)[0], _undistort_maps(intr)[0])


def test_projector_columns_undistort_exactly():
    prj = Intrinsics(1824, 1140, 2228.0, 911.5, 569.5, DIST)
    x = np.linspace(-0.38, 0.38, 50)[None, :]
    y = np.linspace(-0.24, 0.24, 40)[:, None]
    xd, _ = distort_normalized(x, y, DIST)
    got = undistort_projector_columns(prj.focal_px * xd + prj.cx_px, y, prj)
    assert np.max(np.abs(got - (prj.focal_px * x + prj.cx_px))) < 1e-6
    assert np.isnan(undistort_projector_columns(np.array([np.nan]), np.array([0.0]), prj)[0])


def test_blur_circle_by_hand():
    # 3 mm aperture, f = 2000 px, focused at 1 m, object at 2 m: 0.003 * 2000 * 0.5 = 3 px
    assert blur_circle_px(2.0, aperture_m=0.003, focal_px=2000.0, focus_m=1.0) == pytest.approx(3.0)
    assert blur_circle_px(1.0, aperture_m=0.003, focal_px=2000.0, focus_m=1.0) == 0.0
    with pytest.raises(ValueError):
        blur_circle_px(1.0, aperture_m=0.003, focal_px=2000.0, focus_m=0.0)


def test_depth_varying_blur_is_exact_for_constant_sigma():
    img = np.random.default_rng(1).random((60, 80, 3)).astype(np.float32)
    sigma = np.full((60, 80), 1.5)
    ref = cv2.GaussianBlur(img, (0, 0), 1.5, borderType=cv2.BORDER_REPLICATE)
    assert np.allclose(depth_varying_blur(img, sigma), ref, atol=1e-5)
    assert np.array_equal(depth_varying_blur(img, np.zeros((60, 80))), img)
    with pytest.raises(ValueError, match="shape"):
        depth_varying_blur(img, np.zeros((3, 3)))


def _layered_blur_numpy(img, sigma_px, step_px=0.25):
    """depth_varying_blur as numpy computed it before its per-level sum went to C (the reference
    the C loop must give the bits of)."""
    src = np.asarray(img, dtype=np.float32)
    sig = np.nan_to_num(np.asarray(sigma_px, dtype=np.float64), nan=0.0, posinf=0.0)
    levels = np.arange(0.0, float(sig.max()) + step_px, step_px)
    pos = np.clip(sig / step_px, 0.0, len(levels) - 1.0)
    lo = np.floor(pos).astype(np.int64)
    frac = (pos - lo).astype(np.float32)
    out = np.zeros_like(src)
    for k, s in enumerate(levels):
        cur = src if s == 0.0 else cv2.GaussianBlur(src, (0, 0), float(s), float(s), borderType=cv2.BORDER_REPLICATE)
        if cur.ndim == 2 and src.ndim == 3:
            cur = cur[..., None]
        w = np.where(lo == k, 1.0 - frac, 0.0).astype(np.float32) + np.where(lo == k - 1, frac, 0.0).astype(np.float32)
        out += (w[..., None] if src.ndim == 3 else w) * cur
    return out


@pytest.mark.parametrize("channels", [None, 1, 3])
def test_depth_varying_blur_gives_the_bits_of_its_numpy_form(channels):
    """The per-level weights and sums run in C (simbench/_lens.c): the same float32 operations as
    numpy's, so the same bits, for sigma growing across the image (levels in strips: the C loop
    sums over boxes), a level no pixel uses, NaN sigma, and a non-contiguous image."""
    rng = np.random.default_rng(3)
    shape = (70, 90) if channels is None else (70, 90, channels)
    img = rng.random(shape).astype(np.float32)
    sigma = np.linspace(0.0, 2.3, 90)[None, :] * np.ones((70, 1))
    sigma[:, 40:50] = 3.1  # skips the levels between 2.3 and 3.0
    sigma[5:9, 60:70] = np.nan
    sigma[12, 3] = np.inf  # in focus, as NaN
    got = depth_varying_blur(img, sigma)
    assert got.shape == img.shape and got.dtype == np.float32
    assert np.array_equal(got, _layered_blur_numpy(img, sigma))
    wide = np.zeros((70, 180) + shape[2:], np.float32)
    wide[:, ::2] = img
    assert np.array_equal(depth_varying_blur(wide[:, ::2], sigma), got)


def test_projector_defocus_lowers_fringe_contrast_by_the_gaussian_mtf():
    """A Gaussian blur of standard deviation s multiplies a fringe of period T by
    exp(-2 pi^2 s^2 / T^2) (its transfer function)."""
    period, s = 21.0, 3.0
    x = np.arange(840)
    row = (0.5 + 0.5 * np.cos(2 * np.pi * x / period)).astype(np.float32)
    drive = np.repeat(np.repeat(row[None, :, None], 40, 0), 3, 2)
    # sigma = blur circle / 4; choose the distance that gives s
    aperture, f, focus = 0.006, 2228.0, 1.0
    z = 1.0 / (1.0 / focus + 4 * s / (aperture * f))
    out = defocus_pattern(drive, np.full((40, 840), z), aperture_m=aperture, focal_px=f, focus_m=focus)
    line = out[20, 100:-100, 2]
    amp = 0.5 * (line.max() - line.min())
    assert amp == pytest.approx(0.5 * np.exp(-2 * np.pi**2 * s**2 / period**2), rel=0.02)


def test_transfer_curve_and_black_level():
    pat = np.array([[[0, 128, 255]]], np.uint8)
    lin = transfer_curve(pat, transfer="linear")
    assert np.allclose(lin, [0.0, 128 / 255, 1.0])
    gam = transfer_curve(pat, transfer="gamma", gamma=2.2)
    assert np.allclose(gam, [0.0, (128 / 255) ** 2.2, 1.0], atol=1e-6)
    black = transfer_curve(pat, transfer="linear", contrast_ratio=1000.0)
    assert black[0, 0, 0] == pytest.approx(1e-3) and black[0, 0, 2] == pytest.approx(1.0)
    assert black[0, 0, 2] / black[0, 0, 0] == pytest.approx(1000.0)  # the contrast ratio
    for bad in (
        {"transfer": "sRGB"},
        {"transfer": "gamma", "gamma": 0.0},
        {"transfer": "linear", "contrast_ratio": 0.5},
    ):
        with pytest.raises(ValueError):
            transfer_curve(pat, **bad)
    with pytest.raises(ValueError, match="8-bit"):
        transfer_curve(pat.astype(np.float32), transfer="linear")


def test_video_mode_bitplane_timing_against_its_model():
    """A free-running camera collects each bit-plane whole when its exposure is a whole number of
    frames (any phase), on average over the phase whatever its length, and by hand-computed
    shares in a simple case; a triggered camera (no weights) sees the linear transfer."""
    from simbench.sim.projector import video_bitplane_weights

    for phase in (0.0, 0.37, 0.999):
        np.testing.assert_allclose(
            video_bitplane_weights(exposure_s=2 / 60, frame_rate_hz=60.0, phase=phase), 1.0, rtol=1e-9
        )
    mean = np.mean(
        [video_bitplane_weights(exposure_s=0.027, frame_rate_hz=60.0, phase=p) for p in (np.arange(3000) + 0.5) / 3000],
        axis=0,
    )
    np.testing.assert_allclose(mean, 1.0, atol=2e-3)
    # a third of a frame from its start: the red third whole (3x its share of a frame's), nothing else
    w = video_bitplane_weights(exposure_s=1 / 180, frame_rate_hz=60.0, phase=0.0)
    np.testing.assert_allclose(w[0], 3.0, rtol=1e-9)
    np.testing.assert_allclose(w[1:], 0.0, atol=1e-12)
    # half of red's third from its start: the MSB lasts 128/255 of the third, so it is cut just
    # before its end (weight (1/2) / (E f 128/255) = 6 * 255/256) and the next plane is missed
    w = video_bitplane_weights(exposure_s=1 / 360, frame_rate_hz=60.0, phase=0.0)
    assert w[0, 7] == pytest.approx(6.0 * 255 / 256, rel=1e-12) and w[0, 6] == 0.0
    pat = np.arange(256, dtype=np.uint8).reshape(1, 256, 1).repeat(3, axis=2)
    ones = transfer_curve(pat, transfer="linear", bitplane_weights=np.ones((3, 8)))
    np.testing.assert_allclose(ones, transfer_curve(pat, transfer="linear"), atol=1e-7)
    partial = transfer_curve(
        pat, transfer="linear", bitplane_weights=video_bitplane_weights(exposure_s=0.027, frame_rate_hz=60.0, phase=0.3)
    )
    assert np.abs(partial - ones).max() > 0.1  # levels off by more than a tenth of full scale
    for bad in (
        {"exposure_s": 0.0, "frame_rate_hz": 60.0, "phase": 0.0},
        {"exposure_s": 0.01, "frame_rate_hz": 60.0, "phase": 1.0},
    ):
        with pytest.raises(ValueError):
            video_bitplane_weights(**bad)
    with pytest.raises(ValueError, match="shape"):
        transfer_curve(pat, transfer="linear", bitplane_weights=np.ones((3, 7)))


def test_diamond_dmd_pairs_columns_with_alternate_row_offsets():
    rng = np.random.default_rng(2)
    drive = rng.random((6, 10, 3)).astype(np.float32)
    out = dmd_layout(drive, layout="diamond")
    assert np.array_equal(out[0, 0], out[0, 1]) and np.allclose(out[0, 0], 0.5 * (drive[0, 0] + drive[0, 1]))
    assert np.array_equal(out[1, 1], out[1, 2]) and np.allclose(out[1, 1], 0.5 * (drive[1, 1] + drive[1, 2]))
    assert not np.array_equal(out[1, 0], out[1, 1])
    assert out[2:4].mean() == pytest.approx(drive[2:4].mean(), abs=0.05)  # light is conserved up to the edges
    assert dmd_layout(drive, layout="square") is drive
    with pytest.raises(ValueError, match="diamond"):
        dmd_layout(drive, layout="hexagonal")
    with pytest.raises(ValueError, match="even"):
        dmd_layout(drive[:, :9], layout="diamond")


def _transfer_numpy(pattern, *, transfer, gamma=2.2, contrast_ratio=math.inf, bitplane_weights=None):
    """transfer_curve as numpy computed it on the whole image before its table lookup went to C."""
    v = pattern.astype(np.float32) / np.float32(255.0)
    if transfer == "gamma":
        v = v ** np.float32(gamma)
    if bitplane_weights is not None:
        w = np.asarray(bitplane_weights, np.float64)
        codes = np.arange(256)
        shown = codes if transfer == "linear" else np.round((codes / 255.0) ** gamma * 255.0)
        bits = (shown.astype(np.int64)[:, None] >> np.arange(8)) & 1
        lut = (bits * (2.0 ** np.arange(8)) @ w.T / 255.0).astype(np.float32)
        v = np.stack([lut[pattern[..., c], c] for c in range(3)], axis=-1)
    black = np.float32(0.0 if math.isinf(contrast_ratio) else 1.0 / contrast_ratio)
    if black > 0:
        v = black + (np.float32(1.0) - black) * v
    return v.astype(np.float32)


def _diamond_numpy(drive):
    """dmd_layout's diamond as numpy computed it before it went to C."""
    out = np.empty_like(drive)
    even = drive[0::2]
    pair = 0.5 * (even[:, 0::2] + even[:, 1::2])
    out[0::2, 0::2] = pair
    out[0::2, 1::2] = pair
    odd = drive[1::2]
    pair = 0.5 * (odd[:, 1:-1:2] + odd[:, 2::2])
    out[1::2, 1:-1:2] = pair
    out[1::2, 2::2] = pair
    out[1::2, 0] = odd[:, 0]
    out[1::2, -1] = odd[:, -1]
    return out


@pytest.mark.parametrize(
    "settings",
    [
        {"transfer": "linear"},
        {"transfer": "gamma", "gamma": 2.2, "contrast_ratio": 1500.0},
        {"transfer": "gamma", "gamma": 1.8, "bitplane_weights": "video"},
        {"transfer": "linear", "contrast_ratio": 1000.0, "bitplane_weights": "video"},
    ],
)
def test_the_projector_model_gives_the_bits_of_its_numpy_form(settings):
    """The transfer (a table of the 256 codes' values, looked up in C) and the diamond DMD layout
    (in C) give the bits numpy gave on the whole image - for a real pattern size (the paper
    projector's, every code in every channel, odd and even heights) - so projector drives, and
    the render cache keys made from them, did not change when they moved to C."""
    from simbench.sim.projector import video_bitplane_weights

    if settings.get("bitplane_weights") == "video":
        settings = {
            **settings,
            "bitplane_weights": video_bitplane_weights(exposure_s=0.0213, frame_rate_hz=60.0, phase=0.41),
        }
    rng = np.random.default_rng(5)
    pattern = rng.integers(0, 256, (1140, 1824, 3), dtype=np.uint8)
    pattern[0, :256] = np.arange(256, dtype=np.uint8)[:, None]
    drive = transfer_curve(pattern, **settings)
    assert drive.dtype == np.float32 and np.array_equal(drive, _transfer_numpy(pattern, **settings))
    assert np.array_equal(transfer_curve(pattern[:, ::-1], **settings), drive[:, ::-1])  # a non-contiguous pattern
    for rows in (1140, 7):
        assert np.array_equal(dmd_layout(drive[:rows], layout="diamond"), _diamond_numpy(drive[:rows]))
    assert np.array_equal(dmd_layout(drive[..., 1], layout="diamond"), _diamond_numpy(drive[..., 1]))


# the decoder with lens distortion -------------------------------------------------------
# the decoder with lens distortion -------------------------------------------------------

RIG = paper_rig()
DRIVE = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")


def _distorted_rig(camera=DIST, projector=(0.0,) * 5):
    return dataclasses.replace(
        RIG,
        camera=dataclasses.replace(RIG.camera, distortion=camera),
        projector=dataclasses.replace(RIG.projector, distortion=projector),
    )


@pytest.mark.parametrize("mode", ["reference", "calibrated"])
def test_decoder_undistorts_the_camera(mode):
    """A capture through a distorting camera lens, decoded with the rig file's coefficients,
    gives the depth on the ideal pixel grid (resampling costs a little accuracy)."""
    rig = _distorted_rig()
    img, _, z = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1))
    ref, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.0))
    seen_img, seen_ref = distort_image(img, rig.camera), distort_image(ref, rig.camera)
    r = decode(
        seen_img,
        rig=rig,
        params=DecoderParams(mode=mode),
        reference=decode_reference(seen_ref, rig=rig, params=DecoderParams()),
    )
    assert r.valid.mean() > 0.97
    err = r.depth_m[r.valid] - z[r.valid]
    assert np.sqrt(np.mean(err**2)) < 0.2e-3
    naive = decode(seen_img, rig=RIG, params=DecoderParams(mode="calibrated"))  # ignoring the distortion
    bad = naive.depth_m[naive.valid] - z[naive.valid]
    assert np.sqrt(np.mean(bad**2)) > 5 * np.sqrt(np.mean(err**2))


def test_an_8_bit_capture_is_undistorted_without_a_second_quantisation():
    """A new user's audit (2026-11-30): the 20:1 chart's 8-bit capture decoded 96.5 % complete, the
    same values in 16 bits 97.2 %: the decoder undistorted an 8-bit capture in 8 bits, and OpenCV's
    remap rounded every interpolated pixel to an integer level again.  It resamples in float32 now:
    an 8-bit capture and the same levels in 16 bits decode to the same depths (to float32's
    rounding of 1/255 against 257/65535) within 1 um; before, nearly every pixel differed by ~12 um
    and up to 92 um (the remap's 1/32-px weights and the rounding)."""
    rig = _distorted_rig()
    img, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.1))
    ref, _, _ = synthetic_plane_capture(DRIVE, RIG, point_m=(0, 0, 1.0))
    u8 = [np.round(np.clip(distort_image(x / 1.21, rig.camera), 0, 1) * 255).astype(np.uint8) for x in (img, ref)]
    u16 = [x.astype(np.uint16) * np.uint16(257) for x in u8]
    params = DecoderParams(mode="calibrated")
    d8, d16 = (
        decode(c, rig=rig, params=params, reference=decode_reference(r, rig=rig, params=DecoderParams()))
        for c, r in (u8, u16)
    )
    assert d8.valid.mean() > 0.97 and (d8.valid == d16.valid).mean() > 0.9999
    both = d8.valid & d16.valid
    assert np.abs(d8.depth_m[both] - d16.depth_m[both]).max() < 1e-6


@pytest.mark.parametrize("mode", ["reference", "calibrated"])
def test_decoder_handles_projector_distortion(mode):
    """The DMD pattern leaves through a distorting projector lens: reference matching is exact
    along rows in a rectified rig, calibrated triangulation undoes the distortion per column."""
    rig = _distorted_rig(camera=(0.0,) * 5, projector=(-0.05, 0.02, 0.0, 0.0, 0.0))
    img, col, z = synthetic_plane_capture(DRIVE, rig, point_m=(0, 0, 1.2))
    ref, _, _ = synthetic_plane_capture(DRIVE, rig, point_m=(0, 0, 1.0))
    r = decode(
        img, rig=rig, params=DecoderParams(mode=mode), reference=decode_reference(ref, rig=rig, params=DecoderParams())
    )
    assert r.valid.mean() > 0.98
    assert np.sqrt(np.mean((r.column_px[r.valid] - col[r.valid]) ** 2)) < 0.05  # DMD columns
    # 0.03 px of column error in depth: dZ = Z^2 / (f_p B) du (the ideal rig's test uses 0.02 px;
    # near the image ends the reference is extrapolated along its curved column map)
    assert np.sqrt(np.mean((r.depth_m[r.valid] - z[r.valid]) ** 2)) < 0.03 * 1.2**2 / (
        rig.projector.focal_px * rig.baseline_m
    )


@pytest.mark.parametrize("distortion", [(-0.21, 0.1, 0.0, 0.0, 0.0), (0.12, -0.05, 0.002, -0.0015, 0.01)])
def test_remap_grids_are_the_bits_of_the_numpy_lens_model(distortion):
    """The C remap grids (simbench/_lens.c) = the float64 numpy forms of distort_normalized /
    undistort_normalized on the pixel grid, cast to float32: the same operations in the same
    order, no fused multiply-add."""
    from simbench import optics
    from simbench.rig import Intrinsics

    intr = Intrinsics(width_px=97, height_px=61, focal_px=80.0, cx_px=50.3, cy_px=28.9, distortion=distortion)
    gx, gy = pixel_grid(intr)
    for inverse, model in ((False, optics.distort_normalized), (True, optics.undistort_normalized)):
        u, v = model(gx, gy, distortion)
        mx, my = optics._maps(intr, inverse=inverse)
        assert np.array_equal(mx, (u * intr.focal_px + intr.cx_px).astype(np.float32))
        assert np.array_equal(my, (v * intr.focal_px + intr.cy_px).astype(np.float32))
        assert not mx.flags.writeable


def test_lateral_colour_magnifies_each_channel_about_the_principal_point():
    """Closed form: a vertical line at column x0 in channel c lands at c0 + (x0 - c0)(1 + m_c), with
    m_c = shift_c / r_corner (r_corner from the principal point to the farthest corner); a channel
    with no shift keeps its bits.  Tolerance 0.05 px: OpenCV's bilinear remap places samples on a
    1/32-px grid."""
    from simbench.optics import lateral_colour_image, lateral_colour_magnification

    intr = Intrinsics(width_px=320, height_px=240, focal_px=500.0, cx_px=150.5, cy_px=110.0)
    img = np.zeros((240, 320, 3), np.float32)
    xs = np.arange(320)
    x0 = 290.0
    img[...] = np.exp(-0.5 * ((xs - x0) / 1.5) ** 2)[None, :, None]
    shift = (1.0, 0.0, -0.6)
    out = lateral_colour_image(img, intr, shift_px=shift)
    m = lateral_colour_magnification(intr, shift)
    r_corner = math.hypot(319 - 150.5, 239 - 110.0)
    assert m == pytest.approx(np.asarray(shift) / r_corner)
    row = out[110]
    for c in range(3):
        centroid = float((row[:, c] * xs).sum() / row[:, c].sum())
        assert centroid == pytest.approx(150.5 + (x0 - 150.5) * (1 + m[c]), abs=0.05)
    assert np.array_equal(out[..., 1], img[..., 1])
    assert lateral_colour_image(img, intr, shift_px=(0, 0, 0)) is img
    with pytest.raises(ValueError, match="not \\(H, W, 3\\)"):
        lateral_colour_image(img[:10], intr, shift_px=shift)


def test_lateral_colour_biases_the_overlay_phase_by_half_the_code_channels_shift():
    """The paper's Eq. 9 adds the code channels (R, G: the fringe on their stripes) to the fringe
    channel (B).  With R and G magnified by 1 + m and B not, the code channels' fringe is shifted by
    m (x - cx) camera px at column x, and the overlay - two equal cosines - by half of that, so pixel
    x shows the column that was m (x - cx) / 2 px further in: the decoded projector column is off by
    -m (x - cx) / 2 * f_p / f_c (closed form, first order in the shift; 0.32 px, ~1.5 mm at 1 m, at
    the right edge for a 1-px shift at the corner); within 25 % over the outer columns."""
    from simbench.optics import lateral_colour_image, lateral_colour_magnification

    rig = paper_rig()
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    img, col, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.0), supersample=2)
    shift = (1.0, 1.0, 0.0)
    moved = lateral_colour_image(img, rig.camera, shift_px=shift)
    r = decode(moved, rig=rig, params=DecoderParams(mode="calibrated"))
    m = lateral_colour_magnification(rig.camera, shift)[0]
    cam = rig.camera
    xs = np.arange(cam.width_px)
    predicted = (-m * (xs - cam.cx_px) / 2 * rig.projector.focal_px / cam.focal_px)[None, :]
    err = r.column_px - col
    outer = np.zeros(err.shape, bool)
    outer[200:760, 1100:1240] = True
    ok = outer & r.valid
    assert ok.sum() > 10000
    measured, expected = float(np.median(err[ok])), float(np.median(np.broadcast_to(predicted, err.shape)[ok]))
    assert expected < -0.1  # the effect is there to see
    assert measured == pytest.approx(expected, rel=0.25)
