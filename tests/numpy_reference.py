"""The decoder's stages as whole-image numpy expressions (their form before the fused C
loops of :mod:`simbench.decode._kernels`); ``tests/test_kernels.py`` checks that each kernel
gives the same bits.  Also the camera model's (:func:`emva_camera`, ``tests/test_camera.py``)."""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from simbench.decode.color import Stripes
from simbench.decode.phase import _basis, gaussian_kernel, magnitude


def _solver(s1, sc, ss, sc2, ss2, cos1, sin1, s_min=0.05):
    """Per-pixel maps turning the window moments (b0, b1, b2) of the data into the fit.

    The normal equations are ``M p = b`` with ``M = [[s1, sc, ss], [sc, scc, scs], [ss, scs,
    sss]]``; with the adjugate ``C`` and ``det``: ``p = C b / det``.  Returned are the rows
    giving ``a0`` and the carrier-rotated ``re = a1 cos + a2 sin``, ``im = a1 sin - a2 cos``
    (so that ``psi = atan2(im, re)``), ``1/s1`` and the mask of solvable pixels.
    """
    scc = 0.5 * (s1 + sc2)
    sss = 0.5 * (s1 - sc2)
    scs = 0.5 * ss2
    c00 = scc * sss - scs * scs
    c01 = ss * scs - sc * sss
    c02 = sc * scs - ss * scc
    c11 = s1 * sss - ss * ss
    c12 = sc * ss - s1 * scs
    c22 = s1 * scc - sc * sc
    det = s1 * c00 + sc * c01 + ss * c02
    good = (s1 > np.float32(s_min)) & (det > 1e-4 * s1 * s1 * s1)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = np.where(good, np.float32(1) / det, np.float32(0))
        inv_s1 = np.where(good, np.float32(1) / s1, np.float32(0))
    k = (c00 * inv, c01 * inv, c02 * inv)
    p = ((c01 * cos1 + c02 * sin1) * inv, (c11 * cos1 + c12 * sin1) * inv, (c12 * cos1 + c22 * sin1) * inv)
    q = ((c01 * sin1 - c02 * cos1) * inv, (c11 * sin1 - c12 * cos1) * inv, (c12 * sin1 - c22 * cos1) * inv)
    return k, p, q, inv_s1, good


def _dot3(m, b, *, out: np.ndarray, tmp: np.ndarray) -> None:
    """``out = m[0]*b[0] + m[1]*b[1] + m[2]*b[2]`` without temporaries."""
    np.multiply(m[0], b[0], out=out)
    for mi, bi in zip(m[1:], b[1:]):
        np.multiply(mi, bi, out=tmp)
        out += tmp


def _conv(img: np.ndarray, kx: np.ndarray, ky: np.ndarray) -> np.ndarray:
    """The Gaussian window sum as OpenCV's separable filter (zero outside the image)."""
    return cv2.sepFilter2D(img, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_CONSTANT)


@lru_cache(maxsize=8)
def _full_solver(shape: tuple[int, int], omega: float, sx: float, sy: float):
    """:func:`_solver` for an all-certain image (reused across captures of one rig)."""
    cos1, sin1, cos2, sin2 = _basis(shape[1], omega)
    kx, ky = gaussian_kernel(sx), gaussian_kernel(sy)
    ones = np.ones(shape, np.float32)
    moments = [_conv(ones * b, kx, ky) for b in (np.float32(1), cos1, sin1, cos2, sin2)]
    out = _solver(*moments, cos1, sin1)
    for group in out:
        for a in group if isinstance(group, tuple) else (group,):
            a.setflags(write=False)
    return out, moments[0]


def gabor_phase(
    intensity: np.ndarray,
    *,
    certainty: np.ndarray,
    period_px: float,
    sigma_x_px: float,
    sigma_y_px: float,
    min_weight: float = 0.05,
) -> tuple:
    h, w = intensity.shape
    omega = round(2.0 * np.pi / period_px, 12)
    kx, ky = gaussian_kernel(sigma_x_px), gaussian_kernel(sigma_y_px)
    cos1, sin1, cos2, sin2 = _basis(w, omega)
    intensity = intensity.astype(np.float32, copy=False)
    c = certainty.astype(np.float32, copy=False)
    if c.min() >= 1.0:
        (k, p, q, inv_s1, good), s1 = _full_solver((h, w), omega, float(sigma_x_px), float(sigma_y_px))
        ci = intensity
    else:
        moments = [_conv(c * b, kx, ky) for b in (np.float32(1), cos1, sin1, cos2, sin2)]
        k, p, q, inv_s1, good = _solver(*moments, cos1, sin1, min_weight)
        s1 = moments[0]
        ci = c * intensity
    b0 = _conv(ci, kx, ky)
    b1 = _conv(ci * cos1, kx, ky)
    b2 = _conv(ci * sin1, kx, ky)
    e2 = _conv(ci * intensity, kx, ky)
    # the maps are fixed per rig; work in preallocated buffers (each fresh image-sized array
    # costs page faults on top of the arithmetic)
    a0, re, im, t = (np.empty_like(b0) for _ in range(4))
    _dot3(k, (b0, b1, b2), out=a0, tmp=t)
    _dot3(p, (b0, b1, b2), out=re, tmp=t)
    _dot3(q, (b0, b1, b2), out=im, tmp=t)
    # I ~ a0 + R cos(w x - theta); the local phase at x is psi = w x - theta = atan2(im, re)
    wrapped = cv2.phase(re, im)
    wrapped[wrapped >= np.pi] -= np.float32(2 * np.pi)
    amp = magnitude(re, im, tmp=t)
    # weighted residual sum of squares: e2 - p.b, with a1 b1 + a2 b2 written through re, im
    u = np.empty_like(b0)
    np.multiply(a0, b0, out=t)
    np.subtract(e2, t, out=e2)
    np.multiply(cos1, b1, out=t)
    np.multiply(sin1, b2, out=u)
    t += u
    t *= re
    e2 -= t
    np.multiply(sin1, b1, out=t)
    np.multiply(cos1, b2, out=u)
    t -= u
    t *= im
    e2 -= t
    np.maximum(e2, 0, out=e2)
    e2 *= inv_s1
    np.sqrt(e2, out=e2)
    np.multiply(amp, np.float32(np.sqrt(0.5)), out=t)
    ok = good & (amp > 0)
    residual = np.full_like(b0, np.inf)
    np.divide(e2, t, out=residual, where=ok)
    return wrapped, np.where(good, amp, np.float32(0)), a0, residual, s1


def segment_stripes(
    wrapped: np.ndarray,
    valid: np.ndarray,
    *,
    period_px: float,
    min_step_ratio: float = 0.3,
    max_step_ratio: float = 3.0,
    max_gap_px: int = 0,
    gap_tolerance_rad: float = np.pi / 4,
) -> Stripes:
    h, w = wrapped.shape
    omega = 2.0 * np.pi / period_px
    d = np.diff(wrapped, axis=1)
    wrap = d < -np.pi
    step = d + np.float32(2 * np.pi) * wrap
    plausible = (step > min_step_ratio * omega) & (step < min(max_step_ratio * omega, 0.9 * np.pi))
    both = valid[:, 1:] & valid[:, :-1]
    cont = both & plausible & ~wrap  # same stripe continues
    linked = both & plausible & wrap  # next stripe of the pattern starts
    starts = np.zeros((h, w), dtype=bool)
    starts[:, 0] = valid[:, 0]
    starts[:, 1:] = valid[:, 1:] & ~cont
    flat_starts = starts.ravel()
    labels = np.cumsum(flat_starts, dtype=np.int64) - 1
    labels = np.where(valid.ravel(), labels, -1).astype(np.int32).reshape(h, w)
    idx = np.flatnonzero(flat_starts)
    row = (idx // w).astype(np.int32)
    start = (idx % w).astype(np.int32)
    stop = np.empty_like(start)
    if idx.size:
        valid_flat = valid.ravel()
        # a stripe ends where the next one starts or at the first invalid pixel after it
        ends = np.flatnonzero(np.diff(np.concatenate([[False], valid_flat, [False]]).astype(np.int8)) == -1)
        nxt = np.searchsorted(ends, idx, side="right")
        run_end = ends[nxt]
        next_start = np.append(idx[1:], h * w)
        row_end = (row.astype(np.int64) + 1) * w
        stop = (np.minimum(np.minimum(run_end, next_start), row_end) - row.astype(np.int64) * w).astype(np.int32)
    linked_prev = np.zeros(idx.size, dtype=bool)
    inner = start > 0
    linked_prev[inner] = linked[row[inner], start[inner] - 1]
    if max_gap_px > 0:
        omega32 = (np.float32(min_step_ratio * omega), np.float32(min(max_step_ratio * omega, 0.9 * np.pi)))
        return _bridge_gaps(
            wrapped, labels, row, start, stop, linked_prev, omega32, omega, max_gap_px, gap_tolerance_rad
        )
    return Stripes(labels=labels, row=row, start=start, stop=stop, linked_prev=linked_prev)


def _bridge_gaps(wrapped, labels, row, start, stop, linked_prev, bounds, omega, max_gap, tol):
    """The gap bridging of segment_stripes as a pass over the unbridged stripes: a stripe that
    starts unlinked after a gap of 1..max_gap invalid pixels behind the row's previous
    (possibly already merged) stripe is merged into it (no wrap in the gap) or linked to it."""
    lo, hi = float(bounds[0]), float(bounds[1])  # compared in float64, as the kernel does
    keep = np.ones(row.size, bool)
    owner = np.arange(row.size)  # stripe each unbridged stripe ends up in
    row, start, stop, linked_prev = row.copy(), start.copy(), stop.copy(), linked_prev.copy()
    cur = -1
    for s in range(row.size):
        y = row[s]
        gap = start[s] - stop[cur] if cur >= 0 else 0
        if cur >= 0 and row[cur] == y and not linked_prev[s] and 1 <= gap <= max_gap:
            xl, x = stop[cur] - 1, start[s]
            steps = (xl - start[cur]) + (stop[s] - 1 - x)
            acc = (float(wrapped[y, xl]) - float(wrapped[y, start[cur]])) + (
                float(wrapped[y, stop[s] - 1]) - float(wrapped[y, x])
            )
            slope = acc / steps if steps >= 2 else omega
            if lo < slope < hi:
                advance = slope * (x - xl)
                d = float(wrapped[y, x]) - float(wrapped[y, xl])
                k = np.floor((advance - d) / (2.0 * np.pi) + 0.5)
                if k in (0.0, 1.0) and abs(d + 2.0 * np.pi * k - advance) <= tol:
                    if k == 0.0:
                        keep[s] = False
                        owner[s] = cur
                        stop[cur] = stop[s]
                        continue
                    linked_prev[s] = True
        cur = s
    new_index = np.cumsum(keep) - 1
    lut = np.append(new_index[owner], -1).astype(np.int32)  # label -1 stays -1
    labels = lut[labels]
    return Stripes(labels=labels, row=row[keep], start=start[keep], stop=stop[keep], linked_prev=linked_prev[keep])


def vote_codes(code: np.ndarray, stripes: Stripes, *, voting: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    # one histogram over (stripe, code) pairs; label -1 (invalid) lands in the first two bins
    key = (stripes.labels.ravel() + 1) * 2 + code.ravel()
    hist = np.bincount(key, minlength=2 * (stripes.count + 1)).reshape(-1, 2)[1:].astype(np.float64)
    counts = hist[:, 0] + hist[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(counts > 0, hist[:, 1] / counts, 0.5)
    if voting:
        out = (frac >= 0.5).astype(np.uint8)
    else:
        mid = (stripes.start + stripes.stop - 1) // 2
        out = code[stripes.row, mid].astype(np.uint8)
    agreement = np.where(out == 1, frac, 1.0 - frac).astype(np.float32)
    return out, agreement, counts.astype(np.int32)


def chain_extent(linked_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = linked_prev.size
    idx = np.arange(n)
    chain_start = np.maximum.accumulate(np.where(~linked_prev, idx, 0)) if n else idx
    chain_id = np.cumsum(~linked_prev) - 1
    last = np.zeros(chain_id.max() + 1 if n else 0, dtype=np.int64)
    np.maximum.at(last, chain_id, idx)
    return idx - chain_start, last[chain_id] - idx


def window_positions_of_stripes(stripe_code, linked_prev, *, order, table, cycle):
    n = stripe_code.size
    h = (order - 1) // 2
    left, right = chain_extent(linked_prev)
    ok = (left >= h) & (right >= order - 1 - h)
    code = np.zeros(n, dtype=np.int64)
    for j in range(order):
        shifted = np.zeros(n, dtype=np.int64)
        off = j - h
        if off < 0:
            shifted[-off:] = stripe_code[: n + off]
        elif off > 0:
            shifted[:-off] = stripe_code[off:]
        else:
            shifted[:] = stripe_code
        code = code * 2 + shifted
    q = table[code]
    ok &= q >= 0
    return np.where(ok, (q + h) % cycle, -1).astype(np.int32)


def drop_broken_links(positions, linked_prev, *, cycle):
    w = positions.astype(np.int64)
    n = w.size
    out = positions.astype(np.int32, copy=True)
    if n < 2:
        return out
    prev, cur = w[:-1], w[1:]
    broken = linked_prev[1:] & (prev >= 0) & (cur >= 0) & ((cur - prev) % cycle != 1)
    idx = np.flatnonzero(broken) + 1
    out[idx] = -1
    out[idx - 1] = -1
    return out


def pool_code_rows(code, wrapped, valid, *, rows, tolerance_rad=np.pi / 4, out_rows=None):
    h, w = code.shape
    r0, r1, _ = (out_rows or slice(0, h)).indices(h)
    pi, tol = np.float32(np.pi), np.float32(tolerance_rad)
    votes = np.where(code, 1, -1).astype(np.int64)
    total = votes.copy()
    for d in range(1, rows + 1):
        for sgn in (1, -1):
            src = np.arange(h) + sgn * d  # each row's voter d rows away
            ok = (src >= 0) & (src < h)
            y, yy = np.flatnonzero(ok), src[ok]
            diff = (wrapped[yy] - wrapped[y]).astype(np.float32)
            diff = np.where(
                diff >= pi, diff - np.float32(2) * pi, np.where(diff < -pi, diff + np.float32(2) * pi, diff)
            )
            gate = valid[yy] & (diff < tol) & (diff > -tol)
            total[y] += np.where(gate, votes[yy], 0)
    return (total >= 0)[r0:r1]


def contested_positions(positions, kept, linked_prev, *, cycle, reach, min_support):
    n = positions.size
    left, right = chain_extent(linked_prev)
    idx = np.arange(n)
    counts = {side: np.zeros((n, cycle), np.int64) for side in ("left", "right")}
    for off in range(-reach, reach + 1):
        if off == 0:
            continue
        src = idx + off
        ok = ((left >= -off) if off < 0 else (right >= off)) & (src >= 0) & (src < n)
        p = np.full(n, -1, np.int64)
        p[ok] = positions[src[ok]]
        ok &= p >= 0
        h = (p - off) % cycle
        ok &= h != kept
        np.add.at(counts["left" if off < 0 else "right"], (idx[ok], h[ok]), 1)
    cl, cr = counts["left"], counts["right"]
    rival = ((cl >= 1) & (cr >= 1) & (cl + cr >= min_support)).any(axis=1)
    return (kept >= 0) & rival


def neighbour_correct(
    positions: np.ndarray,
    linked_prev: np.ndarray,
    *,
    cycle: int,
    reach: int,
    min_support: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    n = positions.size
    if reach <= 0:
        return positions.copy(), (positions >= 0).astype(np.int32)
    left, right = chain_extent(linked_prev)
    preds = np.full((2 * reach + 1, n), -1, dtype=np.int64)
    for k, off in enumerate(range(-reach, reach + 1)):
        src = np.arange(n) + off
        ok = (left >= -off) if off < 0 else (right >= off)
        ok &= (src >= 0) & (src < n)
        p = np.full(n, -1, dtype=np.int64)
        p[ok] = positions[src[ok]]
        good = ok & (p >= 0)
        preds[k] = np.where(good, (p - off) % cycle, -1)
    # votes per candidate position: a one-hot count over the 2*reach+1 predictions
    counts = np.zeros((cycle, n), dtype=np.int16)
    for k in range(preds.shape[0]):
        for v in range(cycle):
            counts[v] += preds[k] == v
    cols = np.arange(n)
    best = counts.argmax(axis=0)
    best_votes = counts[best, cols].astype(np.int64)
    # A tie between different candidates (typical where a chain was linked across a depth
    # edge) is not evidence for either: drop the stripe rather than guess.
    counts[best, cols] = -1
    rival = counts.max(axis=0) if n else np.zeros(0, np.int16)
    keep = (best_votes >= min_support) & (best_votes > rival)
    return np.where(keep, best, -1).astype(np.int32), np.where(keep, best_votes, 0).astype(np.int32)


def absolute_column(
    position: np.ndarray,
    wrapped: np.ndarray,
    expected_column: np.ndarray,
    *,
    period_px: float,
    cycle: int,
) -> tuple[np.ndarray, np.ndarray]:
    t = np.float32(period_px)
    # column_from_phase(psi + 2 pi W) without the float64 round trip
    col0 = (
        (wrapped + np.float32(np.pi)) * (t / np.float32(2 * np.pi)) + position.astype(np.float32) * t - np.float32(0.5)
    )
    span = np.float32(cycle * period_px)
    k = np.rint((expected_column - col0) / span)
    known = (position >= 0) & np.isfinite(k)
    col = np.where(known, col0 + k * span, np.float32(np.nan))
    n = np.where(known, position + cycle * np.nan_to_num(k).astype(np.int32), -1)
    return col.astype(np.float32, copy=False), n.astype(np.int32, copy=False)


def match_reference(column: np.ndarray, table: np.ndarray) -> np.ndarray:
    h, w = column.shape
    stride = table.shape[1]
    width = stride - 2
    # NaN and out-of-range columns interpolate towards the table's NaN column, giving NaN
    inside = column >= 0
    inside &= column <= width  # False for NaN
    cf = np.where(inside, column, np.float32(width + 0.5))
    bad = ~inside
    fi = np.floor(cf)
    fi[~bad & (fi >= width)] = width - 1
    f = cf - fi
    i = fi.astype(np.int32)
    idx = i + (np.arange(h, dtype=np.int32) * stride)[:, None]
    flat = table.ravel()
    x0 = np.take(flat, idx)
    x1 = np.take(flat, idx + 1)
    return x0 + f * (x1 - x0)


def depth_from_disparity(x_ref: np.ndarray, *, focal_px: float, baseline_m: float, z0_m: float) -> np.ndarray:
    h, w = x_ref.shape
    d = np.arange(w, dtype=np.float32)[None, :] - x_ref
    inv = np.float32(1.0 / z0_m) + d * np.float32(1.0 / (focal_px * baseline_m))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.float32(1.0) / inv
    return np.where(z > 0, z, np.float32(np.nan))


def per_pixel(per_stripe: np.ndarray, labels: np.ndarray, fill) -> np.ndarray:
    ext = np.empty(per_stripe.size + 1, dtype=per_stripe.dtype)
    ext[:-1] = per_stripe
    ext[-1] = fill
    return ext[labels]


def triangulate_columns(column_px: np.ndarray, rig, *, rows: np.ndarray = None, cols: np.ndarray = None) -> np.ndarray:
    """simbench.rig.triangulate_columns in numpy (float64), the operation order the C loop keeps:
    a fixed number of Newton steps per undistortion and of fixed-point steps, and R^T (X - t)
    summed term by term (a BLAS matmul may fuse or reorder them)."""
    from simbench.optics import undistort_projector_columns
    from simbench.rig import COLUMN_NEWTON_STEPS, TRIANGULATION_ITERATIONS

    cam, prj = rig.camera, rig.projector
    col = np.asarray(column_px, dtype=np.float64)
    if rows is None:
        h, w = col.shape
        rx = ((np.arange(w) - cam.cx_px) / cam.focal_px)[None, :]
        ry = ((np.arange(h) - cam.cy_px) / cam.focal_px)[:, None]
    else:
        rx = (np.asarray(cols, dtype=np.float64) - cam.cx_px) / cam.focal_px
        ry = (np.asarray(rows, dtype=np.float64) - cam.cy_px) / cam.focal_px
    r = rig.rotation
    t = np.asarray(rig.position_m)

    def plane_depth(ideal_col: np.ndarray) -> np.ndarray:
        a = (ideal_col - prj.cx_px) / prj.focal_px
        nx, ny, nz = r[0, 0] - a * r[0, 2], r[1, 0] - a * r[1, 2], r[2, 0] - a * r[2, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            return (nx * t[0] + ny * t[1] + nz * t[2]) / (nx * rx + ny * ry + nz)

    if prj.has_distortion:
        ideal = undistort_projector_columns(col, ry, prj, iterations=COLUMN_NEWTON_STEPS)
        if not rig.is_rectified:
            for _ in range(TRIANGULATION_ITERATIONS):
                z = plane_depth(ideal)
                x0, x1, x2 = z * rx - t[0], z * ry - t[1], z - t[2]
                yp = x0 * r[0, 1] + x1 * r[1, 1] + x2 * r[2, 1]
                zp = x0 * r[0, 2] + x1 * r[1, 2] + x2 * r[2, 2]
                with np.errstate(divide="ignore", invalid="ignore"):
                    y_prj = yp / zp
                ideal = undistort_projector_columns(
                    col, np.where(np.isfinite(y_prj), y_prj, ry), prj, iterations=COLUMN_NEWTON_STEPS
                )
        col = ideal
    z = plane_depth(col)
    return np.where(np.isfinite(z) & (z > 0), z, np.nan)


def plane_fit_error(depth_m: np.ndarray, camera, *, mask: np.ndarray | None = None, min_points: int = 100) -> dict:
    """simbench.metrics.plane_fit_error as first written: every pixel's point, then the masked
    ones (the plane fit itself is simbench.metrics.fit_plane's)."""
    from simbench.metrics import fit_plane
    from simbench.rig import pixel_rays

    pts = pixel_rays(camera) * np.asarray(depth_m, dtype=np.float64)[..., None]
    ok = np.isfinite(pts[..., 2])
    if mask is not None:
        ok &= mask
    return fit_plane(pts[ok], min_points=min_points)


def grey_frame(image) -> np.ndarray:
    """simbench.decode.temporal.grey_frame as first written: numpy's mean over the channels."""
    img = np.asarray(image)
    scale = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
    return (img.astype(np.float32) / np.float32(scale)).mean(axis=-1)


def depth_errors(depth_m, gt_depth_m, *, region, exclude=None, outlier_mm: float = 5.0) -> dict:
    """simbench.metrics.depth_errors' error scores as first written: whole-image masks, float64
    maps, numpy's median and percentile."""
    d = np.asarray(depth_m, dtype=np.float64)
    g = np.asarray(gt_depth_m, dtype=np.float64)
    region = region & np.isfinite(g)
    valid = region & np.isfinite(d)
    scored = valid if exclude is None else valid & ~exclude
    err = (d[scored] - g[scored]) * 1000.0
    a = np.abs(err)
    n_region = int(region.sum())
    n_valid = int(valid.sum())
    nan = float("nan")
    return {
        "n_region": n_region,
        "n_valid": n_valid,
        "completeness": float(np.int64(n_valid) / n_region) if n_region else nan,
        "n_scored": int(scored.sum()),
        "mae_mm": float(a.mean()) if a.size else nan,
        "rmse_mm": float(np.sqrt(np.mean(err**2))) if a.size else nan,
        "median_mm": float(np.median(a)) if a.size else nan,
        "p95_mm": float(np.percentile(a, 95)) if a.size else nan,
        "max_mm": float(a.max()) if a.size else nan,
        "bias_mm": float(err.mean()) if a.size else nan,
        "outlier_share": float(np.mean(a > outlier_mm)) if a.size else nan,
    }


def bounded_mean(values, s0, s1, *, width_px, square=False):
    """simbench.decode.color._bounded_mean as plain numpy: double prefix sums, a gather of both ends."""
    if square:
        values = values.astype(np.float64) ** 2
    h, w = values.shape
    n = np.minimum(int(width_px), s1 - s0)
    w0 = np.clip(np.arange(w) - int(width_px) // 2, s0, s1 - n)
    cs = np.zeros((h, w + 1), np.float64)
    np.cumsum(values, axis=1, dtype=np.float64, out=cs[:, 1:])
    return (np.take_along_axis(cs, w0 + n, 1) - np.take_along_axis(cs, w0, 1)) / n


def normalize_channels(rgb, *, half, min_span, clamp_ends=False):
    """simbench.decode.color.normalize_channels as it was in OpenCV and numpy: per channel
    cv2.erode / cv2.dilate over 1 x (2 half + 1), each cv2.blur'ed over as many, the range's
    division where it reaches min_span; ``clamp_ends`` (rows wider than 4 half): the smoothed
    extrema of columns 2 half and W - 1 - 2 half replicated over the 2 half columns beyond them."""
    kernel = np.ones((1, 2 * half + 1), np.uint8)
    box = (2 * half + 1, 1)
    out = np.empty(rgb.shape, np.float32)
    spans = np.empty(rgb.shape, np.float32)
    for c in range(3):
        v = np.ascontiguousarray(rgb[..., c], dtype=np.float32)
        lo = cv2.blur(cv2.erode(v, kernel, borderType=cv2.BORDER_REPLICATE), box, borderType=cv2.BORDER_REPLICATE)
        hi = cv2.blur(cv2.dilate(v, kernel, borderType=cv2.BORDER_REPLICATE), box, borderType=cv2.BORDER_REPLICATE)
        w = v.shape[1]
        if clamp_ends and w > 4 * half:
            q = 2 * half
            for a in (lo, hi):
                a[:, :q] = a[:, q : q + 1]
                a[:, w - q :] = a[:, w - 1 - q : w - q]
        span = hi - lo
        ok = span >= np.float32(min_span)
        with np.errstate(divide="ignore", invalid="ignore"):
            np.divide(v - lo, span, out=out[..., c], where=ok)
        out[..., c][~ok] = 0.0
        spans[..., c] = np.where(ok, span, 0.0)
    return out, spans


def albedo_proxy(rgb, k, *, share):
    """The albedo proxy of simbench.decode.color.albedo_gain as it was in numpy."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        strongest = np.maximum(np.maximum(k[..., 0], k[..., 1]), k[..., 2])[..., None]
        has = k >= np.float32(share) * strongest
        has &= k > 0
        norm = np.where(has, np.maximum(rgb, 0.0) / np.where(has, k, 1.0), 0.0)
        inv2 = np.where(has, 1.0 / np.maximum(k, 1e-12) ** 2, 0.0)
        both = has[..., 0] & has[..., 1]
        w_pair = np.where(both, 1.0 / np.where(both, inv2[..., 0] + inv2[..., 1], 1.0), 0.0)
        w_fringe = np.where(has[..., 2], k[..., 2] ** 2, 0.0)
        total = w_pair + w_fringe
        proxy = np.where(total > 0, (w_pair * (norm[..., 0] + norm[..., 1]) + w_fringe * norm[..., 2]) / total, 0.0)
    return proxy, total > 0


def albedo_step_ratio(g, *, t, n=None):
    """The step ratio max(a, b) / min(a, b) of simbench.decode.color.albedo_edges (a, b: the means
    of the n = 2 t values left and right of each column, plus their floor), and the old score, its
    logarithm |log a - log b| as float32; ``n`` another window (the refinement's t), the row
    padded by 2 t either side all the same (so that the prefix sums are the same numbers)."""
    pad = 2 * t
    n = pad if n is None else n
    h, w = g.shape
    cs = np.zeros((h, w + 2 * pad + 1), np.float64)
    np.cumsum(np.pad(g, ((0, 0), (pad, pad)), mode="edge"), axis=1, dtype=np.float64, out=cs[:, 1:])
    c = pad + 1
    left = (cs[:, c : c + w] - cs[:, c - n : c - n + w]) / n
    right = (cs[:, c + n : c + n + w] - cs[:, c : c + w]) / n
    eps = 1e-3 + 0.02 * np.maximum(left, right)
    a, b = left + eps, right + eps
    return np.maximum(a, b) / np.minimum(a, b), np.abs(np.log(a) - np.log(b)).astype(np.float32)


def side_means(rgb, ys, xs, *, m, rows_mean):
    """The side means of simbench.decode.color.fringe_confirmed as they were in numpy: per channel
    (its rows averaged by ``rows_mean``), prefix sums over the rows holding a step, padded by m
    values each side; (n, 6) float64, left and right of channel 0, 1, 2."""
    rows, row_of = np.unique(ys, return_inverse=True)
    c = xs + m + 1
    out = []
    for ch in range(3):
        g = rows_mean(np.ascontiguousarray(rgb[..., ch], np.float32))[rows].astype(np.float64)
        cs = np.zeros((rows.size, g.shape[1] + 2 * m + 1))
        np.cumsum(np.pad(g, ((0, 0), (m, m)), mode="edge"), axis=1, out=cs[:, 1:])
        out += [(cs[row_of, c] - cs[row_of, c - m]) / m, (cs[row_of, c + m] - cs[row_of, c]) / m]
    return np.stack(out, axis=1)


def column_segments(
    y0,
    x0,
    sign,
    *,
    stop,
    edge,
    frame,
    longest,
):
    """simbench.decode.color._column_segments as it was in numpy."""
    h = stop.shape[0] - 1
    end = np.full(y0.shape, -1)
    rim = np.zeros(y0.shape, bool)
    alive = (y0 >= 0) & (y0 < h)
    for r in range(longest):
        y = y0 + sign * r
        alive &= (y >= 0) & (y < h)
        if not alive.any():
            break
        idx = np.flatnonzero(alive)
        yi = y[idx]
        at = (yi, x0[idx]) if sign == 1 else (np.maximum(yi - 1, 0), x0[idx])
        far = stop[at] & ((yi > 0) | (sign == 1))
        end[idx[far & edge[at]]] = r + 1
        alive[idx[far]] = False
        border = (~far & (yi == (h - 1 if sign == 1 else 0))) | (far & ~edge[at] & frame[at[0]])
        end[idx[border]] = r + 1
        rim[idx[border]] = True
        alive[idx[border]] = False
    return end, rim


def albedo_edges(g, *, t, ratio_min, strip_min=np.inf, log_score=False):
    """Cuts where the step ratio exceeds ratio_min and is the largest within t columns (ends
    replicated), never within 2 t - 1 columns of the left end or 2 t of the right; with
    ``log_score`` as it was decided before (the float32 logarithm against its window maximum
    from cv2.dilate, the threshold log(ratio_min) in float32)."""
    ratio, score = albedo_step_ratio(g, t=t)
    if log_score:
        peak = cv2.dilate(score, np.ones((1, 2 * t + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
        cuts = (score >= peak) & (score > np.float32(np.log(ratio_min)))
    else:
        padded = np.pad(ratio, ((0, 0), (t, t)), mode="edge")
        peak = np.lib.stride_tricks.sliding_window_view(padded, 2 * t + 1, axis=1).max(axis=2)
        cuts = (ratio >= peak) & (ratio > ratio_min)
    n = 2 * t
    cuts[:, : n - 1] = False
    cuts[:, max(0, g.shape[1] - n) :] = False
    # each cut moved to the column within t (and the same limits) where the ratio over t values
    # either side is the largest, the first of equals
    narrow, _ = albedo_step_ratio(g, t=t, n=t)
    # the side the narrow windows' mean is larger on (prefix sums as the ratio's)
    pad = 2 * t
    cs = np.zeros((g.shape[0], g.shape[1] + 2 * pad + 1), np.float64)
    np.cumsum(np.pad(g, ((0, 0), (pad, pad)), mode="edge"), axis=1, dtype=np.float64, out=cs[:, 1:])
    c = pad + 1 + np.arange(g.shape[1])
    up = (cs[:, c + t] - cs[:, c]) > (cs[:, c] - cs[:, c - t])
    out = np.zeros_like(cuts)
    half = t // 2
    w = g.shape[1]
    for y, x in zip(*np.nonzero(cuts)):
        lo, hi = max(n - 1, x - t), min(w - n - 1, x + t)
        best = lo + int(np.argmax(narrow[y, lo : hi + 1]))
        out[y, best] = True
        # a dark strip's far edge: on the darker side, half a period to a period away, rising the
        # other way, over strip_min, the largest within half a period either side
        a0, a1 = (best - t, best - half - 1) if up[y, best] else (best + half + 1, best + t)
        far, top = -1, strip_min
        for j in range(max(n - 1, a0), min(w - n - 1, a1) + 1):
            v = narrow[y, j]
            if up[y, j] == up[y, best] or not v > top:
                continue
            if (narrow[y, max(0, j - half) : min(w, j + half + 1)] > v).any():
                continue
            far, top = j, v
        if far >= 0:
            out[y, far] = True
    return out


def overlay_weights(raw, span, *, unmixing, half, floor):
    """simbench.decode.color.overlay_weights as it was in OpenCV and numpy."""
    mean = cv2.blur(np.ascontiguousarray(raw, dtype=np.float32), (2 * half + 1, 1), borderType=cv2.BORDER_REPLICATE)
    level = np.maximum(mean, 0.0) + np.float32(floor)
    u = np.eye(3) if unmixing is None else np.asarray(unmixing, np.float64)
    var_u = cv2.transform(level, (u * u).astype(np.float32)).reshape(raw.shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(span > 0, var_u / np.maximum(span, 1e-12) ** 2, np.inf).astype(np.float32)
        w_code = (1.0 / (rel[..., 0] + rel[..., 1])).astype(np.float32)
        w_fringe = (1.0 / rel[..., 2]).astype(np.float32)
    return w_code, w_fringe


def weighted_intensity(rgb, w_code, w_fringe):
    """simbench.decode.phase's ``weighted`` intensity as it was in numpy."""
    num = w_code * (rgb[..., 0] + rgb[..., 1]) + w_fringe * rgb[..., 2]
    den = w_code + w_fringe
    return np.divide(num, den, out=np.zeros(num.shape, np.float32), where=den > 0).astype(np.float32, copy=False)


def normalized_color_code(rgb, span):
    """simbench.decode.color.normalized_color_code as it was in numpy."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    has_r, has_g = span[..., 0] > 0, span[..., 1] > 0
    half = np.where(span[..., 2] > 0, np.float32(0.5) * b, np.float32(0.25))
    r = np.where(has_r | ~has_g, r, half)
    g = np.where(has_g | ~has_r, g, half)
    return r >= g


def segment_visibility(proxy, s0, s1, *, period_px, width_px):
    """The albedo flattening's fringe visibility per pixel as it was in numpy (before
    simbench/_ckernels.c's albedo_segments): the standard deviation over the mean of the proxy
    averaged over rows, over the window kept inside the segment narrowed by half a period at
    each end where it has room."""
    from simbench.decode import color

    pv = color._rows_mean(proxy)
    m = color._visibility_margin_px(period_px)
    room = (s1 - s0) > 2 * m + 2
    a0 = np.where(room, s0 + m, s0)
    a1 = np.where(room, s1 - m, s1)
    mu = color._bounded_mean(pv, a0, a1, width_px=width_px)
    var = color._bounded_mean(pv, a0, a1, width_px=width_px, square=True) - mu * mu
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(mu > 0, np.sqrt(np.maximum(var, 0.0)) / np.where(mu > 0, mu, 1.0), 0.0).astype(np.float32)


def crease_bias(column, *, reach, factor, max_step, rows_reach=0, trusted=None):
    """simbench.decode.depth.crease_bias as whole-row numpy passes: ``factor`` times the second
    difference over ``reach`` either side where no step within reach is over ``max_step`` or NaN
    (a prefix count of broken steps), else NaN; then down the columns the mean of the finite ones
    within ``rows_reach`` rows (float64 running sums, rows entering and leaving in order) where the
    pixel's own is finite and the mean > 0, else 0."""
    c = np.asarray(column, np.float32)
    h, w = c.shape
    v = np.full((h, w), np.nan, np.float32)
    span = 2 * reach
    if reach >= 1 and w > span:
        d2 = c[:, span:] - np.float32(2.0) * c[:, reach : w - reach] + c[:, : w - span]
        with np.errstate(invalid="ignore"):
            broken = ~(np.abs(np.diff(c, axis=1)) <= np.float32(max_step))
        if trusted is not None:
            broken |= ~(trusted[:, 1:] & trusted[:, :-1])
        breaks = np.zeros((h, w), np.int32)
        np.cumsum(broken, axis=1, out=breaks[:, 1:])
        whole = breaks[:, span:] == breaks[:, : w - span]
        v[:, reach : w - reach] = np.where(whole, np.float32(factor) * d2, np.float32(np.nan))
    fin = np.isfinite(v)
    z = np.where(fin, v, 0.0).astype(np.float64)
    sums = np.zeros(w, np.float64)
    counts = np.zeros(w, np.int64)
    for r in range(min(h, rows_reach + 1)):
        sums += z[r]
        counts += fin[r]
    out = np.zeros((h, w), np.float32)
    for r in range(h):
        if r > 0:
            if r + rows_reach < h:
                sums += z[r + rows_reach]
                counts += fin[r + rows_reach]
            if r - rows_reach - 1 >= 0:
                sums -= z[r - rows_reach - 1]
                counts -= fin[r - rows_reach - 1]
        with np.errstate(invalid="ignore", divide="ignore"):
            m = np.where(counts > 0, (sums / np.maximum(counts, 1)).astype(np.float32), np.float32(0.0))
        out[r] = np.where(fin[r] & (m > 0), m, np.float32(0.0))
    return out


def edge_bend(column, *, reach, fit, max_step):
    """simbench.decode.depth.edge_bend_bias in numpy: per row, the runs of finite columns with
    steps of at most ``max_step``; at each end a hole or larger step ends, in a run of at least
    ``reach + fit``, the least-squares line through the ``fit`` columns from ``reach`` off the end
    (float64 sums in order from the end: cumulative sums), extrapolated to the ``reach`` columns
    nearest the end; |column - line| there as float32, the larger of two, else 0."""
    c = np.asarray(column, np.float32)
    h, w = c.shape
    out = np.zeros((h, w), np.float32)
    if reach < 1 or fit < 2:
        return out
    n = float(fit)
    su, suu = n * (n - 1.0) / 2.0, (n - 1.0) * n * (2.0 * n - 1.0) / 6.0
    det = n * suu - su * su
    with np.errstate(invalid="ignore"):
        joined = np.abs(np.diff(c, axis=1)) <= np.float32(max_step)
    for r in range(h):
        fin = np.isfinite(c[r])
        x = 0
        while x < w:
            if not fin[x]:
                x += 1
                continue
            e = x
            while e + 1 < w and joined[r, e]:
                e += 1
            if e - x + 1 >= reach + fit:
                for end, step, has_edge in ((e, -1, e + 1 < w), (x, 1, x > 0)):
                    if not has_edge:
                        continue
                    f0 = end + step * reach
                    u = np.arange(fit, dtype=np.float64)
                    y = c[r, f0 + step * np.arange(fit)].astype(np.float64)
                    sy, suy = np.cumsum(y)[-1], np.cumsum(u * y)[-1]
                    slope = (n * suy - su * sy) / det
                    icpt = (sy - slope * su) / n
                    k = np.arange(1, reach + 1, dtype=np.float64)
                    xs = f0 - step * np.arange(1, reach + 1)
                    d = np.abs((c[r, xs].astype(np.float64) - (icpt - slope * k)).astype(np.float32))
                    out[r, xs] = np.maximum(out[r, xs], d)
            x = e + 1
    return out


def emva_camera(
    radiance: np.ndarray,
    *,
    camera,
    electrons_per_radiance: float | np.ndarray,
    exposure_s: float,
    white_balance: np.ndarray | None = (1.0, 1.0, 1.0),
    rng=None,
) -> np.ndarray:
    """:func:`simbench.sim.camera.emva_camera` as whole-image numpy float64 passes (its form before
    the C loops of ``simbench/_lens.c``)."""
    from simbench.sim.camera import bayer_mosaic, demosaic, fixed_pattern

    rad = np.asarray(radiance, dtype=np.float64)
    if rad.ndim != 3 or rad.shape[2] != 3:
        raise ValueError(f"radiance must have shape (H, W, 3), got {rad.shape}")
    if not np.all(np.isfinite(rad)):
        raise ValueError("radiance contains NaN or inf")
    scale = np.asarray(electrons_per_radiance, dtype=np.float64)
    if scale.shape != (3,) or not np.all(scale > 0):
        raise ValueError(f"electrons_per_radiance must be three numbers > 0, got {electrons_per_radiance!r}")
    wb = np.asarray(white_balance, dtype=np.float64)
    if wb.shape != (3,) or not np.all(np.isfinite(wb) & (wb > 0)):
        raise ValueError(f"white_balance must be three finite numbers > 0, got {white_balance!r}")
    mean_e = np.clip(rad, 0.0, None) * scale
    gain = camera.gain * wb
    if camera.cfa != "none":
        mean_e = bayer_mosaic(mean_e, pattern=camera.cfa)
        gain = bayer_mosaic(np.broadcast_to(gain, rad.shape), pattern=camera.cfa)
    shape = mean_e.shape
    if camera.prnu > 0 or camera.dsnu_e > 0:
        gain_fp, dark_fp = fixed_pattern(shape, seed=camera.fixed_pattern_seed, prnu=camera.prnu, dsnu_e=camera.dsnu_e)
        mean_e = mean_e * gain_fp
    else:
        dark_fp = 0.0
    mean_e = mean_e + camera.dark_current_e_s * exposure_s
    if camera.noise:
        gen = np.random.default_rng(rng)
        electrons = gen.poisson(np.minimum(mean_e, 1e12)).astype(np.float64)
        if camera.dark_noise_e > 0:
            electrons += gen.normal(0.0, camera.dark_noise_e, size=shape)
    else:
        electrons = mean_e
    electrons = np.minimum(electrons + dark_fp, camera.full_well_e)
    dn = np.clip(np.rint(gain * electrons + camera.offset_dn), 0, camera.max_dn)
    out = dn.astype(np.uint8 if camera.bits == 8 else np.uint16)
    if camera.cfa != "none":
        out = demosaic(out, pattern=camera.cfa, method=camera.demosaic)
    return out


def centroid_corrected(
    fits,
    certainty,
    *,
    sigma_y_px,
    period_px,
    keep=None,
):
    """simbench.decode.phase.centroid_corrected as it was in numpy."""
    from simbench.decode import phase

    psis = [np.asarray(wrapped, np.float32) for wrapped, _ in fits]
    sigmas = [float(sx) for _, sx in fits]
    c = np.ascontiguousarray(certainty, np.float32)
    rx, ry = len(phase.gaussian_kernel(sigmas[0])) // 2, len(phase.gaussian_kernel(sigma_y_px)) // 2
    # the widest window's cut pixels hold every narrower one's
    cut = phase._not_whole(c, rx, ry)
    cand = cut if keep is None else cut & ~keep
    cols = np.flatnonzero(cand.any(axis=0))
    outs = [psi.copy() for psi in psis]
    if cols.size == 0:
        return outs
    reach = phase.rate_reach_px(sigmas[0], period_px)
    margin = rx + reach + 1
    omega = np.float32(2.0 * np.pi / period_px)
    h, w = c.shape
    for run in np.split(cols, np.flatnonzero(np.diff(cols) > 2 * margin) + 1):
        # a block wide and tall enough that every pixel read holds its whole window within it
        a, b = max(0, int(run[0]) - margin), min(w, int(run[-1]) + margin + 1)
        in_rows = np.flatnonzero(cand[:, a:b].any(axis=1))
        y0, y1 = max(0, int(in_rows[0]) - ry), min(h, int(in_rows[-1]) + ry + 1)
        cs = np.ascontiguousarray(c[y0:y1, a:b])
        block_cut, block_cand = cut[y0:y1, a:b], cand[y0:y1, a:b]
        # OpenCV's filters take a row's last few columns (its width modulo the vector width) in
        # scalar code, a last bit off the vector code's: a block as wide as a whole number of the
        # widest vectors (the outside uncertain, as the image's) gives each pixel the same bits
        # wherever the block starts - which follows the row band's cut pixels (measured: the
        # right border's pixels 1 ulp apart between 1 and 2 bands on scenes/robust_printed.toml)
        padded = np.zeros((y1 - y0, -(-(b - a) // phase.CENTROID_BLOCK_ALIGN) * phase.CENTROID_BLOCK_ALIGN), np.float32)
        padded[:, : b - a] = cs
        dxs = [phase._centroid(padded, sx, sigma_y_px)[:, : b - a] for sx in sigmas]
        with np.errstate(invalid="ignore"):
            # a wholly uncertain window (a shadow wider than it) has no phase to step: its fit
            # returns 0, which would pull the rate towards 0
            centred = (~block_cut & (cs > np.float32(0.5))) | (np.abs(dxs[0]) <= np.float32(phase.CENTRED_PX))
        needs = []
        for psi, dx in zip(psis, dxs):
            with np.errstate(invalid="ignore"):
                needs.append(block_cand & (np.abs(dx) > np.float32(phase.CENTRED_PX)) & np.isfinite(psi[y0:y1, a:b]))
        rows = np.flatnonzero(np.logical_or.reduce([n.any(axis=1) for n in needs]))
        if rows.size == 0:
            continue
        # the rate's steps on the rows some fit needs, once for all fits (each row's sums its own)
        ps, cr = psis[0][y0:y1, a:b][rows], centred[rows]
        step = np.zeros(ps.shape, np.float32)
        step[:, 1:-1] = phase._wrap(ps[:, 2:] - ps[:, :-2]) * np.float32(0.5)
        good = np.zeros(ps.shape, bool)
        good[:, 1:-1] = cr[:, 1:-1] & cr[:, 2:] & cr[:, :-2]
        good &= np.isfinite(step)
        # the steps in fixed point (2^-20 rad), summed as integers: a window's sum is then exact
        # wherever its block starts, so the result does not follow the block's extent
        q = np.where(good, np.rint(step * np.float32(phase.STEP_SCALE)), np.float32(0.0)).astype(np.int64)
        zero = np.zeros((rows.size, 1), np.int64)
        sq = np.concatenate([zero, np.cumsum(q, axis=1)], axis=1)
        sn = np.concatenate([zero, np.cumsum(good, axis=1, dtype=np.int64)], axis=1)
        for psi, out, dx, need in zip(psis, outs, dxs, needs):
            ys, xs = np.nonzero(need)
            if ys.size == 0:
                continue
            row_of = np.searchsorted(rows, ys)
            d = dx[ys, xs]
            # [x, x + reach] where the centre lies right of the pixel, [x - reach, x] left; within the block
            lo = np.where(d > 0, xs, np.maximum(xs - reach, 0))
            hi = np.where(d > 0, np.minimum(xs + reach + 1, b - a), xs + 1)
            sv = (sq[row_of, hi] - sq[row_of, lo]).astype(np.float64) / phase.STEP_SCALE
            sc = sn[row_of, hi] - sn[row_of, lo]
            rate = (sv / np.maximum(sc, 1.0)).astype(np.float32)
            bias = np.where(sc > 0, (rate - omega) * d, np.float32(0.0))
            yy, xx = ys + y0, xs + a
            out[yy, xx] = phase._wrap(psi[yy, xx] - bias)
    return outs


def crease_apex_bias(
    bias,
    column_px,
    *,
    scale_px,
    depth_sign,
    peak_px,
    apex_px,
    apex_factor,
    lobe_share,
    min_px=0.0,
):
    """simbench.decode.depth.crease_apex_bias as it was: every step over the whole image."""
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
    d2 = np.full((h, w), np.nan, np.float32)
    if w > 2 * L:
        # in the concave sense: positive where crease_bias predicts a bias
        d2[:, L:-L] = np.float32(-np.sign(depth_sign)) * (c[:, 2 * L :] - np.float32(2.0) * c[:, L:-L] + c[:, : -2 * L])
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
    fold = apex & known.astype(bool) & (deepest >= np.float32(-lobe_share) * mean)
    if not fold.any():
        return b
    reach = np.ones((1, 2 * int(apex_px) + 1), np.uint8)
    near = cv2.dilate(fold.view(np.uint8), reach).astype(bool)
    raised = cv2.dilate(np.where(fold, b, np.float32(0.0)), reach) * np.float32(apex_factor)
    return np.where(near, np.maximum(b, raised), b).astype(np.float32)
