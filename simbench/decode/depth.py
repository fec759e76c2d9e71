"""Stage 4: absolute phase and depth (paper Eq. 12, 14, 15; Sec. 5.4).

* The stripe index is ``n = W + L*k`` (Eq. 14).  The cycle number ``k`` is not coded; it is
  taken as the one putting the projector column within half a De Bruijn cycle of an expected
  column: the reference plane's at the same pixel (reference mode) or the column of a surface
  at the middle of the working range (calibrated mode).
* Reference mode (paper Sec. 5.4): the pixel ``x_r`` of the same row where the reference
  capture shows the same projector column gives the disparity ``d = x - x_r`` and
  ``1/Z = 1/Z0 + d/(f*B)``, which is Eq. 15 (``Z = f*B/d_total``) with the reference's own
  disparity ``f*B/Z0`` added.  Exact for a rectified rig (parallel axes, baseline along x).
* Calibrated mode: the camera ray meets the plane of the projector column (any rig pose;
  :func:`simbench.rig.triangulate_columns`, in the decoder fused into
  :func:`simbench.decode._kernels.decode_tail`).
"""

from __future__ import annotations

import cv2
import numpy as np

from simbench.decode import _kernels

__all__ = [
    "absolute_column",
    "inverse_column_table",
    "match_reference",
    "depth_from_disparity",
    "crease_bias",
    "crease_apex_bias",
    "crease_trusted",
]


def absolute_column(
    position: np.ndarray,
    wrapped: np.ndarray,
    expected_column: np.ndarray,
    *,
    period_px: float,
    cycle: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Projector column of each pixel from its stripe position, wrapped phase and cycle choice.

    Parameters
    ----------
    position : ndarray, shape (H, W), int32; W in 0..L-1, -1 unknown
    wrapped : ndarray, shape (H, W), float32
    expected_column : ndarray, shape (H, W); the column the cycle number is chosen against
    period_px : float
        Fringe period T in projector pixels.
    cycle : int
        De Bruijn cycle length L in stripes.

    Returns
    -------
    column_px : ndarray, shape (H, W), float32; NaN where unknown
    stripe_index : ndarray, shape (H, W), int32; n of Eq. 14, -1 where unknown

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Eq. 14.
    """
    position = np.ascontiguousarray(position, dtype=np.int32)
    wrapped = np.ascontiguousarray(wrapped, dtype=np.float32)
    expected = np.ascontiguousarray(np.broadcast_to(expected_column, position.shape), dtype=np.float32)
    column = np.empty(position.shape, np.float32)
    index = np.empty(position.shape, np.int32)
    # column_from_phase(psi + 2 pi W) in float32, one pass (simbench.decode._kernels)
    _kernels.absolute_column(
        position, wrapped, expected, np.float32(period_px), np.float32(cycle * period_px), cycle, column, index
    )
    return column, index


def inverse_column_table(reference_column: np.ndarray, *, projector_width: int) -> np.ndarray:
    """Per row of a decoded reference, the sub-pixel x showing each integer projector column.

    Built once per reference so that matching a capture is a table look-up.  Reference pixels
    whose column does not increase strictly along the row are left out.  Columns the row of the
    reference does not show (a surface behind or before the reference plane, near the image
    edge) hold NaN: :func:`simbench.decode.decode` triangulates those with the rig instead.

    Returns
    -------
    ndarray, shape (H, projector_width + 2), float32
        Column ``projector_width + 1`` is all NaN: the look-up's target for unknown columns.
    """
    h, w = reference_column.shape
    ref = reference_column.astype(np.float64)
    run_max = np.fmax.accumulate(np.where(np.isfinite(ref), ref, -np.inf), axis=1)
    prev_max = np.concatenate([np.full((h, 1), -np.inf), run_max[:, :-1]], axis=1)
    keep = np.isfinite(ref) & (ref > prev_max)
    rows, xs = np.nonzero(keep)
    table = np.full((h, projector_width + 2), np.nan, dtype=np.float32)
    if rows.size < 2:
        return table
    vals = ref[rows, xs]
    n = np.bincount(rows, minlength=h).astype(np.float64)
    lo = np.full(h, np.inf)
    hi = np.full(h, -np.inf)
    np.minimum.at(lo, rows, vals)
    np.maximum.at(hi, rows, vals)
    stride = 4.0 * (projector_width + np.abs(vals).max() + 1.0)
    c = np.arange(projector_width + 1, dtype=np.float64)[None, :]
    q = (c + np.arange(h)[:, None] * stride).ravel()
    xr = np.interp(q, vals + rows * stride, xs.astype(np.float64)).reshape(h, -1)
    inside = (c >= lo[:, None]) & (c <= hi[:, None])
    table[:, :-1] = np.where(inside & (n[:, None] >= 2), xr, np.nan)
    return table


def match_reference(column: np.ndarray, table: np.ndarray) -> np.ndarray:
    """For each pixel, the sub-pixel x in the same row of the reference that shows the same
    projector column (linear interpolation in :func:`inverse_column_table`).

    Returns
    -------
    ndarray, shape (H, W), float32; NaN where the reference has no match

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Sec. 5.4 (matching against the reference plane).
    """
    column = np.ascontiguousarray(column, dtype=np.float32)
    out = np.empty(column.shape, np.float32)
    _kernels.match_reference(column, np.ascontiguousarray(table, dtype=np.float32), out)
    return out


def depth_from_disparity(x_ref: np.ndarray, *, focal_px: float, baseline_m: float, z0_m: float) -> np.ndarray:
    """Depth from the disparity to the reference plane: ``1/Z = 1/Z0 + (x - x_r)/(f*B)``, ``B`` the
    baseline signed as the projector's x position (negative on the camera's left: its length alone
    mirrors the depths about Z0).

    Returns
    -------
    ndarray, shape (H, W), float32; NaN where unmatched or not in front of the camera

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Sec. 5.4.
    """
    x_ref = np.ascontiguousarray(x_ref, dtype=np.float32)
    out = np.empty(x_ref.shape, np.float32)
    _kernels.depth_from_disparity(x_ref, np.float32(1.0 / z0_m), np.float32(1.0 / (focal_px * baseline_m)), out)
    return out


def crease_bias(
    column_px: np.ndarray,
    *,
    scale_px: int,
    depth_sign: float,
    bias_ratio: float,
    max_step_px: float,
    rows_reach: int = 0,
    trusted: np.ndarray | None = None,
) -> np.ndarray:
    """Predicted phase bias at concave creases, in projector pixels (ours; the colour-robust
    decoder's ``crease_doubt``).

    Light a concave corner's faces throw at each other carries the fringe of the other face,
    and shifts the fringe near the crease: the decoded column map comes out as if the true one,
    whose slope breaks at the crease, were blurred across it (the library's white corners: a
    Gaussian of ~14 camera px, peak errors 1.3, 0.75 and 0.40 px at 60, 90 and 120 deg; none in
    renders with direct light only).  No window of the phase fit sees it.  What the decoded map
    does show is the break of its slope, as its second difference along the row over
    ``scale_px`` either side, ``D2 = c[x+L] - 2 c[x] + c[x-L]``: ``k (L - |x - x0|)`` for a slope
    change ``k`` at ``x0`` (a triangle), averaged over ``rows_reach`` rows either side (a crease is
    a line; the map's noise is not: on the saturated green board, D2's noise is 0.6 px RMS row by
    row).  The predicted bias is ``bias_ratio`` times that mean where the break is concave (the
    surface bends away from the camera: ``D2`` against ``depth_sign``, the sign of d column / d
    depth along the camera's ray); 0 where the map is convex or flat, and wherever a step between
    neighbours within the reach along the row is over ``max_step_px`` or a hole (a depth edge:
    other terms of the confidence answer for it; such rows are left out of a neighbour's mean).

    Parameters
    ----------
    column_px : ndarray, shape (H, W), float32; projector column, NaN where none
    scale_px : int
        ``L``, camera pixels either side along the row.
    depth_sign : float
        +1 where the projector column grows with depth at fixed camera pixel, -1 where it falls.
    bias_ratio : float
        Predicted bias per pixel of concave ``D2``.
    max_step_px : float
        A larger step between neighbouring pixels is a depth edge.
    rows_reach : int
        Rows either side whose ``D2`` the mean takes (0: the row's own).
    trusted : ndarray, shape (H, W), bool, optional
        Columns that may enter a ``D2`` (a step with an end outside it breaks the windows over it,
        like a depth edge); the decoder's: :func:`crease_trusted`.

    Returns
    -------
    ndarray, shape (H, W), float32, >= 0 (0 within ``scale_px`` of the image's sides)
    """
    c = np.ascontiguousarray(column_px, dtype=np.float32)
    out = np.empty(c.shape, np.float32)
    factor = np.float32(-np.sign(depth_sign) * bias_ratio)
    if trusted is not None:
        trusted = np.ascontiguousarray(trusted, dtype=bool)
    _kernels.crease_bias(c, int(scale_px), factor, max_step_px, int(rows_reach), out, trusted=trusted)
    return out


def edge_bend_bias(
    column_px: np.ndarray, *, reach_px: int, fit_px: int, max_step_px: float, reach_y_px: int = 0, fit_y_px: int = 0
) -> np.ndarray:
    """Measured phase bias beside depth edges and holes, in projector pixels (ours; the
    colour-robust decoder's ``edge_doubt``).

    Within its reach of a depth edge the phase fit's window holds both sides' fringes, and the
    decoded column map bends towards the other side's: beside the deep staircase's 200 mm step
    (``scenes/hard_stairs_deep.toml``) 0.2 px 6 px from the undecoded gap, 0.8 px (6 mm) 2 px from
    it, at a fringe SNR of 3-4 - the wide window fits both fringes' mix well enough, and the
    narrow window, still reaching across, moves with it.  The bend is what the map itself shows:
    along each row, at each end of a run of decoded columns that a hole or a step over
    ``max_step_px`` ends (the row's own ends are no edge), the least-squares line through the
    ``fit_px`` columns from ``reach_px`` pixels off the end - beyond the windows that reach across
    - extrapolated to the ``reach_px`` columns nearest the end; the bias is each one's distance
    from it (the larger, where both ends of a short run reach a pixel).  0 where not measured: a
    run shorter than ``reach_px + fit_px``, and everything farther from an end.  A surface that
    curves within the reach shows as bend too (a sphere's limb, seen at grazing incidence).  With
    ``reach_y_px`` the same down each image column, with ``fit_y_px`` (an edge along the rows: the
    window reaches across it by its extent along y), the bias the larger of the two.

    Parameters
    ----------
    column_px : ndarray, shape (H, W), float32; projector column, NaN where none
    reach_px : int
        Camera pixels from an end whose bias is measured (the decoder: the wide window's 2 sigma).
    fit_px : int
        Camera pixels the line is fitted over (the decoder: one camera period).
    max_step_px : float
        A larger step between neighbouring pixels is a depth edge (the decoder:
        :meth:`simbench.decode.DecoderParams.edge_step_px`).
    reach_y_px, fit_y_px : int
        The same down the columns (the decoder: the wide window's 2 sigma along y, one camera
        period); 0: along the rows only.

    Returns
    -------
    ndarray, shape (H, W), float32, >= 0
    """
    c = np.ascontiguousarray(column_px, dtype=np.float32)
    if c.ndim != 2:
        raise ValueError(f"column_px: expected shape (H, W), got {c.shape}")
    out = np.empty(c.shape, np.float32)
    _kernels.edge_bend(c, int(reach_px), int(fit_px), max_step_px, out, reach_y=int(reach_y_px), fit_y=int(fit_y_px))
    return out


def crease_apex_bias(
    bias: np.ndarray,
    column_px: np.ndarray,
    *,
    scale_px: int,
    depth_sign: float,
    peak_px: int,
    apex_px: int,
    apex_factor: float,
    lobe_share: float,
    min_px: float = 0.0,
) -> np.ndarray:
    """:func:`crease_bias`'s prediction raised at the apex of a fold (ours; the colour-robust
    decoder's ``crease_doubt``): ``bias`` times ``apex_factor`` within ``apex_px`` of each row's
    apex, there the largest ``bias`` within ``apex_px``.

    The crease term predicts a bias of a fixed share of the decoded map's concave second
    difference ``D2`` (:data:`simbench.decode.params.CREASE_BIAS_RATIO`, a least-squares fit over a
    period of the crease); at the apex the error reaches a larger share of it, 0.47-0.55 on the
    library's corners, and counting every decoded pixel the 90-degree corner kept 0.51 % of them
    5-7 mm wrong within 2 px of its crease at confidence 3.1-3.5 (2026-11-30).  An apex is a pixel
    whose ``bias`` is positive and the largest within ``peak_px`` along its row; it is a fold -
    a crease of the surface - when ``D2`` (averaged over ``scale_px`` rows either side, in the
    concave sense) falls nowhere within ``2 scale_px`` of it below ``-lobe_share`` times its own:
    a printed albedo step also bends the decoded map, but as an S, concave on one side and convex
    on the other (on the 20:1 chart the convex lobe reached 0.6-1.4 of the concave peak, on the
    corners from 45 to 120 degrees at most 0.12 of it).

    Parameters
    ----------
    bias : ndarray, shape (H, W), float32 >= 0; :func:`crease_bias`'s prediction
    column_px : ndarray, shape (H, W), float32; the decoded projector column, NaN where none
    scale_px : int
        ``L`` of :func:`crease_bias`.
    depth_sign : float
        As for :func:`crease_bias`.
    peak_px, apex_px : int
        The apex's reach along the row, and how far from it the raised prediction reaches.
    apex_factor : float
        The apex's share of ``D2`` over :func:`crease_bias`'s.
    lobe_share : float
        The deepest convex lobe, as a share of the apex's ``D2``, of a fold.
    min_px : float
        The least prediction (projector px) of an apex that is raised.

    Returns
    -------
    ndarray, shape (H, W), float32, >= ``bias``
    """
    if int(scale_px) < 1 or int(peak_px) < 0 or int(apex_px) < 0:
        raise ValueError(f"scale_px must be >= 1 and peak_px, apex_px >= 0, got {scale_px}, {peak_px}, {apex_px}")
    b = np.ascontiguousarray(bias, dtype=np.float32)
    # only an apex whose prediction reaches min_px is raised: below it (a plane's fitted ripple
    # predicts <= 0.1 px) the raised prediction stays far from any wrong depth, and the test costs
    # ~35 ms a decode at the paper's resolution
    apex = (b > 0) & (b >= np.float32(min_px)) & (b >= cv2.dilate(b, np.ones((1, 2 * int(peak_px) + 1), np.uint8)))
    if not apex.any():
        return b
    # float32 throughout (a fold's lobe test has margins of tenths of its peak; float64 filters and
    # dilations cost ~100 ms a decode at the paper's resolution)
    c = np.asarray(column_px, np.float32)
    h, w = c.shape
    L = int(scale_px)
    fold = np.zeros((h, w), bool)
    # the lobe test at an apex reads D2's row means within 2 L of it along the row, and D2 reads
    # the map L further: it runs on the columns within 2 L of an apex only, each run of them with
    # its own margin (the sums down the columns are each column's own, and a morphological
    # window's outside is the image's wherever the run reaches the image's side: the same bits as
    # over the whole image, on a corner's ~10 apex columns ~10x less work)
    # (runs more than 4 L apart have disjoint lobe tests, and more than 2 apex_px apart disjoint
    # raises: a review found the raises of runs 4 L + 2 .. 2 apex_px apart overwriting each other)
    cols = np.flatnonzero(apex.any(axis=0))
    apart = np.flatnonzero(np.diff(cols) > max(4 * L + 1, 2 * int(apex_px))) + 1
    runs = [(int(r[0]), int(r[-1]) + 1) for r in np.split(cols, apart)]
    for a0, a1 in runs:
        s0, s1 = max(0, a0 - 2 * L), min(w, a1 + 2 * L)
        fold[:, s0:s1] = _folds(c, apex[:, s0:s1], s0, L=L, depth_sign=depth_sign, lobe_share=lobe_share)
    if not fold.any():
        return b
    # raised within apex_px of a fold (every fold lies in a run, and runs lie more than 2 apex_px
    # apart: within apex_px of its own run's columns no other run's fold reaches a pixel)
    out = b.copy()
    reach = np.ones((1, 2 * int(apex_px) + 1), np.uint8)
    for a0, a1 in runs:
        s0, s1 = max(0, a0 - int(apex_px)), min(w, a1 + int(apex_px))
        f, bs = np.ascontiguousarray(fold[:, s0:s1]), b[:, s0:s1]
        near = cv2.dilate(f.view(np.uint8), reach).astype(bool)
        raised = cv2.dilate(np.where(f, bs, np.float32(0.0)), reach) * np.float32(apex_factor)
        out[:, s0:s1] = np.where(near, np.maximum(bs, raised), bs)
    return out


def _folds(c: np.ndarray, apex: np.ndarray, s0: int, *, L: int, depth_sign: float, lobe_share: float) -> np.ndarray:
    """:func:`crease_apex_bias`' lobe test on the columns ``s0 .. s0 + apex.shape[1]`` of the map
    ``c`` ((H, W) float32): the apexes there that are folds."""
    h, w = c.shape
    s1 = s0 + apex.shape[1]
    d2 = np.full((h, s1 - s0), np.nan, np.float32)
    x0, x1 = max(s0, L), min(s1, w - L)  # D2 is defined L from the image's sides
    if x1 > x0:
        # in the concave sense: positive where crease_bias predicts a bias
        d2[:, x0 - s0 : x1 - s0] = np.float32(-np.sign(depth_sign)) * (
            c[:, x0 + L : x1 + L] - np.float32(2.0) * c[:, x0:x1] + c[:, x0 - L : x1 - L]
        )
    ok = np.isfinite(d2)
    # the sums over 2 L + 1 rows, by running sums
    rows = (1, 2 * L + 1)
    total = cv2.boxFilter(np.where(ok, d2, np.float32(0.0)), -1, rows, normalize=False, borderType=cv2.BORDER_CONSTANT)
    count = cv2.boxFilter(ok.astype(np.float32), -1, rows, normalize=False, borderType=cv2.BORDER_CONSTANT)
    mean = np.where(count > 0.5, total / np.maximum(count, np.float32(1.0)), np.float32(0.0)).astype(np.float32)
    lobe = np.ones((1, 4 * L + 1), np.uint8)
    deepest = cv2.erode(mean, lobe)
    # judged only where D2 is known across the whole reach (not by the image's sides, nor a hole)
    known = cv2.erode((count > 0.5).astype(np.uint8), lobe, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return apex & known.astype(bool) & (deepest >= np.float32(-lobe_share) * mean)


def crease_trusted(valid: np.ndarray, *, scale_px: int) -> np.ndarray:
    """The columns :func:`crease_bias` may read in the decoder: the valid ones at least half of
    ``scale_px`` from an invalid one along the row (beside a hole - a depth edge's, a shadow's -
    the fit's windows straddle it and bend the decoded map, which is no crease).

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    margin = np.ones((1, 2 * (int(scale_px) // 2) + 1), np.uint8)
    v = np.ascontiguousarray(valid, dtype=bool)
    return cv2.erode(v.view(np.uint8), margin, borderType=cv2.BORDER_REPLICATE).view(bool)
