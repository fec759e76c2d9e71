"""Stage 4: absolute phase and depth (paper Eq. 12, 14, 15; Sec. 5.4).

* The stripe index is ``n = W + L*k`` (Eq. 14).  The cycle number ``k`` is not coded; it is
  taken as the one putting the projector column within half a De Bruijn cycle of an expected
  column: the reference plane's at the same pixel (reference mode) or the column of a surface
  at the middle of the working range (calibrated mode).
* Reference mode (paper Sec. 5.4): the pixel ``x_r`` of the same row where the reference
  capture shows the same projector column gives the disparity ``d = x - x_r`` and
  ``1/Z = 1/Z0 + d/(f*B)``, which is Eq. 15 (``Z = f*B/d_total``) with the reference's own
  disparity ``f*B/Z0`` added.  Exact for a rectified rig (parallel axes, baseline along x).
* Calibrated mode: the camera ray meets the plane of the projector column (any rig pose).
"""

from __future__ import annotations

import numpy as np

from simbench.pattern import column_from_phase
from simbench.rig import Rig, triangulate_columns

__all__ = ["absolute_column", "match_reference", "depth_from_disparity", "depth_calibrated"]


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
    column_px : ndarray, shape (H, W), float64; NaN where unknown
    stripe_index : ndarray, shape (H, W), int32; n of Eq. 14, -1 where unknown
    """
    known = (position >= 0) & np.isfinite(expected_column)
    col0 = column_from_phase(wrapped.astype(np.float64) + 2.0 * np.pi * position, period_px=period_px)
    span = cycle * period_px
    k = np.rint((np.nan_to_num(expected_column) - col0) / span)
    col = col0 + k * span
    n = position + cycle * k
    return np.where(known, col, np.nan), np.where(known, n, -1).astype(np.int32)


def match_reference(column: np.ndarray, reference_column: np.ndarray, *, max_extrapolation_px: float = 160.0) -> np.ndarray:
    """For each pixel, the sub-pixel x in the same row of the reference with the same column.

    Linear interpolation of the reference's column map along each row; reference pixels whose
    column does not increase strictly along the row are left out.  Columns beyond the part of
    the row the reference shows (a surface behind the reference plane, near the image's right
    edge) are matched on the row's least-squares line - the reference is a plane, whose column
    map is linear along a row for a rectified rig - up to ``max_extrapolation_px`` beyond the
    row's ends; further out the result is NaN.

    Returns
    -------
    ndarray, shape (H, W), float64
    """
    h, w = column.shape
    ref = np.where(np.isfinite(reference_column), reference_column, np.nan)
    run_max = np.fmax.accumulate(np.where(np.isfinite(ref), ref, -np.inf), axis=1)
    prev_max = np.concatenate([np.full((h, 1), -np.inf), run_max[:, :-1]], axis=1)
    keep = np.isfinite(ref) & (ref > prev_max)
    rows, xs = np.nonzero(keep)
    if rows.size < 2:
        return np.full((h, w), np.nan)
    vals = ref[rows, xs]
    lo_val = np.full(h, np.inf)
    hi_val = np.full(h, -np.inf)
    np.minimum.at(lo_val, rows, vals)
    np.maximum.at(hi_val, rows, vals)
    offset = 4.0 * (np.nanmax(np.abs(vals)) + np.nanmax(np.abs(np.nan_to_num(column))) + 1.0)
    keys = vals + rows * offset
    qrows = np.broadcast_to(np.arange(h)[:, None], (h, w))
    q = column + qrows * offset
    xr = np.interp(q.ravel(), keys, xs.astype(np.float64)).reshape(h, w)
    inside = np.isfinite(column) & (column >= lo_val[:, None]) & (column <= hi_val[:, None])
    # per-row line x = a*u + b through the reference's (u, x) samples
    n = np.bincount(rows, minlength=h).astype(np.float64)
    su = np.bincount(rows, vals, h)
    sx = np.bincount(rows, xs, h)
    suu = np.bincount(rows, vals * vals, h)
    sux = np.bincount(rows, vals * xs, h)
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (n * sux - su * sx) / (n * suu - su * su)
        b = (sx - a * su) / n
        x_line = a[:, None] * column + b[:, None]
    outside = np.isfinite(column) & ~inside & (n[:, None] >= 16)
    reach = np.where(column < lo_val[:, None], (lo_val[:, None] - column), (column - hi_val[:, None])) * np.abs(a)[:, None]
    ok_out = outside & (reach <= max_extrapolation_px)
    return np.where(inside, xr, np.where(ok_out, x_line, np.nan))


def depth_from_disparity(x_ref: np.ndarray, *, focal_px: float, baseline_m: float, z0_m: float) -> np.ndarray:
    """Depth from the disparity to the reference plane: ``1/Z = 1/Z0 + (x - x_r)/(f*B)``.

    Returns
    -------
    ndarray, shape (H, W), float64; NaN where unmatched or not in front of the camera
    """
    h, w = x_ref.shape
    d = np.arange(w, dtype=np.float64)[None, :] - x_ref
    inv = 1.0 / z0_m + d / (focal_px * baseline_m)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = 1.0 / inv
    return np.where(np.isfinite(z) & (z > 0), z, np.nan)


def depth_calibrated(column: np.ndarray, rig: Rig) -> np.ndarray:
    """Depth by intersecting each camera ray with its projector column's plane."""
    return triangulate_columns(column, rig)
