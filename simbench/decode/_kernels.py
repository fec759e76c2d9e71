"""The decoder's fused per-pixel loops: C functions (``simbench/_ckernels.c``) behind checked
wrappers (loaded and checked by :mod:`simbench.native`).

Each kernel replaces a chain of whole-image numpy passes by one loop over the pixels, so an
image-sized intermediate is never written to memory, and evaluates the same IEEE float
operations in the same order as the numpy expression it replaces (the docstrings give it), so
results are bit-identical to it; ``tests/test_kernels.py`` compares every kernel with its numpy
form (``tests/numpy_reference.py``).  The one exception is the Gabor fit (:func:`gabor_band`),
which sums in another order: equal to float32 rounding.
"""

from __future__ import annotations

import threading
from functools import lru_cache

import numpy as np

from simbench import native

__all__ = [
    "gabor_band",
    "gather",
    "absolute_column",
    "match_reference",
    "depth_from_disparity",
    "chain_extent",
    "window_positions",
    "drop_broken_links",
    "neighbour_correct",
    "contested_positions",
    "segment_stripes",
    "vote_codes",
    "front_end",
    "validity",
    "pool_code_rows",
    "decode_tail",
    "bounded_mean",
    "normalize_channels",
    "albedo_proxy",
    "albedo_edges",
    "box_level",
    "noise_weights",
    "robust_fringe_code",
    "albedo_segments",
    "side_means",
    "group_median",
    "column_segments",
    "column_side_means",
    "segments_max",
    "centroid_rate_sums",
    "centroid_apply",
    "crease_bias",
    "edge_bend",
]

_P, _I, _F, _D = native.P, native.I64, native.F32, native.F64
_SIGNATURES = {
    "gabor_band": (
        None,
        [_I, _I, _P, _P, _I, _I, _I, _P, _P, _P, _P, _P, _I, _P, _P, _P, _P, _P, _P, _I, _F, _P] + [_P] * 5,
    ),
    "gabor_scratch_floats": (_I, [_I, _I, _I]),
    "front_end_scratch_floats": (_I, [_I, _I]),
    "gabor_table_planes": (_I, []),
    "gather": (None, [_I, _I, _P, _P, _P, _P]),
    "absolute_column": (None, [_I, _P, _P, _P, _F, _F, _I, _P, _P]),
    "match_reference": (None, [_I, _I, _I, _P, _P, _P]),
    "depth_from_disparity": (None, [_I, _I, _P, _F, _F, _P]),
    "chain_extent": (None, [_I, _P, _P, _P]),
    "bounded_mean": (None, [_I, _I, _P, _P, _P, _I, _I, _P, _P]),
    "normalize_scratch_floats": (_I, [_I, _I]),
    "normalize_channels": (None, [_I, _I, _P, _P, _I, _F, _I, _P, _P, _P]),
    "albedo_proxy": (None, [_I, _P, _P, _F, _P, _P]),
    "albedo_edges": (None, [_I, _I, _P, _I, _D, _D, _P, _P, _P, _P]),
    "box_level": (None, [_I, _I, _P, _I, _F, _P]),
    "noise_weights": (None, [_I, _P, _P, _P, _P]),
    "robust_fringe_code": (None, [_I, _P, _P, _P, _P, _P, _P]),
    "albedo_segments": (None, [_I, _I, _P, _P, _P, _I, _I, _D, _P, _P, _P, _P]),
    "side_means": (None, [_I, _I, _P, _I, _P, _P, _I, _P, _P]),
    "group_median": (None, [_I, _P, _P, _I, _P, _P]),
    "column_side_means": (None, [_I, _I, _P, _P, _P, _I, _P, _P]),
    "segments_max": (None, [_I, _I, _P, _P, _P, _P, _I, _P]),
    "centroid_rate_sums": (None, [_I, _I, _P, _P, _F, _P, _P]),
    "centroid_apply": (None, [_I, _I, _I, _P, _P, _P, _P, _P, _I, _F, _D, _I, _I, _P, _P]),
    "column_segments": (None, [_I, _P, _P, _I, _I, _I, _P, _P, _P, _I, _P, _P]),
    "window_positions": (None, [_I, _P, _P, _P, _I, _P, _I, _P]),
    "drop_broken_links": (None, [_I, _P, _P, _I, _P]),
    "neighbour_correct": (None, [_I, _P, _P, _P, _I, _I, _I, _P, _P, _P]),
    "contested_positions": (None, [_I, _P, _P, _P, _P, _I, _I, _I, _P, _P]),
    "segment_stripes": (_I, [_I, _I, _P, _P, _F, _F, _I, _D, _D, _P, _P, _P, _P, _P, _P]),
    "vote_codes": (None, [_I, _I, _P, _P, _P, _P, _P, _I, _P, _P, _P]),
    "front_end": (None, [_I, _I, _P, _I, _I, _I, _I, _I, _I, _F, _F, _P, _P, _P, _P, _P]),
    "validity": (None, [_I, _P, _P, _P, _P, _F, _F, _F, _P]),
    "pool_code_rows": (None, [_I, _I, _I, _I, _P, _P, _P, _I, _F, _P, _P]),
    "crease_bias": (None, [_I, _I, _P, _I, _F, _F, _I, _P, _P, _P, _F, _P, _P, _P, _P, _P]),
    "edge_bend": (None, [_I, _I, _P, _I, _I, _I, _I, _F, _P, _F, _P, _P]),
    "decode_tail": (
        None,
        [_I, _I, _I, _P, _P, _P, _P, _P, _F, _F, _I, _I, _P, _F, _F, _P, _I, _I, _I, _F, _F, _P] + [_P] * 5,
    ),
}
_IMAGE_DTYPES = {np.dtype(np.uint8): 0, np.dtype(np.uint16): 1, np.dtype(np.float32): 2}


@lru_cache(maxsize=1)
def _library():
    return native.bind(_SIGNATURES)


_ptr = native.ptr
_f32 = native.f32


def _check_table(table: np.ndarray, h: int) -> None:
    """The inverse column table of :func:`match_reference`: one row per image row, >= 3 entries."""
    if table.ndim != 2 or table.shape[0] != h or table.shape[1] < 3:
        raise ValueError(f"table: expected shape ({h}, >= 3), got {table.shape}")


_SCRATCH = threading.local()


def _scratch(n: int) -> np.ndarray:
    """A float32 buffer of at least ``n`` values, one per thread, kept between calls: a fresh
    one per call would cost its page faults every time (~20 % of a band's Gabor fit)."""
    buf = getattr(_SCRATCH, "buf", None)
    if buf is None or buf.size < n:
        buf = _SCRATCH.buf = np.empty(n, np.float32)
    return buf


def gabor_band(
    intensity,
    certainty,
    y0,
    y1,
    half_kernels,
    basis,
    table,
    fill_table,
    wrapped,
    amp,
    a0,
    residual,
    support,
    min_weight=0.05,
) -> None:
    """Normalised-convolution Gabor fit (paper Eq. 10-11) of the rows ``y0:y1`` of a band.

    ``intensity``, ``certainty``: (H, W) float32; ``half_kernels``: the centre-and-one-side
    halves of the x window g, of g cos(w k), g sin(w k), g cos(2 w k), g sin(2 w k) (all of one
    length) and of the y window; ``basis``: cos(w x), sin(w x), cos(2 w x), sin(2 w x), each (W,).
    ``table``: None (every window sum computed), or an array (:func:`gabor_table_planes`,
    min(H, 2 ry + 1), W) holding the certainty's sums ``G*c``, ``G*(c cos)``, ``G*(c sin)``,
    ``G*(c cos2)``, ``G*(c sin2)`` of an all-ones band and the normal equations' solution from
    them (rows: the top ``ry`` rows, one interior row, the bottom ``ry`` rows): read for every
    pixel whose window holds only ``c == 1`` (the same bits as computing them), or, with
    ``fill_table``, computed from ``certainty`` (then all ones) and written there.  Outputs
    (y1 - y0, W): the wrapped phase ``atan2(im, re)`` in [-pi, pi) of the fit
    ``I ~ a0 + re cos(w x) + im sin(w x)`` (a polynomial atan2, ~1e-7 rad), the amplitude
    ``sqrt(re^2 + im^2)`` (0 where the normal equations are singular: window weight <=
    ``min_weight`` - the certainty's weighted sum, 0.05 unless asked otherwise - or a near-singular
    determinant), ``a0`` (None: not written, which saves a fifth of the outputs'
    memory traffic), the RMS residual relative to ``amp/sqrt 2`` (inf
    there) and the window's certain weight.

    Window sums are zero outside the image; along x the carrier rides on the window
    (``cos(w (x - k)) = cos wx cos wk + sin wx sin wk``), so one pass over a row gives all of its
    sums; the normal equations are solved by the adjugate (``_solver`` in
    tests/numpy_reference.py, which does the same with OpenCV's separable filter and cv2.phase:
    equal to float32 rounding, tests/test_kernels.py).
    """
    h, w = intensity.shape
    if not 0 <= y0 < y1 <= h:
        raise ValueError(f"rows {y0}:{y1} are not inside the band's {h} rows")
    f4 = np.float32
    kx, kc1, ks1, kc2, ks2, ky = half_kernels
    rx, ry = kx.size - 1, ky.size - 1
    n = y1 - y0
    lib = _library()
    if table is not None:
        shape = (gabor_table_planes(), gabor_table_rows(h, half_kernels), w)
        table = _ptr(table, "table", f4, shape, writable=bool(fill_table))
    scratch = _scratch(lib.gabor_scratch_floats(w, rx, ry))
    lib.gabor_band(
        h,
        w,
        _ptr(intensity, "intensity", f4),
        _ptr(certainty, "certainty", f4, (h, w)),
        int(y0),
        int(y1),
        rx,
        *(
            _ptr(k, name, f4, (rx + 1,))
            for k, name in zip((kx, kc1, ks1, kc2, ks2), ("kx", "kc1", "ks1", "kc2", "ks2"))
        ),
        ry,
        _ptr(ky, "ky", f4),
        *(_ptr(b, name, f4, (w,)) for b, name in zip(basis, ("cos1", "sin1", "cos2", "sin2"))),
        table,
        int(bool(fill_table)),
        _f32(min_weight),
        scratch.ctypes.data,
        *(
            None if a is None and name == "a0" else _ptr(a, name, f4, (n, w), writable=True)
            for a, name in zip((wrapped, amp, a0, residual, support), ("wrapped", "amp", "a0", "residual", "support"))
        ),
    )


def gabor_table_rows(height: int, half_kernels) -> int:
    """Rows of :func:`gabor_band`'s all-certain table for a band of ``height`` rows: an all-ones
    band's certainty sums differ only within ``ry`` rows of its top and bottom, so the top ``ry``
    rows, one interior row and the bottom ``ry`` rows hold them all (``min(H, 2 ry + 1)``)."""
    ry = half_kernels[-1].size - 1
    return min(height, 2 * ry + 1)


def gabor_table_planes() -> int:
    """Planes of :func:`gabor_band`'s all-certain table (5 window sums, the solver's 10 maps)."""
    return _library().gabor_table_planes()


def gather(per_stripe, labels, fill, out) -> None:
    """``out = per_stripe[labels]``, ``fill`` where the label is -1 (``labels`` int32)."""
    dtype = per_stripe.dtype
    n = labels.size
    if out.shape != labels.shape:
        raise ValueError(f"out: expected shape {labels.shape}, got {out.shape}")
    if n and per_stripe.size == 0 and (labels >= 0).any():
        raise ValueError("labels refer to stripes, but per_stripe is empty")
    fill_arr = np.array(fill, dtype=dtype)
    _library().gather(
        n,
        dtype.itemsize,
        _ptr(per_stripe, "per_stripe", dtype),
        _ptr(labels, "labels", np.int32),
        fill_arr.ctypes.data,
        _ptr(out, "out", dtype, writable=True),
    )


def absolute_column(position, wrapped, expected, t, span, cycle, column, index) -> None:
    """Per pixel (float32): ``col0 = (psi + pi) * (t / 2 pi) + W t - 0.5``,
    ``k = rint((expected - col0) / span)``; where ``W >= 0`` and ``k`` is finite:
    ``column = col0 + k span``, ``index = W + L k``; else NaN and -1."""
    shape = position.shape
    _library().absolute_column(
        position.size,
        _ptr(position, "position", np.int32),
        _ptr(wrapped, "wrapped", np.float32, shape),
        _ptr(expected, "expected", np.float32, shape),
        _f32(t),
        _f32(span),
        int(cycle),
        _ptr(column, "column", np.float32, shape, writable=True),
        _ptr(index, "index", np.int32, shape, writable=True),
    )


def match_reference(column, table, out) -> None:
    """Linear look-up of each pixel's column in its row of the inverse table: the table's
    last column is NaN, and a column outside ``[0, width]`` (or NaN) gives NaN."""
    h, w = column.shape
    _check_table(table, h)
    _library().match_reference(
        h,
        w,
        table.shape[1],
        _ptr(column, "column", np.float32),
        _ptr(table, "table", np.float32),
        _ptr(out, "out", np.float32, (h, w), writable=True),
    )


def depth_from_disparity(x_ref, inv_z0, inv_fb, out) -> None:
    """``z = 1 / (1/Z0 + (x - x_ref) / (f B))`` (float32), NaN unless ``z > 0``."""
    h, w = x_ref.shape
    _library().depth_from_disparity(
        h,
        w,
        _ptr(x_ref, "x_ref", np.float32),
        _f32(inv_z0),
        _f32(inv_fb),
        _ptr(out, "out", np.float32, (h, w), writable=True),
    )


def chain_extent(linked_prev, left, right) -> None:
    """Linked stripes before (``left``) and after (``right``) each stripe in its chain."""
    n = linked_prev.size
    _library().chain_extent(
        n,
        _ptr(linked_prev, "linked_prev", np.bool_),
        _ptr(left, "left", np.int64, (n,), writable=True),
        _ptr(right, "right", np.int64, (n,), writable=True),
    )


def bounded_mean(values, s0, s1, width, square, out) -> None:
    """Mean of ``width`` values (or of their squares) along each row, the window kept within
    each pixel's ``[s0, s1)``; ``values`` float32 (H, W), ``s0``/``s1`` int64 (H, W), ``out``
    float64 (H, W)."""
    h, w = values.shape
    width = int(width)
    if width < 1:
        raise ValueError(f"width must be >= 1, got {width}")
    scratch = np.empty(w + 1, np.float64)  # held here: the loop writes through its address
    _library().bounded_mean(
        h,
        w,
        _ptr(values, "values", np.float32, (h, w)),
        _ptr(s0, "s0", np.int64, (h, w)),
        _ptr(s1, "s1", np.int64, (h, w)),
        width,
        int(bool(square)),
        _ptr(scratch, "scratch", np.float64, (w + 1,), writable=True),
        _ptr(out, "out", np.float64, (h, w), writable=True),
    )


def _cycle(cycle) -> int:
    """The De Bruijn cycle length, checked: the kernels take positions modulo it."""
    cycle = int(cycle)
    if cycle < 1:
        raise ValueError(f"cycle must be >= 1, got {cycle}")
    return cycle


def window_positions(code, left, right, order, table, cycle, out) -> None:
    """W of each stripe from its window of ``order`` binary codes (``code`` uint8 0/1, read as
    a binary number into ``table`` of 2**order int32 entries), -1 where the window leaves the
    stripe's chain (``left``, ``right``: :func:`chain_extent`) or ``table`` holds -1."""
    n = code.size
    order, cycle = int(order), _cycle(cycle)
    if order < 1 or table.size != 1 << order:
        raise ValueError(f"table: expected 2**order = {1 << max(order, 0)} entries for order {order}, got {table.size}")
    if n and int(code.max()) > 1:
        raise ValueError("stripe codes must be 0 or 1")
    _library().window_positions(
        n,
        _ptr(code, "code", np.uint8),
        _ptr(left, "left", np.int64, (n,)),
        _ptr(right, "right", np.int64, (n,)),
        order,
        _ptr(table, "table", np.int32),
        cycle,
        _ptr(out, "out", np.int32, (n,), writable=True),
    )


def drop_broken_links(positions, linked_prev, cycle, out) -> None:
    """``out`` = ``positions`` with both stripes of every link whose positions do not follow
    each other (``W[j] != W[j-1] + 1 mod cycle``, both known) at -1."""
    n = positions.size
    _library().drop_broken_links(
        n,
        _ptr(positions, "positions", np.int32),
        _ptr(linked_prev, "linked_prev", np.bool_, (n,)),
        _cycle(cycle),
        _ptr(out, "out", np.int32, (n,), writable=True),
    )


def neighbour_correct(positions, left, right, cycle, reach, min_support, out, support) -> None:
    """Plurality of the positions predicted by the stripe and its linked neighbours within
    ``reach`` (``W[j + o] - o mod L``); kept when it has ``min_support`` votes and beats every
    other candidate, else -1 (``support`` = its votes, 0 if dropped)."""
    n = positions.size
    cycle = _cycle(cycle)
    counts = np.empty(cycle, np.int64)
    _library().neighbour_correct(
        n,
        _ptr(positions, "positions", np.int32),
        _ptr(left, "left", np.int64, (n,)),
        _ptr(right, "right", np.int64, (n,)),
        cycle,
        int(reach),
        int(min_support),
        counts.ctypes.data,
        _ptr(out, "out", np.int32, (n,), writable=True),
        _ptr(support, "support", np.int32, (n,), writable=True),
    )


def contested_positions(positions, kept, left, right, cycle, reach, min_support, out) -> None:
    """``out`` (bool) where a kept stripe's position (``kept`` >= 0) has a rival that the
    linked stripes within ``reach`` predict (``positions[j + o] - o mod L``) on both sides, at
    least once on each and ``min_support`` times in all."""
    n = positions.size
    cycle = _cycle(cycle)
    counts = np.empty(2 * cycle, np.int64)
    _library().contested_positions(
        n,
        _ptr(positions, "positions", np.int32),
        _ptr(kept, "kept", np.int32, (n,)),
        _ptr(left, "left", np.int64, (n,)),
        _ptr(right, "right", np.int64, (n,)),
        cycle,
        int(reach),
        int(min_support),
        counts.ctypes.data,
        _ptr(out, "out", np.bool_, (n,), writable=True),
    )


def segment_stripes(wrapped, valid, lo, hi, max_gap, omega, tol, labels, row, start, stop, linked_prev) -> int:
    """Row-wise stripe segmentation; returns the number of stripes.

    Between pixels ``x-1`` and ``x`` of a row: ``d = psi[x] - psi[x-1]``, a wrap where
    ``d < -pi`` (then ``step = d + 2 pi``), a plausible step when ``lo < step < hi`` (``lo``,
    ``hi`` float32); with both pixels valid the stripe continues (plausible, no wrap), or the
    next stripe starts linked to it (plausible wrap); any other valid pixel starts an unlinked
    stripe, unless it ends a gap of 1 to ``max_gap`` invalid pixels after the row's last stripe
    that the bridge crosses: with no wrap the stripe continues after the gap, with one the next
    starts linked.

    The bridge (wraps, 0 or 1, across the gap between pixels ``xl`` and ``x``): the phase slope
    is the mean step of the stripe ending at ``xl`` and of the run continuing from ``x`` (up to
    its first wrap or break; the nominal ``omega`` if both have fewer than 2 steps together), in
    float64; the gap's advance ``slope * (x - xl)`` chooses the wrap count ``k``, accepted when
    the wrapped phase at ``x`` lies within ``tol`` of the prediction.

    ``row``/``start``/``stop``/``linked_prev`` must hold one entry per possible stripe (H*W).
    """
    h, w = wrapped.shape
    n = h * w
    cls = np.empty(max(w, 1), np.uint8)  # a row's step classes
    return int(
        _library().segment_stripes(
            h,
            w,
            _ptr(wrapped, "wrapped", np.float32),
            _ptr(valid, "valid", np.bool_, (h, w)),
            _f32(lo),
            _f32(hi),
            int(max_gap),
            float(omega),
            float(tol),
            _ptr(labels, "labels", np.int32, (h, w), writable=True),
            _ptr(row, "row", np.int32, (n,), writable=True),
            _ptr(start, "start", np.int32, (n,), writable=True),
            _ptr(stop, "stop", np.int32, (n,), writable=True),
            _ptr(linked_prev, "linked_prev", np.bool_, (n,), writable=True),
            cls.ctypes.data,
        )
    )


def vote_codes(code, labels, row, start, stop, voting, out, agreement, votes) -> None:
    """Per stripe: share of its pixels with code 1 (float64; pixels of a gap it was bridged
    across are not its own); the code is the majority (ties give 1) or, without voting, the
    middle pixel's; ``agreement`` = share agreeing with it; ``votes`` = its own pixels."""
    h, w = labels.shape
    n = row.size
    _library().vote_codes(
        n,
        w,
        _ptr(code, "code", np.bool_, (h, w)),
        _ptr(labels, "labels", np.int32),
        _ptr(row, "row", np.int32),
        _ptr(start, "start", np.int32, (n,)),
        _ptr(stop, "stop", np.int32, (n,)),
        int(bool(voting)),
        _ptr(out, "out", np.uint8, (n,), writable=True),
        _ptr(agreement, "agreement", np.float32, (n,), writable=True),
        _ptr(votes, "votes", np.int32, (n,), writable=True),
    )


def front_end(image, order, mode, width, dark_level, saturation_level, intensity, certainty, lit, code) -> None:
    """One pass from a band of the capture (H, W, 3), uint8/uint16/float32, to the decoder's
    first images: ``intensity`` (paper Eq. 9 as ``(0.5 R + 0.5 G) + 0.5 B``, mode 0, or the
    fringe channel alone, mode 1), ``code`` (Eq. 13, ``R >= G``), ``lit`` and ``certainty``
    (:func:`simbench.decode.phase.certainty_map` with a row window of ``width`` pixels), with
    channels read in ``order`` (the indices of code 1, code 0 and the fringe) and converted as
    :func:`simbench.decode.pipeline.as_float_image` does.  The same bits as the numpy/OpenCV
    stages it replaces (tests/test_kernels.py)."""
    h, w, _ = image.shape
    try:
        dtype = _IMAGE_DTYPES[image.dtype]
    except KeyError:
        raise TypeError(f"image: expected uint8, uint16 or float32, got {image.dtype}") from None
    if image.shape[2] != 3 or sorted(order) != [0, 1, 2]:
        raise ValueError(f"image must be (H, W, 3) and order a permutation of 0, 1, 2: {image.shape}, {order}")
    scratch = np.empty(_library().front_end_scratch_floats(w, int(width)), np.float32)  # the row's peak and flags
    _library().front_end(
        h,
        w,
        _ptr(image, "image", image.dtype),
        dtype,
        *(int(c) for c in order),
        int(mode),
        int(width),
        _f32(dark_level),
        _f32(saturation_level),
        _ptr(intensity, "intensity", np.float32, (h, w), writable=True),
        _ptr(certainty, "certainty", np.float32, (h, w), writable=True),
        _ptr(lit, "lit", np.bool_, (h, w), writable=True),
        _ptr(code, "code", np.bool_, (h, w), writable=True),
        scratch.ctypes.data,
    )


def validity(lit, support, amplitude, residual, min_support, min_amplitude, max_residual, valid) -> None:
    """``valid = lit & (support >= min_support) & (amplitude >= min_amplitude) &
    (residual <= max_residual)``, thresholds in float32."""
    shape = lit.shape
    _library().validity(
        lit.size,
        _ptr(lit, "lit", np.bool_),
        _ptr(support, "support", np.float32, shape),
        _ptr(amplitude, "amplitude", np.float32, shape),
        _ptr(residual, "residual", np.float32, shape),
        _f32(min_support),
        _f32(min_amplitude),
        _f32(max_residual),
        _ptr(valid, "valid", np.bool_, shape, writable=True),
    )


def pool_code_rows(code, wrapped, valid, y0, k, tol, out) -> None:
    """:func:`simbench.decode.color.pool_code_rows` into ``out`` (rows ``y0 .. y0 + len(out)``
    of the (H, W) images ``code``, ``wrapped``, ``valid``)."""
    h, w = code.shape
    h_out = out.shape[0]
    scratch = np.empty(w, np.int32)  # a row's sums
    if out.shape != (h_out, w) or not 0 <= y0 <= h - h_out:
        raise ValueError(f"out: rows {y0}..{y0 + h_out} of a ({h}, {w}) image, got shape {out.shape}")
    _library().pool_code_rows(
        h,
        w,
        int(y0),
        h_out,
        _ptr(code, "code", np.bool_),
        _ptr(wrapped, "wrapped", np.float32, (h, w)),
        _ptr(valid, "valid", np.bool_, (h, w)),
        int(k),
        _f32(tol),
        scratch.ctypes.data,
        _ptr(out, "out", np.bool_, writable=True),
    )


def decode_tail(
    labels,
    stripe_position,
    wrapped,
    expected,
    amplitude,
    *,
    t,
    cycle,
    row0,
    table,
    inv_z0,
    inv_fb,
    rig_values,
    distorted,
    newton_steps,
    refine_steps,
    zmin,
    zmax,
    depth_out,
    valid_out,
    conf_out,
    col_out,
    index_out,
) -> None:
    """The decoder's last stages for a band whose first row is image row ``row0``, in one pass:

    1. ``position = stripe_position[labels]`` (-1 without a stripe, :func:`gather`) and the
       projector column and stripe index of :func:`absolute_column` (span ``cycle * t``);
    2. depth: with ``table`` (reference mode), :func:`match_reference` and
       :func:`depth_from_disparity`, and the pixels whose column the table's row does not show
       (x_ref NaN, column finite) triangulated as :func:`simbench.rig.triangulate_columns`
       does (``rig_values``: :func:`simbench.rig.triangulation_values`; ``distorted``,
       ``newton_steps``, ``refine_steps`` as it passes them); with ``table`` None (calibrated
       mode), every pixel triangulated so;
    3. the outputs: ``valid = (depth >= zmin) & (depth <= zmax)`` (float32), and ``depth``, the
       per-pixel confidence given as ``amplitude`` (the decoder passes the fringe SNR), the
       column and the index where valid, NaN / 0 / NaN / -1 elsewhere.

    The same bits as those steps one after the other (tests/test_kernels.py), without their
    image-sized intermediates.
    """
    h, w = labels.shape
    shape = (h, w)
    if table is not None:
        _check_table(table, h)
    values = np.ascontiguousarray(rig_values, np.float64)
    if values.shape != (22,):
        raise ValueError(f"rig_values: expected 22 numbers, got {values.shape}")
    n_stripes = stripe_position.size
    if n_stripes == 0 and (labels >= 0).any():
        raise ValueError("labels refer to stripes, but stripe_position is empty")
    scratch = np.empty(4 * max(w, 1), np.float32)
    _library().decode_tail(
        h,
        w,
        int(row0),
        _ptr(labels, "labels", np.int32),
        _ptr(stripe_position, "stripe_position", np.int32),
        _ptr(wrapped, "wrapped", np.float32, shape),
        _ptr(expected, "expected", np.float32, shape),
        _ptr(amplitude, "amplitude", np.float32, shape),
        _f32(t),
        _f32(int(cycle) * float(t)),
        int(cycle),
        table.shape[1] if table is not None else 0,
        _ptr(table, "table", np.float32) if table is not None else None,
        _f32(inv_z0),
        _f32(inv_fb),
        values.ctypes.data,
        int(bool(distorted)),
        int(newton_steps),
        int(refine_steps),
        _f32(zmin),
        _f32(zmax),
        scratch.ctypes.data,
        _ptr(depth_out, "depth_out", np.float32, shape, writable=True),
        _ptr(valid_out, "valid_out", np.bool_, shape, writable=True),
        _ptr(conf_out, "conf_out", np.float32, shape, writable=True),
        _ptr(col_out, "col_out", np.float32, shape, writable=True),
        _ptr(index_out, "index_out", np.int32, shape, writable=True),
    )


def normalize_channels(rgb, half, min_span, out, span, gain=None, clamp_ends=False) -> None:
    """:func:`simbench.decode.color.normalize_channels` of an (H, W, 3) float32 image in one
    pass: per row and channel the running minimum and maximum over ``2 half + 1`` pixels, each
    box-averaged over as many (cv2.erode / cv2.dilate then cv2.blur, ends replicated, with the
    double running sums of OpenCV's float32 box filter), ``span = max - min``, ``out = (v - min) /
    span`` where ``span >= min_span`` (float32), else 0; ``span`` (or None) gets the span there,
    else 0; ``gain`` ((H, W) float32, or None) multiplies each pixel's channels first.  The same bits
    as the OpenCV/numpy form (tests/numpy_reference.py).  ``clamp_ends`` (where ``W > 4 half``):
    the ``2 half`` pixels at each end of a row take the mean minimum and maximum of pixel
    ``2 half`` (``W - 1 - 2 half``), the first (last) whose mean reads only whole windows."""
    h, w, c = rgb.shape
    if c != 3 or h < 1 or w < 1:
        raise ValueError(f"rgb: expected (H, W, 3) with H, W >= 1, got {rgb.shape}")
    half = int(half)
    if half < 0:
        raise ValueError(f"half must be >= 0, got {half}")
    lib = _library()
    scratch = _scratch(lib.normalize_scratch_floats(w, half))
    lib.normalize_channels(
        h,
        w,
        _ptr(rgb, "rgb", np.float32, (h, w, 3)),
        None if gain is None else _ptr(gain, "gain", np.float32, (h, w)),
        half,
        _f32(min_span),
        int(bool(clamp_ends)),
        _ptr(out, "out", np.float32, (h, w, 3), writable=True),
        None if span is None else _ptr(span, "span", np.float32, (h, w, 3), writable=True),
        scratch.ctypes.data,
    )


def albedo_proxy(rgb, k, share, proxy, defined) -> None:
    """The albedo proxy of :func:`simbench.decode.color.albedo_gain` from the unmixed capture
    ``rgb`` and its local ranges ``k`` (both (H, W, 3) float32), a channel counted where its range
    is >= ``share`` times the largest: ``proxy`` (H, W) float32 and ``defined`` (H, W) bool (the
    weights' sum > 0).  The same bits as the numpy form (tests/numpy_reference.py)."""
    h, w, _ = rgb.shape
    _library().albedo_proxy(
        h * w,
        _ptr(rgb, "rgb", np.float32, (h, w, 3)),
        _ptr(k, "k", np.float32, (h, w, 3)),
        _f32(share),
        _ptr(proxy, "proxy", np.float32, (h, w), writable=True),
        _ptr(defined, "defined", np.bool_, (h, w), writable=True),
    )


def albedo_edges(g, t, ratio_min, strip_min, cuts) -> None:
    """Albedo steps along the rows of ``g`` ((H, W) float32, the proxy averaged over rows):
    ``cuts[y, x]`` (bool) where the means of the ``2 t`` values either side of the step between
    columns x and x + 1 (ends replicated) differ by more than ``ratio_min`` (with a floor, see
    :func:`simbench.decode.color.albedo_edges`) and the ratio is the largest within ``t``
    pixels; each cut then moved to the column within ``t`` of it where the ratio of the ``t``
    values either side is the largest (the first of equals), and the far edge of a dark strip
    narrower than a period beside it cut too where its ratio exceeds ``strip_min`` (see
    ``albedo_edges`` in simbench/_ckernels.c)."""
    h, w = g.shape
    t = int(t)
    if h < 1 or w < 1:
        raise ValueError(f"g: expected (H, W) with H, W >= 1, got {g.shape}")
    if t < 1:
        raise ValueError(f"t must be >= 1, got {t}")
    cs = np.empty(w + 4 * t + 1, np.float64)
    q = np.empty(w + 2 * t, np.float64)
    pos = np.empty(w, np.int64)
    _library().albedo_edges(
        h,
        w,
        _ptr(g, "g", np.float32, (h, w)),
        t,
        float(ratio_min),
        float(strip_min),
        cs.ctypes.data,
        q.ctypes.data,
        pos.ctypes.data,
        _ptr(cuts, "cuts", np.bool_, (h, w), writable=True),
    )


def box_level(raw, half, floor, level) -> None:
    """Each channel of ``raw`` ((H, W, 3) float32) averaged over ``2 half + 1`` pixels along its
    row (the bits of cv2.blur, ends replicated), then ``max(mean, 0) + floor`` into ``level``."""
    h, w, c = raw.shape
    if c != 3 or h < 1 or w < 1:
        raise ValueError(f"raw: expected (H, W, 3) with H, W >= 1, got {raw.shape}")
    if int(half) < 0:
        raise ValueError(f"half must be >= 0, got {half}")
    _library().box_level(
        h,
        w,
        _ptr(raw, "raw", np.float32, (h, w, 3)),
        int(half),
        _f32(floor),
        _ptr(level, "level", np.float32, (h, w, 3), writable=True),
    )


def noise_weights(var, span, w_code, w_fringe) -> None:
    """``rel = var / max(span, 1e-12)**2`` where ``span > 0``, else inf (float32, (H, W, 3)
    each); ``w_code = 1 / (rel_R + rel_G)``, ``w_fringe = 1 / rel_B`` ((H, W) float32)."""
    h, w, _ = var.shape
    _library().noise_weights(
        h * w,
        _ptr(var, "var", np.float32, (h, w, 3)),
        _ptr(span, "span", np.float32, (h, w, 3)),
        _ptr(w_code, "w_code", np.float32, (h, w), writable=True),
        _ptr(w_fringe, "w_fringe", np.float32, (h, w), writable=True),
    )


def robust_fringe_code(rgb, span, weights, intensity, code) -> None:
    """From normalised channels and their ranges ((H, W, 3) float32 each): the weighted fringe
    (:func:`simbench.decode.phase.overlay_intensity`, mode ``weighted``, with ``weights`` =
    (w_code, w_fringe); None: ``intensity`` not written) and the code
    (:func:`simbench.decode.color.normalized_color_code`; ``code`` None: not written)."""
    h, w, _ = rgb.shape
    if code is not None and span is None:
        raise ValueError("the code needs the channels' ranges (span)")
    if weights is not None:
        wc = _ptr(weights[0], "w_code", np.float32, (h, w))
        wf = _ptr(weights[1], "w_fringe", np.float32, (h, w))
        out = _ptr(intensity, "intensity", np.float32, (h, w), writable=True)
    else:
        wc = wf = out = None
    _library().robust_fringe_code(
        h * w,
        _ptr(rgb, "rgb", np.float32, (h, w, 3)),
        None if span is None else _ptr(span, "span", np.float32, (h, w, 3)),
        wc,
        wf,
        out,
        None if code is None else _ptr(code, "code", np.bool_, (h, w), writable=True),
    )


def albedo_segments(proxy, pv, cuts, width, margin, min_len, mean, vis, short) -> None:
    """The albedo flattening's per-segment measures between the steps ``cuts`` ((H, W) bool):
    ``mean`` = :func:`simbench.decode.color.segment_mean` of ``proxy`` as float32, ``vis`` = the
    visibility of ``pv`` (its standard deviation over its mean, the segments narrowed by
    ``margin``; ``segment_visibility`` in tests/numpy_reference.py), ``short`` = the segment is
    shorter than ``min_len`` pixels.  The same bits as the numpy forms."""
    h, w = proxy.shape
    if h < 1 or w < 1:
        raise ValueError(f"proxy: expected (H, W) with H, W >= 1, got {proxy.shape}")
    width, margin = int(width), int(margin)
    if width < 1 or margin < 0:
        raise ValueError(f"width must be >= 1 and margin >= 0, got {width}, {margin}")
    scratch = np.empty(3 * (w + 1), np.float64)
    _library().albedo_segments(
        h,
        w,
        _ptr(proxy, "proxy", np.float32, (h, w)),
        _ptr(pv, "pv", np.float32, (h, w)),
        _ptr(cuts, "cuts", np.bool_, (h, w)),
        width,
        margin,
        float(min_len),
        scratch.ctypes.data,
        _ptr(mean, "mean", np.float32, (h, w), writable=True),
        _ptr(vis, "vis", np.float32, (h, w), writable=True),
        _ptr(short, "short", np.bool_, (h, w), writable=True),
    )


def side_means(g, ys, xs, m, out) -> None:
    """The means of the ``m`` values of each channel of ``g`` ((H, W, 3) float32) left and right of
    the steps at rows ``ys`` and columns ``xs`` (int64, in row-major order; a step at x is between
    columns x and x + 1), the rows' ends replicated: ``out[i]`` (float64, (n, 6)) = left and right
    of channel 0, 1, 2.  The bits of the prefix sums of :func:`simbench.decode.color.fringe_confirmed`
    as they were in numpy (``side_means`` in tests/numpy_reference.py)."""
    if g.ndim != 3 or g.shape[2] != 3 or g.shape[0] < 1 or g.shape[1] < 1:
        raise ValueError(f"g: expected (H, W, 3) with H, W >= 1, got {g.shape}")
    h, w = g.shape[:2]
    m = int(m)
    if m < 1:
        raise ValueError(f"m must be >= 1, got {m}")
    ys = np.ascontiguousarray(ys, np.int64)
    xs = np.ascontiguousarray(xs, np.int64)
    n = ys.size
    if xs.size != n:
        raise ValueError(f"ys and xs: expected one size, got {ys.size} and {xs.size}")
    if n and (ys.min() < 0 or ys.max() >= h or xs.min() < 0 or xs.max() >= w or (np.diff(ys) < 0).any()):
        raise ValueError(f"ys, xs: expected steps inside ({h}, {w}), rows in ascending order")
    cs = np.empty(3 * (w + 2 * m + 1), np.float64)
    _library().side_means(
        h,
        w,
        _ptr(g, "g", np.float32, (h, w, 3)),
        n,
        ys.ctypes.data,
        xs.ctypes.data,
        m,
        cs.ctypes.data,
        _ptr(out, "out", np.float64, (n, 6), writable=True),
    )


def group_median(values, groups, m, out) -> None:
    """Per group ``g < m`` of ``values`` (float64) by ``groups`` (int64, non-decreasing: each
    group's values together), the element ``np.lexsort((values, groups))`` puts at the group's
    lower median (the ``(c - 1) // 2``-th of its ``c`` values; NaN last, ties in index order) into
    ``out`` ((m,) float64), NaN for an empty group: the bits of the sort, by selection."""
    values = np.ascontiguousarray(values, np.float64)
    groups = np.ascontiguousarray(groups, np.int64)
    n, m = values.size, int(m)
    if groups.shape != values.shape or values.ndim != 1:
        raise ValueError(f"values, groups: expected two 1-D arrays of one size, got {values.shape} and {groups.shape}")
    if m < 0 or (n and (groups[0] < 0 or groups[-1] >= m or (np.diff(groups) < 0).any())):
        raise ValueError(f"groups: expected non-decreasing values in [0, {m})")
    idx = np.empty(n, np.int64)
    _library().group_median(
        n, values.ctypes.data, groups.ctypes.data, m, idx.ctypes.data, _ptr(out, "out", np.float64, (m,), writable=True)
    )


def column_segments(y0, x0, sign, stop, edge, frame, longest) -> tuple[np.ndarray, np.ndarray]:
    """The walks of :func:`simbench.decode.color._column_segments` (its docstring) from rows ``y0``
    down (``sign`` 1) or up (-1) columns ``x0``: ``(end, rim)``, int64 and bool of ``y0``'s size."""
    h1, w = stop.shape
    y0 = np.ascontiguousarray(y0, np.int64)
    x0 = np.ascontiguousarray(x0, np.int64)
    n = y0.size
    if sign not in (1, -1):
        raise ValueError(f"sign must be 1 or -1, got {sign}")
    if x0.size != n or (n and (x0.min() < 0 or x0.max() >= w)):
        raise ValueError(f"x0: expected {n} columns in [0, {w})")
    end = np.empty(n, np.int64)
    rim = np.empty(n, bool)
    _library().column_segments(
        n,
        y0.ctypes.data,
        x0.ctypes.data,
        int(sign),
        h1 - 1,
        w,
        _ptr(stop, "stop", np.bool_, (h1, w)),
        _ptr(edge, "edge", np.bool_, (h1, w)),
        _ptr(frame, "frame", np.bool_, (h1,)),
        int(longest),
        end.ctypes.data,
        rim.ctypes.data,
    )
    return end, rim


def column_side_means(src, yb, xs, k) -> tuple[np.ndarray, np.ndarray]:
    """Each channel of ``src`` ((H, W, 3) float32) averaged over the ``k`` rows above boundary
    ``yb[i]`` (between rows y and y + 1: rows y - 1 .. y - k) and the ``k`` rows below the pair
    straddling it (y + 2 .. y + k + 1), at columns ``xs``: ``(up, dn)``, (n, 3) float64, the bits
    of numpy's ``src[rows, cols, c].mean(axis=1, dtype=np.float64)`` (``k`` < 8: summed in order)."""
    if src.ndim != 3 or src.shape[2] != 3:
        raise ValueError(f"src: expected (H, W, 3), got {src.shape}")
    h, w = src.shape[:2]
    k = int(k)
    if not 1 <= k < 8:
        raise ValueError(f"k must be in [1, 8), got {k}")
    yb = np.ascontiguousarray(yb, np.int64)
    xs = np.ascontiguousarray(xs, np.int64)
    n = yb.size
    # (compared as Python ints: yb.max() + k + 1 could wrap in int64)
    if xs.size != n or (n and (int(yb.min()) < k or int(yb.max()) >= h - k - 1 or xs.min() < 0 or xs.max() >= w)):
        raise ValueError(f"yb, xs: expected {n} boundaries at least {k} rows inside ({h}, {w})")
    up = np.empty((n, 3), np.float64)
    dn = np.empty((n, 3), np.float64)
    _library().column_side_means(
        n, w, _ptr(src, "src", np.float32, (h, w, 3)), yb.ctypes.data, xs.ctypes.data, k, up.ctypes.data, dn.ctypes.data
    )
    return up, dn


def segments_max(gain, y0, x0, lengths, g, sign) -> None:
    """``np.maximum.at(gain, (rows, cols), values)`` for the segments of ``lengths[i]`` rows from
    row ``y0[i]`` down (``sign`` 1) or up (-1) column ``x0[i]``, each of value ``g[i]`` (float32),
    without the index arrays: ``gain`` ((H, W) float32) in place."""
    h, w = gain.shape
    y0, x0, lengths = (np.ascontiguousarray(v, np.int64) for v in (y0, x0, lengths))
    g = np.ascontiguousarray(g, np.float32)
    n = y0.size
    if sign not in (1, -1) or not (x0.size == lengths.size == g.size == n):
        raise ValueError("y0, x0, lengths, g: expected one size each, and sign 1 or -1")
    if n:
        last = y0 + sign * np.maximum(lengths - 1, 0)
        if (lengths < 0).any() or min(y0.min(), last.min()) < 0 or max(y0.max(), last.max()) >= h:
            raise ValueError(f"segments: expected rows inside [0, {h}) and lengths >= 0")
        if x0.min() < 0 or x0.max() >= w:
            raise ValueError(f"x0: expected columns inside [0, {w})")
    _library().segments_max(
        n,
        w,
        y0.ctypes.data,
        x0.ctypes.data,
        lengths.ctypes.data,
        g.ctypes.data,
        int(sign),
        _ptr(gain, "gain", np.float32, (h, w), writable=True),
    )


def centroid_rate_sums(ps, centred, scale) -> tuple[np.ndarray, np.ndarray]:
    """The window-centroid correction's rate sums over the rows of ``ps`` ((R, W) float32, the
    widest fit's phase) where ``centred`` ((R, W) bool) holds at a step's three pixels: ``(sq,
    sn)``, (R, W + 1) int64, the prefix sums of the steps ``rint(scale * wrap(ps[x + 1] -
    ps[x - 1]) / 2)`` and of their count (``centroid_rate_sums`` in simbench/_ckernels.c; the bits
    of the numpy form in tests/numpy_reference.py)."""
    nr, wb = ps.shape
    sq = np.empty((nr, wb + 1), np.int64)
    sn = np.empty((nr, wb + 1), np.int64)
    _library().centroid_rate_sums(
        nr,
        wb,
        _ptr(ps, "ps", np.float32, (nr, wb)),
        _ptr(centred, "centred", np.bool_, (nr, wb)),
        _f32(scale),
        sq.ctypes.data,
        sn.ctypes.data,
    )
    return sq, sn


def centroid_apply(need, dx, row_of, sq, sn, reach, omega, scale, y0, a, psi, out) -> None:
    """The window-centroid correction at the pixels ``need`` ((B, Wb) bool) of the block at row
    ``y0``, column ``a`` of ``psi`` ((H, W) float32), written into ``out`` (same shape): the bias
    ``(rate - omega) dx`` (``dx``: (B, Wb) float32), the rate the mean step within ``reach``
    towards the window's centre from row ``row_of[y]`` of the rate sums ``sq``, ``sn`` (of
    :func:`centroid_rate_sums`, with ``scale``); see ``centroid_apply`` in simbench/_ckernels.c."""
    nb, wb = need.shape
    h, w = psi.shape
    nr = sq.shape[0]
    row_of = np.ascontiguousarray(row_of, np.int64)
    y0, a, reach = int(y0), int(a), int(reach)  # (Python ints: no int64 wrap in the checks)
    if not 0 <= reach <= 1 << 40:
        raise ValueError(f"reach must be in [0, 2**40], got {reach}")
    if row_of.shape != (nb,) or (row_of >= nr).any() or y0 < 0 or a < 0 or y0 + nb > h or a + wb > w:
        raise ValueError(f"block ({nb}, {wb}) at ({y0}, {a}) and its rows: expected inside ({h}, {w}) and {nr} sums")
    if np.logical_and(need, (row_of < 0)[:, None]).any():
        raise ValueError("row_of: a row with pixels to correct has no rate sums")
    _library().centroid_apply(
        nb,
        wb,
        w,
        _ptr(need, "need", np.bool_, (nb, wb)),
        _ptr(dx, "dx", np.float32, (nb, wb)),
        row_of.ctypes.data,
        _ptr(sq, "sq", np.int64, (nr, wb + 1)),
        _ptr(sn, "sn", np.int64, (nr, wb + 1)),
        reach,
        _f32(omega),
        float(scale),
        y0,
        a,
        _ptr(psi, "psi", np.float32, (h, w)),
        _ptr(out, "out", np.float32, (h, w), writable=True),
    )


def crease_bias(
    column, reach: int, factor: float, max_step: float, rows_reach: int, out, *, trusted=None, cap=None
) -> None:
    """Over ``column`` ((H, W) float32): per row ``v = factor * (c[x + L] - 2 c[x] + c[x - L])``
    where no step between neighbours within ``L = reach`` of ``x`` is over ``max_step`` or NaN
    or has an end outside ``trusted`` ((H, W) bool; None: every pixel) (else, and within ``L``
    of the row's ends, none); ``out`` = the mean of the ``v`` there are
    within ``rows_reach`` rows either side, where the pixel has a ``v`` and the mean is > 0, else
    0 (running sums in float64 down each column).  ``cap = (kappa, valid, conf)``: also ``conf =
    fmin(conf, kappa / out)`` where ``valid``, in place."""
    h, w = column.shape
    kappa, valid, conf = cap if cap is not None else (0.0, None, None)
    # scratch: the rows' v, a row's steps, the columns' running sums and counts
    signed = np.empty((h, w), np.float32)
    broken = np.empty(max(w, 1), np.uint8)
    sums = np.empty(max(w, 1), np.float64)
    counts = np.empty(max(w, 1), np.int64)
    _library().crease_bias(
        h,
        w,
        _ptr(column, "column", np.float32, (h, w)),
        int(reach),
        float(factor),
        float(max_step),
        int(rows_reach),
        None if trusted is None else _ptr(trusted, "trusted", np.bool_, (h, w)),
        signed.ctypes.data,
        _ptr(out, "out", np.float32, (h, w), writable=True),
        float(kappa),
        None if cap is None else _ptr(valid, "valid", np.bool_, (h, w)),
        None if cap is None else _ptr(conf, "conf", np.float32, (h, w), writable=True),
        broken.ctypes.data,
        sums.ctypes.data,
        counts.ctypes.data,
    )


def edge_bend(
    column, reach: int, fit: int, max_step: float, out, *, reach_y: int = 0, fit_y: int = 0, cap=None
) -> None:
    """Over ``column`` ((H, W) float32), per row: at each end of a run of finite columns (steps
    between neighbours at most ``max_step``) that a hole or a larger step ends, where the run is
    at least ``reach + fit`` long, ``out`` = |column - the least-squares line through the ``fit``
    columns from ``reach`` pixels off the end, extrapolated| for the ``reach`` columns nearest the
    end (the larger of two), else 0; then the same down each image column with ``reach_y`` and
    ``fit_y`` (0: not read), ``out`` the larger of the two.  ``cap = (kappa, valid, conf)``: also
    ``conf = fmin(conf, kappa / out)`` where ``valid``, in place."""
    h, w = column.shape
    reach, fit, reach_y, fit_y = int(reach), int(fit), int(reach_y), int(fit_y)
    if min(reach, fit, reach_y, fit_y) < 0:
        raise ValueError(f"reaches and fits must be >= 0, got {reach}, {fit}, {reach_y}, {fit_y}")
    # no run is longer than its line: beyond it the same result, and reach + fit cannot overflow
    reach, fit = min(reach, w + 1), min(fit, w + 1)
    reach_y, fit_y = min(reach_y, h + 1), min(fit_y, h + 1)
    kappa, valid, conf = cap if cap is not None else (0.0, None, None)
    _library().edge_bend(
        h,
        w,
        _ptr(column, "column", np.float32, (h, w)),
        reach,
        fit,
        reach_y,
        fit_y,
        _f32(max_step),
        _ptr(out, "out", np.float32, (h, w), writable=True),
        _f32(kappa),
        None if cap is None else _ptr(valid, "valid", np.bool_, (h, w)),
        None if cap is None else _ptr(conf, "conf", np.float32, (h, w), writable=True),
    )
