import numpy as np
import pytest

from simbench.metrics import code_stripes, depth_errors, edge_band, plane_fit_error, points_from_depth, wrong_pixels
from simbench.pattern import PatternSpec, fringe_pattern
from simbench.rig import Intrinsics


def test_depth_errors_by_hand():
    gt = np.ones((4, 5))
    d = gt.copy()
    d[0, 0] = 1.002  # 2 mm
    d[0, 1] = 1.010  # 10 mm: outlier
    d[1, 1] = np.nan
    region = np.ones_like(gt, bool)
    region[3] = False
    m = depth_errors(d, gt, region=region)
    assert m["n_region"] == 15 and m["n_valid"] == 14
    assert m["completeness"] == pytest.approx(14 / 15)
    assert m["mae_mm"] == pytest.approx(12 / 14)
    assert m["outlier_share"] == pytest.approx(1 / 14)
    col = np.zeros_like(gt)
    m = depth_errors(d, gt, region=region, column_px=col + np.array([0, 11, 0, 0, 0]), gt_column_px=col, period_px=21)
    # column 1 is off by > T/2 in rows 0 and 2 (row 1 is invalid there, row 3 outside the region)
    assert m["stripe_order_errors"] == 2
    assert m["stripe_order_error_rate"] == pytest.approx(2 / 14)


def test_plane_fit_error_is_zero_on_a_plane_and_sees_noise():
    cam = Intrinsics.centred(200, 150, 300.0)
    rows, cols = np.mgrid[0:150, 0:200]
    rx, ry = (cols - cam.cx_px) / cam.focal_px, (rows - cam.cy_px) / cam.focal_px
    # plane 0.2 x + 0.1 y + z = 1  ->  z = 1 / (0.2 rx + 0.1 ry + 1)
    z = 1.0 / (0.2 * rx + 0.1 * ry + 1.0)
    assert plane_fit_error(z, cam)["mean_abs_residual_mm"] < 1e-9
    noisy = z + np.random.default_rng(0).normal(0, 1e-3, z.shape)
    e = plane_fit_error(noisy, cam)["mean_abs_residual_mm"]
    assert e == pytest.approx(np.sqrt(2 / np.pi) * 1.0 / np.sqrt(1 + 0.2**2 + 0.1**2), rel=0.05)


def test_edge_band():
    z = np.ones((20, 20))
    z[:, 10:] = 1.2
    b = edge_band(z, band_px=2)
    assert b[:, 7:13].all() and not b[:, :7].any() and not b[:, 13:].any()
    assert not edge_band(np.ones((5, 5)), band_px=3).any()


def test_points_from_depth():
    cam = Intrinsics.centred(3, 3, 1.0)
    p = points_from_depth(np.full((3, 3), 2.0), cam)
    assert np.allclose(p[0, 0], [-2, -2, 2])


@pytest.mark.parametrize("dtypes", [(np.float32, np.float32), (np.float32, np.float64), (np.float64, np.float32)])
def test_depth_errors_of_float32_maps_are_those_of_the_maps_widened_first(dtypes):
    """depth_errors gathers the scored pixels before widening float32 maps to float64: every
    score is the bits of the same maps widened to float64 whole first (the form it had)."""
    rng = np.random.default_rng(len(str(dtypes)))
    h, w = 120, 170
    gt = (1.0 + 0.01 * rng.random((h, w))).astype(dtypes[1])
    d = (gt + rng.normal(0, 3e-4, (h, w))).astype(dtypes[0])
    far = rng.random((h, w)) < 0.1  # gross errors: a float32 difference would round
    d[far] = (3.0 + rng.random(far.sum())).astype(dtypes[0])
    d[rng.random((h, w)) < 0.05] = np.nan
    gt[rng.random((h, w)) < 0.02] = np.nan
    region = rng.random((h, w)) < 0.8
    col = (rng.random((h, w)) * 900).astype(np.float32)
    for exclude in (None, rng.random((h, w)) < 0.1):
        kw = dict(region=region, exclude=exclude, column_px=col, gt_column_px=col + 11 * far, period_px=21.0)
        got = depth_errors(d, gt, **kw)
        assert got == depth_errors(d.astype(np.float64), gt.astype(np.float64), **kw) and got["n_scored"] > 1000
    empty = depth_errors(np.full((h, w), np.nan, np.float32), gt, region=region)
    assert empty["n_valid"] == 0 and np.isnan(empty["mae_mm"])
    ints = depth_errors(np.ones((h, w), np.int32), gt, region=region)  # non-float maps are widened
    assert ints["n_valid"] == ints["n_region"] > 0


@pytest.mark.parametrize("dtypes", [(np.float32, np.float32), (np.float64, np.float64), (np.float32, np.float64)])
def test_depth_errors_give_the_bits_of_the_whole_image_numpy_form(dtypes):
    """The C pass (masks, counts, gathers) and the one-partition median and p95 give every
    error score's bits of the numpy form (tests/numpy_reference.py), with NaN in either map,
    pixels outside the region, excluded pixels, gross errors and an empty selection."""
    from tests import numpy_reference as ref

    rng = np.random.default_rng(7)
    for h, w in ((1, 1), (1, 2), (3, 5), (97, 131), (240, 320)):
        gt = (1.0 + 0.01 * rng.random((h, w))).astype(dtypes[1])
        d = (gt + rng.normal(0, 3e-4, (h, w))).astype(dtypes[0])
        d[rng.random((h, w)) < 0.1] = 3.0
        d[rng.random((h, w)) < 0.05] = np.nan
        gt[rng.random((h, w)) < 0.02] = np.nan
        region = rng.random((h, w)) < 0.9
        for exclude in (None, rng.random((h, w)) < 0.1, np.ones((h, w), bool)):
            got = depth_errors(d, gt, region=region, exclude=exclude)
            want = ref.depth_errors(d, gt, region=region, exclude=exclude)
            assert set(want) <= set(got)
            for k, v in want.items():
                assert (np.isnan(v) and np.isnan(got[k])) or (got[k] == v and type(got[k]) is type(v)), (h, w, k)


def test_median_and_p95_of_one_partition_are_numpys():
    """numpy's median and 95th percentile, bit for bit, on every size from 1 to 300 and a large
    one, with ties, zeros and values of very different sizes."""
    from simbench.metrics import _median_and_p95

    rng = np.random.default_rng(3)
    for n in [*range(1, 301), 99_991, 100_000]:
        for a in (
            np.abs(rng.normal(0, 1, n)),
            np.round(rng.random(n) * 4) / 4,  # ties
            np.abs(rng.standard_cauchy(n)),
            np.zeros(n),
        ):
            assert _median_and_p95(a) == (float(np.median(a)), float(np.percentile(a, 95))), n


@pytest.mark.parametrize("scale", [0.25, 0.5, 1.0])
def test_plane_fit_error_gives_the_bits_of_the_whole_image_form(scale):
    """The Table 1 protocol computed on the counted pixels only equals, bit for bit, the form
    that made every pixel's point first (tests/numpy_reference.py): the same points in the same
    order go to the same plane fit (simbench.metrics.fit_plane)."""
    from simbench.metrics import fit_plane, plane_fit_error
    from simbench.rig import paper_rig, scale_camera
    from tests import numpy_reference as ref

    cam = scale_camera(paper_rig(), scale).camera
    rng = np.random.default_rng(int(scale * 8))
    h, w = cam.size_hw
    y, x = np.mgrid[:h, :w]
    depth = (1.1 + 2e-4 * (x - w / 2) - 1e-4 * (y - h / 3) + rng.normal(0, 3e-4, (h, w))).astype(np.float32)
    depth[rng.random((h, w)) < 0.1] = np.nan
    depth[: h // 5, : w // 4] = np.nan
    mask = rng.random((h, w)) < 0.8
    depth[h // 2, : w // 3] = np.inf
    for d in (depth, depth.astype(np.float64) + rng.normal(0, 1e-9, (h, w))):
        for m in (None, mask):
            got, want = plane_fit_error(d, cam, mask=m), ref.plane_fit_error(d, cam, mask=m)
            assert got == want and got["n_points"] > 1000
    assert plane_fit_error(np.full((h, w), np.nan), cam)["n_points"] == 0
    with pytest.raises(ValueError, match="mask"):
        plane_fit_error(depth, cam, mask=mask[:, :-1])
    few = np.full((h, w), np.nan, np.float32)
    few[5, 5:20] = 1.0
    assert plane_fit_error(few, cam)["n_points"] == 15 and np.isnan(plane_fit_error(few, cam)["mean_abs_residual_mm"])
    with pytest.raises(ValueError, match="does not match the camera"):
        plane_fit_error(depth[:, :-1], cam)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        fit_plane(np.zeros((200, 2)))


def _board(reflectance, ambient: float = 0.02):
    """A capture whose camera column x sees projector column x: linear RGB reflectance times
    (the pattern + ambient), 8 bits; and its true column."""
    spec = PatternSpec()
    drive = fringe_pattern(spec)[:8, :400]
    img = np.rint(np.clip(0.9 * (drive + ambient) * np.asarray(reflectance), 0, 1) * 255).astype(np.uint8)
    col = np.broadcast_to(np.arange(400, dtype=np.float64), (8, 400)).copy()
    col[:, :3] = np.nan  # unlit pixels are left out
    return img, col, spec


def test_code_stripes_of_a_white_and_a_red_board():
    """Closed form: on a white board each code's stripes hold its own channel's fringe (mean
    0.9 * (0.5 + 0.02) of full scale, the cosine's mean 0.5) and the ambient in the other (0.9 * 0.02);
    Eq. 13 reads them right except where both sit at the fringe's dark border (R = G).  A pure red
    board leaves only the ambient in the green-coded stripes' red and nothing in their green, so
    Eq. 13 (R >= G) reads every one of them as red: 0 % right."""
    img, col, spec = _board((1.0, 1.0, 1.0))
    c = code_stripes(img, col, pattern=spec)
    assert c["code1_mean"][0] == pytest.approx(0.9 * 0.52, abs=0.01)
    assert c["code1_mean"][1] == pytest.approx(0.9 * 0.02, abs=0.003)
    assert c["code0_mean"][1] == pytest.approx(0.9 * 0.52, abs=0.01)
    assert c["code1_eq13"] == 1.0 and c["code0_eq13"] > 0.9
    assert c["code1_pixels"] + c["code0_pixels"] == 8 * 397
    img, col, spec = _board((1.0, 0.0, 0.0))
    c = code_stripes(img, col, pattern=spec, where=np.ones(col.shape, bool))
    assert c["code0_mean"][:2] == pytest.approx((0.9 * 0.02, 0.0), abs=0.003)
    assert c["code0_eq13"] == 0.0 and c["code1_eq13"] == 1.0


def test_code_stripes_checks_shapes():
    img, col, spec = _board((1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="does not match"):
        code_stripes(img, col[:, :10], pattern=spec)
    with pytest.raises(ValueError, match="shape"):
        code_stripes(img[..., 0], col, pattern=spec)


def test_a_plane_fit_to_pixels_along_an_image_line_is_no_measurement():
    """A review of the protocols (2026-11-30): the points of one image line lie in one plane
    through the camera centre whatever their depths, so the fit read 0.000000 mm for 109 pixels
    of one row at random depths 0.3-1.8 m.  NaN now, for a row, a column and a diagonal; a patch
    two periods wide of the same random depths is measured (and is far from flat)."""
    from simbench.metrics import MIN_PLANE_SPREAD, pixel_spread

    cam = Intrinsics.centred(640, 480, 600.0)
    rng = np.random.default_rng(3)
    for rows, cols in (
        (np.full(300, 200), np.arange(100, 400)),  # a row
        (np.arange(50, 350), np.full(300, 320)),  # a column
        (np.arange(50, 350), np.arange(100, 400)),  # a diagonal
    ):
        d = np.full((480, 640), np.nan)
        d[rows, cols] = rng.uniform(0.3, 1.8, rows.size)
        assert pixel_spread(d) < 1e-6
        fit = plane_fit_error(d, cam)
        assert fit["n_points"] == 300 and np.isnan(fit["mean_abs_residual_mm"]), fit
    d = np.full((480, 640), np.nan)
    width = int(np.ceil(2 * np.sqrt(12) * MIN_PLANE_SPREAD * 640))  # a strip whose spread is twice the floor
    d[100:300, 200 : 200 + width] = rng.uniform(0.3, 1.8, (200, width))
    assert pixel_spread(d) == pytest.approx(width / np.sqrt(12), rel=0.05)
    assert plane_fit_error(d, cam)["mean_abs_residual_mm"] > 10.0  # (a narrow wedge: far under its errors, but no 0)
    # a strip of half the floor's spread is not measured
    d[:, 200 + width // 4 :] = np.nan
    assert pixel_spread(d) < MIN_PLANE_SPREAD * 640 and np.isnan(plane_fit_error(d, cam)["rms_residual_mm"])


def test_score_reports_no_plane_fit_where_the_truth_is_not_flat():
    """A review (2026-11-30): the ablations scored the step scene's plane fit, 34.9 mm - its shape,
    not its error.  score() reports the fit only where the truth over the decoded pixels is flat
    within PLANAR_TRUTH_RMS_MM; a bowed board (0.2 mm RMS, the flatness study's largest) still
    is."""
    from simbench.metrics import PLANAR_TRUTH_RMS_MM, score
    from simbench.sim.truth import GroundTruth

    cam = Intrinsics.centred(200, 150, 300.0)
    rows, cols = np.mgrid[0:150, 0:200]
    flat = np.full((150, 200), 1.0)
    noise = np.random.default_rng(0).normal(0, 5e-4, flat.shape)

    def scored(truth):
        gt = GroundTruth(
            depth_m=truth.astype(np.float32),
            column_px=np.full(truth.shape, np.nan),
            object_id=np.zeros(truth.shape, np.int16),
            lit=np.ones(truth.shape, bool),
        )
        return score((truth + noise).astype(np.float32), gt, camera=cam)

    assert scored(flat)["plane_mae_mm"] == pytest.approx(0.5 * np.sqrt(2 / np.pi), rel=0.05)
    r2 = ((cols - 100) ** 2 + (rows - 75) ** 2) / 100.0**2
    bowed = flat + 0.6e-3 * (r2 - r2.mean())  # ~0.2 mm RMS
    assert 0.15 < np.std(bowed) * 1000 < PLANAR_TRUTH_RMS_MM and np.isfinite(scored(bowed)["plane_mae_mm"])
    step = np.where(cols < 100, 1.0, 1.1)
    out = scored(step)
    assert np.isnan(out["plane_mae_mm"]) and np.isnan(out["plane_rms_mm"])
    assert out["gt_mae_mm"] == pytest.approx(0.5 * np.sqrt(2 / np.pi), rel=0.05)  # the errors still scored


def test_the_edge_mae_leaves_out_the_callers_exclusions_too():
    """A review (2026-11-30): with an edge band the MAE off the edges dropped the caller's
    ``exclude``, counting pixels every other statistic leaves out."""
    from simbench.metrics import score
    from simbench.sim.truth import GroundTruth

    cam = Intrinsics.centred(60, 40, 100.0)
    truth = np.ones((40, 60), np.float32)
    gt = GroundTruth(
        depth_m=truth, column_px=np.full(truth.shape, np.nan), object_id=np.zeros(truth.shape, np.int16), lit=truth > 0
    )
    depth = truth + np.float32(0.001)
    exclude = np.zeros(truth.shape, bool)
    exclude[10:20, 10:20] = True
    depth[exclude] += np.float32(1.0)  # a metre off, excluded
    out = score(depth, gt, camera=cam, exclude=exclude, edge_band_px=2)
    assert out["gt_mae_mm"] == pytest.approx(1.0, rel=1e-3) and out["edge2_mae_mm"] == pytest.approx(1.0, rel=1e-3)


def test_a_depth_is_wrong_only_if_far_from_every_truth():
    """wrong_pixels: decoded and more than wrong_m from each truth; a truth of NaN near nothing
    (a depth where nothing is seen is wrong); a pixel not decoded never wrong; a stack of truths
    (a moving scene's instants) admits a depth any of them takes there."""
    depth = np.array([[1.000, 1.004, 1.006, np.nan], [1.300, 1.150, 1.0, 1.0]])
    truth = np.array([[1.0, 1.0, 1.0, 1.0], [1.0, 1.0, np.nan, 1.0]])
    assert wrong_pixels(depth, truth, wrong_m=0.005).tolist() == [
        [False, False, True, False],
        [True, True, True, False],
    ]
    later = truth.copy()
    later[1, :2] = 1.3  # the wall behind, seen at another instant of the capture
    swept = wrong_pixels(depth, np.stack([truth, later]), wrong_m=0.005)
    # the wall's depth is right where the wall was seen; halfway between the two is still wrong
    assert swept.tolist() == [[False, False, True, False], [False, True, True, False]]
    with pytest.raises(ValueError, match=r"truth of shape \(2, 3\)"):
        wrong_pixels(depth, np.ones((2, 3)), wrong_m=0.005)


def test_image_motion_is_the_fastest_pixels_travel():
    """``image_motion_px``: the longest (du, dv) of a motion map (3-4-5), 0 for a still recording
    (None) or one that sees nothing move (NaN and zeros), a map of another shape refused."""
    from simbench.metrics import image_motion_px

    m = np.zeros((4, 5, 2), np.float32)
    m[1, 2] = (3.0, -4.0)
    m[2, 3] = (1.0, 1.0)
    m[0, 0] = np.nan
    assert image_motion_px(m) == 5.0
    assert image_motion_px(None) == 0.0 and image_motion_px(np.full((2, 2, 2), np.nan)) == 0.0
    with pytest.raises(ValueError, match=r"expected shape \(H, W, 2\)"):
        image_motion_px(np.zeros((4, 5)))
