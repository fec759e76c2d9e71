"""Stage 2: stripes and their colour code (paper Sec. 5.2, Eq. 13, with voting).

A *stripe* is a run of valid pixels along one image row between two wrapped-phase jumps
(paper Sec. 5.3).  Runs also end at invalid pixels and at phase steps no fringe of plausible
local frequency could make (depth edges); only runs that end in a genuine wrap are *linked* to
their right neighbour, i.e. known to be the next stripe of the pattern.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from simbench.decode import _kernels

__all__ = [
    "color_code",
    "mixing_matrix",
    "CalibrationFrameError",
    "unmix",
    "normalize_channels",
    "code_at_row_ends",
    "albedo_edges",
    "segment_mean",
    "albedo_gain",
    "albedo_gain_reach_rows",
    "column_albedo_gain",
    "column_step_pixels",
    "column_gain_reach_rows",
    "albedo_step_pixels",
    "fringe_confirmed",
    "overlay_weights",
    "normalized_color_code",
    "Stripes",
    "segment_stripes",
    "vote_codes",
    "pool_code_rows",
]


def color_code(rgb: np.ndarray) -> np.ndarray:
    """Per-pixel code of paper Eq. 13: 1 where R >= G (red stripe), else 0.

    Returns
    -------
    ndarray, shape (H, W), bool

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Eq. 13.
    """
    return rgb[..., 0] >= rgb[..., 1]


def normalized_color_code(rgb: np.ndarray, span: np.ndarray) -> np.ndarray:
    """Eq. 13 on channels normalised by :func:`normalize_channels` (R = code 1, G = code 0,
    B = the fringe, as the decoder orders them), where a code channel may carry nothing.

    Where both code channels have a local range it is Eq. 13 (R >= G).  Where one of them has
    none (``span`` 0: a cyan surface reflects no red, a pink one no green), it says nothing
    about the code, and comparing the other with its 0 reads the stripes wrong (a red stripe's
    green at its local minimum ties with it or wins by a quantisation step: on the
    paper's-simulation cyan board 24 % of the pixels decoded, half of them a whole stripe or
    more wrong).  The pattern puts ``C * I`` in one code channel and ``(1 - C) * I`` in the other
    (Eq. 7-8), so the present channel is the fringe ``I`` on its own stripes and 0 on the
    others: it is compared with half the normalised fringe ``I``, the middle of the two, taken
    from the fringe channel (or 0.25, half the normalised fringe's mean of 0.5, where that has no
    range either).  Where
    neither code channel has a range the code is 1, like Eq. 13's tie.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32; normalised channels (0 where a channel has no range)
    span : ndarray, shape (H, W, 3), float32; their local ranges, 0 = none

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    code = np.empty(rgb.shape[:2], bool)
    _kernels.robust_fringe_code(rgb, np.ascontiguousarray(span, dtype=np.float32), None, None, code)
    return code


def mixing_matrix(primaries: Sequence[np.ndarray], dark: np.ndarray, *, region: np.ndarray | None = None) -> np.ndarray:
    """The projector-to-camera coupling matrix K from calibration captures of the reference
    plane (Caspi, Kiryati & Shamir 1998).

    With ``dark`` the plane under a black frame (ambient light and the projector's black level)
    and ``primaries[p]`` under projector primary p at full drive, column p of K is the median
    over ``region`` of ``primaries[p] - dark``, scaled so that ``K[p, p] = 1``: each camera
    channel stays in units of its own primary on the reference.  A surface of spectral
    reflectance rho under narrow-band primaries then records ``c = K diag(rho_p) p`` (rho taken
    at each primary's wavelength), so ``K^-1 c`` separates the primaries whatever the surface
    colour; the broader a primary's spectrum, the less exact this is.

    Parameters
    ----------
    primaries : sequence of 3 ndarray, shape (H, W, 3), float32 in [0, 1]
        Captures under the red, green and blue primary (projector channel order), e.g. from
        :func:`simbench.decode.as_float_image`.
    dark : ndarray, shape (H, W, 3), float32 in [0, 1]
    region : ndarray, shape (H, W), bool, optional
        Pixels to use (default: all).

    Returns
    -------
    ndarray, shape (3, 3), float64; rows camera channels, columns projector primaries

    Raises
    ------
    CalibrationFrameError (a ValueError)
        When a primary does not lift its own channel above the dark frame, when a capture is
        clipped (a channel at full scale, 1.0) on half of ``region`` or more - the median, and
        so K, would then be the clipping level's, not the light's - when the captures read as lit
        by other primaries than their order says (:func:`_check_primary_order`), or when K is
        singular.

    References
    ----------
    D. Caspi, N. Kiryati and J. Shamir, "Range imaging with adaptive color structured light",
    IEEE TPAMI 20(5), 470-480, 1998.
    """
    if len(primaries) != 3:
        raise ValueError(f"need the captures under the 3 primaries, got {len(primaries)}")
    d = _calibration_frame(dark)
    sel = np.ones(d.shape[:2], bool) if region is None else np.asarray(region, bool)
    if sel.shape != d.shape[:2] or not sel.any():
        raise ValueError("region must be a non-empty (H, W) mask of the calibration captures")
    k = np.empty((3, 3))
    own = np.empty(3)  # each capture's own channel, median over the region
    for p, img in enumerate(primaries):
        f = _calibration_frame(img)
        if f.shape != d.shape:
            raise CalibrationFrameError(f"primary capture {p} has shape {f.shape}, the dark frame {d.shape}")
        clipped = (f[sel] >= 1.0).mean(axis=0)
        if clipped.max() >= 0.5:
            c = int(np.argmax(clipped))
            raise CalibrationFrameError(
                f"the calibration capture under projector primary {'RGB'[p]} is clipped: camera channel {'RGB'[c]} at "
                f"full scale on {100 * clipped[c]:.0f} % of the plane, so the coupling matrix would be the clipping "
                "level's - expose the calibration frames (and the captures) shorter"
            )
        k[:, p] = np.median((f - d)[sel], axis=0)
        own[p] = np.median(f[sel][:, p])
    # a dark frame brighter than a capture in any channel is no dark frame (a lit frame in its place:
    # a new user's audit, 2026-11-30, decoded 4 points less complete with half the red frame as the
    # dark one, without a word); noise leaves the medians of unlit channels within ~1e-3 of 0
    low = k < -np.maximum(1e-3, 0.02 * np.diag(k)[None, :])
    if low.any():
        c, p = (int(i) for i in np.unravel_index(np.argmin(np.where(low, k, np.inf)), k.shape))
        raise CalibrationFrameError(
            f"the dark frame is brighter than the capture named {_PRIMARY_NAMES[p]} in camera channel {'RGB'[c]} "
            f"(by {-k[c, p]:.3g} of full scale, median over the plane): is the dark frame the plane under a black "
            "projector frame?"
        )
    _check_alike(k)
    # (first: a capture of another primary in this one's place does not light its own channel either)
    _check_primary_order(k)
    for p in range(3):
        if not k[p, p] > 1e-3:
            if np.median(d[sel][:, p]) > own[p] + 1e-3:
                raise CalibrationFrameError(
                    f"the dark frame is brighter than the capture under projector primary {'RGB'[p]} in camera channel "
                    f"{'RGB'[p]}: is the dark frame the plane under a black projector frame?"
                )
            raise CalibrationFrameError(
                f"projector primary {'RGB'[p]} does not light camera channel {'RGB'[p]} above the dark frame: not a "
                f"calibration capture"
            )
    k /= np.diag(k)[None, :]
    if np.linalg.cond(k) > 1e3:
        raise CalibrationFrameError(f"the coupling matrix is singular (condition number {np.linalg.cond(k):.3g})")
    return k


class CalibrationFrameError(ValueError):
    """A calibration capture that is not what its name says (:func:`mixing_matrix`); the
    command line names the frames' files with it."""


# The captures' order is judged by the product of K's entries along each assignment of camera
# channels to primaries, prod_p k[sigma(p), p]: a camera channel's gain and a primary's power
# scale every assignment's product alike, so only the light's spectral overlap decides, and the
# true assignment (each channel with its own primary) wins by far - on the perfect white of
# results/crosstalk.md the best other one (G and B exchanged) reaches 0.34 x 0.25 = 0.085 of it.
# A new user's audit (2026-11-30) renamed the green and blue captures: K then read 0.34 and 0.25
# on its diagonal, and the unmixing made 8 % of the chart's depths > 5 mm wrong, exit 0, without a
# word.  Another assignment is taken as the frames' order when it beats the named one outright.
_PRIMARY_NAMES = ("red", "green", "blue")


def _check_primary_order(k: np.ndarray) -> None:
    """Raise :class:`CalibrationFrameError` when the three captures read in another order than
    their names (``k``: the raw medians, rows camera channels, columns the captures)."""
    import itertools

    lifted = np.maximum(np.asarray(k, np.float64), 0.0)
    scores = {perm: float(np.prod([lifted[perm[p], p] for p in range(3)])) for perm in itertools.permutations(range(3))}
    best = max(scores, key=scores.get)
    if best == (0, 1, 2) or scores[best] <= scores[(0, 1, 2)]:
        return
    named = [f"the capture named {_PRIMARY_NAMES[p]} looks {_PRIMARY_NAMES[best[p]]}" for p in range(3) if best[p] != p]
    raise CalibrationFrameError(
        "the calibration captures read as lit by other primaries than their names say: "
        + "; ".join(named)
        + " (each camera channel responds most to its own primary): were the frames renamed or the channels reordered?"
    )


def _check_alike(k: np.ndarray) -> None:
    """Raise :class:`CalibrationFrameError` when two captures light the camera's channels in the
    same proportions (one copied over another: the matrix was refused as singular, naming
    neither)."""
    cols = np.maximum(np.asarray(k, np.float64), 0.0)
    norm = np.linalg.norm(cols, axis=0)
    for a in range(3):
        for b in range(a + 1, 3):
            if norm[a] > 0 and norm[b] > 0 and float(cols[:, a] @ cols[:, b]) / (norm[a] * norm[b]) > 0.999:
                raise CalibrationFrameError(
                    f"the captures named {_PRIMARY_NAMES[a]} and {_PRIMARY_NAMES[b]} light the camera's channels alike "
                    "(the same primary twice?): each must be the plane under its own primary"
                )


def _calibration_frame(img) -> np.ndarray:
    a = np.asarray(img, dtype=np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"calibration captures must have shape (H, W, 3), got {a.shape}")
    return a


def unmix(rgb: np.ndarray, unmixing: np.ndarray) -> np.ndarray:
    """``unmixing @ c`` per pixel (``unmixing`` = the inverse of :func:`mixing_matrix`'s K,
    rows and columns in the capture's channel order): each channel then holds one primary.

    Returns
    -------
    ndarray, shape (H, W, 3), float32 (may be slightly negative where noise is)
    """
    out = cv2.transform(np.ascontiguousarray(rgb, dtype=np.float32), np.asarray(unmixing, np.float32))
    return out.reshape(rgb.shape)


def _code_window_px(period_px: float, order: int) -> int:
    # in a binary De Bruijn sequence of order n the longest run of one code is n stripes, so
    # the nearest stripe of the other code is at most (n + 1) / 2 periods away
    return int(np.ceil((order + 1) / 2 * period_px)) + 1


def normalize_channels(
    rgb: np.ndarray,
    *,
    period_px: float,
    order: int,
    min_span: float,
    return_span: bool = False,
    gain: np.ndarray | None = None,
    clamp_ends: bool = False,
    extrema_gain: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each channel rescaled to its local range across neighbouring stripes.

    ``(v - local_min) / (local_max - local_min)`` per channel, over a window along the row wide
    enough to hold a stripe of each colour wherever the pixel is: in a binary De Bruijn
    sequence of order n the longest run of one code is n stripes, so the nearest stripe of the
    other code is at most ``(n + 1) / 2`` periods away.  A surface that absorbs one stripe
    colour (a red board reflects little green) then shows the same normalised fringe and the
    same R-versus-G contrast as a white one, and the local minimum removes ambient light and
    the projector's black level.  Not in the paper (its Eq. 9 and 13 use the raw channels):
    our option for coloured surfaces, at the price of amplifying the noise of a weak channel.

    The running minimum and maximum (the window clipped to the row) are then averaged over the
    same window (the row's ends replicated).  Raw, they step
    where an albedo edge enters the window, half a window away from the edge, and the step in
    the normalised fringe fails the phase fit there (measured on ``scenes/robust_printed.toml``:
    a second invalid line beside every printed edge, cutting off a 2-period strip of stripes
    that could not form De Bruijn windows); averaged, they ramp across the window, which the
    fit follows like any slow change of fringe amplitude.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32
    period_px : float
        Fringe period in camera pixels.
    order : int
        De Bruijn window length n.
    min_span : float
        A channel whose local range is below this (full-scale units) carries no fringe there;
        it is set to 0 (for the colour code see :func:`normalized_color_code`).
    return_span : bool
        Also return the local ranges.
    gain : ndarray, shape (H, W), float32, optional
        A per-pixel gain every channel is multiplied by first (:func:`albedo_gain`'s): the result
        of ``rgb * gain[..., None]`` without that image.
    clamp_ends : bool
        Within a window of a row's ends (``2 half`` pixels), the ranges of the first (last) pixel
        whose mean reads only extrema of whole windows, pixel ``2 half`` (``W - 1 - 2 half``): the
        window moved inward instead of cut by the row's end (for the colour code there:
        :func:`code_at_row_ends`).  Rows of ``4 half`` pixels or fewer are as without it.
    extrema_gain : ndarray, shape (H, W), float32, optional (with ``gain``)
        The gain with which each pixel enters the running minimum and maximum, where not
        ``gain`` (:func:`mixed_pixel_gain`'s: a pixel beside a step of the gain); each pixel's
        own value is still ``v * gain`` rescaled by the ranges so found.

    Returns
    -------
    ndarray, shape (H, W, 3), float32, in [0, 1] away from albedo edges
        (and with ``return_span`` the local ranges, shape (H, W, 3), float32, 0 where below
        ``min_span``)
    """
    half = _code_window_px(period_px, order)
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    out = np.empty(rgb.shape, np.float32)
    spans = np.empty(rgb.shape, np.float32) if return_span else None
    # one pass per row (simbench/_ckernels.c): the running extrema by van Herk / Gil-Werman and
    # their box means in the double running sums of OpenCV's float32 box filter, the bits of
    # cv2.erode / cv2.dilate + cv2.blur (tests/test_kernels.py)
    if gain is not None:
        gain = np.ascontiguousarray(gain, dtype=np.float32)
        if gain.shape != rgb.shape[:2]:
            raise ValueError(f"gain: expected shape {rgb.shape[:2]}, got {gain.shape}")
    own = None  # the pixels whose own gain is not their extrema's, and by how much
    if extrema_gain is not None:
        if gain is None:
            raise ValueError("extrema_gain needs gain")
        extrema_gain = np.ascontiguousarray(extrema_gain, dtype=np.float32)
        if extrema_gain.shape != rgb.shape[:2]:
            raise ValueError(f"extrema_gain: expected shape {rgb.shape[:2]}, got {extrema_gain.shape}")
        at = np.nonzero(extrema_gain != gain)
        if at[0].size:
            own = at, gain[at] - extrema_gain[at]
            gain = extrema_gain
            if spans is None:
                spans = np.empty(rgb.shape, np.float32)
    _kernels.normalize_channels(rgb, half, min_span, out, spans, gain, clamp_ends)
    if own is not None:
        # (v g - min) / span = (v g' - min) / span + v (g - g') / span where span >= min_span (the
        # kernel wrote 0 and a span of 0 elsewhere, and those stay)
        at, more = own
        span_at = spans[at]
        with np.errstate(divide="ignore", invalid="ignore"):
            extra = np.where(span_at > 0, rgb[at] * more[:, None] / span_at, np.float32(0.0))
        out[at] += extra.astype(np.float32)
    return (out, spans) if return_span else out


def code_at_row_ends(
    rgb: np.ndarray,
    code: np.ndarray,
    *,
    period_px: float,
    order: int,
    min_span: float,
    gain: np.ndarray | None = None,
) -> np.ndarray:
    """``code`` with the colour code read again within a window of each end of every row, against
    local ranges made of whole windows only (ours, with :func:`normalize_channels`).

    At a row's end :func:`normalize_channels` cuts its window to the pixels inside the row: half
    a window at the very end, (n + 1) / 2 periods, which may hold stripes of one code only (the
    longest run is n), and the box mean of the extrema spreads that over another half window - so
    that the other code channel's range comes out too small there and a weak pixel's code reads by
    chance.  Measured on ``scenes/robust_staircase.toml``: the one-pixel stripe at the left border
    read the wrong code in 435 of its 960 rows, and each such row lost the 4-stripe sliver of wall
    beside it (3.4 % of the scene).  Here the ``2 half`` pixels at each end take the ranges of the
    first (last) pixel whose mean reads only whole windows (``clamp_ends``): 1 row of 960 still
    misreads (with the ranges of the first whole window itself, half as far in, 55 did).  Only the
    code is read so: the fringe's normalisation keeps the cut window, which follows a nearby albedo
    step more closely (measured: moving the fringe's window too cost the printed charts 0.3-0.6 %
    completeness).

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32; the capture the code channels were normalised from
        (unmixed, before :func:`normalize_channels`)
    code : ndarray, shape (H, W), bool; :func:`normalized_color_code` of it (not changed)
    period_px, order, min_span :
        As for :func:`normalize_channels`.
    gain : ndarray, shape (H, W), float32, optional
        The gain the code's normalisation took (:func:`albedo_gain`).

    Returns
    -------
    ndarray, shape (H, W), bool; ``code`` itself where a row holds no such pixel (``W <= 4 half``)
    """
    half = _code_window_px(period_px, order)
    h, w = code.shape
    if w <= 4 * half:
        return code
    q = 2 * half
    # pixel 2 half's ranges read the extrema of the columns up to 4 half: a strip of them gives the
    # row's own values (at the right end to the rounding of the box means' running sums, which
    # start at the strip's first column instead of the row's)
    strip = 4 * half + 1
    out = code.copy()
    for cols, ends, dest in (
        (slice(0, strip), slice(0, q), slice(0, q)),
        (slice(w - strip, w), slice(strip - q, strip), slice(w - q, w)),
    ):
        normed, span = normalize_channels(
            rgb[:, cols],
            period_px=period_px,
            order=order,
            min_span=min_span,
            return_span=True,
            gain=None if gain is None else gain[:, cols],
            clamp_ends=True,
        )
        out[:, dest] = normalized_color_code(normed[:, ends], span[:, ends])
    return out


# Albedo flattening (ours, the colour-robust decoder's ``albedo_flatten``).  An albedo step is
# found where the period-free means of the albedo proxy over two periods on either side differ by
# more than this ratio (assumption: 1.35, e^0.3 - above the proxy's own swing on uniform
# saturated boards, where a crosstalk residue makes the two code stripes differ by up to ~1.3x,
# measured on scenes/hard_paint_orange.toml; below the low-contrast chart's 1.6x,
# scenes/hard_chart_low.toml)
ALBEDO_EDGE_RATIO = 1.35
# the far edge of a dark strip narrower than a period beside a step (a seam between two faces, a
# thin shadow or printed line) is cut where the one-period ratio back towards the light exceeds
# this (assumption: 1.8, above the code runs' swing on saturated prints; measured 2026-11-29: the
# seam between Table 3's cube and cuboid faces, ~2x darker, left uncut, the cuboid's segment began
# in it and its first ~50 px were brightened 1.25x - its MAE by the colour-robust decoder 0.148 ->
# 0.133 mm with it (0.172 with the gain's continuous fade before it); at 1.35 the red and orange
# tiles of scenes/robust_printed.toml were cut at their code runs, 96.8 -> 96.0 % complete and
# 0.04 -> 0.10 % wrong)
ALBEDO_STRIP_RATIO = 1.8
# a cut is dropped where the blue fringe, which carries no code, comes back at this share or more
# of the strongest channel on both sides and steps by less than this ratio (fringe_confirmed;
# assumption: 0.5 - blue at least half the strongest channel, well above a saturated print's
# crosstalk residue; 1.1 - a print step the proxy sees at 1.35 or more shows in blue too, unless
# the two inks reflect blue alike.  Measured 2026-11-29 on scenes/robust_printed.toml (16 spp):
# 96.67 -> 97.53 % complete at 0.040 % wrong; share 0.25: 97.35 %; without the share test (blue
# judging everywhere) 97.28 % but 0.18 % wrong - the red tile's real edges dropped; the 25 hard
# scenes within 0.1 % and Table 3 the same)
ALBEDO_CONFIRM_SHARE = 0.5
ALBEDO_CONFIRM_RATIO = 1.1
# rows averaged before the step test (a step along the stripes is one in every row; noise is not)
ALBEDO_EDGE_ROWS = 5
# rows the per-row albedo is averaged over (the gain of one row's 4-period mean is noisy on dark ink)
ALBEDO_MEAN_ROWS = 3
# a segment between two steps shorter than this many periods holds no whole fringe cycle to take a
# mean over: left as it is
ALBEDO_MIN_SEGMENT_PERIODS = 1.5
# a channel whose local range is under this share of the strongest channel's is left out of the
# albedo proxy (assumption: 0.1; the rendered orange board's blue is 0.07 of its red, mostly
# crosstalk residue that follows the code)
ALBEDO_MIN_CHANNEL_SHARE = 0.1
# the most a pixel's channels are amplified (a 0.04-albedo ink beside 0.8 paper needs 20x)
ALBEDO_MAX_GAIN = 50.0
# a step of the flattening's gain by this factor or more marks the pixels beside it as mixed (the
# pair straddling it, along a row and down a column, and along a row its bright side out to
# ALBEDO_SKIP_BRIGHT_PX; DecoderParams.albedo_edge_skip; assumption: 2 - where the gain steps by
# 2x a mixed pixel's light is off its side's by up to 2x, beyond what a window's fit absorbs as a
# change of fringe amplitude.  Measured on the 25 hard scenes, 2026-11-29: 1.5 and 3 move no scene
# by more than 0.4 % of its pixels - the 3:1 chart 99.40 % kept at 1.5, 99.39 % at 2, 99.01 % at 3)
ALBEDO_SKIP_RATIO = 2.0
# pixels marked beside such a step along a row on its brighter (lower-gain) side, counted from the
# step, the straddling one included; down a column, the two rows straddling it.  A step across the
# rows (a printed edge along them) biases no phase - the rows it mixes see the same projector
# columns - but the mixed rows' fringe, flattened by the wrong gain, adds to the residual of every
# window over them: on the 20:1 ink, whose fringe SNR is 4.3-5 away from any edge (the operating
# point is 3), the windows within ~8 rows of such an edge fell to 2.1-3.  Why the bright side's
# 2nd and 3rd pixels along a row are off is only partly known: the camera's demosaicing (the
# `paper` sensor: bilinear, a 3x3 support) fills their missing colours from the straddling pixel,
# but a synthetic 20:1 board through that demosaicing gains only 0.1-0.5 % from the 2nd.  Measured
# since (2026-12-03): the gain's steps along the rows sit in the ink - the ratio of the means either
# side (albedo_edges' placement) is largest once the darker side's window is past the paper's blur -
# by 0.87 / 1.20 / 1.82 px on average on the synthetic 20:1 board blurred by 0.7 / 1 / 1.5 px, and by
# 4-5 px on the rendered turned 20:1 chart's dim far side, where the ink's first pixels keep the
# paper's gain (tests/test_robust_decoder.py, a strict xfail: the steps on the print's edges).
# The skipped samples count for a window's support (the pipeline adds their share back):
# they are lit surface, left out for their mixed light.  Chosen on the rendered 20:1 chart
# (scenes/hard_chart_high.toml, the cached captures of `simbench reproduce hard_scenes`, share of
# the scored pixels kept at the operating point, 1280x960 / 640x480; measured 2026-11-30):
#   the pair along rows only (before)                          88.3 / 80.3 %
#   + the bright side's 2nd pixel                              91.2 / 84.6 %  (dark side's too: - / 81.6)
#   + the bright row of the pair down columns                  95.6 / 87.6 %  (dark row 94.9 / 88.3, both 95.9 / 84.0)
#   + skipped samples count for the support, both rows         96.0 / 92.2 %  (bright row only 95.6 / 90.4)
#   + the bright side out to 3 pixels                          96.6 / 93.1 %  (4: 96.6 / 92.5, 5: 96.5 / 88.7)
# MAE 0.474 -> 0.425 mm (1280x960), none > 5 mm wrong.  Held out: scenes/robust_printed.toml (16 spp)
# 97.69 -> 97.91 % complete, MAE 0.366 -> 0.365 mm; step.toml and robust_staircase.toml within 0.01 %
ALBEDO_SKIP_BRIGHT_PX = 3
# the pixels either side of a step of the column gain left out of the phase fit
# (column_step_pixels): its steps are placed to about a pixel and the blur mixes about one more.
# Chosen on scenes/hard_chart_fine_mid.toml (the cached capture of `simbench reproduce
# hard_scenes`, 1280x960, share of the scored pixels kept at the operating point, 2026-12-01):
# albedo_step_pixels' alone 94.2 %, MAE 0.414 mm; 2 along the rows 96.3 % (0.330 mm); and down the
# columns 97.5 % (0.326 mm); 3 each way 97.5 %, more pixels > 5 mm wrong (0.035 against 0.025 %).
# Held out, charts rendered the same way and not kept (ink, squares, distance, pose): 0.2, 12 mm,
# 0.9 m: 91.6 -> 96.3 %; 0.32, 8 mm, 0.8 m: 96.5 -> 98.2 %; 0.16, 11 mm, 1 m: 83.2 -> 92.0 %; the
# same turned 20 deg about y: 72.0 -> 77.1 %; the 3:1 chart turned 3 deg in its plane: 86.5 ->
# 94.8 %; 0.4, 10 mm, tilted 10 deg: 92.7 % either way; MAE down on each.  On the synthetic board
# of tests/test_robust_decoder.py (no lens, no Bayer mosaic; a Gaussian blur or a Bayer mosaic
# added, or the print turned a few degrees, change little) the same 2 px cost the 3:1 fine print
# ~10 points of its pixels (its steps are placed exactly there, and the samples left out lower its
# fringe SNR): what places the rendered chart's steps a pixel off is not pinned down - not the
# lens distortion's resampling (the 3:1 chart gains as much within 0.3 of the half-height of its
# centre, 91.9 -> 95.8 %, as beyond 0.9 of it, 94.1 -> 97.5 %) (2026-12-01)
COLUMN_SKIP_PX = 2
# a segment whose fringe visibility (the proxy's standard deviation over its mean, rows averaged
# over ALBEDO_EDGE_ROWS) is under this share of the most visible one within the window carries no
# fringe - a projector shadow, not dark ink - and is not brightened (assumption: 0.5; measured
# visibility ratios: a 20:1 ink beside its paper ~0.9, the cube's shadow on the wall beside
# Table 3's cuboid face ~0.1-0.2, as dark as that ink, 8 DN at its peaks)
ALBEDO_MIN_VISIBILITY = 0.5


def _segment_bounds(cuts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel, the first and one-past-last column of its segment (``cuts[y, x]``: a step
    between columns x and x + 1)."""
    h, w = cuts.shape
    x = np.arange(w)
    first = np.ones((h, w), bool)
    first[:, 1:] = cuts[:, :-1]
    s0 = np.maximum.accumulate(np.where(first, x, 0), axis=1)
    s1 = np.minimum.accumulate(np.where(cuts, x + 1, w)[:, ::-1], axis=1)[:, ::-1]
    return s0, s1


def segment_mean(values: np.ndarray, cuts: np.ndarray, *, width_px: int) -> np.ndarray:
    """Mean of ``width_px`` pixels along each row, the window centred on the pixel but moved
    (and, in a shorter segment, shortened) so that it never crosses a cut.

    Parameters
    ----------
    values : ndarray, shape (H, W); taken as float32
    cuts : ndarray, shape (H, W), bool; ``cuts[y, x]`` separates columns x and x + 1
    width_px : int

    Returns
    -------
    ndarray, shape (H, W), float64; with no cut, the box mean with the window kept inside the
    image at its borders
    """
    return _bounded_mean(values, *_segment_bounds(cuts), width_px=width_px)


def _bounded_mean(
    values: np.ndarray, s0: np.ndarray, s1: np.ndarray, *, width_px: int, square: bool = False
) -> np.ndarray:
    """:func:`segment_mean` over given segment bounds, in one pass per row (simbench/_ckernels.c:
    double prefix sums, the bits of numpy's cumsum path, tests/test_kernels.py); ``square`` means
    the squares.  The values are taken as float32 (the decoder's images are)."""
    out = np.empty(values.shape, np.float64)
    _kernels.bounded_mean(
        np.ascontiguousarray(values, np.float32),
        np.ascontiguousarray(s0, np.int64),
        np.ascontiguousarray(s1, np.int64),
        int(width_px),
        square,
        out,
    )
    return out


def _visibility_margin_px(period_px: float) -> int:
    """How far inside its cuts a segment's fringe visibility is measured (half a period): the
    optics blur the brighter side a few pixels across a step, and a cut sits up to a few pixels off
    it (measured: a lit edge ~8 px into a shadow's segment on ``scenes/hard_stairs_deep.toml``)."""
    return max(1, int(round(period_px / 2)))


def albedo_edges(proxy: np.ndarray, *, period_px: float) -> np.ndarray:
    """Albedo steps along the rows of an albedo proxy (a fringe times the surface's brightness).

    The mean over two whole periods on each side of a column has no fringe left in it; where
    the two differ by more than :data:`ALBEDO_EDGE_RATIO` (rows averaged over
    :data:`ALBEDO_EDGE_ROWS` first, the row's ends replicated, a floor of ``1e-3 + 0.02`` times
    the larger mean added to both so that noise on black stays no step) and the ratio is the
    largest within a period, the row has a step there (one pass per row in
    ``simbench/_ckernels.c``; the ratio is compared as it is, in double: its logarithm, used
    before, ranks the same but left the last bit to each machine's vector library).

    Returns
    -------
    ndarray, shape (H, W), bool; True between columns x and x + 1 (never within two periods of
    the image's left or right border, where one side's window would reach past it)
    """
    return _edges_of_rows(_rows_mean(proxy), period_px=period_px)


def _rows_mean(proxy: np.ndarray) -> np.ndarray:
    """The proxy (or each channel of an (H, W, C) image) averaged over :data:`ALBEDO_EDGE_ROWS`
    rows (ends replicated)."""
    return cv2.blur(np.ascontiguousarray(proxy, np.float32), (1, ALBEDO_EDGE_ROWS), borderType=cv2.BORDER_REPLICATE)


def _edges_of_rows(g: np.ndarray, *, period_px: float) -> np.ndarray:
    cuts = np.empty(g.shape, bool)
    _kernels.albedo_edges(g, max(2, int(round(period_px))), ALBEDO_EDGE_RATIO, ALBEDO_STRIP_RATIO, cuts)
    return cuts


def fringe_confirmed(cuts: np.ndarray, rgb: np.ndarray, *, period_px: float) -> np.ndarray:
    """``cuts`` less those the fringe channel contradicts (ours; :func:`albedo_gain`'s).

    The proxy's code pair follows the code on a saturated print: where one code colour comes back
    weakly, the crosstalk residue the unmixing (calibrated on white) leaves in it makes the stripes
    of one code brighter, and a run of three of them reads as a step (measured on
    ``scenes/robust_printed.toml``: cuts inside its red, orange and purple tiles, gain jumps of
    2-3x within one print).  The blue fringe carries no code: where blue comes back at
    :data:`ALBEDO_CONFIRM_SHARE` or more of the strongest channel on both sides of a cut, its means
    over two periods either side (rows averaged as the step test's) must differ by
    :data:`ALBEDO_CONFIRM_RATIO` or more, else the cut is dropped; where blue is weaker it cannot
    judge and the cut stays.

    Parameters
    ----------
    cuts : ndarray, shape (H, W), bool; :func:`albedo_edges`' (``cuts[y, x]``: a step between x and x + 1)
    rgb : ndarray, shape (H, W, 3), float32; the unmixed capture the proxy was made from
    period_px : float

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    ys, xs = np.nonzero(cuts)
    if ys.size == 0:
        return cuts
    m = 2 * max(2, int(round(period_px)))
    # the channels' rows averaged in one call (the bits of each channel's alone), then each step's
    # side means from per-row prefix sums in double (simbench/_ckernels.c: the bits of the numpy
    # form, side_means in tests/numpy_reference.py; ~5x faster where most rows hold a step)
    means = np.empty((ys.size, 6), np.float64)
    _kernels.side_means(_rows_mean(rgb), ys, xs, m, means)
    r_l, r_r, g_l, g_r, b_l, b_r = means.T
    judged = (b_l >= ALBEDO_CONFIRM_SHARE * np.maximum(np.maximum(r_l, g_l), b_l)) & (
        b_r >= ALBEDO_CONFIRM_SHARE * np.maximum(np.maximum(r_r, g_r), b_r)
    )
    eps = 1e-3 + 0.02 * np.maximum(b_l, b_r)
    ratio = np.maximum(b_l + eps, b_r + eps) / np.minimum(b_l + eps, b_r + eps)
    drop = judged & (ratio < ALBEDO_CONFIRM_RATIO)
    out = cuts.copy()
    out[ys[drop], xs[drop]] = False
    return out


def albedo_gain_reach_rows(period_px: float, order: int) -> int:
    """How many rows above and below a pixel :func:`albedo_gain` reads to make that pixel's gain:
    the spans' box mean (half a window), the edge rows' mean and erosion
    (:data:`ALBEDO_EDGE_ROWS`), the segment means' row average (:data:`ALBEDO_MEAN_ROWS`), and
    one row more: :func:`albedo_step_pixels` compares each row's gain with the next row's.  The
    decoder's row bands carry this many rows more than the phase fit needs
    (:func:`simbench.decode.bands.row_bands`), so that a band's gain and skipped pixels are the
    whole image's."""
    return _code_window_px(period_px, order) + ALBEDO_EDGE_ROWS // 2 + ALBEDO_MEAN_ROWS // 2 + 1


# Printed steps down the columns (ours, the colour-robust decoder's ``albedo_columns``).  A
# rig whose baseline runs along the camera's rows sees the projector's stripes run down its
# columns: down a column the fringe and the code stay as they are, and the light changes with
# the surface alone.  Rows averaged on each side of a boundary between two rows, beyond the pair
# the camera's blur mixes (assumption: 4 - the noise of a 20:1 ink's few-DN fringe halved, and
# a printed band of 2 x (4 + 1) rows, 4.6 mm at 1 m, still seen whole)
COLUMN_EDGE_ROWS = 4
# the columns either side over which a boundary's step is summed to find its row down the column
# and its darker side (a fringe's trough, dark on both sides, cannot place it; assumption: a
# quarter period - the trough's darkest third is then within reach of its brighter flanks)
COLUMN_PLACE_PERIODS = 0.25
# a boundary whose two sides' light differs by ALBEDO_EDGE_RATIO or more is a print's edge where
# the rows beyond it are a scaled copy of the rows before it, fringe included: along the run of
# such boundaries in a row, at least COLUMN_MIN_COPY_SHARE of its columns (those not in a
# fringe's trough) have their dark-over-bright ratio within COLUMN_COPY_RATIO of the run's median
# (assumption: 1.25 and 0.75 - a 20:1 ink's 5-18 DN of light, 4 rows averaged, is within 1.25x of
# its ratio at 8 bits; a projector shadow's border leaves no fringe on its dark side, whose ratio
# then follows 1 / the bright side's fringe, over a 4x range outside the troughs: ~40 % within
# 1.25x; a depth edge shifts the fringe, s, and its ratio f(x - s) / f(x) varies alike unless s
# is a small part of a period, where flattening the brightness step is flattening shading)
COLUMN_COPY_RATIO = 1.25
COLUMN_MIN_COPY_SHARE = 0.75
# ... over at least this many periods of columns (a shorter run holds too little of the fringe's
# shape to tell a scaled copy from a shifted one; assumption: 0.4), and at least COLUMN_MIN_RUN_PX
# columns (the share test's sample: of 8 ratios that follow the fringe, 6 within 1.25x of their
# median is rare; of 3, a quarter period at a quarter of the paper's resolution, it is not - the
# motion study's bust, 320x240, had its shading flattened at a few runs of 2-4 columns) ...
COLUMN_MIN_RUN_PERIODS = 0.4
COLUMN_MIN_RUN_PX = 8
# ... its length counting every column, its ratios those of the columns 1 .. COLUMN_RUN_END_PX from
# its ends where they agree better than all of them do (the first such trim with the best share):
# there the square beside along the row is part of the light (the camera's blur: the lens, and the
# demosaicing, which fills a Bayer mosaic's red and blue from samples two columns apart; a trim
# only where it helps - dropping good columns of a short run leaves its noisy ones more weight).
# With none, on scenes/hard_chart_fine_turned.toml's 22-px squares two mixed columns at each end
# of a run of ~20 failed the share test of a print's edge in one channel, and the square kept gain
# 1 over its last columns: a step inside the ink that the phase fit read as fringe, 5-7 mm wrong
# at confidences over the operating point.  With 1 alone (until 2026-12-02) the blue channel still
# failed it on ~0.4 % of that chart's ink: measured at a square's bottom edge at row 480, its blue
# ratio 0.74 and 0.52 in the run's first two columns, 0.29 and 0.30 in its last two, 0.20 between
# (12 of 17 within 1.25x of the median) ...
COLUMN_RUN_END_PX = 2
# ... an edge at boundary y counting for the runs of the rows y - 1, y and y + 1 (a print's edge that
# slants in the image - a print turned about the vertical - or whose peak the noise moves steps from
# boundary to boundary along the row; at most one edge of a column is within 3 boundaries: their
# peak test) ...
COLUMN_RUN_ROWS = 3
# ... whose brighter side's light varies along it by at least this share of its mean (a run on
# a fringe's flat crest, or under strong ambient light, cannot show a shift; assumption: 0.1)
COLUMN_MIN_VARIATION = 0.1
# the run's columns whose own darker side is the other count in its statistics not at all, and
# take its gain where both their sides are under this share of the run's brighter side's mean (a
# fringe's trough; assumption: 0.25 - a trough's darkest third), not beside a square's edge
COLUMN_TROUGH_SHARE = 0.25
# a column whose light on both sides of a boundary is under this share of the mean either side
# along the row (a quarter period) takes the darker side of its neighbours', not its own (deep in a
# fringe's trough its own is noise; assumption: 0.1)
COLUMN_DIM_SHARE = 0.1
# a run's darker-over-brighter ratio of the rows next to the skipped pair (half of each side's
# COLUMN_EDGE_ROWS) over that of the rows beyond them: a print's edge is a step, its sides flat
# down the column (that ratio ~1), where a ramp - a highlight's lobe fading, a glossy part's
# sheen, shading - changes within the sides as across them: with 4 rows a side, the near
# halves' centres 4 rows apart, the far halves' 8 and the sides' 6, by (8 - 4) / 6 = 2/3 of the
# step in logarithm.  A run whose median ratio is over COLUMN_RAMP_SHARE of its step is left
# alone (assumption: 1/3, halfway - a step the blur spreads ~25 % of into the row beyond the
# pair still passes; scenes/specular.toml's aluminium sphere, 640 x 480, had a 13-row segment of
# its highlight's rim flattened by 1.8x and lost ~2 % of its pixels beside the gain's steps)
COLUMN_RAMP_SHARE = 1.0 / 3.0
# a segment down a column between two print edges is flattened when it is at most this many
# periods long (assumption: 2 - longer segments are as wide as the steps along the rows need,
# ALBEDO_MIN_SEGMENT_PERIODS, in every print of squares; the decoder's row bands carry the rows)
COLUMN_MAX_SEGMENT_PERIODS = 2.0
# the darker side's crest, k times the brighter side's in its brightest channel, must reach this
# share of ``floor`` (the decoder's dark_level): the lit test compares one pixel's maximum over a
# period, which the noise lifts, where this crest is the run's scale times 4-row means; and the
# scaled copy, which the run has passed, is the fringe's evidence (noise or an ambient-lit shadow
# is no copy).  Assumption: 0.5.  The 20:1 ink of scenes/hard_chart_fine.toml crests at 0.03-0.04
# in its blue: at 1 (until 2026-12-03) none of it was flattened and nothing decoded; its
# completeness at the operating point is 90.3-90.5 % for any share from 0.25 to 0.625 (at 0.75,
# 19.9 %: the ink's crest is at the cliff, not the share)
COLUMN_CREST_SHARE = 0.5
# a segment down a column between two print edges whose darker side it is is flattened only where
# their gains agree within this factor: each is a run's median of ratios within COLUMN_COPY_RATIO,
# so COLUMN_COPY_RATIO squared.  A projector shadow's band between a lit wall and a dimmer surface
# below it is no ink: its two edges' ratios are the wall's and the other surface's (measured on
# scenes/hard_sphere_before_wall.toml: 1.9-3.6x apart over 38 segments, 226 pixels flattened
# without this test once COLUMN_CREST_SHARE and the per-column channel test let its runs through);
# the fine charts' squares: at most 1.43x (20:1), 1.08x (3:1), 1.46x (5:1 turned).  Not caught:
# scenes/specular.toml's aluminium sphere, where chance runs in its highlight's speckle now pass
# (85 pixels at ~2.2x; its colour-robust scores 41.92 -> 41.97 % complete, 0.249 -> 0.262 % wrong)
COLUMN_SCALE_AGREE = COLUMN_COPY_RATIO**2
# a run whose copy holds over this share of its columns (not COLUMN_MIN_COPY_SHARE), or that a
# channel's copy test fails, is a weak edge: it closes a segment started by a print edge whose gain
# it agrees with (COLUMN_SCALE_AGREE) - two measures of one ink - and starts none (assumption: 0.5,
# a majority; the 20:1 ink's 4-row means on its darker side are 2-5 DN in the channels' mean: of
# scenes/hard_chart_fine.toml's 8 squares left wholly at gain 1, each had one edge at 0.87-0.94 and
# the other at 0.69-0.74)
COLUMN_WEAK_SHARE = 0.5


def column_segment_rows(period_px: float) -> int:
    """The longest segment down a column :func:`column_albedo_gain` flattens (rows)."""
    return int(np.ceil(COLUMN_MAX_SEGMENT_PERIODS * period_px))


def column_gain_reach_rows(period_px: float) -> int:
    """How many rows above and below a pixel :func:`column_albedo_gain` reads to make that
    pixel's gain: the edges of the longest segment it flattens (:func:`column_segment_rows` + 1),
    the runs an edge counts for and the edges they hold (2 x :data:`COLUMN_RUN_ROWS` // 2), the
    rows each edge's test averages beyond it and the pair it skips (:data:`COLUMN_EDGE_ROWS` + 1),
    the boundaries its peak test compares it with (2), and the rows the pixels beside its steps
    are marked from (:data:`COLUMN_SKIP_PX`; :func:`albedo_step_pixels` compares each row's gain
    with the next row's, one of them)."""
    runs = 2 * (COLUMN_RUN_ROWS // 2)
    return column_segment_rows(period_px) + 1 + runs + COLUMN_EDGE_ROWS + 1 + 2 + COLUMN_SKIP_PX


def _median_share(qa: np.ndarray, ru: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Per run (``ru`` < ``m``): the median ``k`` of the ratios ``qa`` and the share of them within
    :data:`COLUMN_COPY_RATIO` of it (NaN where a run has none)."""
    n = np.bincount(ru, minlength=m).astype(np.float64)
    # the median (beside a square's edge along the row a column's dark side holds the
    # neighbour's light: an outlier a median ignores), the lower one, by selection
    # (simbench/_ckernels.c: the element np.lexsort((qa, ru)) puts there, ~10x faster; the runs'
    # columns are in run order, rid being a cumulative sum)
    k = np.empty(m, np.float64)
    _kernels.group_median(qa, ru, m, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        copy = np.abs(np.log(qa / k[ru])) <= np.log(COLUMN_COPY_RATIO)
        share = np.bincount(ru, copy, m) / n
    return k, share


def _scaled_copy(a, b, rid, own, m, up_v, dn_v, *, from_end, of_max: bool = False):
    """Per run (``rid`` < ``m``) of :func:`column_albedo_gain`: the median ``k`` of its columns'
    dark-over-bright ratios ``a / b``, the share of them within :data:`COLUMN_COPY_RATIO` of it
    and their count - over the columns whose own darker side is the run's (``own``) and that are
    not in a fringe's trough (both sides ``up_v``, ``dn_v`` under :data:`COLUMN_TROUGH_SHARE` of
    the run's brighter side's mean, or with ``of_max`` its brightest column); ``k`` and the share
    those of the run's columns at least e from its ends (``from_end``: 0 at an end), e = 1 ..
    :data:`COLUMN_RUN_END_PX`, instead where more of theirs are within reach (the first such e
    with the most) - per column those columns and the troughs', and per run that level."""
    if of_max:
        level = np.zeros(m)
        np.maximum.at(level, rid[own], b[own])
    else:
        n_own = np.bincount(rid[own], minlength=m).astype(np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            level = np.bincount(rid[own], b[own], m) / n_own
    with np.errstate(invalid="ignore"):
        trough = np.maximum(up_v, dn_v) < COLUMN_TROUGH_SHARE * level[rid]
    use = own & ~trough & (b > 0)
    ru = rid[use]
    qa = a[use] / b[use]
    n = np.bincount(ru, minlength=m).astype(np.float64)
    k, share = _median_share(qa, ru, m)
    placed = from_end[use]
    for e in range(1, COLUMN_RUN_END_PX + 1):
        mid = placed >= e
        k_in, share_in = _median_share(qa[mid], ru[mid], m)
        with np.errstate(invalid="ignore"):
            better = share_in > share
        k, share = np.where(better, k_in, k), np.where(better, share_in, share)
    return k, share, n, use, trough, level


def column_albedo_gain(rgb: np.ndarray, *, period_px: float, floor: float) -> np.ndarray | None:
    """Per-pixel gain that flattens printed albedo steps found down the columns (ours; not in the
    paper), or None where there is none.

    :func:`albedo_gain` finds a print's steps along the rows, where the fringe itself varies: it
    needs a segment of :data:`ALBEDO_MIN_SEGMENT_PERIODS` periods to tell the print's brightness
    from the fringe's, and a checkerboard of squares about one period wide (10 mm at 1 m) decodes
    nowhere.  Down a column nothing but the surface varies, so a step there is measured from a
    few rows on each side, whatever the squares' width:

    1. each boundary between rows y and y + 1 compares the light (the channels' mean, ``rgb``
       unmixed) of the :data:`COLUMN_EDGE_ROWS` rows next to it on each side; summed over
       :data:`COLUMN_PLACE_PERIODS` either side along the row, their contrast's peak down the
       column (over two boundaries each way) places an edge - the means skipping the pair the
       blur mixes (rows y and y + 1) tie over three boundaries at a sharp edge - and, where it
       reaches :data:`ALBEDO_EDGE_RATIO`, a candidate; the darker side is the column's own
       (:data:`COLUMN_DIM_SHARE`: in a trough, its neighbours');
    2. the edges of one row that follow each other with the same darker side form a run; a run
       is a print's edge where the darker side's light is a scaled copy of the brighter side's
       along it: outside the fringe's troughs (:data:`COLUMN_TROUGH_SHARE`) and the columns
       whose own darker side is the other (beside a square's edge along the row), at least
       :data:`COLUMN_MIN_COPY_SHARE` of its columns' dark-over-bright ratios (the means that skip
       the mixed pair) within :data:`COLUMN_COPY_RATIO` of their median ``k``, in the channels'
       mean and in each channel over its columns whose darker side ``k`` lights to ``floor`` (a
       20:1 ink's code channel across the other code's stripes is ~2 DN, its ratio the noise's),
       over at least :data:`COLUMN_MIN_RUN_PERIODS` periods and :data:`COLUMN_MIN_RUN_PX` columns, the brighter
       side varying by :data:`COLUMN_MIN_VARIATION` or more - a projector shadow's border leaves no
       fringe on its dark side, and a depth edge shifts the fringe (and, where that lines up, the
       code stripes) - where ``1 / k >=`` :data:`ALBEDO_EDGE_RATIO`, the darker side's crest,
       ``k`` times the brighter side's, reaches :data:`COLUMN_CREST_SHARE` of ``floor`` in one
       channel at least (a darker print
       brightened is its noise brightened; the decoder's lit test reads the brightest channel
       too: :func:`simbench.decode.phase.certainty_map`), and the sides are flat down the column:
       the ratio of their halves next to the boundary over that of their halves beyond, the
       run's median, at most ``(1 / k) **`` :data:`COLUMN_RAMP_SHARE` (a ramp - a highlight's
       lobe - is a scaled copy too);
    3. the darker side's segment, down to the next print edge of its column, takes the gain
       ``1 / k`` (at most :data:`ALBEDO_MAX_GAIN`) where that edge is within
       :func:`column_segment_rows` and, where its darker side is this segment too, its gain agrees
       (:data:`COLUMN_SCALE_AGREE`: one ink under both); a longer segment is left to the steps
       along the rows.  A run that fails only the copy share (over :data:`COLUMN_WEAK_SHARE` of
       its columns) or a channel's copy test is a weak edge: it closes a segment whose darker
       side it faces and whose gain it agrees with, and starts none (nor counts for the frame's
       test below; in the first or last two boundaries it stays the frame's).  The
       image's top or bottom row closes a segment too where the segment beyond its edge is
       closed within reach (a square the frame cuts, in a column of squares that short: the
       3:1 print of ``scenes/hard_chart_fine_mid.toml`` lost ~20 rows at each end of the image
       without it; a print of taller squares is the steps along the rows' to flatten, its cut
       squares too - flattened down the columns, 40 mm squares at 1.6:1 lost a few hundred
       pixels near the frame).  A step at the first or last two boundaries, whose peak test saw
       one side only, is the frame's for the segments that reach it (an edge a row or two inside
       the frame, too near it to place or judge: on ``scenes/hard_chart_fine_turned.toml`` ~0.4 %
       of the ink, squares under a sliver of paper at the top and bottom rows, kept gain 1).

    The pixels beside the gain's steps hold both sides' light: :func:`column_step_pixels`.

    A pixel's gain is the larger of its segment's two print edges' (a weak edge's gain only
    checks the other's).  Shading, falloff and any change
    slower than the rows compared pass through; a stripe pattern that does not run down the
    image's columns (a rig with a vertical baseline) shows no copy there and is left alone.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32; the unmixed capture
    period_px : float
        Fringe period in camera pixels.
    floor : float
        The decoder's ``dark_level`` (full scale): the darker side's crest needs
        :data:`COLUMN_CREST_SHARE` of it, and a channel's column is judged where its darker side's
        light (``k`` times its brighter side's) reaches it.

    Returns
    -------
    ndarray, shape (H, W), float32 in [1, :data:`ALBEDO_MAX_GAIN`], or None
    """
    src = np.ascontiguousarray(rgb, np.float32)
    h, w = src.shape[:2]
    n_rows = COLUMN_EDGE_ROWS
    if h < 2 * n_rows + 2 + 4 or w < 2 or src.ndim != 3:
        return None
    # the channels' mean, then the means of n rows from each row on (summed in a fixed order: the
    # same bits whichever rows a band holds)
    total = cv2.transform(src, np.full((1, src.shape[2]), 1.0 / src.shape[2], np.float32))
    runs = total[: h - n_rows + 1].copy()
    for i in range(1, n_rows):
        runs += total[i : h - n_rows + 1 + i]
    runs *= np.float32(1.0 / n_rows)
    ys = np.arange(n_rows, h - n_rows - 1)  # boundary y: between rows y and y + 1
    # (each a row range of runs: runs[ys + d] as a view, not a copy)
    rows_at = {d: runs[n_rows + d : n_rows + d + ys.size] for d in (-n_rows, -n_rows + 1, 1, 2)}
    above = rows_at[-n_rows]  # rows y - n .. y - 1
    below = rows_at[2]  # rows y + 2 .. y + n + 1 (rows y and y + 1 straddle the boundary)
    reach = max(1, int(round(COLUMN_PLACE_PERIODS * period_px)))
    box = (2 * reach + 1, 1)
    # the edge is placed with the rows either side of the boundary next to it (rows y - n + 1 .. y
    # and y + 1 .. y + n): its contrast then peaks at a sharp edge's own boundary, where the
    # means that skip the straddling pair are alike for three boundaries
    step = rows_at[-n_rows + 1] - rows_at[1]
    diff = cv2.blur(step, box, borderType=cv2.BORDER_REPLICATE)
    both = cv2.blur(rows_at[-n_rows + 1] + rows_at[1], box, borderType=cv2.BORDER_REPLICATE)
    contrast = cv2.blur(np.abs(step), box, borderType=cv2.BORDER_REPLICATE) / np.maximum(both, np.float32(1e-6))
    # a step of ALBEDO_EDGE_RATIO: contrast (r - 1) / (r + 1)
    cand = contrast >= np.float32((ALBEDO_EDGE_RATIO - 1.0) / (ALBEDO_EDGE_RATIO + 1.0))
    if not cand.any():
        return None
    peak = cand.copy()  # the step's own boundary: the contrast peaks there down the column (ties: the upper one)
    for d in (1, 2):
        peak[d:] &= contrast[d:] > contrast[:-d]
        peak[:-d] &= contrast[:-d] >= contrast[d:]
    if not peak.any():
        return None
    # runs along the rows: the edges of consecutive columns with the same darker side, an edge at
    # boundary y counting for the runs of rows y - 1 .. y + 1 (COLUMN_RUN_ROWS) and judged there
    # with its own boundary's light
    pk = np.flatnonzero(peak.ravel())
    up_p, dn_p = above.ravel()[pk], below.ravel()[pk]
    # each column's own darker side, but in a fringe's trough (dark on both sides, its side is
    # noise) the side of the columns either side
    with np.errstate(invalid="ignore", divide="ignore"):
        dim = (up_p + dn_p) < np.float32(COLUMN_DIM_SHARE) * both.ravel()[pk]
        # (the two sides' light closer than a print edge's ratio: a trough not that dark, whose side
        # is noise too; it takes the side of the sure columns either side along its run)
        unsure = np.maximum(up_p, dn_p) < np.float32(ALBEDO_EDGE_RATIO) * np.minimum(up_p, dn_p)
    down_p = np.where(dim, diff.ravel()[pk] > 0, dn_p < up_p)
    shifts = np.arange(COLUMN_RUN_ROWS) - COLUMN_RUN_ROWS // 2
    key = (pk[None, :] - shifts[:, None] * w).ravel()  # the run's row, the edge's column
    of = np.tile(np.arange(pk.size), shifts.size)  # the edge
    shift = np.repeat(shifts, pk.size)  # its boundary less the run's row
    keep = (key >= 0) & (key < peak.size)
    # (a column's keys are its edges', 3 boundaries apart at least: no two alike)
    order_ = np.argsort(key[keep], kind="stable")
    key, of, shift = key[keep][order_], of[keep][order_], shift[keep][order_]
    sel = pk[of]
    up_f, dn_f, down = up_p[of], dn_p[of], down_p[of]
    joined = np.zeros(key.size, bool)  # the column after the one before, in the same row
    joined[1:] = (key[1:] == key[:-1] + 1) & (key[1:] % w != 0)
    unsure = unsure[of]
    if unsure.any():
        at = np.arange(key.size)
        chain = np.cumsum(~joined)
        left = np.maximum.accumulate(np.where(unsure, -1, at))
        right = np.minimum.accumulate(np.where(unsure, key.size, at)[::-1])[::-1]
        li, ri = np.maximum(left, 0), np.minimum(right, key.size - 1)
        both_sides = (left >= 0) & (chain[li] == chain) & (right < key.size) & (chain[ri] == chain)
        down = np.where(unsure & both_sides & (down[li] == down[ri]), down[li], down)
    start = ~joined
    start[1:] |= down[1:] != down[:-1]
    rid = np.cumsum(start) - 1
    firsts = np.flatnonzero(start)
    place = np.arange(rid.size) - firsts[rid]
    from_end = np.minimum(place, np.diff(np.append(firsts, rid.size))[rid] - 1 - place)
    up_v, dn_v = up_f.astype(np.float64), dn_f.astype(np.float64)
    # the column's own darker side: beside a square's edge along the row, the run's side is its
    # neighbour's, and in a fringe's trough, dark on both sides, either
    own = (dn_v < up_v) == down
    a = np.where(down, dn_v, up_v)  # the darker side's light
    b = np.where(down, up_v, dn_v)
    m = int(rid.max()) + 1
    k, share, n, use, trough, _ = _scaled_copy(a, b, rid, own, m, up_v, dn_v, from_end=from_end)
    # the sides' halves next to the pair and beyond it (a ramp's light changes within the sides)
    # (read at the run's edges only; summed in the rows' order, as the side means are)
    half = n_rows // 2
    by_e, bx_e = ys[sel[use] // w], sel[use] % w
    d_use = down[use]

    def rows_sum(first: np.ndarray) -> np.ndarray:
        out = total[first, bx_e].copy()
        for i in range(1, half):
            out += total[first + i, bx_e]
        return out

    up_near, up_far = rows_sum(by_e - half), rows_sum(by_e - n_rows)
    dn_near, dn_far = rows_sum(by_e + 2), rows_sum(by_e + 2 + n_rows - half)
    a_near, a_far = np.where(d_use, dn_near, up_near), np.where(d_use, dn_far, up_far)
    b_near, b_far = np.where(d_use, up_near, dn_near), np.where(d_use, up_far, dn_far)
    with np.errstate(divide="ignore", invalid="ignore"):
        ramp_c = (a_near.astype(np.float64) * b_far) / (b_near.astype(np.float64) * a_far)
    ramp_c = np.where(np.isfinite(ramp_c), ramp_c, np.inf)
    ramp, _ = _median_share(ramp_c, rid[use], m)
    with np.errstate(divide="ignore", invalid="ignore"):
        bu = b[use]
        sb, sbb = np.bincount(rid[use], bu, m), np.bincount(rid[use], bu * bu, m)
        variation = np.sqrt(np.maximum(sbb / n - (sb / n) ** 2, 0.0)) / (sb / n)
        base = (
            (n >= max(COLUMN_MIN_RUN_PERIODS * period_px, COLUMN_MIN_RUN_PX))
            & (variation >= COLUMN_MIN_VARIATION)
            & (k > 0)
            & (k * ALBEDO_EDGE_RATIO <= 1.0)
            # (a step, not a ramp: ramp <= (1 / k) ** COLUMN_RAMP_SHARE)
            & (np.log(ramp) <= COLUMN_RAMP_SHARE * -np.log(k))
        )
        ok = base & (share >= COLUMN_MIN_COPY_SHARE)
        # a weaker copy (COLUMN_WEAK_SHARE) only closes a segment whose other edge is a print's
        # and agrees with it (COLUMN_SCALE_AGREE)
        weak_or_ok = base & (share >= COLUMN_WEAK_SHARE)
    if not ok.any():
        return None
    # each colour channel a scaled copy too (its own scale: a coloured ink): across a depth edge
    # whose fringe happens to line up, the code stripes do not (a shifted De Bruijn window)
    part = weak_or_ok[rid]
    sub, rsub, dsub, osub, esub = sel[part], rid[part], down[part], own[part], from_end[part]
    # (one pass over the edges for every channel, simbench/_ckernels.c: the bits of numpy's
    # src[rows, cols, c].mean(axis=1, dtype=np.float64) over rows y - 1 .. y - n and y + 2 .. y + n + 1)
    side_up, side_dn = _kernels.column_side_means(src, ys[sub // w], sub % w, n_rows)
    # the darker side's crest, the scaled copy's, in its brightest channel - the decoder's lit test
    # reads the brightest channel too (certainty_map); the channels' mean of a fringe in one
    # channel and a code in another is ~a third of it (scenes/hard_chart_fine_turned.toml's far
    # left, 5:1 ink at ~1.1 m: 0.039 in the mean, 0.048 in its blue and 0.07 in its green code)
    lit = np.zeros(m, bool)
    for c in range(src.shape[2]):
        cu, cd = side_up[:, c], side_dn[:, c]
        ca, cb = np.where(dsub, cd, cu), np.where(dsub, cu, cd)
        # (a code channel is dark across the other code's stripes: its level is its crest's)
        k_c, _, _, _, _, crest_c = _scaled_copy(ca, cb, rsub, osub, m, cu, cd, from_end=esub, of_max=True)
        with np.errstate(invalid="ignore"):
            lit |= k_c * crest_c >= np.float32(COLUMN_CREST_SHARE * floor)
        # the copy judged in the columns whose darker side the run's scale k lights to floor: a
        # darker side under it is a few DN whose ratio is the noise's (a channel the run's stripes
        # hardly light - a code channel across the other code's stripes - judges nothing)
        with np.errstate(invalid="ignore"):
            lit_enough = osub & (k[rsub] * cb >= floor)
        _, share_c, n_c, _, _, _ = _scaled_copy(ca, cb, rsub, lit_enough, m, cu, cd, from_end=esub, of_max=True)
        judged = n_c >= max(COLUMN_MIN_RUN_PERIODS * period_px, COLUMN_MIN_RUN_PX)
        with np.errstate(invalid="ignore"):
            ok &= ~judged | (share_c >= COLUMN_MIN_COPY_SHARE)
    # weak: the copy share under COLUMN_MIN_COPY_SHARE, or a channel's test failed (a weak run's
    # channels are not asked to pass: their copy is the noisier one)
    weak = weak_or_ok & ~ok & lit
    ok &= lit
    with np.errstate(divide="ignore"):
        run_gain = np.where(ok | weak, np.minimum(1.0 / k, ALBEDO_MAX_GAIN), 1.0).astype(np.float32)

    def edges_of(runs: np.ndarray, taken: np.ndarray | None = None) -> np.ndarray:
        # an edge is a print's where one of its runs is (its column's own darker side there, or a
        # trough's): its own row's, else the row above's, else below's; its gain is that run's
        fit = runs[rid] & (own | trough)
        if taken is not None:
            fit &= ~taken[of]
        cand = np.flatnonzero(fit)
        cand = cand[np.lexsort((shift[cand], np.abs(shift[cand]), of[cand]))]
        return cand[np.unique(of[cand], return_index=True)[1]]

    pick = edges_of(ok)
    if pick.size == 0:
        return None
    strong = np.zeros(pk.size, bool)
    strong[of[pick]] = True
    pick_weak = edges_of(weak, strong)
    g = run_gain[rid[pick]]
    chosen = sel[pick]
    row, bx = np.divmod(chosen, w)
    by = ys[row]  # the edge's boundary y: between rows y and y + 1
    edge = np.zeros((h + 1, w), bool)  # edge[y]: a print edge (or a weak one) between rows y and y + 1
    edge[by, bx] = True
    # its gain, signed by its darker side: + below the boundary, - above it
    scale = np.zeros((h + 1, w), np.float32)
    scale[by, bx] = np.where(down[pick], g, -g)
    # the first and last two boundaries' peaks were compared on one side only (the rows beyond
    # them are the frame's): such a step is an edge too near the frame to place or judge - the
    # frame's own, for the segments that reach it
    frame = np.zeros(h + 1, bool)
    frame[ys[:2]] = frame[ys[-2:]] = True
    strong_edge = edge.copy()  # (the frame's test of a cut square reads print edges only)
    weak_edge = np.zeros((h + 1, w), bool)
    if pick_weak.size:
        wy, wx = ys[sel[pick_weak] // w], sel[pick_weak] % w
        gw = run_gain[rid[pick_weak]]
        # (a weak step in the frame's rows stays the frame's)
        inner = ~frame[wy]
        wy, wx, gw, wd = wy[inner], wx[inner], gw[inner], down[pick_weak][inner]
        edge[wy, wx] = weak_edge[wy, wx] = True
        scale[wy, wx] = np.where(wd, gw, -gw)
    down = down[pick]
    # any step down a column ends a segment; the segment is flattened where that step is a print edge
    stop = np.zeros((h + 1, w), bool)
    stop[ys] = peak
    longest = column_segment_rows(period_px)
    gain = np.ones((h, w), np.float32)
    for sign in (1, -1):
        pick = down if sign == 1 else ~down
        # the segment's first row (the darker side's), and the brighter side's first row
        y0, x0, g0 = (by + 1)[pick] if sign == 1 else by[pick], bx[pick], g[pick]
        end, rim = _column_segments(y0, x0, sign, stop=stop, edge=edge, frame=frame, longest=longest)
        if rim.any():
            # a square the frame cuts is flattened where the column's print is fine: the
            # segment beyond its edge is a flattened one's length (a print of squares taller
            # than the reach is the steps along the rows' to flatten, the cut one too)
            y1 = by[pick][rim] if sign == 1 else (by + 1)[pick][rim]
            other, _ = _column_segments(y1, x0[rim], -sign, stop=stop, edge=strong_edge, frame=frame, longest=longest)
            end[np.flatnonzero(rim)[other <= 0]] = -1
        # (the segments of one direction do not overlap: the next edge ends each)
        # (np.maximum.at over every segment's pixels, without their index arrays: simbench/_ckernels.c)
        done = end > 0
        # a segment between two print edges whose darker side it is lies under one ink: their
        # gains agree (COLUMN_SCALE_AGREE)
        both = np.flatnonzero(done & ~rim)
        far_y = y0[both] + end[both] - 1 if sign == 1 else y0[both] - end[both]
        g_far = -sign * scale[far_y, x0[both]]  # > 0 where the far edge's darker side is this segment
        g_near = g0[both]
        apart = np.maximum(g_far, g_near) > np.float32(COLUMN_SCALE_AGREE) * np.minimum(g_far, g_near)
        # (a weak far edge closes the segment only facing it and agreeing)
        disagree = ((g_far > 0) & apart) | (weak_edge[far_y, x0[both]] & ~(g_far > 0))
        done[both[disagree]] = False
        _kernels.segments_max(gain, y0[done], x0[done], end[done], g0[done], sign)
    # (no segment closed by a print edge: nothing to flatten)
    return gain if (gain != 1.0).any() else None


def _column_segments(
    y0: np.ndarray,
    x0: np.ndarray,
    sign: int,
    *,
    stop: np.ndarray,
    edge: np.ndarray,
    frame: np.ndarray,
    longest: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The segments down (``sign`` 1) or up (-1) the columns ``x0`` from rows ``y0`` to the next
    step (``stop[y]``: a step between rows y and y + 1): their lengths in rows where that step is
    a print edge (``edge``) or the image's border within ``longest`` rows, else -1; and whether
    the border ended each (a square the frame cuts: no other step between, or a step at a
    boundary ``frame[y]`` marks, too near the border to be judged).  One walk per start in
    simbench/_ckernels.c (the results of the numpy form, column_segments in
    tests/numpy_reference.py, which stepped every start a row at a time: ~10x slower)."""
    return _kernels.column_segments(y0, x0, sign, stop, edge, frame, longest)


def column_step_pixels(
    gain: np.ndarray, *, ratio: float = ALBEDO_SKIP_RATIO, reach_px: int = COLUMN_SKIP_PX
) -> np.ndarray:
    """The pixels within ``reach_px`` of a step of :func:`column_albedo_gain` by ``ratio`` or more,
    on both sides, along the rows and down the columns (ours; left out of the phase fit as
    :func:`albedo_step_pixels`' are, which mark the column gain's steps too, but closer).

    The column gain's steps are placed to about a pixel - along a row where its runs of edges
    end, down a column at a contrast peak of row means - and the camera's blur (the bilinear
    demosaicing's neighbour rows and columns, the lens) mixes about a pixel more each side: a
    pixel there takes one side's gain on light partly the other's, off by up to the ratio
    (:data:`COLUMN_SKIP_PX`).

    Parameters
    ----------
    gain : ndarray, shape (H, W), float32 >= 1; :func:`column_albedo_gain`'s
    ratio : float
        The step, as the larger gain over the smaller, from which the pixels are marked.
    reach_px : int >= 1
        Pixels marked on each side of a step (1: the pair straddling it).

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    from simbench import validate as v

    reach_px = v.integer(reach_px, "reach_px", lo=1)
    g = np.asarray(gain, np.float32)
    r = np.float32(ratio)
    out = np.zeros(g.shape, bool)
    for axis in (0, 1):
        n = g.shape[axis]
        if n < 2:
            continue
        a, b = np.moveaxis(g, axis, 0)[1:], np.moveaxis(g, axis, 0)[:-1]
        step = (a >= r * b) | (b >= r * a)  # step[i]: between pixels i and i + 1
        view = np.moveaxis(out, axis, 0)
        for s in range(min(reach_px, n - 1)):
            view[s + 1 :] |= step[: n - 1 - s]  # pixels i + 1 + s, on the far side
            view[: n - 1 - s] |= step[s:]  # pixels i - s, on the near side
    return out


def mixed_pixel_gain(gain: np.ndarray, mixed: np.ndarray, *, reach_px: int) -> np.ndarray:
    """``gain`` with each ``mixed`` pixel's replaced by the least gain within ``reach_px`` of it
    (a square of side ``2 reach_px + 1``; ours, not in the paper): the gain with which such a
    pixel enters the channel normalisation's running extrema (:func:`normalize_channels`'
    ``extrema_gain``).

    A pixel beside a step of the flattening's gain (:func:`albedo_step_pixels`,
    :func:`column_step_pixels`) holds light of both sides, and its own side's gain - the darker
    side's, up to :data:`ALBEDO_MAX_GAIN` - can lift it above either side's flattened light.  The
    phase fit leaves it out, but the running maximum takes it, and its box mean spreads it over
    ~4 periods of the row: the span rises by a share that changes from row to row and along the
    row, a change of the fringe's amplitude inside every window over it, which shifts the fitted
    phase.  With the brighter side's gain it can be no brighter than the flattened light around
    it, and too dark it is no lower than the fringe's troughs, which the running minimum holds in
    every window.  Its own value keeps its own gain (the colour code reads it).  Measured on
    ``scenes/hard_chart_fine_turned.toml`` (5:1 squares ~one period wide; the cached capture of
    `simbench reproduce hard_scenes`, 2026-12-02, with the column gain's fixes of that day): the
    pixels kept at the operating point 95.7 -> 99.3 %, MAE 0.55 -> 0.30 mm; the mixed pixels'
    values at that gain too, 97.6 % (on the synthetic fine print of tests/test_robust_decoder.py,
    unblurred, 99.5 -> 95.2 % at 10:1: the values are the colour code's).

    Parameters
    ----------
    gain : ndarray, shape (H, W), float32 >= 1
    mixed : ndarray, shape (H, W), bool
    reach_px : int >= 1
        How far from a mixed pixel the step it lies beside can be.

    Returns
    -------
    ndarray, shape (H, W), float32 (a new array)
    """
    from simbench import validate as v

    reach_px = v.integer(reach_px, "reach_px", lo=1)
    g = np.ascontiguousarray(gain, np.float32)
    if g.shape != np.shape(mixed):
        raise ValueError(f"mixed: expected shape {g.shape}, got {np.shape(mixed)}")
    side = 2 * reach_px + 1
    # (the border replicated: a pixel at the image's edge has no lower gain beyond it)
    low = cv2.erode(g, np.ones((side, side), np.uint8), borderType=cv2.BORDER_REPLICATE)
    return np.where(mixed, low, g)


def column_flattened(rgb: np.ndarray, columns: np.ndarray) -> np.ndarray:
    """The light :func:`albedo_gain` looks for steps along the rows in, once the column gain has
    flattened a print's steps down the columns (ours): ``rgb`` times ``columns``, each pixel
    beside a step of the column gain (:func:`column_step_pixels`) held within the range of the
    flattened light of the pixels beside no step in the square of side ``2 COLUMN_SKIP_PX + 3``
    around it (each channel; where the square holds none, at the lowest gain near it,
    :func:`mixed_pixel_gain`).

    A pixel straddling a step of the column gain holds both sides' light, and with the darker
    side's gain - up to ~20x beside a 20:1 ink - it is a spike over the flattened light around
    it: on the rendered turned 20:1 chart (``scenes/hard_chart_fine_high_turned.toml``) the blue
    of one such pixel 6.6 against 0.4 either side, which lifts the mean of the two periods beside
    it by ~1.4x.  The step test along the rows (:func:`albedo_edges`) read those spikes as steps,
    and the row gain's steps cut the flattened print where it has none.  The lowest gain near
    each such pixel instead (as the normalisation's extrema take them) ends the spikes, but
    darkens the ink's first two columns beside every step into dips: on the synthetic 20:1
    checkerboard of 1.75-period squares (tests/test_robust_decoder.py) 99.0 -> 91.7 % kept; the
    range of the light around them leaves a correctly flattened pixel as it is.  Measured
    2026-12-03 (the cached captures of `simbench reproduce hard_scenes`, kept at the operating
    point, MAE, share > 5 mm wrong; with the lowest gain in brackets): that chart 86.5 -> 92.9 %
    (92.2), 0.669 -> 0.518 mm (0.528), 0.101 -> 0.004 %; the 20:1 chart facing the camera
    (``hard_chart_fine.toml``) 94.8 -> 96.7 %, 0.464 -> 0.349 mm, 0.019 -> 0.005 % (the same);
    every other hard scene the same bits but the turned 5:1 chart's (99.68 %, 0.362 mm either way;
    0.366 mm).

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32; the unmixed capture
    columns : ndarray, shape (H, W), float32 >= 1; :func:`column_albedo_gain`'s

    Returns
    -------
    ndarray, shape (H, W, 3), float32
    """
    if np.shape(columns) != np.shape(rgb)[:2]:
        raise ValueError(f"columns: expected shape {np.shape(rgb)[:2]}, got {np.shape(columns)}")
    flat = (rgb * columns[..., None]).astype(np.float32)
    mixed = column_step_pixels(columns)
    if not mixed.any():
        return flat
    square = np.ones((2 * COLUMN_SKIP_PX + 3,) * 2, np.uint8)
    far = np.float32(np.finfo(np.float32).max)
    beside = np.repeat(mixed[..., None], 3, axis=2)
    # the range of the flattened light around each pixel, over the pixels beside no step
    hi = cv2.dilate(np.where(beside, -far, flat), square, borderType=cv2.BORDER_REPLICATE)
    lo = cv2.erode(np.where(beside, far, flat), square, borderType=cv2.BORDER_REPLICATE)
    low = rgb * mixed_pixel_gain(columns, mixed, reach_px=COLUMN_SKIP_PX)[..., None]
    held = np.where(hi > -far, np.clip(flat, lo, hi), low)
    return np.where(beside, held, flat).astype(np.float32)


def albedo_step_pixels(
    gain: np.ndarray, *, ratio: float = ALBEDO_SKIP_RATIO, bright_px: int = ALBEDO_SKIP_BRIGHT_PX
) -> np.ndarray:
    """The pixels beside a step of :func:`albedo_gain` by ``ratio`` or more (ours;
    ``DecoderParams.albedo_edge_skip``): along a row, the two that straddle it and, on its brighter
    side (the lower gain), those out to ``bright_px`` from it; down a column, the two that straddle
    it.

    The gain is a step where the print's albedo is one; the camera's blur is not: the two pixels
    straddling the edge hold both sides' light, which the gain flattens by the wrong factor - the
    dark side's pixel, amplified ~20x beside a 20:1 ink, carries the paper's fringe at 20x into
    every window over it - and on the step's bright side the next pixels are biased too
    (:data:`ALBEDO_SKIP_BRIGHT_PX`; the cause only partly known).  Down a column the step is a
    printed edge along the rows, which biases no phase but adds its mixed rows to the residual of
    the windows over them, the fringe SNR the confidence is.  Their samples are left out of
    the phase fit (their own phase then comes from their neighbours', as a clipped pixel's does),
    but count for its windows' support: they are lit surface.  On ``scenes/hard_chart_high.toml``
    81.9 -> 86.7 % of the pixels kept at the operating point with the pair along rows, the 3:1
    chart 97.1 -> 99.4 %; 88.3 -> 96.6 % with all of it (:data:`ALBEDO_SKIP_BRIGHT_PX`'s comment).

    Parameters
    ----------
    gain : ndarray, shape (H, W), float32 >= 1
    ratio : float
        The step, as the larger gain over the smaller, from which the pixels are marked.
    bright_px : int >= 1
        Pixels marked along a row on the step's brighter side, the straddling one included (1:
        the pair only).

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    from simbench import validate as v

    bright_px = v.integer(bright_px, "bright_px", lo=1)
    g = np.asarray(gain, np.float32)
    r = np.float32(ratio)
    out = np.zeros(g.shape, bool)
    h, w = g.shape
    if w >= 2:
        a, b = g[:, 1:], g[:, :-1]  # the gain right and left of each boundary between two pixels
        up = a >= r * b  # brighter (lower gain) on the left
        down = b >= r * a  # brighter on the right
        out[:, 1:] |= up | down
        out[:, :-1] |= up | down
        for s in range(1, min(bright_px, w - 1)):
            out[:, : w - 1 - s] |= up[:, s:]
            out[:, 1 + s :] |= down[:, : w - 1 - s]
    if h >= 2:
        # down the columns: the pair (ALBEDO_SKIP_BRIGHT_PX's comment)
        below, above = g[1:], g[:-1]
        step = (below >= r * above) | (above >= r * below)
        out[:-1] |= step
        out[1:] |= step
    return out


def albedo_gain(rgb: np.ndarray, span: np.ndarray, *, period_px: float, order: int) -> np.ndarray:
    """Per-pixel gain that flattens printed albedo steps out of a capture before
    :func:`normalize_channels` (ours; not in the paper).

    :func:`normalize_channels` rescales each channel by its range over a window of about four
    periods; across an albedo step inside that window (a printed chart, text) the range is the
    brighter side's, so the darker side's fringe comes out faint, and the phase fit over the step
    sees a fringe whose offset and amplitude jump: a biased phase, measured as 0.48 mm MAE and
    25 % of the pixels below the confidence operating point on a 3:1 chart of 40 mm squares at
    1 m (``scenes/hard_chart_mid.toml``).  Here the brightness is measured per segment between
    steps and divided out:

    1. An albedo proxy free of the code: each channel over its local range ``span`` (averaged
       over a window wider than the code's longest run, so that the code stripes weigh alike),
       the code pair ``R + G`` and the fringe ``B`` combined with weights ``span**2`` (the pair's
       ``1 / (1/span_R**2 + 1/span_G**2)``), leaving out a channel under
       :data:`ALBEDO_MIN_CHANNEL_SHARE` of the strongest (its crosstalk residue would make the
       proxy follow the code) and the pair where one code colour does not come back (a magenta
       board: its green-coded stripes are dark); with neither, the gain is 1;
    2. the steps of the proxy along the rows (:func:`albedo_edges`), less those the blue fringe,
       which carries no code, contradicts where it can judge (:func:`fringe_confirmed`);
    3. the proxy's mean over the normalisation window, kept inside each segment
       (:func:`segment_mean`), averaged over :data:`ALBEDO_MEAN_ROWS` rows: the segment's
       brightness;
    4. gain = (that mean's running maximum over the window, box-averaged) / (that mean), so that
       every segment is brought to the brighter neighbour's level and the result varies slowly.
       Segments shorter than :data:`ALBEDO_MIN_SEGMENT_PERIODS` periods keep gain 1, and the
       gain fades to 1 over a window's width beyond half a window from any step, linearly and
       without a jump, so that uniform surfaces (and the results on them) are left as they were.
       (Until 2026-11-29 the fade jumped from 1 to 1/2 at half a window from a step - a gain
       step of up to 2x inside a uniform print, which the phase fit read as an albedo step: on
       ``scenes/robust_printed.toml``'s green tile ~1000 pixels 1.1 projector px, 5 mm, off.)

    Shading, falloff and any change slower than a window pass through; depth edges with a
    brightness step are flattened like printed ones.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32; the unmixed capture
    span : ndarray, shape (H, W, 3), float32; :func:`normalize_channels`' local ranges of ``rgb``
    period_px : float
        Fringe period in camera pixels.
    order : int
        De Bruijn window length.

    Returns
    -------
    ndarray, shape (H, W), float32, in [1, :data:`ALBEDO_MAX_GAIN`]; 1 far from any step
    """
    half = _code_window_px(period_px, order)
    width = 2 * half + 1
    k = cv2.blur(np.ascontiguousarray(span, np.float32), (4 * half + 1, width), borderType=cv2.BORDER_REPLICATE)
    # a channel the surface hardly reflects carries mostly noise and crosstalk residue; the pair is
    # free of the code only where both code colours come back (one pass, simbench/_ckernels.c,
    # the bits of the numpy form in tests/numpy_reference.py)
    proxy = np.empty(k.shape[:2], np.float32)
    total_pos = np.empty(k.shape[:2], bool)
    _kernels.albedo_proxy(np.ascontiguousarray(rgb, np.float32), k, ALBEDO_MIN_CHANNEL_SHARE, proxy, total_pos)
    rows = _rows_mean(proxy)
    steps = _edges_of_rows(rows, period_px=period_px)
    # no step in the band (a uniform surface: most bands of most scenes): the gain is 1, and the
    # tests below, which only remove steps, need not run (~3 ms a band at the paper's resolution)
    if not steps.any():
        return np.ones(proxy.shape, np.float32)
    # only where the proxy is defined across a whole window (it is not, where it would follow the
    # code, and a border between defined and not is no albedo step)
    defined = cv2.erode(
        total_pos.view(np.uint8),
        np.ones((ALBEDO_EDGE_ROWS, 4 * half + 1), np.uint8),
        borderType=cv2.BORDER_REPLICATE,
    ).astype(bool)
    cuts = fringe_confirmed(steps & defined, rgb, period_px=period_px)
    if not cuts.any():
        # no step: the fade below is 0 everywhere and the gain exactly 1; no segment to measure
        return np.ones(proxy.shape, np.float32)
    # per pixel, over its segment: the proxy's window mean, the fringe's visibility, the segment's
    # length (one pass per row, simbench/_ckernels.c: the bits of segment_mean and
    # _segment_visibility, tests/test_kernels.py)
    mean = np.empty(proxy.shape, np.float32)
    vis = np.empty(proxy.shape, np.float32)
    short = np.empty(proxy.shape, bool)
    _kernels.albedo_segments(
        proxy,
        rows,
        cuts,
        width,
        _visibility_margin_px(period_px),
        ALBEDO_MIN_SEGMENT_PERIODS * period_px,
        mean,
        vis,
        short,
    )
    mean = cv2.blur(mean, (1, ALBEDO_MEAN_ROWS), borderType=cv2.BORDER_REPLICATE)
    shadow = vis < ALBEDO_MIN_VISIBILITY * cv2.dilate(vis, np.ones((1, width), np.uint8))
    level = cv2.blur(
        cv2.dilate(mean, np.ones((1, width), np.uint8), borderType=cv2.BORDER_REPLICATE),
        (width, 1),
        borderType=cv2.BORDER_REPLICATE,
    )
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = np.where(mean > 1e-6, level / np.maximum(mean, 1e-6), 1.0)
    gain = np.minimum(gain, ALBEDO_MAX_GAIN)
    gain[short | ~defined | shadow] = 1.0
    # 1 within half a window of a step, then down to 0 over a window's width: the box mean of a
    # run reaching a window beyond the step (continuous; a jump in the fade is a step in the gain)
    near = cv2.dilate(cuts.astype(np.uint8), np.ones((1, 2 * width - 1), np.uint8)).astype(np.float32)
    fade = cv2.blur(near, (width, 1), borderType=cv2.BORDER_REPLICATE)
    return (1.0 + (gain - 1.0) * fade).astype(np.float32)


def overlay_weight_reach_rows(period_px: float, order: int) -> int:
    """How many rows above and below a pixel :func:`overlay_weights` reads with ``down_columns``:
    half the code window.  The decoder's row bands carry this many rows more
    (:func:`simbench.decode.bands.row_bands`), so that a band's weights are the whole image's."""
    return _code_window_px(period_px, order)


def overlay_weights(
    raw: np.ndarray,
    span: np.ndarray,
    *,
    unmixing: np.ndarray | None,
    period_px: float,
    order: int,
    floor: float,
    down_columns: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Inverse noise variances of the normalised code pair (R + G) and fringe channel (B).

    A normalised channel ``(u - lo) / span`` has noise ``sigma_u / span``.  ``u`` is the
    unmixed channel ``sum_j U[c, j] c_j`` of raw channels ``c_j`` whose variance is taken
    proportional to ``c_j + floor`` (photon shot noise plus a read-noise floor in the same
    full-scale units: only ratios matter, the camera's gain drops out), with ``c_j`` the
    local mean over the code window.  The pair R + G has the sum of both variances: in every
    stripe one of them carries the fringe and the other only noise.

    With ``down_columns`` (ours, the colour-robust decoder's ``weights_down_columns``) each
    weight where it is not 0 is then the mean of the weights down its column over the code
    window's ``2 half + 1`` rows (:func:`overlay_weight_reach_rows`; the image's top and bottom
    rows replicated).  Down a column the fringe and the code stay as they are and only the
    surface changes, yet each pixel's weights are made from its own row's level and ranges: on a
    print's dark ink, whose channels are a few DN, those vary from row to row (on the rendered
    20:1 chart of 10 mm squares, ``scenes/hard_chart_fine.toml``, the mix ``w_fringe / (w_code +
    w_fringe)`` varies by 0.010 (1 sigma) about its column's mean, correlated more with the row
    two away than with the next: the Bayer mosaic's alternate rows), and the overlay's mix of the
    code pair and the fringe channel, whose normalised fringes are not alike there, changes from
    pixel to pixel inside every fit window.  Averaged, the pixels the chart gains fit with less
    residual (median 0.355 -> 0.248 of the fringe amplitude).  Measured 2026-12-03 on the cached
    captures of `simbench reproduce hard_scenes` (kept at the operating point, MAE): that chart
    96.74 -> 97.83 %, 0.349 mm either way; the turned 20:1 chart of 12 mm squares 92.92 ->
    94.78 %, 0.518 -> 0.510 mm; over 11 / 21 / 43 rows the first ~97.1 / 97.3 / 97.7 %.  The mean
    over a square of the code window instead (rows and columns): 97.88 and 94.87 %, but the
    aluminium sphere of ``scenes/specular.toml`` 0.26 -> 0.52 % of its decoded pixels > 5 mm
    wrong (down the columns 0.35 %); along the rows alone no chart gains.  Chosen on these charts
    (in sample); the other 26 hard scenes move by <= 0.07 points.  The synthetic boards of
    tests/test_robust_decoder.py (Gaussian noise, or a Bayer mosaic and its bilinear
    demosaicing at half resolution) gain nothing from it: what makes the rendered ink's weights
    matter is not pinned down.

    Parameters
    ----------
    raw : ndarray, shape (H, W, 3), float32; the capture before unmixing
    span : ndarray, shape (H, W, 3), float32; local ranges of the unmixed channels, 0 = no fringe
    unmixing : ndarray, shape (3, 3), or None (identity)
    floor : float
        Read-noise floor, full-scale units (assumption of the caller).
    down_columns : bool
        Each weight averaged down its column (above).

    Returns
    -------
    w_code, w_fringe : ndarray, shape (H, W), float32; 0 where a channel has no fringe
    """
    half = _code_window_px(period_px, order)
    raw = np.ascontiguousarray(raw, dtype=np.float32)
    level = np.empty(raw.shape, np.float32)
    _kernels.box_level(raw, half, floor, level)
    u = np.eye(3) if unmixing is None else np.asarray(unmixing, np.float64)
    var_u = cv2.transform(level, (u * u).astype(np.float32)).reshape(raw.shape)
    w_code = np.empty(raw.shape[:2], np.float32)
    w_fringe = np.empty(raw.shape[:2], np.float32)
    _kernels.noise_weights(var_u, np.ascontiguousarray(span, dtype=np.float32), w_code, w_fringe)
    if down_columns:
        rows = (1, 2 * overlay_weight_reach_rows(period_px, order) + 1)
        w_code, w_fringe = (
            np.where(w > 0, cv2.blur(w, rows, borderType=cv2.BORDER_REPLICATE), w) for w in (w_code, w_fringe)
        )
    return w_code, w_fringe


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
    max_gap_px: int = 0,
    gap_tolerance_rad: float = np.pi / 4,
) -> Stripes:
    """Split each row into stripes at wrapped-phase jumps, optionally bridging short gaps.

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
    max_gap_px : int
        Bridge gaps of up to this many invalid pixels (0: never).  Beside an albedo edge along
        the stripes the phase fit fails for a few pixels (its window straddles two
        reflectances) although the phase runs on across it; unbridged, every such gap cuts the
        row's chain of linked stripes, and a stripe cut off between two gaps, or between a gap
        and the image border, has too few neighbours for a De Bruijn window.  The phase slope
        on both sides of the gap (the stripe before it, the run after it) predicts the advance
        across it; if the phase after the gap lies within ``gap_tolerance_rad`` of the
        prediction, the stripe continues across the gap (no wrap in it) or the next stripe
        starts linked (one wrap).  Keep the gap shorter than a period, so that at most one
        wrap can hide in it.  A wrong bridge (a depth edge whose phase happens to continue) is
        caught like any wrong link, by the De Bruijn windows on both sides
        (:func:`simbench.decode.debruijn.drop_broken_links`).
    gap_tolerance_rad : float
        Largest distance, in radians, between the predicted and the measured phase after a
        bridged gap (assumption: pi/4, a quarter of the phase's +-pi range of outcomes, so a
        random phase jump at a depth edge is taken for a bridge with probability 1/4).

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
        np.ascontiguousarray(wrapped, dtype=np.float32),
        np.ascontiguousarray(valid, dtype=bool),
        lo,
        hi,
        int(max_gap_px),
        float(omega),
        float(gap_tolerance_rad),
        labels,
        row,
        start,
        stop,
        linked_prev,
    )
    return Stripes(
        labels=labels,
        row=row[:n].copy(),
        start=start[:n].copy(),
        stop=stop[:n].copy(),
        linked_prev=linked_prev[:n].copy(),
    )


def pool_code_rows(
    code: np.ndarray,
    wrapped: np.ndarray,
    valid: np.ndarray,
    *,
    rows: int,
    tolerance_rad: float = np.pi / 4,
    out_rows: slice | None = None,
) -> np.ndarray:
    """Each pixel's code voted by the pixels above and below it in the same stripe (ours).

    The stripes run down the image (the baseline runs along x), so a pixel's code is also the
    code of the pixels ``rows`` above and below it whose wrapped phase lies within
    ``tolerance_rad`` of its own (the same place in the same period; a surface tilted about x
    moves the phase slowly from row to row) and that are valid.  The pixel's code is the sign
    of its own vote (``+1`` for code 1, ``-1`` for 0) plus theirs, a tie 1 (Eq. 13's ``>=``).
    The vote of one row's stripe (:func:`vote_codes`) then stands on ``2 rows + 1`` rows' pixels:
    where the code channels are at the noise (a dark board seen through a noisy sensor) one row's
    vote misreads stripes while the pooled one does not.  At a horizontal depth edge the rows
    beyond it are another stripe; the phase test keeps a quarter of such rows (a random phase
    jump) and the pixel's own side outvotes them but within a few rows of the edge.

    Parameters
    ----------
    code : ndarray, shape (H, W), bool
    wrapped : ndarray, shape (H, W), float32; the wrapped phase
    valid : ndarray, shape (H, W), bool; the pixels whose phase stands
    rows : int
        Rows above and below that vote.
    tolerance_rad : float
        Largest phase difference of a voting pixel (assumption: pi/4, as a bridged gap's,
        :func:`segment_stripes`).
    out_rows : slice, optional
        The rows to return (default all); the others only vote.

    Returns
    -------
    ndarray, shape (len(out_rows), W), bool
    """
    code = np.ascontiguousarray(code, dtype=bool)
    h, w = code.shape
    r0, r1, _ = (out_rows or slice(0, h)).indices(h)
    out = np.empty((r1 - r0, w), bool)
    _kernels.pool_code_rows(
        code,
        np.ascontiguousarray(wrapped, dtype=np.float32),
        np.ascontiguousarray(valid, dtype=bool),
        r0,
        rows,
        tolerance_rad,
        out,
    )
    return out


def vote_codes(code: np.ndarray, stripes: Stripes, *, voting: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One code per stripe.

    With ``voting`` (paper Sec. 5.2) the majority of the stripe's pixels (its label's, not
    those of a gap it was bridged across) decides (ties give 1,
    like Eq. 13's ``>=``); without it, the stripe's middle pixel decides.

    Returns
    -------
    stripe_code : ndarray, shape (S,), uint8
    agreement : ndarray, shape (S,), float32; share of the stripe's pixels agreeing with it
    votes : ndarray, shape (S,), int32; the stripe's own pixels (its net vote for its code is
        ``votes * (2 agreement - 1)``: :data:`simbench.decode.debruijn.CODE_VOTE_PERIODS`)

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Sec. 5.3 (colour voting along a stripe).
    """
    out = np.empty(stripes.count, np.uint8)
    agreement = np.empty(stripes.count, np.float32)
    votes = np.empty(stripes.count, np.int32)
    _kernels.vote_codes(
        np.ascontiguousarray(code, dtype=bool),
        stripes.labels,
        stripes.row,
        stripes.start,
        stripes.stop,
        bool(voting),
        out,
        agreement,
        votes,
    )
    return out, agreement, votes
