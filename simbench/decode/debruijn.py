"""Stage 3: stripe order from De Bruijn windows, with neighbour check and correction
(paper Sec. 5.3).

Each stripe's window is the codes of the stripes around it (for order 3: previous, own, next,
as paper Eq. 3); the window's place in the cycle gives the stripe's position W.  Successive
linked stripes must have successive positions, so each neighbour within ``reach`` also predicts
W; the plurality of the predictions wins, and a stripe that no neighbour confirms is dropped.
"""

from __future__ import annotations

import numpy as np

from simbench.decode import _kernels

__all__ = ["chain_extent", "window_positions_of_stripes", "neighbour_correct", "drop_broken_links"]


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
