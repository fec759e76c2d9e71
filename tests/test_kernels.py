"""The fused C loops (simbench.decode._kernels) give the same bits as the whole-image numpy
expressions they replaced (tests/numpy_reference.py), on realistic and on awkward inputs."""

import numpy as np
import pytest

from simbench.decode import color, debruijn, depth, phase
from simbench.decode.pipeline import _per_pixel
from tests import numpy_reference as ref

T_CAM = 21.8


def same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f")


def fringe(h=90, w=300, seed=0, holes=True):
    """A noisy fringe whose phase drifts (slant and a step), with dark holes and a clipped spot."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[:h, :w].astype(np.float64)
    psi = 2 * np.pi * x / T_CAM * (1 + 0.15 * y / h) + np.where(x > w * 0.6, 2.0, 0.0)
    img = (0.45 + 0.35 * np.cos(psi) + rng.normal(0, 0.02, (h, w))).astype(np.float32)
    cert = np.ones((h, w), np.float32)
    if holes:
        cert[h // 3 : h // 2, w // 4 : w // 3] = 0  # shadow
        cert[rng.random((h, w)) < 0.01] = 0  # scattered clipped pixels
        cert[:, :3] = 0
    return img, cert


def close_fit(got, want, *, phase_where_amplitude_above=0.02):
    """The C Gabor fit against OpenCV's separable filter (tests/numpy_reference.py): the window
    sums are added in another order (taps paired, the carrier on the window), so they agree to
    float32 rounding - about 1e-7 relative per sum, amplified by the 3x3 solve where the window
    is cut by holes; the bounds below are 3-10x what the fringes here show (measured: phase
    3.3e-4 rad = 0.001 camera px where the amplitude passes the decoder's 0.02, beside the holes,
    1.3e-5 rad elsewhere; amplitude/offset 7e-6, residual 2.7e-4, support 4e-7)."""
    wrapped, amp, a0, residual, support = want
    assert np.abs(got.support - support).max() <= 5e-6
    assert np.abs(got.offset - a0).max() <= 1e-4
    assert np.abs(got.amplitude - amp).max() <= 1e-4
    same(np.isfinite(got.residual), np.isfinite(residual))
    fin = np.isfinite(residual)
    assert np.all(np.abs(got.residual[fin] - residual[fin]) <= 3e-3 * (1 + np.abs(residual[fin])))
    strong = amp > phase_where_amplitude_above
    d = np.angle(np.exp(1j * (got.wrapped[strong].astype(np.float64) - wrapped[strong])))
    assert np.abs(d).max(initial=0) <= 1e-3
    assert np.isfinite(got.wrapped).all() and (got.wrapped >= -np.pi).all() and (got.wrapped < np.pi).all()


@pytest.mark.parametrize("holes", [False, True], ids=["all-certain", "with-holes"])
@pytest.mark.parametrize("shape", [(90, 300), (1, 64), (7, 23), (490, 1280)])
def test_gabor_fit_matches_numpy(holes, shape):
    img, cert = fringe(*shape, holes=holes)
    kw = dict(period_px=T_CAM, sigma_x_px=0.25 * T_CAM, sigma_y_px=0.15 * T_CAM)
    close_fit(phase.gabor_phase(img, certainty=cert, **kw), ref.gabor_phase(img, certainty=cert, **kw))


def test_gabor_fit_with_weights_and_a_lowered_floor_matches_numpy():
    """Certain samples weighing 0.02-1 (the colour-robust decoder's flattened prints: 1/gain) and
    the kernel's floor on the weights' sum lowered to 0.001 (``min_weight``): the C fit is still
    the numpy form's, and windows whose weights sum to under 0.05 but over 0.001 - no fit at the
    default floor - are fitted."""
    img, cert = fringe(90, 300, holes=True)
    weights = cert * np.where((np.arange(300) // 9) % 2 == 1, np.float32(0.02), np.float32(1.0))[None, :]
    kw = dict(period_px=T_CAM, sigma_x_px=0.25 * T_CAM, sigma_y_px=0.15 * T_CAM)
    got = phase.gabor_phase(img, certainty=weights, min_weight=0.001, **kw)
    close_fit(got, ref.gabor_phase(img, certainty=weights, min_weight=0.001, **kw))
    default = phase.gabor_phase(img, certainty=weights, **kw)
    lifted = (got.support > 0.001) & (got.support <= 0.05)
    assert lifted.any() and (default.amplitude[lifted] == 0).all() and (got.amplitude[lifted] > 0).any()


@pytest.mark.parametrize("phi0", [0.0, 1.0, -2.5, 3.1, np.pi])
def test_gabor_fit_recovers_a_known_fringe_phase(phi0):
    """A pure fringe ``0.5 + 0.3 cos(w x + phi0)``: away from the borders (where the window is
    whole) the wrapped phase is ``w x + phi0`` in [-pi, pi) to 2e-6 rad (measured ~1e-6: float32
    sums; the polynomial atan2 adds ~1e-7) and the amplitude 0.3 to 1e-6."""
    h, w = 40, 400
    psi = 2 * np.pi / T_CAM * np.arange(w) + phi0
    img = np.broadcast_to((0.5 + 0.3 * np.cos(psi)).astype(np.float32), (h, w)).copy()
    kw = dict(period_px=T_CAM, sigma_x_px=0.25 * T_CAM, sigma_y_px=0.15 * T_CAM)
    r = phase.gabor_phase(img, certainty=np.ones((h, w), np.float32), **kw)
    inner = slice(20, w - 20)
    d = np.angle(np.exp(1j * (r.wrapped[:, inner].astype(np.float64) - psi[inner])))
    assert np.abs(d).max() <= 2e-6
    assert np.abs(r.amplitude[:, inner] - 0.3).max() <= 1e-6
    assert (r.wrapped >= -np.pi).all() and (r.wrapped < np.pi).all()


def certainty_cases(h, w, seed):
    """Certainty maps that put uncertain pixels where the kernel's bookkeeping could slip: none,
    everywhere, a single pixel at each corner and edge (inside rx / ry of the border), holes
    and scattered pixels, weights other than 0 and 1, and a weight one ulp above 1."""
    rng = np.random.default_rng(seed)
    ones = np.ones((h, w), np.float32)
    yield "all-certain", ones
    yield "none-certain", np.zeros((h, w), np.float32)
    for y, x in ((0, 0), (h - 1, w - 1), (h // 2, 2), (min(3, h - 1), w // 2), (h - 1, w - 5)):
        c = ones.copy()
        c[y, x] = 0
        yield f"one-pixel-{y}-{x}", c
    yield "holes", fringe(h, w, seed=seed)[1]
    c = ones.copy()
    graded = rng.random((h, w)) < 0.3
    c[graded] = rng.uniform(0, 1, graded.sum())
    yield "graded", c
    c = ones.copy()
    c[h // 2, w // 3] = np.nextafter(np.float32(1), np.float32(2))
    yield "above-one", c


@pytest.mark.parametrize("shape", [(1, 64), (7, 23), (20, 100), (21, 100), (22, 100), (90, 300)])
def test_gabor_fit_reading_the_all_certain_table_gives_the_bits_of_computing_every_sum(shape):
    """The certainty's window sums of every pixel whose window is wholly certain come from the
    all-ones table (phase._all_certain_table): the fit must be the bits of the one that computes
    every sum itself (table None), on any certainty, band height (below, at and above the table's
    2 ry + 1 = 21 rows) and output row range."""
    from simbench.decode import _kernels

    h, w = shape
    img, _ = fringe(h, w, seed=4, holes=False)
    omega = round(2.0 * np.pi / T_CAM, 12)
    sx, sy = 0.25 * T_CAM, 0.15 * T_CAM
    kernels, basis = phase._half_kernels(omega, sx, sy), phase._basis(w, omega)
    ry = kernels[-1].size - 1
    assert ry == 10
    table = phase._all_certain_table(min(h, 2 * ry + 1), w, omega, sx, sy)
    for name, cert in certainty_cases(h, w, seed=h):
        for y0, y1 in {(0, h), (h // 3, h), (0, max(1, h - 4)), (h // 2, h // 2 + 1)}:
            want = tuple(np.empty((y1 - y0, w), np.float32) for _ in range(5))
            got = tuple(np.empty((y1 - y0, w), np.float32) for _ in range(5))
            _kernels.gabor_band(img, cert, y0, y1, kernels, basis, None, False, *want)
            _kernels.gabor_band(img, cert, y0, y1, kernels, basis, table, False, *got)
            for g, x in zip(got, want):
                assert np.array_equal(g, x, equal_nan=True), (name, y0, y1)
    whole = phase.gabor_phase(img, certainty=np.ones((h, w), np.float32), period_px=T_CAM, sigma_x_px=sx, sigma_y_px=sy)
    assert np.array_equal(whole.support[min(ry, h - 1)], table[0, min(ry, h - 1)])


def test_gabor_fit_is_the_same_for_any_band_split():
    """The decoder's row bands carry a halo of 3 sigma_y rows: the fit of the band's own rows
    must then be the bits of the whole image's (zero beyond the image, never beyond the band)."""
    img, cert = fringe(120, 200, holes=True)
    sy = 0.15 * T_CAM
    halo = int(np.ceil(3 * sy))
    kw = dict(period_px=T_CAM, sigma_x_px=0.25 * T_CAM, sigma_y_px=sy)
    whole = phase.gabor_phase(img, certainty=cert, **kw)
    for a, b in ((0, 50), (50, 120), (30, 31)):
        lo, hi = max(0, a - halo), min(120, b + halo)
        part = phase.gabor_phase(img[lo:hi], certainty=cert[lo:hi], **kw)
        for f in ("wrapped", "amplitude", "offset", "residual", "support"):
            same(getattr(part, f)[a - lo : b - lo], getattr(whole, f)[a:b])


def test_gabor_fit_rows_do_not_depend_on_the_output_range():
    """The column sums are made for blocks of output rows in tiles of columns (the block's
    product rows stay in L1): rows y0:y1 of a band must be the bits of the same rows of the whole
    band's fit, for ranges that start anywhere in a block, with and without the all-ones table,
    on images wider than a tile."""
    from simbench.decode import _kernels

    h, w = 90, 600
    img, _ = fringe(h, w, seed=7, holes=False)
    omega = round(2.0 * np.pi / T_CAM, 12)
    sx, sy = 0.25 * T_CAM, 0.15 * T_CAM
    kernels, basis = phase._half_kernels(omega, sx, sy), phase._basis(w, omega)
    table = phase._all_certain_table(_kernels.gabor_table_rows(h, kernels), w, omega, sx, sy)
    for name, cert in certainty_cases(h, w, seed=3):
        for tab in (None, table):
            whole = tuple(np.empty((h, w), np.float32) for _ in range(5))
            _kernels.gabor_band(img, cert, 0, h, kernels, basis, tab, False, *whole)
            for y0, y1 in ((1, 90), (5, 6), (7, 40), (13, 77), (83, 90)):
                part = tuple(np.empty((y1 - y0, w), np.float32) for _ in range(5))
                _kernels.gabor_band(img, cert, y0, y1, kernels, basis, tab, False, *part)
                for p, x in zip(part, whole):
                    assert np.array_equal(p, x[y0:y1], equal_nan=True), (name, tab is None, y0, y1)


@pytest.mark.parametrize("method", ["gabor", "ftp", "wfr"])
def test_phase_without_the_offset_gives_the_same_bits_otherwise(method):
    """offset=False (the decoder's call: no stage reads the offset, and the Gabor kernel then
    does not write it) leaves every other output bit for bit as it was."""
    from simbench.decode.params import PHASE_METHODS

    img, cert = fringe(60, 300, holes=True)
    kw = dict(certainty=cert, period_px=T_CAM, sigma_x_px=0.25 * T_CAM, sigma_y_px=0.15 * T_CAM)
    full = PHASE_METHODS[method](img, **kw)
    lean = PHASE_METHODS[method](img, offset=False, **kw)
    assert lean.offset is None and full.offset.shape == img.shape
    for f in ("wrapped", "amplitude", "residual", "support"):
        same(getattr(lean, f), getattr(full, f))


def test_gabor_fit_on_flat_and_empty_images():
    kw = dict(period_px=T_CAM, sigma_x_px=5.0, sigma_y_px=3.0)
    empty = phase.gabor_phase(np.zeros((20, 40), np.float32), certainty=np.zeros((20, 40), np.float32), **kw)
    assert (empty.amplitude == 0).all() and np.isinf(empty.residual).all() and (empty.support == 0).all()
    assert (empty.wrapped == 0).all()
    flat = np.full((20, 40), 0.5, np.float32)
    got = phase.gabor_phase(flat, certainty=np.ones((20, 40), np.float32), **kw)
    want = ref.gabor_phase(flat, certainty=np.ones((20, 40), np.float32), **kw)
    assert np.abs(got.support - want[4]).max() <= 5e-6 and np.abs(got.offset - want[2]).max() <= 1e-4
    # no fringe: no amplitude (the phase of rounding noise is meaningless), the offset is the level
    assert got.amplitude.max() < 1e-5 and np.allclose(got.offset[got.support > 0.5], 0.5, atol=1e-5)


def stripes_input(seed=1):
    img, cert = fringe(seed=seed)
    p = phase.gabor_phase(img, certainty=cert, period_px=T_CAM, sigma_x_px=5.0, sigma_y_px=3.0)
    rng = np.random.default_rng(seed)
    valid = (p.amplitude > 0.1) & (rng.random(img.shape) > 0.02)
    return p.wrapped, valid, img > 0.45


@pytest.mark.parametrize("seed", [1, 2])
def test_segmentation_and_voting_match_numpy(seed):
    wrapped, valid, code = stripes_input(seed)
    got = color.segment_stripes(wrapped, valid, period_px=T_CAM)
    want = ref.segment_stripes(wrapped, valid, period_px=T_CAM)
    for f in ("labels", "row", "start", "stop", "linked_prev"):
        same(getattr(got, f), getattr(want, f))
    assert got.count > 100 and got.linked_prev.any()
    for voting in (True, False):
        for a, b in zip(color.vote_codes(code, got, voting=voting), ref.vote_codes(code, want, voting=voting)):
            same(a, b)


def step_row(bound):
    """A row whose phase grows by exactly ``bound`` (float32) per pixel."""
    b = np.float32(bound)
    return np.float32([[0, b, 2 * b, 4 * b]])


def test_segmentation_edge_cases():
    for wrapped, valid in (
        (np.zeros((3, 5), np.float32), np.zeros((3, 5), bool)),  # nothing valid
        (np.zeros((0, 5), np.float32), np.zeros((0, 5), bool)),  # no rows
        (np.zeros((2, 1), np.float32), np.ones((2, 1), bool)),  # one column
        (np.tile(np.float32([3.0, -3.0]), (2, 3)), np.ones((2, 6), bool)),  # a wrap at every pixel
        # steps exactly at segment_stripes' plausibility bounds (0.3 and min(3, 0.9 pi / omega) omega)
        (step_row(0.3 * (2.0 * np.pi / T_CAM)), np.ones((1, 4), bool)),
        (step_row(min(3.0 * (2.0 * np.pi / T_CAM), 0.9 * np.pi) / 2), np.ones((1, 4), bool)),
    ):
        got = color.segment_stripes(wrapped, valid, period_px=T_CAM)
        want = ref.segment_stripes(wrapped, valid, period_px=T_CAM)
        for f in ("labels", "row", "start", "stop", "linked_prev"):
            same(getattr(got, f), getattr(want, f))
        code = np.ones(wrapped.shape, bool)
        for a, b in zip(color.vote_codes(code, got), ref.vote_codes(code, want)):
            same(a, b)


@pytest.mark.parametrize("rows", [1, 4, 9])
def test_pooled_code_matches_numpy(rows):
    """Phases near the +-pi seam (the wrapped difference) and NaN phases included."""
    from simbench.decode.color import pool_code_rows

    rng = np.random.default_rng(rows)
    h, w = 60, 70
    code = rng.random((h, w)) < 0.5
    wrapped = (rng.random((h, w)) * 2 - 1).astype(np.float32) * np.float32(np.pi)
    wrapped[::7] = np.float32(np.pi) - np.float32(1e-3)
    wrapped[3::7] = -np.float32(np.pi)
    wrapped[5, ::3] = np.nan
    valid = rng.random((h, w)) < 0.8
    for out_rows in (None, slice(10, 50), slice(0, 3)):
        got = pool_code_rows(code, wrapped, valid, rows=rows, out_rows=out_rows)
        same(got, ref.pool_code_rows(code, wrapped, valid, rows=rows, out_rows=out_rows))
    assert not np.array_equal(pool_code_rows(code, wrapped, valid, rows=rows), code)


@pytest.mark.parametrize("corrupt", [0.15, 0.6], ids=["mostly-right", "mostly-wrong"])
@pytest.mark.parametrize("reach,min_support", [(1, 1), (3, 2), (8, 3)])
def test_contested_positions_match_numpy(reach, min_support, corrupt):
    rng = np.random.default_rng(reach + 10)
    n, cycle = 5000, 8
    linked = rng.random(n) > 0.1
    linked[0] = False
    true = np.arange(n) % cycle
    positions = np.where(rng.random(n) < corrupt, rng.integers(-1, cycle, n), true).astype(np.int32)
    kept, _ = debruijn.neighbour_correct(positions, linked, cycle=cycle, reach=3, min_support=2)
    kw = dict(cycle=cycle, reach=reach, min_support=min_support)
    got = debruijn.contested_positions(positions, kept, linked, **kw)
    same(got, ref.contested_positions(positions, kept, linked, **kw))
    assert 0 < got.sum() < (kept >= 0).sum()
    empty = np.zeros(0, np.int32)
    same(debruijn.contested_positions(empty, empty, empty.astype(bool), **kw), np.zeros(0, bool))


@pytest.mark.parametrize("corrupt", [0.15, 0.6], ids=["mostly-right", "mostly-wrong"])
@pytest.mark.parametrize("reach,min_support", [(1, 1), (2, 2), (3, 2), (4, 3)])
def test_neighbour_correction_matches_numpy(reach, min_support, corrupt):
    """Also where most stripes are wrong, so that the kernel's majority shortcut and its full
    count both decide often."""
    rng = np.random.default_rng(reach)
    n, cycle = 5000, 8
    linked = rng.random(n) > 0.1
    linked[0] = False
    true = np.arange(n) % cycle
    positions = np.where(rng.random(n) < corrupt, rng.integers(-1, cycle, n), true).astype(np.int32)
    for a, b in zip(debruijn.chain_extent(linked), ref.chain_extent(linked)):
        same(a.astype(np.int64), b.astype(np.int64))
    got = debruijn.neighbour_correct(positions, linked, cycle=cycle, reach=reach, min_support=min_support)
    want = ref.neighbour_correct(positions, linked, cycle=cycle, reach=reach, min_support=min_support)
    for a, b in zip(got, want):
        same(a, b)
    empty = np.zeros(0, np.int32)
    for a, b in zip(
        debruijn.neighbour_correct(empty, empty.astype(bool), cycle=cycle, reach=reach),
        ref.neighbour_correct(empty, empty.astype(bool), cycle=cycle, reach=reach),
    ):
        same(a, b)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("order", [2, 3, 4, 5])
def test_window_positions_and_broken_links_match_numpy(seed, order):
    """The stripes' De Bruijn windows and the broken-link rule in C: the numpy forms' outputs,
    on chains of every length (1 to many), unknown positions and tables with holes."""
    from simbench.pattern import de_bruijn, window_positions

    rng = np.random.default_rng(seed)
    n = 3000
    code = rng.integers(0, 2, n).astype(np.uint8)
    linked = rng.random(n) < 0.85
    linked[0] = False
    cycle = 1 << order
    table = window_positions(de_bruijn(order), order=order)
    table[rng.random(table.size) < 0.1] = -1
    got = debruijn.window_positions_of_stripes(code, linked, order=order, table=table, cycle=cycle)
    same(got, ref.window_positions_of_stripes(code, linked, order=order, table=table, cycle=cycle))
    assert (got >= 0).mean() > 0.3
    successive = np.arange(n) + rng.integers(0, 2, n) * (rng.random(n) < 0.05)  # a few links broken
    positions = np.where(rng.random(n) < 0.1, -1, successive % cycle).astype(np.int32)
    dropped = debruijn.drop_broken_links(positions, linked, cycle=cycle)
    same(dropped, ref.drop_broken_links(positions, linked, cycle=cycle))
    assert 0 < (dropped != positions).sum() < n // 4
    for m in (0, 1, 2):
        same(
            debruijn.drop_broken_links(positions[:m], linked[:m], cycle=cycle),
            ref.drop_broken_links(positions[:m], linked[:m], cycle=cycle),
        )
        same(
            debruijn.window_positions_of_stripes(code[:m], linked[:m], order=order, table=table, cycle=cycle),
            ref.window_positions_of_stripes(code[:m], linked[:m], order=order, table=table, cycle=cycle),
        )
    with pytest.raises(ValueError, match="0 or 1"):
        debruijn.window_positions_of_stripes(code + 1, linked, order=order, table=table, cycle=cycle)
    with pytest.raises(ValueError, match="2\\*\\*order"):
        debruijn.window_positions_of_stripes(code, linked, order=order, table=table[:-1], cycle=cycle)


def test_absolute_column_and_gather_match_numpy():
    wrapped, valid, _ = stripes_input(3)
    rng = np.random.default_rng(3)
    labels = np.where(valid, rng.integers(0, 400, wrapped.shape), -1).astype(np.int32)
    per_stripe = rng.integers(-1, 8, 400).astype(np.int32)
    for fill, arr in ((-1, per_stripe), (0.0, rng.random(400).astype(np.float32)), (-1, per_stripe.astype(np.int8))):
        same(_per_pixel(arr, labels, fill), ref.per_pixel(arr, labels, fill))
    position = ref.per_pixel(per_stripe, labels, -1)
    expected = (np.arange(wrapped.shape[1], dtype=np.float32) * 1.1 + rng.normal(0, 30, wrapped.shape)).astype(
        np.float32
    )
    expected[0, :5] = np.nan
    for period in (21.0, 15.0, 8.5):
        got = depth.absolute_column(position, wrapped, expected, period_px=period, cycle=8)
        want = ref.absolute_column(position, wrapped, expected, period_px=period, cycle=8)
        for a, b in zip(got, want):
            same(a, b)


def test_reference_matching_and_depth_match_numpy():
    rng = np.random.default_rng(4)
    h, w, width = 40, 200, 300
    table = np.sort(rng.uniform(0, w, (h, width + 2)), axis=1).astype(np.float32)
    table[:, -1] = np.nan
    table[1:][rng.random((h - 1, width + 2)) < 0.05] = np.nan
    column = rng.uniform(-5, width + 5, (h, w)).astype(np.float32)
    column[rng.random(column.shape) < 0.1] = np.nan
    column[0, :4] = [0.0, float(width), np.nextafter(np.float32(width), np.float32(0)), -0.0]
    x_ref = depth.match_reference(column, table)
    same(x_ref, ref.match_reference(column, table))
    assert x_ref[0, 1] == table[0, width]  # the last projector column itself is matched
    assert np.isfinite(x_ref).mean() > 0.5
    x_ref[0, 10] = 1e9  # a disparity putting the point behind the camera
    kw = dict(focal_px=2312.532, baseline_m=0.093, z0_m=1.0)
    same(depth.depth_from_disparity(x_ref, **kw), ref.depth_from_disparity(x_ref, **kw))


def gapped_fringe(seed):
    """Stripes input with short invalid gaps across every row (albedo edges along the stripes),
    one of them at a phase step that must not be bridged (a depth edge)."""
    wrapped, valid, code = stripes_input(seed)
    rng = np.random.default_rng(seed)
    valid = valid.copy()
    for x0 in rng.integers(10, wrapped.shape[1] - 30, 8):
        valid[:, x0 : x0 + rng.integers(1, 21)] = False
    return wrapped, valid, code


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_gap_bridging_matches_numpy(seed):
    wrapped, valid, code = gapped_fringe(seed)
    kw = dict(period_px=T_CAM, max_gap_px=int(0.95 * T_CAM))
    got = color.segment_stripes(wrapped, valid, **kw)
    want = ref.segment_stripes(wrapped, valid, **kw)
    for f in ("labels", "row", "start", "stop", "linked_prev"):
        same(getattr(got, f), getattr(want, f))
    plain = color.segment_stripes(wrapped, valid, period_px=T_CAM)
    assert got.count < plain.count and got.linked_prev.sum() > plain.linked_prev.sum()
    for voting in (True, False):
        for a, b in zip(color.vote_codes(code, got, voting=voting), ref.vote_codes(code, want, voting=voting)):
            same(a, b)


def capture_band(dtype, seed=5, h=30, w=170):
    """An RGB capture with dark regions, clipped pixels and values on the thresholds."""
    rng = np.random.default_rng(seed)
    img = rng.random((h, w, 3))
    img[:, 40:90] *= 0.03  # unlit
    img[5:9, 100:130] = 1.0  # clipped
    img[12, :, :] = 0.04  # exactly at dark_level (in float32)
    img[15, :, :] *= 0.03  # a row with no lit window
    img[16, :, :] = np.maximum(img[16], 0.5)  # a row that is all bright
    img[18, w // 2] *= 0.03  # one dark pixel in a bright row
    if dtype == np.uint8:
        return np.round(img * 255).astype(np.uint8)
    if dtype == np.uint16:
        return np.round(img * 65535).astype(np.uint16)
    return img.astype(np.float32)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
@pytest.mark.parametrize("order", [(0, 1, 2), (2, 0, 1)])
@pytest.mark.parametrize("mode", ["overlay", "blue"])
@pytest.mark.parametrize("w", [170, 15, 9, 1])
def test_front_end_matches_the_stages_it_fuses(dtype, order, mode, w):
    """One pass = as_float_image + certainty_map + overlay_intensity + color_code, bit for bit,
    also where the row is shorter than the lit window."""
    from simbench.decode import _kernels
    from simbench.decode.pipeline import as_float_image

    img = capture_band(dtype, w=w)
    for window, sat in ((1.0, 1.0), (8.0, 0.9)):
        rgb = as_float_image(img)[..., list(order)]
        cert, lit = phase.certainty_map(
            rgb, period_px=T_CAM, dark_level=0.04, saturation_level=sat, window_periods=window
        )
        shape = img.shape[:2]
        got = dict(
            intensity=np.empty(shape, np.float32),
            certainty=np.empty(shape, np.float32),
            lit=np.empty(shape, bool),
            code=np.empty(shape, bool),
        )
        _kernels.front_end(
            img,
            list(order),
            {"overlay": 0, "blue": 1}[mode],
            phase.certainty_window_px(T_CAM, window),
            0.04,
            sat,
            *got.values(),
        )
        same(got["intensity"], phase.overlay_intensity(rgb, mode=mode))
        same(got["certainty"], cert)
        same(got["lit"], lit)
        same(got["code"], color.color_code(rgb))
        if w > 100 and window == 1.0:
            assert got["lit"].any() and not got["lit"].all()


def test_front_end_lit_window_of_a_row_does_not_see_the_row_before():
    """The lit window is made per row (the OR of the bright flags by doubling, over a padded
    row): rows lit only at one end, after rows lit at the other, keep the clipped window's rule."""
    from simbench.decode import _kernels

    h, w = 6, 120
    img = np.zeros((h, w, 3), np.uint8)
    img[0, :3] = 200  # bright at the left end only
    img[1, -1] = 200  # then only at the right end
    img[2, 40] = 200
    img[3, :] = 200
    img[4, 2] = 200
    img[5, -3:] = 200
    width = phase.certainty_window_px(T_CAM, 1.0)
    rgb = np.asarray(img, np.float32) * np.float32(1 / 255)
    _, lit = phase.certainty_map(rgb, period_px=T_CAM, dark_level=0.04, saturation_level=1.0, window_periods=1.0)
    got = [np.empty((h, w), np.float32), np.empty((h, w), np.float32), np.empty((h, w), bool), np.empty((h, w), bool)]
    _kernels.front_end(img, [0, 1, 2], 0, width, 0.04, 1.0, *got)
    same(got[2], lit)
    r = width // 2
    assert got[2][1].tolist() == [False] * (w - 1 - r) + [True] * (r + 1)


def test_validity_matches_numpy():
    from simbench.decode import _kernels

    rng = np.random.default_rng(6)
    shape = (20, 50)
    lit = rng.random(shape) < 0.8
    support, amp, res = (rng.random(shape).astype(np.float32) for _ in range(3))
    amp[0, :3] = np.float32(0.02)  # on the threshold, as numpy compares it (float32)
    res[1, :3] = np.nan
    for max_res in (0.6, np.inf):
        got = np.empty(shape, bool)
        _kernels.validity(lit, support, amp, res, 0.5, 0.02, max_res, got)
        same(got, lit & (support >= 0.5) & (amp >= 0.02) & (res <= max_res))


def tail_rig(distorted_projector: bool, rectified: bool):
    import dataclasses

    from simbench.rig import paper_rig

    rig = paper_rig()
    if not rectified:
        rig = dataclasses.replace(rig, position_m=(0.09, 0.004, -0.002), rotation_deg=(0.4, -1.5, 0.3))
    if distorted_projector:
        rig = dataclasses.replace(
            rig, projector=dataclasses.replace(rig.projector, distortion=(0.05, -0.01, 0.001, 0.0005, 0.0))
        )
    return rig


@pytest.mark.parametrize("mode", ["reference", "calibrated"])
@pytest.mark.parametrize("distorted_projector", [False, True])
@pytest.mark.parametrize("rectified", [True, False])
def test_decode_tail_gives_the_bits_of_its_steps(mode, distorted_projector, rectified):
    """The fused tail (simbench.decode._kernels.decode_tail) = the stripe positions per pixel,
    the absolute column (Eq. 14), reference matching and depth from the disparity with the
    columns the reference row does not show triangulated (reference mode) or every column
    triangulated (calibrated mode), then the outputs of the depth range - each step in its numpy
    form (tests/numpy_reference.py), one after the other."""
    from simbench.decode import _kernels
    from simbench.rig import (
        COLUMN_NEWTON_STEPS,
        TRIANGULATION_ITERATIONS,
        projector_column_at_depth,
        triangulation_values,
    )

    rig = tail_rig(distorted_projector, rectified)
    rng = np.random.default_rng(7)
    h, w, row0, cycle, t = 30, 203, 400, 8, 21
    wrapped = rng.uniform(-np.pi, np.pi, (h, w)).astype(np.float32)
    n_stripes = 500
    labels = rng.integers(-1, n_stripes, (h, w)).astype(np.int32)
    position = rng.integers(-1, cycle, n_stripes).astype(np.int32)
    # columns chosen near those of a plane at 1.1 m, so that many triangulate into the range
    expected = projector_column_at_depth(1.1, rig)[row0 : row0 + h, :w].astype(np.float32)
    expected[0, :3] = np.nan
    amplitude = rng.random((h, w)).astype(np.float32)
    width = rig.projector.width_px
    table = np.sort(rng.uniform(0, w, (h, width + 2)), axis=1).astype(np.float32)
    table[:, -1] = np.nan
    table[:, : int(np.nanmedian(expected))] = np.nan  # columns the reference rows do not show
    position_map = ref.per_pixel(position, labels, -1)
    column, index = ref.absolute_column(position_map, wrapped, expected, period_px=t, cycle=cycle)
    rows, cols = np.mgrid[row0 : row0 + h, :w]
    if mode == "reference":
        x_ref = ref.match_reference(column, table)
        z = ref.depth_from_disparity(x_ref, focal_px=rig.camera.focal_px, baseline_m=rig.baseline_m, z0_m=1.0)
        beyond = np.isnan(x_ref) & np.isfinite(column)
        assert 0.05 < beyond.mean() < 0.6 and np.isfinite(z).mean() > 0.2
    else:
        beyond = ~np.isnan(column)
        z = np.full((h, w), np.nan, np.float32)
    z[beyond] = ref.triangulate_columns(column[beyond], rig, rows=rows[beyond], cols=cols[beyond]).astype(np.float32)
    # the range ends at two of the depths, so that both comparisons meet an equal value
    zmin, zmax = (float(np.nanquantile(z, q, method="lower")) for q in (0.2, 0.9))
    outs = [np.full((h, w), 7, dt) for dt in (np.float32, bool, np.float32, np.float32, np.int32)]
    _kernels.decode_tail(
        labels,
        position,
        wrapped,
        expected,
        amplitude,
        t=t,
        cycle=cycle,
        row0=row0,
        table=table if mode == "reference" else None,
        inv_z0=1.0,
        inv_fb=1.0 / (rig.camera.focal_px * rig.baseline_m),
        rig_values=triangulation_values(rig),
        distorted=distorted_projector,
        newton_steps=COLUMN_NEWTON_STEPS,
        refine_steps=0 if rectified else TRIANGULATION_ITERATIONS,
        zmin=zmin,
        zmax=zmax,
        depth_out=outs[0],
        valid_out=outs[1],
        conf_out=outs[2],
        col_out=outs[3],
        index_out=outs[4],
    )
    valid = (z >= np.float32(zmin)) & (z <= np.float32(zmax))
    assert 0.1 < valid.mean() < 0.9 and (valid & beyond).any()
    assert mode == "calibrated" or (valid & ~beyond).any()
    same(outs[1], valid)
    same(outs[0], np.where(valid, z, np.float32(np.nan)))
    same(outs[2], np.where(valid, amplitude, np.float32(0)))
    same(outs[3], np.where(valid, column, np.float32(np.nan)))
    same(outs[4], np.where(valid, index, np.int32(-1)))


def test_kernel_wrappers_refuse_what_the_c_code_cannot_read():
    from simbench.decode import _kernels

    a = np.zeros((4, 6), np.float32)
    lit, valid = np.zeros((4, 6), bool), np.empty((4, 6), bool)
    with pytest.raises(TypeError, match="dtype"):
        _kernels.validity(lit, a.astype(np.float64), a, a, 0.5, 0.0, 1.0, valid)
    with pytest.raises(ValueError, match="contiguous"):
        _kernels.validity(lit, a, a, a, 0.5, 0.0, 1.0, np.empty((4, 12), bool)[:, ::2])
    with pytest.raises(ValueError, match="shape"):
        _kernels.validity(lit, a, a, a[:2], 0.5, 0.0, 1.0, valid)
    with pytest.raises(ValueError, match="writable"):
        valid.setflags(write=False)
        _kernels.validity(lit, a, a, a, 0.5, 0.0, 1.0, valid)
    with pytest.raises(TypeError, match="uint8, uint16 or float32"):
        _kernels.front_end(np.zeros((2, 3, 3), np.int32), [0, 1, 2], 0, 3, 0.04, 1.0, *([None] * 4))
    with pytest.raises(ValueError, match="rows"):
        _kernels.gabor_band(a, a, 2, 9, None, None, None, False, *([a] * 5))


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("square", [False, True])
def test_bounded_mean_matches_numpy(seed, square):
    """The albedo flattening's segment-bounded window means (simbench.decode.color): the C
    loop's bits are numpy's, for windows wider and narrower than the segments, cuts at the
    row's ends and rows with none."""
    rng = np.random.default_rng(seed)
    h, w = 7, 97
    values = rng.random((h, w), dtype=np.float32) * np.float32(3.0)
    cuts = rng.random((h, w)) < np.array([0.02, 0.1, 0.0, 0.3, 0.05, 1.0, 0.01])[:, None]
    s0, s1 = color._segment_bounds(cuts)
    for width in (1, 4, 9, 41, 200):
        got = color._bounded_mean(values, s0, s1, width_px=width, square=square)
        want = ref.bounded_mean(values, s0, s1, width_px=width, square=square)
        assert got.dtype == np.float64 and np.array_equal(got, want), width


def robust_inputs(seed=0, h=40, w=300):
    """A fringe with code stripes on printed tiles of three albedos, a shadow, a saturated
    patch, a channel that has no range over part of the image, noise and negative values (an
    unmixed capture has them)."""
    rng = np.random.default_rng(seed)
    x = np.arange(w)
    fringe = 0.5 + 0.5 * np.cos(2 * np.pi * x / T_CAM)
    code = (np.floor(x / T_CAM) % 3 == 0).astype(float)
    albedo = np.where((x // 70) % 3 == 0, 0.9, np.where((x // 70) % 3 == 1, 0.3, 0.05))
    img = np.empty((h, w, 3))
    img[..., 0] = code * fringe * albedo
    img[..., 1] = (1 - code) * fringe * albedo
    img[..., 2] = fringe * albedo
    img += rng.normal(0, 0.01, img.shape)
    img[:, 200:230] = rng.normal(0, 0.002, (h, 30, 3))  # shadow
    img[5:9, 100:130] = 1.0  # clipped
    img[20:, :, 1] = 0.3  # no range in one channel
    return img.astype(np.float32)


@pytest.mark.parametrize("w", [300, 60, 7, 1])
@pytest.mark.parametrize("half", [45, 3, 2, 1, 0])
def test_channel_normalisation_matches_opencv(w, half):
    """The colour-robust decoder's normalisation (running extrema by van Herk / Gil-Werman, box
    means in double running sums): the bits of cv2.erode / cv2.dilate + cv2.blur and numpy, also
    where the row is shorter than the window."""
    from simbench.decode import _kernels

    rgb = np.ascontiguousarray(robust_inputs(w=max(w, 300))[:, :w])
    for min_span in (0.01, 0.0):
        plain = None
        for clamp in (False, True):
            out = np.empty_like(rgb)
            span = np.empty_like(rgb)
            _kernels.normalize_channels(rgb, half, min_span, out, span, None, clamp)
            want_out, want_span = ref.normalize_channels(rgb, half=half, min_span=min_span, clamp_ends=clamp)
            same(out, want_out)
            same(span, want_span)
            if clamp:
                moved = not np.array_equal(out, plain, equal_nan=True)
                assert moved == (w > 4 * half > 0), (w, half)  # the ends moved where a whole mean fits
            plain = out
    got = color.normalize_channels(rgb, period_px=T_CAM, order=3, min_span=0.01, return_span=True)
    want = ref.normalize_channels(rgb, half=color._code_window_px(T_CAM, 3), min_span=0.01)
    same(got[0], want[0])
    same(got[1], want[1])
    # with the albedo flattening's gain: the bits of normalising rgb * gain (also with clamp_ends)
    gain = (1.0 + 3.0 * np.random.default_rng(w).random(rgb.shape[:2])).astype(np.float32)
    for clamp in (False, True):
        got = color.normalize_channels(
            rgb, period_px=T_CAM, order=3, min_span=0.01, return_span=True, gain=gain, clamp_ends=clamp
        )
        want = ref.normalize_channels(
            rgb * gain[..., None], half=color._code_window_px(T_CAM, 3), min_span=0.01, clamp_ends=clamp
        )
        same(got[0], want[0])
        same(got[1], want[1])
    with pytest.raises(ValueError, match="gain"):
        color.normalize_channels(rgb, period_px=T_CAM, order=3, min_span=0.01, gain=gain[:, :-1])


@pytest.mark.parametrize("half", [0, 1, 2, 3, 4])
def test_box_means_follow_opencvs_row_sums_where_rounding_shows(half):
    """A huge value beside small ones: a running sum loses the small ones after the huge value
    leaves the window, and OpenCV's float32 box filter adds windows of 3 and 5 afresh at every
    pixel instead (and copies for a window of 1) - the C box means (of the normalisation's
    extrema and of the noise level) do the same, so they keep its bits even there (found by a
    review: before, windows of 1, 3 and 5 differed here; the decoder's are >= 7)."""
    import cv2

    from simbench.decode import _kernels

    rgb = np.ones((2, 12, 3), np.float32)
    rgb[:, 0] = 1e20
    rgb[1, 5] = -3e19
    k = 2 * half + 1
    level = np.empty_like(rgb)
    _kernels.box_level(rgb, half, 0.0, level)
    same(level, np.maximum(cv2.blur(rgb, (k, 1), borderType=cv2.BORDER_REPLICATE), 0.0) + np.float32(0.0))
    for min_span in (0.0, 0.5):
        out, span = np.empty_like(rgb), np.empty_like(rgb)
        _kernels.normalize_channels(rgb, half, min_span, out, span)
        want = ref.normalize_channels(rgb, half=half, min_span=min_span)
        same(out, want[0])
        same(span, want[1])


def test_kernel_wrappers_refuse_empty_images_and_negative_windows():
    from simbench.decode import _kernels

    empty = np.empty((4, 0, 3), np.float32)
    with pytest.raises(ValueError, match="W >= 1"):
        _kernels.normalize_channels(empty, 3, 0.01, empty.copy(), None)
    with pytest.raises(ValueError, match="W >= 1"):
        _kernels.box_level(empty, 3, 0.04, empty.copy())
    with pytest.raises(ValueError, match="half"):
        _kernels.box_level(np.ones((2, 5, 3), np.float32), -2, 0.04, np.empty((2, 5, 3), np.float32))
    with pytest.raises(ValueError, match="W >= 1"):
        _kernels.albedo_edges(np.empty((3, 0), np.float32), 21, 1.35, 1.8, np.empty((3, 0), bool))
    e = np.empty((3, 0), np.float32)
    with pytest.raises(ValueError, match="W >= 1"):
        _kernels.albedo_segments(e, e, np.empty((3, 0), bool), 91, 10, 30.0, e, e, np.empty((3, 0), bool))


def test_albedo_proxy_and_noise_weights_match_numpy():
    """The albedo flattening's proxy, the overlay's noise weights, the weighted fringe and the
    normalised code: the bits of the numpy forms they replaced, with channels below the share,
    zero, tiny and absent ranges."""
    from simbench.decode import _kernels

    rgb = robust_inputs(seed=1)
    normed, span = color.normalize_channels(rgb, period_px=T_CAM, order=3, min_span=0.01, return_span=True)
    k = np.ascontiguousarray(span * np.float32(0.7))
    k[3:6, :, 0] = 1e-30  # tiny: 1 / k**2 overflows
    k[6:8, :, 2] = 0.0
    k[10:12] = 0.0  # no channel: undefined
    h, w = k.shape[:2]
    proxy, defined = np.empty((h, w), np.float32), np.empty((h, w), bool)
    _kernels.albedo_proxy(rgb, k, 0.1, proxy, defined)
    want_proxy, want_defined = ref.albedo_proxy(rgb, k, share=0.1)
    same(proxy, want_proxy)
    same(defined, want_defined)
    assert defined.any() and not defined.all()
    unmixing = np.linalg.inv(np.array([[1.0, 0.2, 0.05], [0.15, 1.0, 0.1], [0.02, 0.1, 1.0]]))
    for u in (None, unmixing):
        w_code, w_fringe = color.overlay_weights(rgb, span, unmixing=u, period_px=T_CAM, order=3, floor=0.04)
        want = ref.overlay_weights(rgb, span, unmixing=u, half=color._code_window_px(T_CAM, 3), floor=0.04)
        same(w_code, want[0])
        same(w_fringe, want[1])
        assert (w_code == 0).any() and (w_code > 0).any()
        same(
            phase.overlay_intensity(normed, mode="weighted", weights=(w_code, w_fringe)),
            ref.weighted_intensity(normed, w_code, w_fringe),
        )
    same(color.normalized_color_code(normed, span), ref.normalized_color_code(normed, span))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_albedo_edges_match_numpy_and_rank_as_the_logarithm_did(seed):
    """Albedo steps: the C loop's cuts are the numpy form's (the step ratio in double, its
    window maximum), and on these rows the same as the float32 logarithm of the ratio decided
    before (a logarithm ranks alike; only last-bit ties could differ)."""
    rng = np.random.default_rng(seed)
    h, w = 12, 400
    x = np.arange(w)
    albedo = np.where((x // rng.integers(30, 90)) % 2 == 0, 0.8, rng.uniform(0.05, 0.6))
    g = (albedo * (0.5 + 0.5 * np.cos(2 * np.pi * x / T_CAM)) + rng.normal(0, 0.01, (h, w))).astype(np.float32)
    g[4, 150:] *= 1.5  # one step of exactly the threshold region's size
    t = int(round(T_CAM))
    got = color.albedo_edges(g, period_px=T_CAM)
    # albedo_edges averages five rows first
    import cv2

    rows = cv2.blur(g, (1, color.ALBEDO_EDGE_ROWS), borderType=cv2.BORDER_REPLICATE)
    same(got, ref.albedo_edges(rows, t=t, ratio_min=color.ALBEDO_EDGE_RATIO, strip_min=color.ALBEDO_STRIP_RATIO))
    same(
        got,
        ref.albedo_edges(
            rows, t=t, ratio_min=color.ALBEDO_EDGE_RATIO, strip_min=color.ALBEDO_STRIP_RATIO, log_score=True
        ),
    )
    assert got.any()
    # black with noise: the floor keeps it free of steps
    assert not color.albedo_edges(
        np.abs(g - g) + rng.normal(0, 1e-4, g.shape).astype(np.float32), period_px=T_CAM
    ).any()
    assert not got[:, : 2 * t - 1].any() and not got[:, w - 2 * t :].any()


@pytest.mark.parametrize("seed", [0, 1])
def test_albedo_segments_match_numpy(seed):
    """The flattening's per-segment measures in one pass: the bits of segment_mean (as float32),
    the visibility (tests/numpy_reference.py) and the segments' lengths, for segments shorter and longer than the
    window and its margins, and rows with no step."""
    from simbench.decode import _kernels

    rng = np.random.default_rng(seed)
    h, w = 9, 301
    proxy = (rng.random((h, w)) * 2).astype(np.float32)
    proxy[:5] = 0.0  # rows 0-2 average to 0 over five rows: no visibility
    rows = color._rows_mean(proxy)
    cuts = rng.random((h, w)) < np.array([0.02, 0.1, 0.05, 0.0, 0.3, 0.01, 1.0, 0.03, 0.005])[:, None]
    width, period = 91, T_CAM
    mean, vis, short = np.empty((h, w), np.float32), np.empty((h, w), np.float32), np.empty((h, w), bool)
    margin = color._visibility_margin_px(period)
    _kernels.albedo_segments(proxy, rows, cuts, width, margin, 1.5 * period, mean, vis, short)
    s0, s1 = color._segment_bounds(cuts)
    same(mean, color._bounded_mean(proxy, s0, s1, width_px=width).astype(np.float32))
    same(vis, ref.segment_visibility(proxy, s0, s1, period_px=period, width_px=width))
    same(short, (s1 - s0) < 1.5 * period)
    assert short.any() and not short.all() and (vis > 0).any() and (vis[:3] == 0).all()


@pytest.mark.parametrize("m", [4, 42])
def test_fringe_check_side_means_match_numpy(m):
    """The fringe check's side means of each step (fringe_confirmed): the bits of the per-channel
    prefix sums in numpy, for steps at the rows' ends (padding replicated), rows with one step and
    with many, negative values (an unmixed capture's) and one-row images; the three channels'
    rows averaged in one call are each channel's alone."""
    import cv2

    from simbench.decode import _kernels

    rng = np.random.default_rng(m)
    for h, w in [(40, 300), (7, 90), (1, 50)]:
        rgb = (rng.random((h, w, 3)) * rng.random((1, w, 1)) - 0.05).astype(np.float32)
        cuts = rng.random((h, w)) < 0.05
        cuts[0, [0, w - 1]] = True
        ys, xs = np.nonzero(cuts)
        got = np.empty((ys.size, 6))
        rows = color._rows_mean(rgb)
        for c in range(3):
            one = cv2.blur(
                np.ascontiguousarray(rgb[..., c]), (1, color.ALBEDO_EDGE_ROWS), borderType=cv2.BORDER_REPLICATE
            )
            same(rows[..., c], one)
        _kernels.side_means(rows, ys, xs, m, got)
        same(got, ref.side_means(rgb, ys, xs, m=m, rows_mean=color._rows_mean))
    with pytest.raises(ValueError, match="ascending"):
        _kernels.side_means(rows, np.array([1, 0]), np.array([0, 0]), m, np.empty((2, 6)))


def test_group_median_is_the_element_lexsort_puts_there():
    """The copy test's per-run median by selection: the very element np.lexsort((values, runs))
    puts at each run's lower median - with NaN (last), infinities, ties, -0.0 beside 0.0 (index
    order), empty runs (NaN) and runs of one value."""
    from simbench.decode import _kernels

    def by_sort(qa, ru, m):
        n = np.bincount(ru, minlength=m)
        order = np.lexsort((qa, ru))
        first = np.concatenate([[0], np.cumsum(n)[:-1]]).astype(np.int64)
        k = np.full(m, np.nan)
        has = n > 0
        k[has] = qa[order][first[has] + (n[has] - 1) // 2]
        return k

    rng = np.random.default_rng(0)
    for trial in range(300):
        n, m = int(rng.integers(0, 80)), int(rng.integers(1, 9))
        ru = np.sort(rng.integers(0, m, n))
        qa = rng.choice([0.0, -0.0, 1.0, np.nan, np.inf, -np.inf, -1.0, 2.5], n) if trial % 2 else rng.random(n)
        got = np.empty(m)
        _kernels.group_median(qa, ru, m, got)
        assert got.tobytes() == by_sort(qa, ru, m).tobytes(), trial
    with pytest.raises(ValueError, match="non-decreasing"):
        _kernels.group_median(np.zeros(2), np.array([1, 0]), 2, np.empty(2))


def test_column_walks_match_numpy():
    """The column flattening's segment walks (one start at a time in C): the results of the numpy
    form that stepped every start a row at a time, both ways, with starts outside the image,
    steps at the first boundary, frame-marked boundaries and reaches longer than the image."""
    from simbench.decode import _kernels

    rng = np.random.default_rng(3)
    for _ in range(400):
        h, w = int(rng.integers(1, 30)), int(rng.integers(1, 6))
        stop = rng.random((h + 1, w)) < rng.random() * 0.4
        edge = stop & (rng.random((h + 1, w)) < 0.6)
        frame = rng.random(h + 1) < 0.3
        n = int(rng.integers(0, 20))
        y0, x0 = rng.integers(-2, h + 2, n), rng.integers(0, w, n)
        sign, longest = int(rng.choice([1, -1])), int(rng.integers(1, 40))
        got = _kernels.column_segments(y0, x0, sign, stop, edge, frame, longest)
        want = ref.column_segments(y0, x0, sign, stop=stop, edge=edge, frame=frame, longest=longest)
        same(got[0], want[0])
        same(got[1], want[1])


def test_segment_gains_match_maximum_at():
    """The column gain's segments raised in place: np.maximum.at over their rows' index arrays,
    overlapping segments, zero lengths, both ways, and NaN on either side kept."""
    from simbench.decode import _kernels

    rng = np.random.default_rng(5)
    h, w = 40, 30
    for sign in (1, -1):
        gain = rng.uniform(0.5, 2.0, (h, w)).astype(np.float32)
        gain[3, 4] = np.nan
        n = 200
        lengths = rng.integers(0, 12, n)
        y0 = rng.integers(12, h - 12, n)
        x0 = rng.integers(0, w, n)
        g = rng.uniform(0.5, 3.0, n).astype(np.float32)
        g[:3] = np.nan
        g[3:6] = gain[y0[3:6], x0[3:6]]  # ties
        want = gain.copy()
        rows = np.concatenate([y0[i] + sign * np.arange(lengths[i]) for i in range(n)])
        cols = np.repeat(x0, lengths)
        np.maximum.at(want, (rows, cols), np.repeat(g, lengths))
        _kernels.segments_max(gain, y0, x0, lengths, g, sign)
        same(gain, want)
    with pytest.raises(ValueError, match="inside"):
        _kernels.segments_max(gain, np.array([h - 1]), np.array([0]), np.array([3]), np.ones(1, np.float32), 1)


def test_column_side_means_match_numpys_mean():
    """Each channel's mean over the rows above and below a boundary: the bits of numpy's
    ``mean(axis=1, dtype=np.float64)`` of the gathered rows, on values spanning six decades."""
    from simbench.decode import _kernels

    rng = np.random.default_rng(1)
    h, w, k = 60, 200, color.COLUMN_EDGE_ROWS
    src = (rng.random((h, w, 3)) ** 3 * rng.choice([1e-3, 1.0, 1e3], (h, w, 3))).astype(np.float32)
    src[10 : 10 + 2 * k + 2, :5] = -0.0  # k values of -0.0: numpy's mean is +0.0
    yb, xs = rng.integers(k, h - k - 1, 500), rng.integers(0, w, 500)
    yb[:5], xs[:5] = k + 10, np.arange(5)
    up, dn = _kernels.column_side_means(src, yb, xs, k)
    rows_up = yb[:, None] - np.arange(1, k + 1)[None, :]
    rows_dn = yb[:, None] + 1 + np.arange(1, k + 1)[None, :]
    for c in range(3):
        same(up[:, c], src[rows_up, xs[:, None], c].mean(axis=1, dtype=np.float64))
        same(dn[:, c], src[rows_dn, xs[:, None], c].mean(axis=1, dtype=np.float64))
    with pytest.raises(ValueError, match="inside"):
        _kernels.column_side_means(src, np.array([h - 2]), np.array([0]), k)
    with pytest.raises(ValueError, match="inside"):  # (an int64 wrap let this through)
        _kernels.column_side_means(src, np.array([2**63 - 2]), np.array([0]), k)


@pytest.mark.parametrize("seed", [0, 1])
def test_centroid_correction_matches_numpy(seed):
    """The window-centroid correction's rate sums and per-pixel bias in C: the bits of the numpy
    form, on a noisy fringe whose rate changes mid-image, with scattered holes (the skipped step
    pixels of a printed chart: windows cut everywhere), a shadow, NaN phases, two fits and a
    carrier bank's kept pixels; and all certain (the image's ends alone cut windows)."""
    from simbench.decode.phase import centroid_corrected, gabor_phase

    rng = np.random.default_rng(seed)
    h, w, period = 70, 330, 21.8
    x = np.arange(w)
    psi = 2 * np.pi * x / period * np.where(x < w // 2, 0.85, 1.15)
    img = (0.5 + 0.4 * np.cos(psi) + rng.normal(0, 0.02, (h, w))).astype(np.float32)
    cert = np.ones((h, w), np.float32)
    cert[rng.random((h, w)) < 0.03] = 0.0
    cert[20:40, 100:130] = 0.0
    sx, sy = 0.5 * period, 0.3 * period
    kw = dict(certainty=cert, period_px=period, sigma_y_px=sy, offset=False)
    wide = gabor_phase(img, sigma_x_px=sx, **kw).wrapped
    narrow = gabor_phase(img, sigma_x_px=sx / 2, **kw).wrapped
    narrow[rng.random((h, w)) < 0.01] = np.nan
    keep = rng.random((h, w)) < 0.05
    for fits, kept in (([(wide, sx), (narrow, sx / 2)], None), ([(wide, sx)], keep)):
        got = centroid_corrected(fits, cert, sigma_y_px=sy, period_px=period, keep=kept)
        want = ref.centroid_corrected(fits, cert, sigma_y_px=sy, period_px=period, keep=kept)
        for g, f, (psi_in, _) in zip(got, want, fits):
            assert g.tobytes() == f.tobytes()
            assert (g != psi_in).any()  # (something was corrected)
    # the wrapper refuses what would read or write outside the arrays (a review: a negative reach
    # segfaulted; an int64 y0 near 2**63 wrapped past the bounds check)
    from simbench.decode import _kernels

    need, dx = np.ones((1, 4), bool), np.ones((1, 4), np.float32)
    sums = np.zeros((1, 5), np.int64)
    psi_small = np.zeros((2, 8), np.float32)
    for reach, y0 in ((-(10**15), 0), (3, np.int64(2**63 - 1))):
        with pytest.raises(ValueError):
            _kernels.centroid_apply(
                need, dx, np.zeros(1), sums, sums, reach, 0.3, 2.0**20, y0, 0, psi_small, psi_small.copy()
            )
    # all certain: only the windows the image's left and right ends cut
    whole = np.ones((h, w), np.float32)
    got = centroid_corrected([(wide, sx)], whole, sigma_y_px=sy, period_px=period)[0]
    same(got, ref.centroid_corrected([(wide, sx)], whole, sigma_y_px=sy, period_px=period)[0])
    assert (got[:, w // 4 : -w // 4] == wide[:, w // 4 : -w // 4]).all()


def test_fold_apexes_match_the_whole_image_form():
    """crease_apex_bias judges folds on the columns within reach of an apex only: the bits of the
    whole-image form, with folds by the image's sides, runs of apex columns closer and farther
    than the lobe's reach, an S-shaped print bend, holes in the map and rows without a fold."""
    from simbench.decode.depth import crease_apex_bias, crease_bias

    rng = np.random.default_rng(2)
    h, w, reach = 90, 420, 22
    maps = np.empty((h, w), np.float32)
    for y in range(h):
        # the slope drops at each fold (concave); every seventh row has none
        folds = [] if y % 7 == 0 else [(12 + y % 5, 0.3), (150, 0.25), (150 + 4 * reach + 3 + y % 3, 0.2), (400, 0.3)]
        slope = np.ones(w)
        for x0, k in folds:
            slope[x0:] -= k
        if y % 11 == 3:  # a print's S: the slope drops, then rises back as much
            slope[270:] -= 0.25
            slope[300:] += 0.25
        maps[y] = np.concatenate([[0.0], np.cumsum(slope[:-1])]) + rng.normal(0, 0.001, w)
    maps[rng.random((h, w)) < 0.0005] = np.nan
    kw = dict(scale_px=reach, depth_sign=1.0)
    bias = crease_bias(maps, bias_ratio=0.3, max_step_px=3.0, rows_reach=reach, **kw)
    for min_px in (0.0, 0.15):
        args = dict(peak_px=10, apex_px=8, apex_factor=0.55 / 0.3, lobe_share=0.3, min_px=min_px, **kw)
        got = crease_apex_bias(bias, maps, **args)
        want = ref.crease_apex_bias(bias, maps, **args)
        same(got, want)
        assert (got > bias).any()
    # a raise reaching farther than the lobe (apex_px > 2 L): runs of apexes 4 L + 2 .. 2 apex_px
    # apart are raised together (a review: each overwrote the other's raise)
    line = np.tile(np.arange(40, dtype=np.float32), (3, 1))
    apexes = np.zeros((3, 40), np.float32)
    apexes[:, 10], apexes[:, 17] = 2.0, 1.0
    args = dict(scale_px=1, depth_sign=1.0, peak_px=1, apex_px=5, apex_factor=1.5, lobe_share=0.3)
    same(crease_apex_bias(apexes, line, **args), ref.crease_apex_bias(apexes, line, **args))
    with pytest.raises(ValueError, match="scale_px must be >= 1"):
        crease_apex_bias(apexes, line, **{**args, "scale_px": 0})


def test_crease_bias_matches_numpy():
    """The crease term's C loops: the bits of its numpy form on a noisy map with concave and convex
    breaks, depth steps, holes and rows too short for the reach, for both signs and row reaches
    from none to more than the map's height."""
    rng = np.random.default_rng(3)
    x = np.arange(300, dtype=np.float32)
    col = np.tile(np.where(x < 150, x, 150 + 0.8 * (x - 150)), (12, 1)).astype(np.float32)
    col += rng.normal(0.0, 0.05, col.shape).astype(np.float32)
    col[2, 200:] += 10.0  # a depth edge
    col[3, 120:125] = np.nan  # a hole
    col[4] = np.where(x < 150, x, 150 + 1.2 * (x - 150))  # convex for factor > 0
    trusted = rng.random(col.shape) < 0.995  # a few distrusted pixels break their windows
    for factor in (0.3, -0.3):
        for reach in (1, 22, 149, 150):
            for rows in (0, 1, 4, 20):
                for t in (None, trusted):
                    got = np.empty_like(col)
                    depth._kernels.crease_bias(col, reach, factor, 3.0, rows, got, trusted=t)
                    want = ref.crease_bias(col, reach=reach, factor=factor, max_step=3.0, rows_reach=rows, trusted=t)
                    same(got, want)
    got = np.empty_like(col)
    depth._kernels.crease_bias(col, 22, 0.3, 3.0, 2, got)
    assert (got > 0).any() and (got == 0).any()
    # the confidence cap in the same call: fmin(conf, kappa / bias) where valid
    conf = rng.uniform(0.0, 40.0, col.shape).astype(np.float32)
    valid = rng.random(col.shape) < 0.8
    want = conf.copy()
    with np.errstate(divide="ignore"):
        np.fmin(want, np.float32(1.34) / got, out=want, where=valid)
    depth._kernels.crease_bias(col, 22, 0.3, 3.0, 2, np.empty_like(col), cap=(np.float32(1.34), valid, conf))
    same(conf, want)


def test_edge_bend_matches_numpy():
    """The edge term's C loops: the bits of its numpy form on a noisy map with depth steps, holes,
    runs shorter than the reach and fit, a run at the row's end and a single-pixel run, for reaches
    and fits from none to more than a row."""
    rng = np.random.default_rng(5)
    x = np.arange(300, dtype=np.float32)
    col = np.tile(0.9 * x + 40.0, (10, 1)).astype(np.float32)
    col += rng.normal(0.0, 0.05, col.shape).astype(np.float32)
    col[1, 180:] += 12.0  # a depth edge without a hole
    col[2, 100:111] = np.nan  # a hole
    col[3, :] = np.nan
    col[3, 150] = 7.0  # a lone decoded pixel
    col[4, 40:] = np.nan  # a run at the row's start, a hole after it
    col[5, 20:25] = np.nan
    col[5, 60:65] = np.nan  # a 35-px run between holes
    col[6, 120:] += np.linspace(0.0, 3.0, 180, dtype=np.float32) ** 2  # a bend, no edge
    col[7, 95:100] -= np.array([0.2, 0.4, 0.8, 1.2, 2.0], np.float32)  # bent towards a hole
    col[7, 100:110] = np.nan
    for reach in (0, 1, 5, 11, 150, 400, 2**62):
        for fit in (0, 1, 2, 22, 300, 2**62):
            got = np.empty_like(col)
            depth._kernels.edge_bend(col, reach, fit, 3.0, got)
            same(got, ref.edge_bend(col, reach=reach, fit=fit, max_step=3.0))
    got = np.empty_like(col)
    depth._kernels.edge_bend(col, 11, 22, 3.0, got)
    assert (got[7, 89:100] > 0).all() and got[7, 99] > 1.5 and (got[7, :89] == 0).all()
    # down the columns: the numpy form of the map turned a quarter, the larger of the two passes
    turned = np.ascontiguousarray(np.vstack([col, col[::-1] + 2.0]).T)  # (300, 20): runs down 300 rows
    for reach, fit, reach_y, fit_y in (
        (0, 0, 11, 22),
        (3, 5, 11, 22),
        (11, 22, 1, 2),
        (11, 22, 0, 22),
        (2, 4, 400, 2**62),
    ):
        both = np.empty_like(turned)
        depth._kernels.edge_bend(turned, reach, fit, 3.0, both, reach_y=reach_y, fit_y=fit_y)
        rows = ref.edge_bend(turned, reach=reach, fit=fit, max_step=3.0)
        cols = ref.edge_bend(np.ascontiguousarray(turned.T), reach=reach_y, fit=fit_y, max_step=3.0).T
        same(both, np.maximum(rows, cols))
    with pytest.raises(ValueError, match="must be >= 0"):
        depth._kernels.edge_bend(col, 11, 22, 3.0, np.empty_like(col), reach_y=-1, fit_y=2)
    # the confidence cap in the same call: fmin(conf, kappa / bias) where valid
    conf = rng.uniform(0.0, 40.0, col.shape).astype(np.float32)
    valid = rng.random(col.shape) < 0.8
    want = conf.copy()
    with np.errstate(divide="ignore"):
        np.fmin(want, np.float32(1.34) / got, out=want, where=valid)
    depth._kernels.edge_bend(col, 11, 22, 3.0, np.empty_like(col), cap=(np.float32(1.34), valid, conf))
    same(conf, want)
    # ... after both passes: the cap reads their larger bend
    conf = rng.uniform(0.0, 40.0, turned.shape).astype(np.float32)
    valid = rng.random(turned.shape) < 0.8
    depth._kernels.edge_bend(turned, 3, 5, 3.0, both, reach_y=11, fit_y=22)
    want = conf.copy()
    with np.errstate(divide="ignore"):
        np.fmin(want, np.float32(1.34) / both, out=want, where=valid)
    depth._kernels.edge_bend(
        turned, 3, 5, 3.0, np.empty_like(turned), reach_y=11, fit_y=22, cap=(np.float32(1.34), valid, conf)
    )
    same(conf, want)


def test_a_library_older_than_its_sources_is_named_stale(tmp_path):
    """A C loop whose signature changed (vote_codes gained an output) would read the new call's
    arguments from the old signature's places: loading a library built before its sources were
    last changed is refused, naming them (and `make setup`)."""
    import os

    from simbench import native

    built = tmp_path / "_ckernels.so"
    built.write_bytes(b"")
    src = [tmp_path / "_ckernels.c", tmp_path / "_lens.c"]
    for s in src:
        s.write_text("/* */")
    t = built.stat().st_mtime
    os.utime(src[0], (t - 10, t - 10))
    os.utime(src[1], (t + 10, t + 10))
    assert native.stale_sources(built, tuple(src)) == ["_lens.c"]
    assert native.stale_sources(built, (tmp_path / "missing.c", src[0])) == []  # not shipped: not judged
    assert native.stale_sources(__import__("pathlib").Path(native._built_file())) == []  # this build: current
