"""Stage 3: stripe order from De Bruijn windows, with neighbour check and correction
(paper Sec. 5.3).

Each stripe's window is the codes of the stripes around it (for order 3: previous, own, next,
as paper Eq. 3); the window's place in the cycle gives the stripe's position W.  Successive
linked stripes must have successive positions, so each neighbour within ``reach`` also predicts
W; the plurality of the predictions wins, and a stripe that no neighbour confirms is dropped.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from simbench.decode import _kernels

if TYPE_CHECKING:
    from simbench.decode.color import Stripes

__all__ = [
    "chain_extent",
    "window_positions_of_stripes",
    "neighbour_correct",
    "drop_broken_links",
    "contested_positions",
    "CODE_VOTE_PERIODS",
    "uncertain_positions",
    "keep_certain_sides",
    "keep_straddler_parts",
    "stripe_floor",
]


def chain_extent(linked_prev: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """How many linked stripes precede and follow each stripe in its chain.

    Returns
    -------
    left, right : ndarray, shape (S,), int64
    """
    linked_prev = np.ascontiguousarray(linked_prev, dtype=bool)
    left = np.empty(linked_prev.size, np.int64)
    right = np.empty(linked_prev.size, np.int64)
    _kernels.chain_extent(linked_prev, left, right)
    return left, right


def window_positions_of_stripes(
    stripe_code: np.ndarray,
    linked_prev: np.ndarray,
    *,
    order: int,
    table: np.ndarray,
    cycle: int,
) -> np.ndarray:
    """Position W in the De Bruijn cycle of each stripe from its window of ``order`` codes.

    The window of stripe ``j`` is stripes ``j - h .. j - h + order - 1`` with
    ``h = (order - 1) // 2``; it must lie inside one linked chain.

    Returns
    -------
    ndarray, shape (S,), int32; -1 where the window is incomplete or unknown
    """
    left, right = chain_extent(linked_prev)
    out = np.empty(stripe_code.size, np.int32)
    _kernels.window_positions(
        np.ascontiguousarray(stripe_code, dtype=np.uint8),
        left,
        right,
        order,
        np.ascontiguousarray(table, dtype=np.int32),
        cycle,
        out,
    )
    return out


def neighbour_correct(
    positions: np.ndarray,
    linked_prev: np.ndarray,
    *,
    cycle: int,
    reach: int,
    min_support: int = 2,
) -> tuple[np.ndarray, np.ndarray]:
    """Check each stripe's W against its linked neighbours and correct it by plurality.

    Parameters
    ----------
    positions : ndarray, shape (S,), int32; W per stripe, -1 unknown
    linked_prev : ndarray, shape (S,), bool
    cycle : int
        De Bruijn cycle length L.
    reach : int
        Neighbours on each side that vote; 0 turns the correction off.
    min_support : int
        Votes the winner needs; with fewer the stripe becomes unknown (-1).

    Returns
    -------
    corrected : ndarray, shape (S,), int32
    support : ndarray, shape (S,), int32; number of predictions agreeing with the result

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Sec. 5.3 (neighbour correction of the stripe
       order).
    """
    n = positions.size
    if reach <= 0:
        return positions.copy(), (positions >= 0).astype(np.int32)
    positions = np.ascontiguousarray(positions, dtype=np.int32)
    left, right = chain_extent(linked_prev)
    out = np.empty(n, np.int32)
    support = np.empty(n, np.int32)
    # A tie between different candidates (typical where a chain was linked across a depth
    # edge) is not evidence for either: the stripe is dropped rather than guessed.
    _kernels.neighbour_correct(positions, left, right, cycle, reach, min_support, out, support)
    return out, support


def drop_broken_links(positions: np.ndarray, linked_prev: np.ndarray, *, cycle: int) -> np.ndarray:
    """Drop both stripes of every link whose positions do not follow each other.

    Linked stripes must have successive W (``W[s] = W[s-1] + 1 mod L``).  After the
    neighbour correction a link that breaks this rule marks a depth edge the phase did not
    show - typically a step whose disparity is close to a whole number of periods, so the
    wrapped phase runs on smoothly across it and one stripe straddles both surfaces.  Which
    of its pixels lie on which surface is unknown, so both stripes of the link are dropped
    rather than unwrapped a whole period off.

    Returns
    -------
    ndarray, shape (S,), int32; ``positions`` with the dropped stripes at -1
    """
    out = np.empty(positions.size, np.int32)
    _kernels.drop_broken_links(
        np.ascontiguousarray(positions, dtype=np.int32), np.ascontiguousarray(linked_prev, dtype=bool), cycle, out
    )
    return out


def contested_positions(
    positions: np.ndarray,
    kept: np.ndarray,
    linked_prev: np.ndarray,
    *,
    cycle: int,
    reach: int,
    min_support: int,
) -> np.ndarray:
    """The kept stripes whose position a run of other stripes around them contests (ours).

    A stripe is contested when another position is predicted for it (``W[j + o] - o mod L``,
    from the windows' positions before the correction) by linked stripes on both of its sides
    within ``reach``, at least once on each and ``min_support`` times in all.  A run of misread
    codes that reads like another stretch of the sequence decodes coherently, so that the
    neighbour correction keeps it (its stripes vote for one another); the stripes beyond it on
    both sides still agree with each other through it, and that is what this finds.  A hidden
    depth edge contests nothing: the other surface predicts its positions from one side only
    (:func:`keep_certain_sides` keeps such a stripe).  A thin object between two hidden edges
    reads like such a run and is doubted too - a cost in completeness, not a wrong depth.

    Parameters
    ----------
    positions : ndarray, shape (S,), int32; W of each stripe's own window, -1 unknown
    kept : ndarray, shape (S,), int32; the W decided for each stripe, -1 dropped
    linked_prev : ndarray, shape (S,), bool
    cycle : int
    reach : int
        Neighbours per side that are looked at.
    min_support : int
        The rival's votes, both sides together, that make a contest: as many as a position needs
        to be kept (``DecoderParams.min_support``).

    Returns
    -------
    ndarray, shape (S,), bool
    """
    out = np.empty(positions.size, bool)
    left, right = chain_extent(linked_prev)
    _kernels.contested_positions(
        np.ascontiguousarray(positions, dtype=np.int32),
        np.ascontiguousarray(kept, dtype=np.int32),
        left,
        right,
        cycle,
        reach,
        min_support,
        out,
    )
    return out


# The net vote (pixels for a stripe's code less those against it) under which the code does not
# count as read (DecoderParams.code_doubt), in fringe periods of the camera: a stripe is a period
# wide, so a whole one on lit paper holds ~0.8 T of votes; 0.2 T is a piece of a stripe (the
# 2-px pieces on a checkerboard's ink at T = 10.5 px) or a tie.  Measured on the synthetic 20:1
# checkerboard of 1.5-period squares (tests/test_robust_decoder.py): 0.2 T leaves none of the
# 675 pixels half a cycle off (0.1 T: 29 of a 1.6-period board's, a period off), at a cost of
# 0.02 % of the 3.4-period board's pixels and 0.13 % of a noisy dark board's; of the 25 rendered
# hard scenes only the sphere before a wall moved (98.104 -> 98.100 % complete, 0.049 -> 0.045 %
# of its pixels more than 5 mm wrong; results/hard_scenes.md).
CODE_VOTE_PERIODS = 0.2


def uncertain_positions(
    positions: np.ndarray,
    kept: np.ndarray,
    linked_prev: np.ndarray,
    certain: np.ndarray,
    *,
    order: int,
    cycle: int,
    reach: int,
    min_support: int,
) -> np.ndarray:
    """The kept stripes whose position the windows of well-read codes do not give (ours).

    The windows (``positions``, before the correction) that hold a stripe whose code is not
    ``certain`` are set aside, and the neighbour correction (:func:`neighbour_correct`) run over
    the rest: a kept stripe it gives no position, or another, is uncertain.  A stripe whose own
    code is uncertain keeps its position where windows of well-read codes around it predict it;
    a chain of pieces of stripes, whose codes are ties or read from a couple of pixels, reads
    like some stretch of the sequence one time in four (of the 2**5 codes of five stripes, 8 do)
    and is set aside as a whole.  The decoder asks ``min_support`` 1 of it (one window of read
    codes, no rival as often: :func:`neighbour_correct` needs a strict plurality): the kept stripe
    had the correction's own votes already.

    Parameters
    ----------
    positions : ndarray, shape (S,), int32; W of each stripe's own window, -1 unknown
    kept : ndarray, shape (S,), int32; the W decided for each stripe, -1 dropped
    linked_prev : ndarray, shape (S,), bool
    certain : ndarray, shape (S,), bool; the stripes whose code counts as read
    order, cycle : int
    reach, min_support : int
        As :func:`neighbour_correct`, for the windows of read codes.

    Returns
    -------
    ndarray, shape (S,), bool
    """
    certain = np.asarray(certain, bool)
    whole = certain.copy()
    h = (order - 1) // 2  # stripe j's window: j - h .. j - h + order - 1 (window_positions_of_stripes)
    for o in range(1, h + 1):
        whole[o:] &= certain[:-o]
    for o in range(1, order - h):
        whole[:-o] &= certain[o:]
    # a window leaving its chain is -1 already: the shifts across a chain's end change nothing
    read = np.where(whole, np.asarray(positions, np.int32), np.int32(-1))
    again, _ = neighbour_correct(read, linked_prev, cycle=cycle, reach=reach, min_support=min_support)
    kept = np.asarray(kept, np.int32)
    return (kept >= 0) & (again != kept)


def stripe_floor(values: np.ndarray, stripes: Stripes) -> np.ndarray:
    """The lowest of ``values`` over each stripe's own pixels (its label's: not those of a gap
    it was bridged across).

    Parameters
    ----------
    values : ndarray, shape (H, W), float32; e.g. the confidence
    stripes : :class:`simbench.decode.color.Stripes`

    Returns
    -------
    ndarray, shape (S,), float32; NaN values are passed over (a stripe of NaN only: NaN)
    """
    n = stripes.count
    if n == 0:
        return np.empty(0, np.float32)
    h, w = values.shape
    flat = np.where(stripes.labels >= 0, values, np.float32(np.nan)).astype(np.float32).ravel()
    # stripes lie in scan order without overlap: reduce over [start, stop) and skip the runs between
    flat = np.append(flat, np.float32(np.nan))
    base = stripes.row.astype(np.int64) * w
    idx = np.empty(2 * n, np.int64)
    idx[0::2] = base + stripes.start
    idx[1::2] = base + stripes.stop
    with np.errstate(invalid="ignore"):
        return np.fmin.reduceat(flat, idx)[0::2].astype(np.float32)


def _links(p: np.ndarray, linked_prev: np.ndarray, *, cycle: int) -> tuple[np.ndarray, np.ndarray]:
    """Of the links between known positions ``p`` (int64, -1 unknown): the broken ones, as the index
    j of the link between stripes j - 1 and j, and ``follows[j]``: that link holds (W consecutive)."""
    linked = np.asarray(linked_prev, bool)
    both = (p[:-1] >= 0) & (p[1:] >= 0) & linked[1:]
    step = np.mod(p[1:] - p[:-1], cycle)
    follows = np.zeros(p.size, bool)
    follows[1:] = both & (step == 1)
    return np.flatnonzero(both & (step != 1)) + 1, follows


def _far_links_hold(follows: np.ndarray, ok: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per stripe, whether its link on its left / right holds to a neighbour where ``ok``."""
    left, right = np.zeros(follows.size, bool), np.zeros(follows.size, bool)
    left[1:] = follows[1:] & ok[:-1]
    right[:-1] = follows[1:] & ok[1:]
    return left, right


def keep_certain_sides(
    positions: np.ndarray,
    dropped: np.ndarray,
    linked_prev: np.ndarray,
    floor: np.ndarray,
    *,
    cycle: int,
    min_confidence: float,
) -> np.ndarray:
    """Give back the stripe of a broken link that the edge is not in (ours).

    :func:`drop_broken_links` drops both stripes of a link whose W do not follow each other: a
    depth edge the wrapped phase ran on across, inside one of the two (the one that straddles
    both surfaces) or at their border.  The phase windows over the edge are biased, and the
    confidence's stability term marks them (``DecoderParams.phase_stability``), so where every
    pixel of one stripe is at or above ``min_confidence`` and the other holds a pixel below it,
    the edge is in the other; the first is kept with its W if its link on its far side holds
    (that neighbour kept, W consecutive), so that its W is confirmed by a chain on its own side
    of the edge.  Measured on ``scenes/hard_stairs_deep.toml``: a step whose projector column
    jumps by 20.6 px (0.98 of a period), and the whole period on its near side had been dropped.
    A step the phase crosses without any pixel below ``min_confidence`` keeps both dropped.

    Parameters
    ----------
    positions : ndarray, shape (S,), int32; W after :func:`neighbour_correct`
    dropped : ndarray, shape (S,), int32; :func:`drop_broken_links` of ``positions``
    linked_prev : ndarray, shape (S,), bool
    floor : ndarray, shape (S,), float32; each stripe's lowest confidence (:func:`stripe_floor`)
    cycle : int
    min_confidence : float
        The decoder's operating point.

    Returns
    -------
    ndarray, shape (S,), int32; ``dropped`` with the kept stripes' W given back
    """
    p = np.asarray(positions, np.int64)
    d = np.asarray(dropped, np.int32)
    out = d.copy()
    if p.size < 2:
        return out
    broken, follows = _links(p, linked_prev, cycle=cycle)
    if broken.size == 0:
        return out
    # a stripe's link on its left / right holds, to a neighbour that survived the drop
    left_ok, right_ok = _far_links_hold(follows, d >= 0)
    f = np.asarray(floor, np.float32)
    thr = np.float32(min_confidence)
    a, b = broken - 1, broken
    # an unknown floor (NaN) is neither clean nor evidence of the edge
    with np.errstate(invalid="ignore"):
        keep_a = (f[a] >= thr) & (f[b] < thr) & left_ok[a]
        keep_b = (f[b] >= thr) & (f[a] < thr) & right_ok[b]
    out[a[keep_a]] = p[a[keep_a]]
    out[b[keep_b]] = p[b[keep_b]]
    return out


def keep_straddler_parts(
    positions: np.ndarray,
    kept: np.ndarray,
    linked_prev: np.ndarray,
    stripes: Stripes,
    confidence: np.ndarray,
    floor: np.ndarray,
    *,
    cycle: int,
    min_confidence: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Keep the part of a broken link's dropped stripe that lies on its own chain's side of the
    edge (ours).

    After :func:`drop_broken_links` (and :func:`keep_certain_sides`) a stripe of a broken link
    may still be dropped although its link on its other side holds, to a kept neighbour whose
    every pixel is at or above ``min_confidence``: its W agrees with a trustworthy chain beyond
    it, and only its part on the far side of the hidden depth edge - a few pixels of it - belongs
    to the other surface.  (A neighbour under the operating point is no such evidence: measured
    on ``scenes/hard_sphere_before_wall.toml``, a chain along the sphere's limb, all of it below
    the operating point and two periods off, would have given a stripe beside it its W.)

    The windows over the edge are biased, so where the stripe holds a pixel below
    ``min_confidence`` its lowest confidence marks where the edge is: the stripe's pixels on its
    own chain's side of that minimum keep its W (a stripe right of the link: its pixels right of
    the minimum; left of the link: left of it), the rest become unlabelled.  The pixels near the
    edge keep their low confidence, so the operating point still removes them.  A stripe with no
    pixel below ``min_confidence`` stays dropped: nothing shows where in it (or whether in it) the
    edge is, and a split at a noise minimum would give the pixels between it and the edge the
    other surface's W, a whole period off.

    Parameters
    ----------
    positions : ndarray, shape (S,), int32; W after :func:`neighbour_correct`
    kept : ndarray, shape (S,), int32; ``positions`` after the link check (dropped: -1)
    linked_prev : ndarray, shape (S,), bool
    stripes : :class:`simbench.decode.color.Stripes`
    confidence : ndarray, shape (H, W), float32; the stripes' image's
    floor : ndarray, shape (S,), float32; each stripe's lowest confidence (:func:`stripe_floor`)
    cycle : int
    min_confidence : float
        The decoder's operating point; 0 splits nothing.

    Returns
    -------
    positions : ndarray, shape (S,), int32; ``kept`` with the split stripes' W given back
    labels : ndarray, shape (H, W), int32; ``stripes.labels`` with the dropped parts -1 (a copy
        whenever a stripe was a candidate; ``stripes.labels`` itself is never written)
    """
    p = np.asarray(positions, np.int64)
    out = np.asarray(kept, np.int32).copy()
    labels = stripes.labels
    if p.size < 2 or min_confidence <= 0.0:
        return out, labels
    broken, follows = _links(p, linked_prev, cycle=cycle)
    if broken.size == 0:
        return out, labels
    with np.errstate(invalid="ignore"):
        clean = (out >= 0) & (np.asarray(floor, np.float32) >= np.float32(min_confidence))
    left_ok, right_ok = _far_links_hold(follows, clean)
    # (stripe, keep its right part): right of a broken link with its right link holding, or left
    # of one with its left link holding; a stripe between two broken links has neither
    todo = [(int(s), True) for s in broken if out[s] < 0 and right_ok[s]]
    todo += [(int(s), False) for s in broken - 1 if out[s] < 0 and left_ok[s]]
    if not todo:
        return out, labels
    labels = labels.copy()
    for s, keep_right in todo:
        y, x0, x1 = int(stripes.row[s]), int(stripes.start[s]), int(stripes.stop[s])
        own = labels[y, x0:x1] == s
        c = np.where(own, confidence[y, x0:x1], np.float32(np.inf))
        k = int(np.argmin(c))  # the first lowest: a stripe has its edge once
        if not c[k] < np.float32(min_confidence):
            continue  # nothing marks the edge
        part = labels[y, x0:x1]
        if keep_right:
            part[: k + 1][own[: k + 1]] = -1
        else:
            part[k:][own[k:]] = -1
        out[s] = p[s]
    return out, labels
