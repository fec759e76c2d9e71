"""Fused per-pixel loops of the decoder (numba).

Each kernel replaces a chain of whole-image numpy passes by one loop over the pixels, so an
image-sized intermediate is never written to memory: the decoder is memory-bound (measured on
the 2-core reference machine: ~70 % of a 1280x960 decode was elementwise numpy passes), and a
fused loop reads its inputs once.

Every kernel evaluates the same float32 operations in the same order as the numpy expression it
replaces (the docstrings give it), so results are bit-identical to it; numba is used without
``fastmath`` (no reassociation, no fused multiply-add), and the tests compare each kernel with
its numpy form.  Kernels release the GIL (``nogil``): the decoder runs them in its row-band
threads.  Compiled code is cached on disk (``cache=True``), so only the first process compiles.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = [
    "gabor_fit",
    "wrap_to_pi",
    "gather",
    "absolute_column",
    "match_reference",
    "depth_from_disparity",
    "chain_extent",
    "neighbour_correct",
    "segment_stripes",
    "vote_codes",
]

# error_model="numpy": a float division by zero gives inf/NaN as in numpy instead of raising, which
# also drops the per-division zero test that keeps LLVM from vectorising the loops (measured:
# gabor_fit 15.7 -> 1.6 ms on 480x1280)
_JIT = dict(nogil=True, cache=True, error_model="numpy")


@numba.njit(**_JIT)
def gabor_fit(
    b0, b1, b2, e2, s1m, scm, ssm, sc2m, ss2m, cos1, sin1, re, im, a0, amp, residual
):  # pragma: no cover - compiled
    """Weighted least-squares fringe fit from the window moments, per pixel.

    Inputs (float32, (H, W); ``cos1``/``sin1`` (1, W)): the data moments ``b0 = G*(cI)``,
    ``b1 = G*(cI cos)``, ``b2 = G*(cI sin)``, ``e2 = G*(cI I)`` and the certainty moments
    ``s1 = G*c``, ``sc = G*(c cos)``, ``ss = G*(c sin)``, ``sc2 = G*(c cos2)``, ``ss2 = G*(c sin2)``.
    Outputs: ``a0`` and the carrier-rotated ``re``, ``im`` of the fit, the amplitude
    ``sqrt(re^2 + im^2)`` (0 where the normal equations are singular) and the RMS residual
    relative to ``amp/sqrt 2`` (inf there).  The normal equations ``M p = b`` with
    ``M = [[s1, sc, ss], [sc, scc, scs], [ss, scs, sss]]`` are solved by the adjugate, in the
    operation order of the numpy form (``_solver`` and ``gabor_phase`` in tests/numpy_reference.py).
    """
    h, w = b0.shape
    half = np.float32(0.5)
    zero = np.float32(0.0)
    one = np.float32(1.0)
    s_min = np.float32(0.05)
    det_min = np.float32(1e-4)
    rms = np.float32(np.sqrt(0.5))
    inf = np.float32(np.inf)
    for y in range(h):
        for x in range(w):
            s1 = s1m[y, x]
            sc = scm[y, x]
            ss = ssm[y, x]
            sc2 = sc2m[y, x]
            ss2 = ss2m[y, x]
            c = cos1[0, x]
            s = sin1[0, x]
            scc = half * (s1 + sc2)
            sss = half * (s1 - sc2)
            scs = half * ss2
            c00 = scc * sss - scs * scs
            c01 = ss * scs - sc * sss
            c02 = sc * scs - ss * scc
            c11 = s1 * sss - ss * ss
            c12 = sc * ss - s1 * scs
            c22 = s1 * scc - sc * sc
            det = s1 * c00 + sc * c01 + ss * c02
            good = (s1 > s_min) and (det > det_min * s1 * s1 * s1)
            inv = one / det if good else zero
            inv_s1 = one / s1 if good else zero
            k0 = c00 * inv
            k1 = c01 * inv
            k2 = c02 * inv
            p0 = (c01 * c + c02 * s) * inv
            p1 = (c11 * c + c12 * s) * inv
            p2 = (c12 * c + c22 * s) * inv
            q0 = (c01 * s - c02 * c) * inv
            q1 = (c11 * s - c12 * c) * inv
            q2 = (c12 * s - c22 * c) * inv
            d0 = b0[y, x]
            d1 = b1[y, x]
            d2 = b2[y, x]
            a = k0 * d0 + k1 * d1 + k2 * d2
            r = p0 * d0 + p1 * d1 + p2 * d2
            i = q0 * d0 + q1 * d1 + q2 * d2
            a0[y, x] = a
            re[y, x] = r
            im[y, x] = i
            m = np.sqrt(r * r + i * i)
            e = e2[y, x] - a * d0
            e = e - (c * d1 + s * d2) * r
            e = e - (s * d1 - c * d2) * i
            if e < zero:  # np.maximum(e, 0): NaN stays NaN
                e = zero
            e = np.sqrt(e * inv_s1)
            t = m * rms
            amp[y, x] = m if good else zero
            residual[y, x] = e / t if (good and m > zero) else inf


@numba.njit(**_JIT)
def wrap_to_pi(phase):  # pragma: no cover - compiled
    """In place: ``phase[phase >= pi] -= 2 pi`` (float32; cv2.phase gives [0, 2 pi])."""
    pi = np.float32(np.pi)
    two_pi = np.float32(2 * np.pi)
    flat = phase.reshape(-1)
    for j in range(flat.size):
        if flat[j] >= pi:
            flat[j] -= two_pi


@numba.njit(**_JIT)
def gather(per_stripe, labels, fill, out):  # pragma: no cover - compiled
    """``out = per_stripe[labels]``, ``fill`` where the label is -1."""
    lab = labels.reshape(-1)
    dst = out.reshape(-1)
    for j in range(lab.size):
        s = lab[j]
        dst[j] = per_stripe[s] if s >= 0 else fill


@numba.njit(**_JIT)
def absolute_column(position, wrapped, expected, t, span, cycle, column, index):  # pragma: no cover - compiled
    """Per pixel (float32): ``col0 = (psi + pi) * (t / 2 pi) + W t - 0.5``,
    ``k = rint((expected - col0) / span)``; where ``W >= 0`` and ``k`` is finite:
    ``column = col0 + k span``, ``index = W + L k``; else NaN and -1."""
    pi = np.float32(np.pi)
    scale = t / np.float32(2 * np.pi)
    half = np.float32(0.5)
    nan = np.float32(np.nan)
    pos = position.reshape(-1)
    psi = wrapped.reshape(-1)
    exp = expected.reshape(-1)
    col = column.reshape(-1)
    idx = index.reshape(-1)
    for j in range(pos.size):
        p = pos[j]
        c0 = (psi[j] + pi) * scale + np.float32(p) * t - half
        k = np.float32(np.rint((exp[j] - c0) / span))
        if p >= 0 and np.isfinite(k):
            col[j] = c0 + k * span
            idx[j] = p + cycle * np.int32(k)
        else:
            col[j] = nan
            idx[j] = -1


@numba.njit(**_JIT)
def match_reference(column, table, out):  # pragma: no cover - compiled
    """Linear look-up of each pixel's column in its row of the inverse table: the table's
    last column is NaN, and a column outside ``[0, width]`` (or NaN) gives NaN."""
    h, w = column.shape
    width = table.shape[1] - 2
    fw = np.float32(width)
    nan = np.float32(np.nan)
    for y in range(h):
        for x in range(w):
            c = column[y, x]
            if c >= np.float32(0) and c <= fw:
                fi = np.floor(c)
                if fi >= fw:
                    fi = np.float32(width - 1)
                f = c - fi
                i = np.int64(fi)
                x0 = table[y, i]
                x1 = table[y, i + 1]
                out[y, x] = x0 + f * (x1 - x0)
            else:
                out[y, x] = nan


@numba.njit(**_JIT)
def depth_from_disparity(x_ref, inv_z0, inv_fb, out):  # pragma: no cover - compiled
    """``z = 1 / (1/Z0 + (x - x_ref) / (f B))`` (float32), NaN unless ``z > 0``."""
    h, w = x_ref.shape
    one = np.float32(1.0)
    nan = np.float32(np.nan)
    for y in range(h):
        for x in range(w):
            d = np.float32(x) - x_ref[y, x]
            z = one / (inv_z0 + d * inv_fb)
            out[y, x] = z if z > np.float32(0) else nan


@numba.njit(**_JIT)
def chain_extent(linked_prev, left, right):  # pragma: no cover - compiled
    """Linked stripes before (``left``) and after (``right``) each stripe in its chain."""
    n = linked_prev.size
    start = 0
    for j in range(n):
        if not linked_prev[j]:
            start = j
        left[j] = j - start
    end = n - 1
    for j in range(n - 1, -1, -1):
        right[j] = end - j
        if not linked_prev[j]:
            end = j - 1


@numba.njit(**_JIT)
def neighbour_correct(positions, left, right, cycle, reach, min_support, out, support):  # pragma: no cover - compiled
    """Plurality of the positions predicted by the stripe and its linked neighbours within
    ``reach`` (``W[j + o] - o mod L``); kept when it has ``min_support`` votes and beats every
    other candidate, else -1 (``support`` = its votes, 0 if dropped)."""
    n = positions.size
    counts = np.zeros(cycle, np.int64)
    for j in range(n):
        counts[:] = 0
        for off in range(-reach, reach + 1):
            src = j + off
            ok = (left[j] >= -off) if off < 0 else (right[j] >= off)
            if ok and src >= 0 and src < n:
                p = positions[src]
                if p >= 0:
                    counts[(p - off) % cycle] += 1
        best = 0
        for v in range(1, cycle):
            if counts[v] > counts[best]:
                best = v
        votes = counts[best]
        rival = -1
        for v in range(cycle):
            if v != best and counts[v] > rival:
                rival = counts[v]
        if votes >= min_support and votes > rival:
            out[j] = best
            support[j] = votes
        else:
            out[j] = -1
            support[j] = 0


@numba.njit(**_JIT)
def _bridge(wrapped, valid, y, xl, x, first, lo, hi, omega, tol):  # pragma: no cover - compiled
    """Wraps (0 or 1) across the invalid gap between pixels ``xl`` and ``x`` of row ``y``, or -1.

    ``first`` is the first pixel of the stripe ending at ``xl``.  The phase slope is the mean
    step of that stripe and of the run continuing from ``x`` (up to its first wrap or break;
    the nominal ``omega`` if both have fewer than 2 steps together), in float64; the gap's
    advance ``slope * (x - xl)`` chooses the wrap count ``k``, accepted when the wrapped phase
    at ``x`` lies within ``tol`` of the prediction.
    """
    w = wrapped.shape[1]
    neg_pi = np.float32(-np.pi)
    steps = xl - first
    acc = np.float64(wrapped[y, xl]) - np.float64(wrapped[y, first])
    j = x
    while j + 1 < w and valid[y, j + 1]:
        d = wrapped[y, j + 1] - wrapped[y, j]
        if d < neg_pi or not (d > lo and d < hi):
            break
        j += 1
    steps += j - x
    acc += np.float64(wrapped[y, j]) - np.float64(wrapped[y, x])
    slope = acc / steps if steps >= 2 else omega
    if not (slope > lo and slope < hi):
        return -1
    advance = slope * (x - xl)
    d = np.float64(wrapped[y, x]) - np.float64(wrapped[y, xl])
    two_pi = 2.0 * np.pi
    k = np.floor((advance - d) / two_pi + 0.5)
    if (k == 0.0 or k == 1.0) and abs(d + two_pi * k - advance) <= tol:
        return np.int64(k)
    return -1


@numba.njit(**_JIT)
def segment_stripes(
    wrapped, valid, lo, hi, max_gap, omega, tol, labels, row, start, stop, linked_prev
):  # pragma: no cover - compiled
    """Row-wise stripe segmentation; returns the number of stripes.

    Between pixels ``x-1`` and ``x`` of a row: ``d = psi[x] - psi[x-1]``, a wrap where
    ``d < -pi`` (then ``step = d + 2 pi``), a plausible step when ``lo < step < hi``; with both
    pixels valid the stripe continues (plausible, no wrap), or the next stripe starts linked to
    it (plausible wrap); any other valid pixel starts an unlinked stripe, unless it ends a gap
    of 1 to ``max_gap`` invalid pixels after the row's last stripe that :func:`_bridge`
    crosses: with no wrap the stripe continues after the gap, with one the next starts linked.
    ``row``/``start``/``stop``/``linked_prev`` must hold one entry per possible stripe (H*W).
    """
    h, w = wrapped.shape
    neg_pi = np.float32(-np.pi)
    two_pi = np.float32(2 * np.pi)
    s = -1
    for y in range(h):
        for x in range(w):
            if not valid[y, x]:
                labels[y, x] = -1
                continue
            cont = False
            link = False
            if x > 0 and valid[y, x - 1]:
                d = wrapped[y, x] - wrapped[y, x - 1]
                wrap = d < neg_pi
                step = d + two_pi if wrap else d
                if step > lo and step < hi:
                    cont = not wrap
                    link = wrap
            elif max_gap > 0 and s >= 0 and row[s] == y and x - stop[s] <= max_gap:
                k = _bridge(wrapped, valid, y, stop[s] - 1, x, start[s], lo, hi, omega, tol)
                cont = k == 0
                link = k == 1
            if not cont:
                s += 1
                row[s] = y
                start[s] = x
                linked_prev[s] = link
            labels[y, x] = s
            stop[s] = x + 1
    return s + 1


@numba.njit(**_JIT)
def vote_codes(code, labels, row, start, stop, voting, out, agreement):  # pragma: no cover - compiled
    """Per stripe: share of its pixels with code 1 (float64; pixels of a gap it was bridged
    across are not its own); the code is the majority (ties give 1) or, without voting, the
    middle pixel's; ``agreement`` = share agreeing with it."""
    n = row.size
    for s in range(n):
        y = row[s]
        ones = 0
        count = 0
        for x in range(start[s], stop[s]):
            if labels[y, x] == s:
                ones += code[y, x]
                count += 1
        frac = ones / count if count > 0 else 0.5
        if voting:
            c = 1 if frac >= 0.5 else 0
        else:
            c = 1 if code[y, (start[s] + stop[s] - 1) // 2] else 0
        out[s] = c
        agreement[s] = np.float32(frac if c == 1 else 1.0 - frac)
