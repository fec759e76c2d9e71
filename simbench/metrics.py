"""Error measures against ground truth, and the paper's own protocols.

* :func:`depth_errors` - MAE, RMSE, median and p95 absolute error (mm), completeness, outlier
  share and stripe-order error rate, over the pixels ground truth says are seen and lit.
* :func:`plane_fit_error` - paper Table 1: mean absolute residual to a least-squares plane.
* :func:`edge_band` - pixels near depth discontinuities, to exclude from edge-sensitive scores.
* :func:`score` - the scores every experiment reports, one protocol for every depth system.
* :func:`wrong_pixels` - decoded pixels far from every depth the truth takes there: one instant,
  or a moving scene's instants over its capture.
* :func:`code_stripes` - what a capture holds in the stripes of each code, and how often the
  paper's colour code (Eq. 13) reads them right: why a board can or cannot be decoded.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import TYPE_CHECKING

import cv2
import numpy as np

from simbench import native
from simbench.pattern import PatternSpec, check_channels
from simbench.rig import Intrinsics, pixel_rays

if TYPE_CHECKING:
    from simbench.sim.truth import GroundTruth

__all__ = [
    "edge_band",
    "depth_errors",
    "plane_fit_error",
    "fit_plane",
    "pixel_spread",
    "points_from_depth",
    "score",
    "wrong_pixels",
    "every_decoded_pixel",
    "confidence_curve",
    "image_motion_px",
    "MOVING_TRUTH_NOTE",
    "code_stripes",
    "implausible_depth",
    "implausible_columns",
]


def edge_band(
    gt_depth_m: np.ndarray, *, object_id: np.ndarray | None = None, band_px: int, rel_jump: float = 0.02
) -> np.ndarray:
    """Pixels within ``band_px`` of a depth discontinuity.

    A discontinuity lies between 4-neighbours whose ground-truth depths differ by more than
    ``rel_jump`` of the depth, that belong to different objects, or of which one sees nothing.

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    z = np.asarray(gt_depth_m, dtype=np.float64)
    seen = np.isfinite(z)
    edge = np.zeros(z.shape, dtype=bool)
    for axis in (0, 1):
        a = np.take(z, np.arange(z.shape[axis] - 1), axis=axis)
        b = np.take(z, np.arange(1, z.shape[axis]), axis=axis)
        with np.errstate(invalid="ignore"):
            jump = np.abs(a - b) > rel_jump * np.fmin(a, b)
        jump |= np.isfinite(a) != np.isfinite(b)
        if object_id is not None:
            oa = np.take(object_id, np.arange(z.shape[axis] - 1), axis=axis)
            ob = np.take(object_id, np.arange(1, z.shape[axis]), axis=axis)
            jump |= oa != ob
        sl_a = [slice(None)] * 2
        sl_b = [slice(None)] * 2
        sl_a[axis] = slice(0, -1)
        sl_b[axis] = slice(1, None)
        edge[tuple(sl_a)] |= jump
        edge[tuple(sl_b)] |= jump
    if band_px > 0:
        k = np.ones((2 * band_px + 1, 2 * band_px + 1), np.uint8)
        edge = cv2.dilate(edge.astype(np.uint8), k) > 0
    return edge & seen


def image_motion_px(motion_px: np.ndarray | None) -> float:
    """The largest image motion of a recording's pixels over its capture (camera px; 0 for a
    still one): the length of ``motion_px``'s (dx, dy) at its fastest pixel.

    Parameters
    ----------
    motion_px : ndarray, shape (H, W, 2), float, or None
        Each pixel's image motion over the capture (:attr:`simbench.sim.truth.GroundTruth.motion_px`,
        a recording's ``gt_motion.npy``).
    """
    if motion_px is None:
        return 0.0
    m = np.asarray(motion_px, np.float64)
    if m.ndim != 3 or m.shape[-1] != 2:
        raise ValueError(f"motion_px: expected shape (H, W, 2), got {m.shape}")
    length = np.hypot(m[..., 0], m[..., 1])
    return float(np.nanmax(length)) if np.isfinite(length).any() else 0.0


# what a score of a moving recording measures (the truth is one instant; the motion study's measure
# judges each pixel against every depth it saw: simbench.experiments.motion.capture_truths)
MOVING_TRUTH_NOTE = (
    "the recording moves ({px:.1f} px of image motion over its capture at the fastest pixel): its ground truth is "
    "the scene at mid-capture, so depth smeared beside a moving outline counts as error here "
    "(`simbench reproduce motion` judges each pixel against every depth it saw; docs/motion.md)"
)


def depth_errors(
    depth_m: np.ndarray,
    gt_depth_m: np.ndarray,
    *,
    region: np.ndarray,
    exclude: np.ndarray | None = None,
    column_px: np.ndarray | None = None,
    gt_column_px: np.ndarray | None = None,
    period_px: float | None = None,
    outlier_mm: float = 5.0,
) -> dict:
    """Scores of a depth map against ground truth.

    Parameters
    ----------
    depth_m, gt_depth_m : ndarray, shape (H, W), float; NaN = invalid / nothing
    region : ndarray, shape (H, W), bool
        Pixels that count (normally: seen by the camera and lit by the projector).
    exclude : ndarray, shape (H, W), bool, optional
        Pixels left out of the error statistics (e.g. an edge band); they still count for
        completeness.
    column_px, gt_column_px, period_px : optional
        Decoded and true projector columns and the fringe period, for the stripe-order error:
        a pixel whose column is off by more than half a period was unwrapped into the wrong
        stripe (its phase is off by a multiple of 2*pi).
    outlier_mm : float
        Absolute error above which a pixel is an outlier.

    Returns
    -------
    dict
        ``n_region``, ``n_valid``, ``completeness``, ``n_scored``, ``mae_mm``, ``rmse_mm``,
        ``median_mm``, ``p95_mm``, ``max_mm``, ``bias_mm``, ``outlier_share`` and, with
        columns, ``stripe_order_errors`` and ``stripe_order_error_rate`` (share of valid pixels).
    """
    # float32 maps stay float32 until the scored pixels are gathered: the same float64 values,
    # half the bytes moved; the masks, counts and gathers are one C pass (numpy's operations:
    # tests/test_metrics.py compares the bits)
    d, g = (
        np.ascontiguousarray(a if a.dtype in (np.float32, np.float64) else a.astype(np.float64))
        for a in map(np.asarray, (depth_m, gt_depth_m))
    )
    region = np.ascontiguousarray(region, dtype=bool)
    if d.shape != g.shape or region.shape != g.shape:
        raise ValueError(f"shapes differ: depth {d.shape}, ground truth {g.shape}, region {region.shape}")
    if exclude is not None:
        exclude = np.ascontiguousarray(exclude, dtype=bool)
        if exclude.shape != g.shape:
            raise ValueError(f"shapes differ: exclude {exclude.shape}, ground truth {g.shape}")
    valid = np.empty(g.shape, bool)
    err = np.empty(g.size)
    counts = np.zeros(2, np.int64)
    n_scored = native.bind(_SCORED).scored_errors(
        g.size,
        native.ptr(d, "depth", d.dtype),
        int(d.dtype == np.float32),
        native.ptr(g, "gt", g.dtype),
        int(g.dtype == np.float32),
        native.ptr(region, "region", np.bool_),
        None if exclude is None else native.ptr(exclude, "exclude", np.bool_),
        native.ptr(valid, "valid", np.bool_, writable=True),
        native.ptr(err, "err", np.float64, writable=True),
        native.ptr(counts, "counts", np.int64, writable=True),
    )
    err = err[:n_scored]
    a = np.abs(err)
    n_region, n_valid = int(counts[0]), int(counts[1])
    median, p95 = _median_and_p95(a) if a.size else (float("nan"), float("nan"))
    out = {
        "n_region": n_region,
        "n_valid": n_valid,
        "completeness": float(np.int64(n_valid) / n_region) if n_region else float("nan"),
        "n_scored": int(n_scored),
        "mae_mm": float(a.mean()) if a.size else float("nan"),
        "rmse_mm": float(np.sqrt(np.mean(err**2))) if a.size else float("nan"),
        "median_mm": median,
        "p95_mm": p95,
        "max_mm": float(a.max()) if a.size else float("nan"),
        "bias_mm": float(err.mean()) if a.size else float("nan"),
        "outlier_share": float(np.mean(a > outlier_mm)) if a.size else float("nan"),
    }
    if column_px is not None and gt_column_px is not None:
        if period_px is None:
            raise ValueError("period_px is needed for the stripe-order error")
        both = valid & np.isfinite(column_px) & np.isfinite(gt_column_px)
        wrong = np.abs(column_px[both] - gt_column_px[both]) > 0.5 * period_px
        out["stripe_order_errors"] = int(wrong.sum())
        out["stripe_order_error_rate"] = float(wrong.mean()) if wrong.size else float("nan")
    return out


_SCORED = {
    "scored_errors": (
        native.I64,
        [native.I64, native.P, native.I64, native.P, native.I64, native.P, native.P, native.P, native.P, native.P],
    )
}


def _median_and_p95(a: np.ndarray) -> tuple[float, float]:
    """``np.median(a)`` and ``np.percentile(a, 95)`` of a non-empty float64 array without NaN,
    from the order statistics they need (:func:`_order_statistics`; the two took half of a
    score's time, partitioning the whole array at several places each).  They are combined by
    numpy's formulas: the median is the mean of the middle one or two; the percentile
    interpolates linearly (numpy's ``_lerp``) at the virtual index (n - 1) q, q = 95 / 100, taking
    the last value beyond n - 1.  tests/test_metrics.py compares both with numpy's."""
    n = a.size
    middle = [n // 2 - 1, n // 2] if n % 2 == 0 else [n // 2]
    v = (n - 1) * np.true_divide(95, 100)
    if v >= n - 1:
        lo = hi = n - 1
        gamma = v - np.float64(-1)  # numpy's index there is -1; the weight multiplies a zero difference
    else:
        lo = int(np.floor(v))
        hi = lo + 1
        gamma = v - np.float64(lo)
    stats = _order_statistics(a, {*middle, lo, hi})
    median = np.mean(np.array([stats[k] for k in middle]))
    below, above = stats[lo], stats[hi]
    diff = above - below
    p95 = above - diff * (1 - gamma) if gamma >= 0.5 else below + diff * gamma
    return float(median), float(p95)


def _order_statistics(a: np.ndarray, ks) -> dict[int, np.float64]:
    """The values at sorted positions ``ks`` of the 1-D array ``a`` (not modified), by
    single-position partitions of shrinking prefixes, largest position first: numpy partitions at
    one position several times faster than at several (its vectorised selection takes one), and
    the value at a sorted position does not depend on how it is found.  A position just below
    the last one found is the largest of the prefix left."""
    out = {}
    rest = a
    for k in sorted(ks, reverse=True):
        if k + 1 == rest.size:
            out[k] = rest.max()
        else:
            rest = np.partition(rest, k)
            out[k] = rest[k]
            rest = rest[:k]
    return out


def points_from_depth(depth_m: np.ndarray, camera: Intrinsics) -> np.ndarray:
    """Camera-frame 3-D points of every pixel, shape (H, W, 3); NaN where depth is NaN."""
    return _rays(camera) * np.asarray(depth_m, dtype=np.float64)[..., None]


@lru_cache(maxsize=8)
def _rays(camera: Intrinsics) -> np.ndarray:
    """:func:`simbench.rig.pixel_rays`, made once per camera (read-only): every score needs them."""
    rays = pixel_rays(camera)
    rays.setflags(write=False)
    return rays


# assumption: a plane fit (3 parameters) says something about a surface only from ~100 points
# on; below that (a board decoded at well under 0.01 %) it reports NaN instead of a flattering ~0 mm
MIN_PLANE_POINTS = 100
# ... and only from points that spread across the image in both directions: the points of one
# image line lie in one plane through the camera centre whatever their depths, so a fit to them
# reads ~0 mm (a review of the protocols, 2026-11-30: 109 pixels of one row at random depths
# 0.3-1.8 m, 0.000000 mm; Table 1's paint blue board by the paper's decoder, decoded along a few
# rows, 1.7e-14 mm beside a 674 mm error against ground truth).  The fit is reported where the
# pixels' coordinates spread, along their narrower principal axis, by a standard deviation of at
# least this share of the image's width (assumption: 1 %, 12.8 px at 1280 px, as wide as a
# 44-px strip - two fringe periods of the paper's camera, beyond the phase fit's window, so
# that no decoding error correlated along a stripe fits as a tilt across the strip)
MIN_PLANE_SPREAD = 0.01


def plane_fit_error(
    depth_m: np.ndarray, camera: Intrinsics, *, mask: np.ndarray | None = None, min_points: int = MIN_PLANE_POINTS
) -> dict:
    """Paper Table 1 protocol: fit a plane to the measured points by least squares and report
    the mean absolute (orthogonal) residual in mm.

    What it cannot see: any error that is itself planar (a wrong baseline or Z0 tilts or
    shifts the plane; the fit absorbs it), and the pixels that did not decode.

    Returns
    -------
    dict with ``mean_abs_residual_mm``, ``rms_residual_mm``, ``normal`` and ``n_points``
    (NaN scores when fewer than ``min_points`` points decoded, or when their pixels lie along a
    line: :data:`MIN_PLANE_SPREAD`)

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Table 1 and Sec. 6 (error against the least-
       squares plane).
    """
    d = np.ascontiguousarray(depth_m, dtype=np.float64)
    if d.shape != tuple(camera.size_hw):
        raise ValueError(f"depth map {d.shape} does not match the camera {tuple(camera.size_hw)}")
    if mask is not None:
        mask = np.ascontiguousarray(mask, dtype=bool)
        if mask.shape != d.shape:
            raise ValueError(f"mask {mask.shape} does not match the depth map {d.shape}")
    # the points of the pixels that count (finite depth - the rays' z is 1 - and in the mask):
    # points_from_depth(depth_m, camera)[ok] and fit_plane's centring, in one C pass with
    # numpy's operations in numpy's order (tests/test_metrics.py compares the bits)
    points = np.empty((d.size, 3))
    n = native.bind(_CENTRED).centred_points(
        d.size,
        native.ptr(d, "depth", np.float64),
        native.ptr(_rays(camera), "rays", np.float64, (*d.shape, 3)),
        None if mask is None else native.ptr(mask, "mask", np.bool_),
        native.ptr(points, "points", np.float64, writable=True),
    )
    if n < max(3, min_points):
        return _no_plane(n)
    if pixel_spread(d, mask) < MIN_PLANE_SPREAD * camera.size_hw[1]:
        return _no_plane(n)
    return _plane_of_centred(points[:n])


def pixel_spread(depth_m: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The standard deviation (px) of the coordinates of the pixels with a finite depth (and in
    ``mask``) along their narrower principal axis: 0 for pixels along one image line, whatever
    their depths (:data:`MIN_PLANE_SPREAD`)."""
    ok = np.isfinite(depth_m) if mask is None else np.isfinite(depth_m) & mask
    ys, xs = np.nonzero(ok)
    if ys.size < 2:
        return 0.0
    cov = np.cov(np.stack([xs, ys]).astype(np.float64))
    return float(np.sqrt(max(np.linalg.eigvalsh(cov)[0], 0.0)))


_CENTRED = {"centred_points": (native.I64, [native.I64, native.P, native.P, native.P, native.P])}


def _no_plane(n: int) -> dict:
    return {
        "mean_abs_residual_mm": float("nan"),
        "rms_residual_mm": float("nan"),
        "normal": [float("nan")] * 3,
        "n_points": int(n),
    }


def fit_plane(points_m: np.ndarray, *, min_points: int = MIN_PLANE_POINTS) -> dict:
    """The least-squares plane through ``points_m`` (N, 3), float64 metres, and the residuals
    of the points from it (:func:`plane_fit_error`'s scores; NaN with fewer than
    ``min_points`` points)."""
    p = np.asarray(points_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points_m must have shape (N, 3), got {p.shape}")
    if len(p) < max(3, min_points):
        return _no_plane(len(p))
    return _plane_of_centred(p - p.mean(axis=0))


def _plane_of_centred(q: np.ndarray) -> dict:
    """:func:`fit_plane`'s scores of the points ``q`` (N, 3) less their centroid."""
    # the least-squares plane's normal: the scatter matrix's eigenvector of least eigenvalue
    # (the same as the last right singular vector of q, at 3x3 instead of N x 3 cost)
    _, vecs = np.linalg.eigh(q.T @ q)
    normal = vecs[:, 0]
    r = q @ normal * 1000.0
    return {
        "mean_abs_residual_mm": float(np.mean(np.abs(r))),
        "rms_residual_mm": float(np.sqrt(np.mean(r**2))),
        "normal": [float(x) for x in normal],
        "n_points": int(len(q)),
    }


# the plane fit of score() is reported where the ground truth over the decoded pixels lies within
# this RMS of its own least-squares plane (assumption: 1 mm - 5x the largest board form of the
# flatness study, results/flatness.md, 0.21 mm RMS, and above the colour-robust decoder's plane-fit
# residuals of Table 1, at most 0.65 mm; a step, a sphere or a box in the region is far beyond it)
PLANAR_TRUTH_RMS_MM = 1.0


def score(
    depth_m: np.ndarray,
    gt: GroundTruth,
    *,
    camera: Intrinsics,
    region: np.ndarray | None = None,
    exclude: np.ndarray | None = None,
    column_px: np.ndarray | None = None,
    period_px: float | None = None,
    edge_band_px: int = 0,
    detail: bool = False,
) -> dict:
    """The scores every experiment reports for one depth map of any depth system.

    Parameters
    ----------
    depth_m : ndarray, shape (H, W), float32 metres, NaN = invalid
    gt : :class:`simbench.sim.truth.GroundTruth` at the same pixels (``depth_m``, ``lit``,
        ``object_id``, ``column_px``)
    camera : the camera of the depth map (for the plane fit)
    region : ndarray, shape (H, W), bool, optional
        Pixels that count (default: those ground truth says are seen and lit; a face mask for
        Table 3).
    exclude : ndarray, shape (H, W), bool, optional
        Pixels left out of the ground-truth error statistics but not of completeness.
    column_px, period_px : optional
        Decoded projector columns and the fringe period (structured-light systems), for the
        stripe-order errors against ``gt.column_px``.
    edge_band_px : int
        With N > 0 also ``gt_p95_mm``, ``outlier_share`` and ``edge<N>_mae_mm``, the MAE outside
        an N-px band at depth edges (:func:`edge_band`).
    detail : bool
        Also ``gt_median_mm``, ``gt_p95_mm``, ``outlier_share`` and ``n_scored``.

    Returns
    -------
    dict
        ``plane_mae_mm`` / ``plane_rms_mm``: the paper's protocol, mean absolute (RMS) residual
        of the decoded points to their least-squares plane (:func:`plane_fit_error`; it absorbs
        any error that is planar, so it cannot see a tilt or an offset of the whole board; NaN
        where the ground truth over the decoded pixels is not flat, :data:`PLANAR_TRUTH_RMS_MM`);
        ``gt_mae_mm``, ``gt_rmse_mm``, ``bias_mm``: against ground truth (they see everything
        the plane fit hides, but no error shared by ground truth and decoding, e.g. a wrong
        rig used for both); ``completeness``; with columns ``stripe_order_errors`` and their
        rate: pixels whose projector column is off by more than half a period.
    """
    region = gt.lit if region is None else region
    with_columns = column_px is not None and getattr(gt, "column_px", None) is not None
    m = depth_errors(
        depth_m,
        gt.depth_m,
        region=region,
        exclude=exclude,
        column_px=column_px if with_columns else None,
        gt_column_px=gt.column_px if with_columns else None,
        period_px=period_px,
    )
    fit = plane_fit_error(depth_m, camera, mask=region)
    if np.isfinite(fit["rms_residual_mm"]):
        # the plane fit measures a flat target; over a region that is not one, it measures the
        # scene's shape and which pixels decoded (a review, 2026-11-30: the step scene's ablation
        # rows read 'plane fit 34.9 mm'): NaN where the truth over the same pixels is not flat
        decoded = np.isfinite(np.asarray(depth_m)) & np.asarray(region, bool)
        truth_fit = plane_fit_error(gt.depth_m, camera, mask=decoded)
        if not truth_fit["rms_residual_mm"] <= PLANAR_TRUTH_RMS_MM:
            fit = _no_plane(fit["n_points"])
    out = {
        "plane_mae_mm": fit["mean_abs_residual_mm"],
        "plane_rms_mm": fit["rms_residual_mm"],
        "gt_mae_mm": m["mae_mm"],
        "gt_rmse_mm": m["rmse_mm"],
        "bias_mm": m["bias_mm"],
        "completeness": m["completeness"],
    }
    if with_columns:
        out.update(
            {"stripe_order_errors": m["stripe_order_errors"], "stripe_order_error_rate": m["stripe_order_error_rate"]}
        )
    if detail:
        out.update(
            {
                "gt_median_mm": m["median_mm"],
                "gt_p95_mm": m["p95_mm"],
                "outlier_share": m["outlier_share"],
                "n_scored": m["n_scored"],
            }
        )
    if edge_band_px > 0:
        band = edge_band(gt.depth_m, object_id=gt.object_id, band_px=edge_band_px)
        # (the caller's exclusions too: until 2026-11-30 they were dropped here, so the edge MAE
        # counted pixels the other statistics leave out - a review of the protocols; no caller
        # passed both)
        off_edges = depth_errors(
            depth_m, gt.depth_m, region=region, exclude=band if exclude is None else band | exclude
        )
        out.update(
            {
                "gt_p95_mm": m["p95_mm"],
                "outlier_share": m["outlier_share"],
                f"edge{edge_band_px}_mae_mm": off_edges["mae_mm"],
            }
        )
    return out


def wrong_pixels(depth_m: np.ndarray, truth_depth_m: np.ndarray, *, wrong_m: float) -> np.ndarray:
    """Per pixel: decoded (finite depth) and farther than ``wrong_m`` from every truth, a truth of
    NaN (nothing seen) near nothing - a depth where the truth sees nothing is wrong.

    Parameters
    ----------
    depth_m : ndarray, shape (H, W)
        Decoded depth (m), NaN where not decoded.
    truth_depth_m : ndarray, shape (H, W) or (K, H, W)
        The truth, or K truths (a moving scene at K instants of its capture: a depth any of them
        takes there is right, so a blurred pixel is judged by what it saw, not by one instant).
    wrong_m : float
        The distance (m) beyond which a depth is wrong.

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    d = np.asarray(depth_m, np.float64)
    truths = np.asarray(truth_depth_m)
    if truths.shape[-2:] != d.shape or truths.ndim not in (2, 3):
        raise ValueError(f"truth of shape {truths.shape} for a depth map of shape {d.shape}")
    near = np.zeros(d.shape, bool)
    with np.errstate(invalid="ignore"):
        for t in truths.reshape(-1, *d.shape):
            near |= np.abs(d - np.asarray(t, np.float64)) <= wrong_m
    return np.isfinite(d) & ~near


def code_stripes(
    image: np.ndarray, column_px: np.ndarray, *, pattern: PatternSpec, where: np.ndarray | None = None
) -> dict:
    """What a capture holds in the stripes of each code, from the true projector column.

    Each pixel is put in the stripe its true column ``column_px`` lies in (:mod:`simbench.pattern`:
    stripe ``s`` spans columns ``s*T - 0.5 .. (s+1)*T - 0.5``) and so gets its true code; over
    the pixels of each code, the mean of every camera channel and the share whose colour code
    by paper Eq. 13 (the code-1 channel at least the code-0 one, on the raw channels) is the
    true code.  A board whose stripes of one code hold nothing in either code channel reads 0
    for that code whatever a decoder does after Eq. 13.

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), uint8, uint16 or float (full scale 1)
    column_px : ndarray, shape (H, W), float; NaN where no projector column lights the pixel
    pattern : PatternSpec
        Its period, codes and channel assignment.
    where : ndarray, shape (H, W), bool, optional
        Pixels to use (e.g. ground truth's ``lit``); default every pixel with a column.

    Returns
    -------
    dict
        ``code{k}_mean`` (tuple of 3 floats, the R, G, B means in full-scale units),
        ``code{k}_eq13`` (share of the code-``k`` pixels Eq. 13 reads as ``k``) and
        ``code{k}_pixels`` for ``k`` in 1, 0; NaN means where a code has no pixel.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image must have shape (H, W, 3), got {img.shape}")
    col = np.asarray(column_px, dtype=np.float64)
    if col.shape != img.shape[:2]:
        raise ValueError(f"column_px shape {col.shape} does not match the image's {img.shape[:2]}")
    scale = {np.dtype(np.uint8): 1 / 255, np.dtype(np.uint16): 1 / 65535}.get(img.dtype, 1.0)
    use = np.isfinite(col) if where is None else (np.asarray(where, bool) & np.isfinite(col))
    codes = pattern.codes()
    stripe = np.floor((col[use] + 0.5) / pattern.period_px).astype(np.int64)
    code = codes[np.mod(stripe, codes.size)]
    px = img[use].astype(np.float64) * scale
    one, zero, _ = check_channels(pattern.channels)
    reads_one = px[:, one] >= px[:, zero]  # paper Eq. 13
    out: dict = {}
    for k in (1, 0):
        sel = code == k
        n = int(sel.sum())
        out[f"code{k}_mean"] = tuple(float(x) for x in px[sel].mean(axis=0)) if n else (float("nan"),) * 3
        out[f"code{k}_eq13"] = float((reads_one[sel] == bool(k)).mean()) if n else float("nan")
        out[f"code{k}_pixels"] = n
    return out


def every_decoded_pixel(
    depth_m: np.ndarray, gt_depth_m: np.ndarray, region: np.ndarray, *, wrong_mm: float = 5.0
) -> dict:
    """What :func:`depth_errors` leaves out: every decoded pixel (finite depth) of the image,
    the region's and the rest (shadows, pixels the projector does not reach; the edge band).

    Returns ``n_decoded`` (every decoded pixel), ``n_decoded_outside`` (those outside
    ``region``) and ``wrong_share_all``: the share of ``n_decoded`` farther than ``wrong_mm``
    from the truth, a decoded pixel where the truth is NaN counting wrong
    (:func:`wrong_pixels`); NaN where nothing is decoded.  A depth map scored over its region
    alone hides the wrong depths it writes outside it (an audit, 2026-12-05: 2640 unlit pixels
    set to 0.5 m scored the same as the clean map); the hard scenes' goal is on this share."""
    d = np.asarray(depth_m)
    decoded = np.isfinite(d)
    n = int(decoded.sum())
    wrong = int(wrong_pixels(d, gt_depth_m, wrong_m=wrong_mm / 1000.0).sum())
    return {
        "n_decoded": n,
        "n_decoded_outside": int((decoded & ~np.asarray(region, bool)).sum()),
        "wrong_share_all": wrong / n if n else float("nan"),
    }


def confidence_curve(
    depth_m: np.ndarray,
    confidence: np.ndarray,
    gt_depth_m: np.ndarray,
    region: np.ndarray,
    *,
    thresholds: Sequence[float],
    wrong_mm: float = 5.0,
) -> list[dict]:
    """Completeness (share of ``region``) and wrong shares (> ``wrong_mm`` from
    ``gt_depth_m``) when only the decoded pixels whose ``confidence`` reaches each of
    ``thresholds`` are kept: ``wrong_share`` of the kept pixels of ``region``,
    ``wrong_share_all`` of every kept pixel of the image, a depth where the truth has none
    counting wrong (:func:`every_decoded_pixel`); NaN where none is kept.  The curve a
    confidence's operating point is chosen from (the hard scenes' study; ``simbench score
    --confidence``)."""
    decoded = region & np.isfinite(depth_m)
    n_region = max(int(region.sum()), 1)
    conf = confidence[decoded]
    wrong = np.abs(depth_m - gt_depth_m)[decoded] > wrong_mm / 1000.0
    anywhere = np.isfinite(depth_m)
    conf_all = np.asarray(confidence)[anywhere]
    wrong_all = wrong_pixels(depth_m, gt_depth_m, wrong_m=wrong_mm / 1000.0)[anywhere]
    out = []
    for t in thresholds:
        kept = conf >= t
        n = int(kept.sum())
        kept_all = conf_all >= t
        n_all = int(kept_all.sum())
        out.append(
            {
                "threshold": float(t),
                "completeness": n / n_region,
                "wrong_share": float(wrong[kept].mean()) if n else float("nan"),
                "wrong_share_all": float(wrong_all[kept_all].mean()) if n_all else float("nan"),
            }
        )
    return out


def implausible_depth(depth: np.ndarray, gt: np.ndarray, region: np.ndarray) -> list[str]:
    """What makes a depth map look like something other than a decode of this scene in metres:
    no finite depth where it is scored, depths <= 0, or a median far (> 5x) from the ground
    truth's - another unit, another scene.  Scored all the same (the numbers say how far off):
    ``simbench score`` prints these as warnings, :func:`simbench.score` logs them."""
    ok = region & np.isfinite(gt)
    d = depth[ok]
    finite = np.isfinite(d)
    if not finite.any():
        return ["it holds no finite depth where the scene is scored: the errors are undefined (a decode of nothing?)"]
    out = []
    # over the whole map: 0 marking the holes of a shadow counts in the wrong share of every
    # decoded pixel, outside the region too (a review, 2026-12-05)
    everywhere = np.asarray(depth)[np.isfinite(depth)]
    if (everywhere <= 0).any():
        out.append(
            f"{int((everywhere <= 0).sum())} of its depths are <= 0 m, scored as decoded depths (and wrong): if "
            "they mark pixels not decoded, write NaN there (simbench score --zero-is-hole reads them so)"
        )
    gt_median = float(np.median(gt[ok][finite]))
    if not gt_median > 0:  # (an audit: a ground truth of median 0 divided by zero)
        return [*out, f"the ground truth's median depth is {gt_median:.3g} m: is it a depth map in metres?"]
    ratio = float(np.median(d[finite])) / gt_median
    if not 0.2 <= ratio <= 5.0:
        out.append(
            f"its median depth is {ratio:.3g}x the ground truth's ({gt_median:.3g} m): is it in metres, "
            "and of this scene? (simbench's depth maps are float32 metres)"
        )
    return out


def implausible_columns(column_px: np.ndarray, gt_column_px: np.ndarray) -> list[str]:
    """What makes a decoded column map look like something else (a depth map in metres): its
    median under a hundredth of the ground-truth columns' (projector columns run to ~1800 px)."""
    col = np.asarray(column_px, np.float64)
    gcol = np.asarray(gt_column_px, np.float64)
    c, g = col[np.isfinite(col)], gcol[np.isfinite(gcol)]
    if not c.size or not g.size or np.median(g) <= 0:
        return []
    if abs(float(np.median(c))) < 0.01 * float(np.median(g)):
        return [
            f"its median {float(np.median(c)):.3g} is far below the ground truth's projector columns (median "
            f"{float(np.median(g)):.4g} px): a depth map in metres? (a column map is the decoder's column.npy, "
            "simbench decode --debug-dir)"
        ]
    return []
