"""Stage 2: stripes and their colour code (paper Sec. 5.2, Eq. 13, with voting).

A *stripe* is a run of valid pixels along one image row between two wrapped-phase jumps
(paper Sec. 5.3).  Runs also end at invalid pixels and at phase steps no fringe of plausible
local frequency could make (depth edges); only runs that end in a genuine wrap are *linked* to
their right neighbour, i.e. known to be the next stripe of the pattern.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from simbench.decode import _kernels

__all__ = ["color_code", "normalize_channels", "Stripes", "segment_stripes", "vote_codes"]


def color_code(rgb: np.ndarray) -> np.ndarray:
    """Per-pixel code of paper Eq. 13: 1 where R >= G (red stripe), else 0.

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    return rgb[..., 0] >= rgb[..., 1]


def normalize_channels(rgb: np.ndarray, *, period_px: float, order: int, min_span: float) -> np.ndarray:
    """Each channel rescaled to its local range across neighbouring stripes.

    ``(v - local_min) / (local_max - local_min)`` per channel, over a window along the row wide
    enough to hold a stripe of each colour wherever the pixel is: in a binary De Bruijn
    sequence of order n the longest run of one code is n stripes, so the nearest stripe of the
    other code is at most ``(n + 1) / 2`` periods away.  A surface that absorbs one stripe
    colour (a red board reflects little green) then shows the same normalised fringe and the
    same R-versus-G contrast as a white one, and the local minimum removes ambient light and
    the projector's black level.  Not in the paper (its Eq. 9 and 13 use the raw channels):
    our option for coloured surfaces, at the price of amplifying the noise of a weak channel.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32
    period_px : float
        Fringe period in camera pixels.
    order : int
        De Bruijn window length n.
    min_span : float
        A channel whose local range is below this (full-scale units) carries no fringe there;
        it is set to 0.

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1]
    """
    half = int(np.ceil((order + 1) / 2 * period_px)) + 1
    kernel = np.ones((1, 2 * half + 1), np.uint8)
    out = np.empty(rgb.shape, np.float32)
    for c in range(3):
        v = np.ascontiguousarray(rgb[..., c], dtype=np.float32)
        lo = cv2.erode(v, kernel, borderType=cv2.BORDER_REPLICATE)
        span = cv2.dilate(v, kernel, borderType=cv2.BORDER_REPLICATE) - lo
        ok = span >= min_span
        np.divide(v - lo, span, out=out[..., c], where=ok)
        out[..., c][~ok] = 0.0
    return out


@dataclass(frozen=True)
class Stripes:
    """Stripe segmentation of an image.

    labels : ndarray, shape (H, W), int32; stripe index per pixel, -1 where invalid
    row, start, stop : ndarray, shape (S,), int32; each stripe is ``[start, stop)`` of ``row``
    linked_prev : ndarray, shape (S,), bool; stripe ``s - 1`` is the pattern's previous stripe
    """

    labels: np.ndarray
    row: np.ndarray
    start: np.ndarray
    stop: np.ndarray
    linked_prev: np.ndarray

    @property
    def count(self) -> int:
        return int(self.row.size)


def segment_stripes(
    wrapped: np.ndarray,
    valid: np.ndarray,
    *,
    period_px: float,
    min_step_ratio: float = 0.3,
    max_step_ratio: float = 3.0,
) -> Stripes:
    """Split each row into stripes at wrapped-phase jumps.

    Parameters
    ----------
    wrapped : ndarray, shape (H, W), float32 in [-pi, pi)
    valid : ndarray, shape (H, W), bool
    period_px : float
        Nominal fringe period in camera pixels; the expected phase step per pixel is
        ``2*pi/period_px``.
    min_step_ratio, max_step_ratio : float
        A step (after unwrapping a jump) outside ``[min, max] * 2*pi/period_px`` is a
        discontinuity: the run ends there without a link.

    Returns
    -------
    Stripes
    """
    h, w = wrapped.shape
    omega = 2.0 * np.pi / period_px
    lo = np.float32(min_step_ratio * omega)
    hi = np.float32(min(max_step_ratio * omega, 0.9 * np.pi))
    labels = np.empty((h, w), np.int32)
    # room for one stripe per pixel; only the pages of the stripes found are ever touched
    row, start, stop = (np.empty(h * w, np.int32) for _ in range(3))
    linked_prev = np.empty(h * w, bool)
    n = _kernels.segment_stripes(
        np.ascontiguousarray(wrapped, dtype=np.float32), np.ascontiguousarray(valid, dtype=bool), lo, hi, labels, row, start, stop, linked_prev
    )
    return Stripes(labels=labels, row=row[:n].copy(), start=start[:n].copy(), stop=stop[:n].copy(), linked_prev=linked_prev[:n].copy())


def vote_codes(code: np.ndarray, stripes: Stripes, *, voting: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """One code per stripe.

    With ``voting`` (paper Sec. 5.2) the majority of the stripe's pixels decides (ties give 1,
    like Eq. 13's ``>=``); without it, the stripe's middle pixel decides.

    Returns
    -------
    stripe_code : ndarray, shape (S,), uint8
    agreement : ndarray, shape (S,), float32; share of the stripe's pixels agreeing with it
    """
    out = np.empty(stripes.count, np.uint8)
    agreement = np.empty(stripes.count, np.float32)
    _kernels.vote_codes(np.ascontiguousarray(code, dtype=bool), stripes.row, stripes.start, stripes.stop, bool(voting), out, agreement)
    return out, agreement
