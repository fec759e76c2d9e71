"""Stage 1: intensity by channel overlay (paper Eq. 9) and wrapped phase by a 2-D Gabor filter
(paper Eq. 10-11).

The Gabor filter is evaluated as a *normalised convolution* (Knutsson & Westin, CVPR 1993):
at each pixel we fit ``a0 + a1*cos(w*x) + a2*sin(w*x)`` to the intensity under the Gaussian
window of the Gabor kernel, weighting each sample by a certainty (0 outside the image, in
shadow, or where a channel is saturated).  Where the window is complete this is the classic
Gabor response with its DC leakage removed; at image borders and around invalid pixels it stays
unbiased for a fringe of the nominal frequency, where a plain Gabor filter would not.  The fit
residual relative to the fringe amplitude flags pixels whose window straddles a depth edge.

The window sums and the fit run in one C kernel (:func:`simbench.decode._kernels.gabor_band`):
each row is read once for all of its sums (the carrier rides on the window), in registers,
eight pixels at a time; ``tests/numpy_reference.py`` keeps the same fit written with OpenCV's
separable filters, which it matches to float32 rounding (tests/test_kernels.py,
tests/test_accuracy_guard.py).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

from simbench.decode import _kernels

__all__ = [
    "INTENSITY_MODES",
    "overlay_intensity",
    "window_share",
    "weighted_fit",
    "MIN_WINDOW_WEIGHT",
    "certainty_window_px",
    "certainty_map",
    "PhaseResult",
    "gabor_phase",
    "bank_fit",
    "CARRIER_BANK",
    "BANK_STRETCH_SHARE",
    "fringe_snr",
    "MAX_FRINGE_SNR",
    "centroid_corrected",
    "shadow_margin",
    "SHADOW_LEVEL",
    "SHADOW_MIN_RUN_PERIODS",
    "SHADOW_REACH_SIGMAS",
]


def _overlay(rgb: np.ndarray) -> np.ndarray:
    # paper Eq. 9: the fringe lives in B and in one of R/G, so (R+G+B)/2 is the full fringe
    out = cv2.transform(np.asarray(rgb, dtype=np.float32), np.full((1, 3), 0.5, np.float32))
    return out.reshape(rgb.shape[:2])


def _blue(rgb: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(rgb[..., 2], dtype=np.float32)


def _weighted(rgb: np.ndarray, weights: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    # normalised channels: the code pair R + G carries the fringe in every stripe, B carries it
    # everywhere; each gets its inverse noise variance (one weight for the pair, so a red and
    # a green stripe are weighted alike and the stripe colour cannot bias the fringe)
    if weights is None:
        raise ValueError(
            "intensity_mode 'weighted' needs normalised channels (color_normalize=True) and their noise weights"
        )
    # (w_code (R + G) + w_fringe B) / (w_code + w_fringe) in float32, 0 where both weights are 0
    # (one pass, simbench/_ckernels.c)
    rgb = np.ascontiguousarray(rgb, dtype=np.float32)
    out = np.empty(rgb.shape[:2], np.float32)
    w = tuple(np.ascontiguousarray(a, dtype=np.float32) for a in weights)
    _kernels.robust_fringe_code(rgb, None, w, out, None)
    return out


INTENSITY_MODES = {"overlay": _overlay, "blue": _blue, "weighted": _weighted}


def overlay_intensity(
    rgb: np.ndarray, *, mode: str = "overlay", weights: tuple[np.ndarray, np.ndarray] | None = None
) -> np.ndarray:
    """Fringe intensity from a capture.

    Parameters
    ----------
    rgb : ndarray, shape (H, W, 3), float32 in [0, 1]
    mode : {"overlay", "blue", "weighted"}
        ``overlay`` is paper Eq. 9, ``(R + G + B) / 2``; ``blue`` uses the blue channel alone;
        ``weighted`` (ours) is ``(w_code (R + G) + w_fringe B) / (w_code + w_fringe)`` of
        normalised channels with ``weights`` from
        :func:`simbench.decode.color.overlay_weights`.
    weights : (w_code, w_fringe), each ndarray of shape (H, W), float32; ``weighted`` only

    Returns
    -------
    ndarray, shape (H, W), float32

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Eq. 9.
    """
    try:
        fn = INTENSITY_MODES[mode]
    except KeyError:
        raise ValueError(f"unknown intensity mode {mode!r}; valid: {sorted(INTENSITY_MODES)}") from None
    return fn(rgb, weights) if mode == "weighted" else fn(rgb)


def certainty_window_px(period_px: float, window_periods: float = 1.0) -> int:
    """Width in pixels (odd, at least 3) of the row window over which :func:`certainty_map`
    looks for a lit pixel."""
    return max(3, int(round(window_periods * period_px)) | 1)


def certainty_map(
    rgb: np.ndarray, *, period_px: float, dark_level: float, saturation_level: float, window_periods: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Which pixels carry usable fringe samples, and which are lit at all.

    A pixel is *unlit* when the brightest pixel within ``window_periods`` fringe periods along
    its row is below ``dark_level`` (projector shadow, black surface): fringe troughs are dark
    even where lit, so a per-pixel threshold would not do.  A pixel's sample is *uncertain* when it is unlit or any
    channel is at or above ``saturation_level`` (clipped); the phase fit skips uncertain samples,
    so a clipped pixel inside a lit region still gets a phase from its neighbours.

    Returns
    -------
    certainty : ndarray, shape (H, W), float32 in {0, 1}
    lit : ndarray, shape (H, W), bool
    """
    r, g, b = cv2.split(rgb)
    peak = cv2.max(cv2.max(r, g), b)
    width = certainty_window_px(period_px, window_periods)
    local_max = cv2.dilate(peak, np.ones((1, width), np.uint8), borderType=cv2.BORDER_REPLICATE)
    lit = local_max >= dark_level
    return (lit & (peak < saturation_level)).astype(np.float32), lit


@dataclass(frozen=True)
class PhaseResult:
    """Output of the phase stage; every array has shape (H, W), float32.

    wrapped : wrapped phase psi in [-pi, pi) (see :mod:`simbench.pattern` for the convention)
    amplitude : fringe amplitude B of the local fit (intensity units); 0 where unfit
    offset : local mean A of the fit; None when not asked for (``offset=False``: the decoder does
        not use it, and the Gabor kernel then does not write it)
    residual : RMS fit residual divided by the RMS of the fitted fringe (``amplitude/sqrt 2``)
    support : share of the window's weight on certain samples (1 = complete window)
    """

    wrapped: np.ndarray
    amplitude: np.ndarray
    offset: np.ndarray | None
    residual: np.ndarray
    support: np.ndarray


# The largest fringe SNR reported: a noise-free synthetic fringe fits to rounding error (residual
# ~1e-7), whose reciprocal says nothing more than "perfect" (assumption: 1e4 is far above any
# rendered or real capture: a 12-bit camera's quantisation alone limits it to ~1e3).
MAX_FRINGE_SNR = 1.0e4


def fringe_snr(residual: np.ndarray) -> np.ndarray:
    """The fringe's signal-to-residual ratio per pixel: the RMS of the fitted fringe
    (``amplitude / sqrt 2``) over the RMS of what the local cosine fit leaves in its window, i.e.
    ``1 / residual`` of :class:`PhaseResult`; the decoder's confidence.

    Everything the fit's model (offset + one cosine of the nominal period) does not explain lowers
    it: sensor and render noise (for white noise of standard deviation sigma and fringe amplitude
    B, ``SNR = B / (sigma sqrt 2)``), a depth edge or an albedo step in the window, a second fringe
    of another phase added by interreflection or a specular lobe, a chirp.  0 where the fit did not
    run (residual NaN or infinite), at most :data:`MAX_FRINGE_SNR`.

    Parameters
    ----------
    residual : ndarray, shape (H, W), float32
        :attr:`PhaseResult.residual`.

    Returns
    -------
    ndarray, shape (H, W), float32
    """
    r = np.asarray(residual, np.float32)
    snr = np.maximum(r, np.float32(1.0 / MAX_FRINGE_SNR))
    np.reciprocal(snr, out=snr)
    with np.errstate(invalid="ignore"):
        snr[~(r >= 0) | ~np.isfinite(r)] = 0.0
    return snr


# The narrow window's fringe SNR counts (DecoderParams.narrow_snr) only where the wide fit's
# residual is at most this share of the highest within the wide window's reach: off the
# discontinuity that raises it.  For a window whose far-side share is c, the residual grows as
# sqrt(c (1 - c)), highest (c = 1/2) on the discontinuity itself, where the narrow window is as
# mixed as the wide one and its fit of a nominal-period cosine to two half-fringes can still
# look clean (measured on synthetic phase jumps: pixels 0.5-1 rad off with narrow SNR > 3); half
# of the peak is c <= 7 %, where the narrow window (half the width) holds < 0.1 % of the far side.
NARROW_SNR_RESIDUAL_SHARE = 0.5
# ... and only where the wide window's own fringe SNR is at least this: a share relative to the
# local peak depends on the peak's height (a shadow, a far side of other amplitude), so the wide
# window's far side is bounded absolutely too.  With a far-side share c of equal amplitude and a
# phase offset theta the wide fit leaves a residual of RMS B sqrt(c (1 - c)) |1 - e^(i theta)| /
# sqrt 2 against the fringe's B / sqrt 2: SNR 2 is c <= 6.7 % (theta = pi) to 15 % (theta uniform),
# where the narrow window holds <= 0.1-2 % of the far side.  Measured after the fact (2026-11-26,
# full-resolution hard scenes at the operating point): without it hard_stairs_deep kept 0.20 % of
# its decoded pixels > 5 mm wrong 5-7 px beside a depth edge (wide SNR 1.7-2.3, narrow 6-12, both
# windows' phases biased alike: a bias in the image itself there, every decoder and window width);
# with it 0.054 %, robust_staircase (16 spp) 97.43 -> 97.12 % complete, none wrong.  A floor of 2.5
# or a share of 0.25-0.35 instead took the staircase under 97 %.
NARROW_SNR_MIN_WIDE_SNR = 2.0


# The shadow margin (DecoderParams.shadow_doubt).  A dark run: the normalised overlay intensity
# (the colour-robust decoder's, ~0.08 at a lit fringe's trough, ~0.85 at its crest) below
# SHADOW_LEVEL for at least SHADOW_MIN_RUN_PERIODS of the camera's period - longer than any
# trough's (a lit fringe stays under 0.15 for ~4 of its ~22 px), so a shadow, an unlit patch or
# the image beyond a silhouette, not a fringe.  A pixel within SHADOW_REACH_SIGMAS of the wide
# window's sigma_x of one has the run in its window: the fringe there ends wherever the shadow
# cuts it, through the projector's penumbra, not at a trough, and the fit of a whole cosine to a
# cut one is biased (the paper's step, scenes/discontinuity.toml, row 700: the four lit pixels
# 3-6 px before the cube's shadow 2.1-2.4 projector px, 16-19 mm, off at fringe SNR 3.6-4.9).
# Measured on rendered scenes (the colour-robust decoder at its operating point, decoded pixels
# > 5 mm wrong / complete, all lit pixels): the step 0.46 -> 0.36 % / 94.44 -> 94.28 % (off
# a 5-px band at depth edges 0.109 -> 0.047 %), the staircase 0.74 -> 0.33 % / 89.86 ->
# 89.48 %, the bust 0.145 -> 0.098 % / 90.80 -> 90.59 %, the box before a wall 0.001 % both /
# 96.85 -> 96.63 %; at 0.45 (1.8 sigma) the step no better, the box before a wall 96.44 %.
# The level is an assumption between a trough and a half-lit pixel (0.25 moved the step by
# nothing and the bust's completeness by 0.8 %).
SHADOW_LEVEL = 0.15
SHADOW_MIN_RUN_PERIODS = 0.5
SHADOW_REACH_SIGMAS = 1.25


def shadow_margin(intensity: np.ndarray, *, period_px: float, sigma_x_px: float) -> np.ndarray:
    """The pixels beside a dark run along their row (constants above), within
    :data:`SHADOW_REACH_SIGMAS` ``sigma_x_px`` of it, the run itself excluded.

    Parameters
    ----------
    intensity : ndarray, shape (H, W), float32
        The normalised overlay intensity (the colour-robust decoder's, Eq. 9 on the normalised
        channels); NaN reads as dark.
    period_px, sigma_x_px : float
        The camera's fringe period and the wide window's standard deviation along x.

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    i = np.asarray(intensity, np.float32)
    dark = (~(i >= np.float32(SHADOW_LEVEL))).astype(np.uint8)
    # an odd width: OpenCV's opening by an even one moves the run a pixel right (its erosion and
    # dilation share the anchor), off the first lit pixel after it
    run = max(1, int(round(SHADOW_MIN_RUN_PERIODS * period_px))) | 1
    runs = cv2.morphologyEx(dark, cv2.MORPH_OPEN, np.ones((1, run), np.uint8), borderType=cv2.BORDER_REPLICATE)
    reach = max(1, int(round(SHADOW_REACH_SIGMAS * sigma_x_px)))
    near = cv2.dilate(runs, np.ones((1, 2 * reach + 1), np.uint8), borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return (near > 0) & (runs == 0)


def off_discontinuity(residual: np.ndarray, *, sigma_x_px: float) -> np.ndarray:
    """Where the narrow window's fringe SNR may stand for a pixel's (:data:`NARROW_SNR_RESIDUAL_SHARE`):
    its wide-window fit residual is at most that share of the highest residual within
    ``3 sigma_x_px`` along its row (the wide window's reach), and its wide fringe SNR at least
    :data:`NARROW_SNR_MIN_WIDE_SNR`.

    Parameters
    ----------
    residual : ndarray, shape (H, W), float32
        The wide fit's :attr:`PhaseResult.residual` (NaN or inf where unfit: never off).
    sigma_x_px : float
        The wide window's standard deviation along x.

    Returns
    -------
    ndarray, shape (H, W), bool
    """
    r = np.asarray(residual, np.float32)
    finite = np.isfinite(r)
    rr = np.where(finite, r, np.float32(0.0))
    reach = max(1, int(np.ceil(3.0 * sigma_x_px)))
    peak = cv2.dilate(rr, np.ones((1, 2 * reach + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
    return (
        finite
        & (rr <= np.float32(NARROW_SNR_RESIDUAL_SHARE) * peak)
        & (rr <= np.float32(1.0 / NARROW_SNR_MIN_WIDE_SNR))
    )


def gaussian_kernel(sigma: float) -> np.ndarray:
    """Unit-sum sampled Gaussian, radius ``ceil(3 sigma)`` (the decoder's row halo assumes it)."""
    r = max(1, int(np.ceil(3.0 * sigma)))
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return (k / k.sum()).astype(np.float32)


def window_share(weights: np.ndarray, *, sigma_x_px: float, sigma_y_px: float) -> np.ndarray:
    """Each pixel's Gaussian window's share of its weight on ``weights``: the window of
    :func:`gabor_phase` (:func:`gaussian_kernel` in x and y, unit sum; nothing beyond the image),
    so that for a certainty map it is that fit's ``support``.

    Parameters
    ----------
    weights : ndarray, shape (H, W), float32 in [0, 1]
    sigma_x_px, sigma_y_px : float
        The window's standard deviations.

    Returns
    -------
    ndarray, shape (H, W), float32 in [0, 1] (to rounding)
    """
    w = np.ascontiguousarray(weights, dtype=np.float32)
    kx, ky = gaussian_kernel(float(sigma_x_px)), gaussian_kernel(float(sigma_y_px))
    return cv2.sepFilter2D(w, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_CONSTANT)


def magnitude(
    re: np.ndarray, im: np.ndarray, *, tmp: np.ndarray | None = None, out: np.ndarray | None = None
) -> np.ndarray:
    """``sqrt(re^2 + im^2)`` in float32, the same bits wherever the arrays sit in memory.

    ``cv2.magnitude`` is not used: with Intel IPP (in the PyPI wheels) its last bit depends on
    the buffers' alignment (measured: 24 of 96 shifted copies differed), so a fresh allocation
    could change a decoded amplitude between runs.
    """
    out = np.multiply(re, re, out=out)
    tmp = np.multiply(im, im, out=tmp)
    out += tmp
    return np.sqrt(out, out=out)


@lru_cache(maxsize=8)
def _basis(width: int, omega: float, column0: int = 0):
    """cos/sin of the carrier and of its double at columns ``column0 .. column0 + width - 1``."""
    x = np.arange(column0, column0 + width, dtype=np.float64) * omega
    out = tuple(np.ascontiguousarray(r, dtype=np.float32) for r in (np.cos(x), np.sin(x), np.cos(2 * x), np.sin(2 * x)))
    for a in out:
        a.setflags(write=False)
    return out


@lru_cache(maxsize=8)
def _half_kernels(omega: float, sx: float, sy: float) -> tuple[np.ndarray, ...]:
    """Half (centre and one side) of the window's x kernel g, of g cos(w k), g sin(w k),
    g cos(2 w k), g sin(2 w k), and of the y kernel (float32; products taken in float64 from
    the float32 g)."""
    gx, gy = gaussian_kernel(sx), gaussian_kernel(sy)
    rx, ry = len(gx) // 2, len(gy) // 2
    g = gx[rx:].astype(np.float64)
    k = np.arange(rx + 1, dtype=np.float64)
    carried = [g * f(m * omega * k) for m in (1, 2) for f in (np.cos, np.sin)]
    out = tuple(np.ascontiguousarray(a, dtype=np.float32) for a in (gx[rx:], *carried, gy[ry:]))
    for a in out:
        a.setflags(write=False)
    return out


# The normalised-convolution fit's floor on its window's weight (the Gabor kernel's s_min,
# simbench/_ckernels.c fit_solver): a window with at most this share of its Gaussian weight on
# certain samples has no fit (amplitude 0, residual inf).
MIN_WINDOW_WEIGHT = 0.05


def _fit(
    intensity: np.ndarray,
    certainty: np.ndarray,
    omega: float,
    sx: float,
    sy: float,
    table=None,
    offset: bool = True,
    column0: int = 0,
    min_weight: float = MIN_WINDOW_WEIGHT,
) -> tuple:
    """The band fit of :func:`simbench.decode._kernels.gabor_band`: (wrapped, amp, a0, residual,
    support), a0 None unless ``offset``; ``table`` as it takes it (read); ``column0``: the image
    column of the band's first (the carrier's origin)."""
    h, w = intensity.shape
    out = tuple(None if q == 2 and not offset else np.empty((h, w), np.float32) for q in range(5))
    basis = _basis(w, omega, column0)
    kernels = _half_kernels(omega, sx, sy)
    _kernels.gabor_band(intensity, certainty, 0, h, kernels, basis, table, False, *out, min_weight=min_weight)
    return out


@lru_cache(maxsize=16)
def _all_certain_table(n: int, w: int, omega: float, sx: float, sy: float, column0: int = 0) -> np.ndarray:
    """The certainty's window sums of an all-ones band and the fit's solver from them, which
    every pixel whose window is wholly certain shares: ``n`` rows
    (:func:`simbench.decode._kernels.gabor_table_rows`), made from an all-ones band of ``n`` rows
    in a fraction of a millisecond."""
    kernels = _half_kernels(omega, sx, sy)
    ones = np.ones((n, w), np.float32)
    table = np.empty((_kernels.gabor_table_planes(), n, w), np.float32)
    out = tuple(np.empty((n, w), np.float32) for _ in range(5))
    _kernels.gabor_band(ones, ones, 0, n, kernels, _basis(w, omega, column0), table, True, *out)
    table.setflags(write=False)
    return table


def check_phase_inputs(intensity: np.ndarray, certainty: np.ndarray, period_px: float) -> None:
    """The checks every phase stage of :data:`simbench.decode.params.PHASE_METHODS` makes."""
    if intensity.ndim != 2 or certainty.shape != intensity.shape:
        raise ValueError(f"intensity {intensity.shape} and certainty {certainty.shape} must be equal 2-D shapes")
    if not period_px > 2:
        raise ValueError(f"period_px must be > 2, got {period_px}")


def gabor_phase(
    intensity: np.ndarray,
    *,
    certainty: np.ndarray,
    period_px: float,
    sigma_x_px: float,
    sigma_y_px: float,
    offset: bool = True,
    column0: int = 0,
    min_weight: float = MIN_WINDOW_WEIGHT,
) -> PhaseResult:
    """Wrapped phase of a vertical-stripe fringe by a Gaussian-windowed (Gabor) fit.

    Parameters
    ----------
    intensity : ndarray, shape (H, W), float32
    certainty : ndarray, shape (H, W), float32 in [0, 1]
    period_px : float
        Nominal fringe period in camera pixels (the Gabor carrier, paper Eq. 10).
    sigma_x_px, sigma_y_px : float
        Standard deviations of the Gaussian envelope.
    offset : bool
        Whether to return the fit's offset (``PhaseResult.offset``; None otherwise).
    column0 : int
        The image column of ``intensity``'s first (a slice of an image's columns gives the bits
        the whole image's fit gives there, where the window lies within the slice).
    min_weight : float
        A window whose certainty-weighted sum (its Gaussian's weights sum to 1) is at most this
        has no fit (:func:`weighted_fit` lowers it for weights under 1).

    Returns
    -------
    PhaseResult

    References
    ----------
    .. [1] F. Li et al., "Single-Shot Dense Depth Sensing with Color Sequence Coded Fringe
       Pattern", Sensors 17(11), 2558, 2017, Sec. 5.2, Eq. 10-11.
    .. [2] D. Gabor, "Theory of communication", J. IEE 93(26), 429-457, 1946.
    """
    check_phase_inputs(intensity, certainty, period_px)
    if not 0.0 <= min_weight < 1.0:
        raise ValueError(f"min_weight must be in [0, 1) (a share of the window's weight), got {min_weight}")
    omega = round(2.0 * np.pi / period_px, 12)
    intensity = np.ascontiguousarray(intensity, dtype=np.float32)
    c = np.ascontiguousarray(certainty, dtype=np.float32)
    sx, sy = float(sigma_x_px), float(sigma_y_px)
    h, w = intensity.shape
    n = _kernels.gabor_table_rows(h, _half_kernels(omega, sx, sy))
    table = _all_certain_table(n, w, omega, sx, sy, column0)
    wrapped, amp, a0, residual, s1 = _fit(
        intensity, c, omega, sx, sy, table, offset=offset, column0=column0, min_weight=min_weight
    )
    return PhaseResult(
        wrapped=wrapped,
        amplitude=amp,
        offset=a0,
        residual=residual,
        support=s1,
    )


def weighted_fit(method: Callable[..., PhaseResult], *, min_weight: float) -> Callable[..., PhaseResult]:
    """:func:`gabor_phase` (``method``) taking a certainty that carries per-sample weights - a
    certain sample's in ``(0, 1]``, an uncertain one's 0 - and returning, but for the fit itself,
    what the fit of the 0/1 certainty returns: its ``support`` is the window's share of certain
    samples, and a window whose share is at most :data:`MIN_WINDOW_WEIGHT` has no fit.  The fit's
    own floor, on the weights' sum, is lowered to ``min_weight`` (at most ``MIN_WINDOW_WEIGHT``
    times the least weight, so that it never acts first).  A pixel whose window's certain samples
    all weigh 1 gets the bits of the unweighted fit: the same kernel sums, its support the kernel's
    own plus an exact 0, the floor the same test of the same sum - so a row band that holds no
    weight under 1 may take the plain fit and give the same result."""

    def fit(intensity: np.ndarray, *, certainty: np.ndarray, sigma_x_px: float, sigma_y_px: float, **kw):
        c = np.ascontiguousarray(certainty, dtype=np.float32)
        if c.size and not (c.min() >= 0.0 and c.max() <= 1.0):
            # a weight over 1 would count as negative lost weight: a support over the window's share
            raise ValueError(f"weights must be in [0, 1], got {c.min()} .. {c.max()}")
        out = method(intensity, certainty=c, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px, min_weight=min_weight, **kw)
        lost = (c > 0).astype(np.float32) - c  # each certain sample's weight under 1
        support = out.support + window_share(lost, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px)
        none = support <= np.float32(MIN_WINDOW_WEIGHT)
        zero = np.float32(0.0)
        return PhaseResult(
            wrapped=np.where(none, zero, out.wrapped),
            amplitude=np.where(none, zero, out.amplitude),
            offset=None if out.offset is None else np.where(none, zero, out.offset),
            residual=np.where(none, np.float32(np.inf), out.residual),
            support=support,
        )

    return fit


# The colour-robust decoder's carrier bank (DecoderParams.carrier_bank): (period scale, sigma_y
# scale) of the fits tried where the nominal one fails its residual test.  A surface seen at a
# steep angle shows the fringe at another period in the camera (the box interior's side faces:
# the projector column grows 1.40x and 0.52x as fast along the row as on a board facing the rig)
# or tilted (its top and bottom faces: 0.60 projector px per row against 0.96 per column, 32 deg),
# which a window of the nominal period and height does not fit: the misfit is no noise, and the
# residual test rejects it.  A period 1/1.4 of the nominal, the window scaled with it, fits
# fringes up to ~1.7 times the nominal frequency (within ~20 % of a carrier: the Gabor window's
# misfit at 20 % is under a third of the residual test's limit); a window 0.3 as tall (sigma_y
# ~1 px) fits fringes tilted up to ~45 deg (its phase spread across its height stays under
# ~1 rad).  Measured on the box interior (2026-11-26, full resolution): its left, top and bottom
# faces then pass the residual test (completeness 76.3 -> 89.7 % with the rules below, 90.1 % with
# the crease term's hole margin).  Tried and left out: periods 1.4-2.2 x the nominal, for fringes
# seen stretched - chosen nowhere but on the box's right face,
# lit by the projector at grazing incidence (a +-6 DN fringe on ~25 DN of the other faces' light),
# which no fit decodes; each entry costs two more fits where the nominal one fails.  A bank fit's
# pixel keeps its own fit's SNR: the narrow window's SNR (DecoderParams.narrow_snr) is for pixels
# beside an edge, and on the aluminium sphere of scenes/specular.toml it had lifted 48 bank-fit
# pixels > 5 mm wrong over the operating point (its wrong share 0.17 -> 0.27 %; without it 0.18 %).
CARRIER_BANK = ((1.0 / 1.4, 1.0), (1.0, 0.3))
# The bank is tried only along a stretch the nominal fit misfits as a whole: where the nominal
# residual stays over this share of the residual test's limit across the nominal window's reach
# (3 sigma_x either side along the row).  A fringe 1.4x as fast leaves the nominal window a residual
# of 0.57-0.68 all along (measured, noise-free), a tilted one 0.69; beside a depth or albedo edge
# the residual is high only within the window's reach of it, and on a face's clean stretch beyond
# it ~0.05.  Without it (the lowest residual wherever the nominal fit failed) Table 3's cuboid had
# the faster carrier win on 692 pixels 8-9 px inside its edge, 2.3 mm off on average (a window
# narrower in x straddles less of the edge and fits it with a clean-looking residual of 0.31-0.49),
# and the face's MAE rose from 0.149 to 0.160 mm; with it 17 pixels, 0.149 mm.  Also tried: a cap of
# 0.3 on the bank fit's own residual (the cuboid 0.152 mm, and 78 stripe-order errors on the box
# interior), and a check that the fitted phase runs at the carrier's rate (beside the edge the
# fitted phase runs fast too).  The bank is tried only where the nominal fit fails the residual
# test itself: as the residual of a fringe 1.4x as fast swings about the limit, part of such a face
# keeps the nominal fit (0.045 rad off, measured noise-free); trying the bank from half the limit
# instead (before the stretch rule) took the box interior 88.9 -> 89.2 % but the sphere before its
# wall to 0.114 % of its pixels > 5 mm wrong and the 20:1 chart to an MAE of 0.51 mm.
BANK_STRETCH_SHARE = 0.5


def bank_fit(
    method: Callable[..., PhaseResult],
    intensity: np.ndarray,
    *,
    certainty: np.ndarray,
    period_px: float,
    sigma_x_px: float,
    sigma_y_px: float,
    max_residual: float,
    candidates: np.ndarray | None = None,
    min_support: float = 0.0,
    choice: np.ndarray | None = None,
    bank: tuple[tuple[float, float], ...] = CARRIER_BANK,
) -> tuple[PhaseResult, np.ndarray]:
    """The phase fit of ``method`` (a :data:`simbench.decode.PHASE_METHODS` entry) at the nominal
    period, and where its residual is over ``max_residual`` all along a stretch of the row (over
    :data:`BANK_STRETCH_SHARE` ``* max_residual`` within the window's reach) the fit with the
    lowest residual of it and the bank's entries (:data:`CARRIER_BANK`: each scales the period and the
    window's width by its first number, the window's height by its second).

    Parameters
    ----------
    method : callable
        ``method(intensity, certainty=, period_px=, sigma_x_px=, sigma_y_px=, offset=False,
        column0=)`` (:func:`gabor_phase`; ``column0`` with a slice of columns).
    intensity, certainty : ndarray, shape (H, W), float32
    period_px, sigma_x_px, sigma_y_px : float
        The nominal fit's.
    max_residual : float
        A pixel whose nominal residual is at most this (the residual test's limit) keeps the
        nominal fit.
    candidates : ndarray, shape (H, W), bool, optional
        The pixels that may take another fit (the lit ones); default all.
    min_support : float
        ... and whose nominal window has at least this share of its weight on certain samples
        (another carrier does not mend a window that reaches into a shadow).
    choice : ndarray, shape (H, W), int8, optional
        Instead of choosing: the choice of an earlier call (0 nominal, ``j`` the bank's ``j``-th
        entry), e.g. the wide fit's for the stability term's narrow one.
    bank : tuple of (float, float)

    Returns
    -------
    (PhaseResult, choice): the fit per pixel (no offset) and which fit it is (int8)
    """

    def fit(scale_x: float, scale_y: float, cols: slice | None = None) -> PhaseResult:
        kw = dict(
            period_px=period_px * scale_x,
            sigma_x_px=sigma_x_px * scale_x,
            sigma_y_px=sigma_y_px * scale_y,
            offset=False,
        )
        if cols is None:
            return method(intensity, certainty=certainty, **kw)
        return method(
            np.ascontiguousarray(intensity[:, cols]),
            certainty=np.ascontiguousarray(certainty[:, cols]),
            column0=cols.start,
            **kw,
        )

    nominal = fit(1.0, 1.0)
    choose = choice is None
    if choose:
        with np.errstate(invalid="ignore"):
            todo = ~(nominal.residual <= np.float32(max_residual))
            todo &= nominal.support >= np.float32(min_support)
        if candidates is not None:
            todo &= candidates
        # a whole stretch misfit, not a discontinuity: the nominal residual stays high across
        # the window's reach (NaN, unfit, counts as high)
        reach = max(1, int(np.ceil(3.0 * sigma_x_px)))
        high = np.where(np.isnan(nominal.residual), np.float32(np.inf), nominal.residual)
        low = cv2.erode(high, np.ones((1, 2 * reach + 1), np.uint8), borderType=cv2.BORDER_REPLICATE)
        todo &= low > np.float32(BANK_STRETCH_SHARE * max_residual)
        choice = np.zeros(todo.shape, np.int8)
        if not todo.any():
            return nominal, choice
    elif not choice.any():
        return nominal, choice
    parts = [a.copy() for a in (nominal.wrapped, nominal.amplitude, nominal.residual, nominal.support)]
    for j, (scale_x, scale_y) in enumerate(bank, 1):
        if not period_px * scale_x > 2:
            # a carrier at or past the sampling limit (2 px) cannot be in the image (a pattern
            # designer's audit, 2026-11-30: a 2.1-px camera period failed the decode with "period_px
            # must be > 2, got 1.48", the bank's faster carrier)
            continue
        need = todo if choose else choice == j
        # only the columns within the window's reach of a pixel that needs this fit: a pixel's
        # fit reads its window alone, and with the carrier referred to the image's columns
        # (column0) it has the bits of the whole row's fit, whatever the slice (so the result
        # does not depend on the decoder's row bands)
        reach = int(np.ceil(3.0 * sigma_x_px * scale_x)) + 1
        for c0, c1 in _column_runs(need.any(axis=0), reach):
            q = fit(scale_x, scale_y, slice(c0, c1))
            view = [a[:, c0:c1] for a in parts]
            if choose:
                with np.errstate(invalid="ignore"):
                    take = todo[:, c0:c1] & (q.residual < view[2])
                choice[:, c0:c1][take] = j
            else:
                take = need[:, c0:c1]
            for dst, src in zip(view, (q.wrapped, q.amplitude, q.residual, q.support)):
                np.copyto(dst, src, where=take)
    return PhaseResult(wrapped=parts[0], amplitude=parts[1], offset=None, residual=parts[2], support=parts[3]), choice


def _column_runs(needed: np.ndarray, reach: int) -> list[tuple[int, int]]:
    """Column ranges ``[c0, c1)`` covering every needed column and ``reach`` columns either
    side, merged where they touch."""
    idx = np.flatnonzero(needed)
    if idx.size == 0:
        return []
    w = needed.size
    gaps = np.flatnonzero(np.diff(idx) > 2 * reach)
    starts = np.concatenate([[idx[0]], idx[gaps + 1]])
    ends = np.concatenate([idx[gaps], [idx[-1]]])
    return [(max(0, int(a) - reach), min(w, int(b) + reach + 1)) for a, b in zip(starts, ends)]


# The window-centroid correction (ours; the colour-robust decoder's DecoderParams.centroid_correction).
# A window cut by the certainty (the image's border, a shadow, an unlit or clipped patch) weighs
# one side of its pixel only; where the fringe runs at another rate than the fit's carrier (a
# surface tilted against the rig: the library's 45-degree corner shows it 15 % faster on one face
# and 15 % slower on the other) the fitted phase is that of the window's weighted centre, not the
# pixel's: off by the rate difference times the centre's offset, to first order.  Measured on
# scenes/hard_corner_045.toml (full resolution): 0.19-0.33 rad at the image's outermost columns,
# where the narrow and wide fits then disagree and the phase-stability term doubted ~0.7 % of the
# image (0.01-0.15 rad left after the correction).  The rate is the mean step of the wrapped phase
# between neighbours whose windows are centred (within CENTRED_PX), within RATE_REACH_PERIODS
# periods beyond the window's reach on the side the window's centre lies (its weight lies there;
# across a shadow or an edge the other side may be another surface at another rate) - assumption:
# two periods, ~45 steps, whose mean has the noise of a 45-px baseline.  A centre closer than
# CENTRED_PX to its pixel is left alone (assumption: 0.05 px, where a 15 % rate difference biases
# the phase by ~0.002 rad, a twentieth of the phase noise at an SNR of 3).
RATE_REACH_PERIODS = 2.0
CENTRED_PX = 0.05
STEP_SCALE = float(2**20)


def _not_whole(c: np.ndarray, rx: int, ry: int) -> np.ndarray:
    """Pixels whose window (2 rx + 1 by 2 ry + 1) may have its certainty-weighted centre off the
    pixel in x: the certainty ``c`` (values in {0, 1}) is not one value throughout the window, the
    outside beyond the left and right ends counting as 0.  Rows beyond the top and bottom repeat
    the end rows: a window cut there alone is as centred in x as its rows are."""
    u8 = cv2.copyMakeBorder((c > 0.5).view(np.uint8), 0, 0, rx, rx, cv2.BORDER_CONSTANT, value=0)
    k = np.ones((2 * ry + 1, 2 * rx + 1), np.uint8)
    lo = cv2.erode(u8, k, borderType=cv2.BORDER_REPLICATE)
    hi = cv2.dilate(u8, k, borderType=cv2.BORDER_REPLICATE)
    return (lo != hi)[:, rx : rx + c.shape[1]]


def _centroid(c: np.ndarray, sigma_x_px: float, sigma_y_px: float) -> np.ndarray:
    """The x offset (px, + to the right) of each pixel's window centre weighted by the certainty
    ``c``: ``sum g c u / sum g c`` (:func:`gaussian_kernel` in x and y, the image's outside
    uncertain); NaN where the window holds no certainty."""
    gx, gy = gaussian_kernel(sigma_x_px), gaussian_kernel(sigma_y_px)
    u = np.arange(len(gx), dtype=np.float32) - np.float32(len(gx) // 2)
    # sepFilter2D correlates, out(x) = sum_u k(u) c(x + u): the window as the fit weighs it
    total = cv2.sepFilter2D(c, cv2.CV_32F, gx, gy, borderType=cv2.BORDER_CONSTANT)
    moment = cv2.sepFilter2D(c, cv2.CV_32F, gx * u, gy, borderType=cv2.BORDER_CONSTANT)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > np.float32(1e-6), moment / total, np.float32(np.nan)).astype(np.float32)


# columns a block of centroid_corrected is padded to a multiple of (64 float32: wider than any
# vector unit's, 16 for AVX-512)
CENTROID_BLOCK_ALIGN = 64


def _wrap(a: np.ndarray) -> np.ndarray:
    """``a`` wrapped to [-pi, pi) (the fit's convention: pi itself folds to -pi), float32."""
    two_pi = np.float32(2 * np.pi)
    r = (a - two_pi * np.rint(a / two_pi)).astype(np.float32, copy=False)
    return np.where(r >= np.float32(np.pi), r - two_pi, r).astype(np.float32, copy=False)


def rate_reach_px(sigma_x_px: float, period_px: float) -> int:
    """Columns :func:`centroid_corrected` reads the fringe's rate over from a pixel: the
    window's reach and :data:`RATE_REACH_PERIODS` periods."""
    return len(gaussian_kernel(sigma_x_px)) // 2 + max(1, int(round(RATE_REACH_PERIODS * period_px)))


def centroid_corrected(
    fits: Sequence[tuple[np.ndarray, float]],
    certainty: np.ndarray,
    *,
    sigma_y_px: float,
    period_px: float,
    keep: np.ndarray | None = None,
    weights: np.ndarray | None = None,
) -> list[np.ndarray]:
    """Gabor fits of one image - ``(wrapped, sigma_x_px)``, the widest window first, each with
    windows ``sigma_x_px`` by ``sigma_y_px`` and carrier ``2 pi / period_px`` on samples of
    ``certainty`` (in {0, 1}) - each less the first-order bias of every window whose
    certainty-weighted centre lies ``dx`` off its pixel: ``wrap(psi - (rate - omega) dx)``.
    ``rate`` is the mean step of the first fit's phase between neighbours whose (first-fit)
    windows are centred within :data:`CENTRED_PX` and hold certain samples (a wholly uncertain
    window's fit is no phase), over the :func:`rate_reach_px` + 1 columns
    from the pixel towards its window's centre.  A pixel stays as it is where its window's centre
    is within :data:`CENTRED_PX` of it, where no such step is in reach, and where ``keep`` (e.g.
    another carrier's fit).

    ``weights`` ((H, W) float32, or None: the certainty): the samples' weights in the fits where
    they were weighed (:func:`weighted_fit`), which place the windows' centres; which windows are
    cut and which centred the certainty alone says.

    Each corrected pixel reads its own window and columns alone, so the result does not depend
    on how the image is cut into row bands.

    Returns
    -------
    list of ndarray, shape (H, W), float32: the fits in their order
    """
    psis = [np.ascontiguousarray(wrapped, np.float32) for wrapped, _ in fits]
    sigmas = [float(sx) for _, sx in fits]
    c = np.ascontiguousarray(certainty, np.float32)
    rx, ry = len(gaussian_kernel(sigmas[0])) // 2, len(gaussian_kernel(sigma_y_px)) // 2
    # the widest window's cut pixels hold every narrower one's
    cut = _not_whole(c, rx, ry)
    cand = cut if keep is None else cut & ~keep
    cols = np.flatnonzero(cand.any(axis=0))
    outs = [psi.copy() for psi in psis]
    if cols.size == 0:
        return outs
    reach = rate_reach_px(sigmas[0], period_px)
    margin = rx + reach + 1
    omega = np.float32(2.0 * np.pi / period_px)
    h, w = c.shape
    for run in np.split(cols, np.flatnonzero(np.diff(cols) > 2 * margin) + 1):
        # a block wide and tall enough that every pixel read holds its whole window within it
        a, b = max(0, int(run[0]) - margin), min(w, int(run[-1]) + margin + 1)
        in_rows = np.flatnonzero(cand[:, a:b].any(axis=1))
        y0, y1 = max(0, int(in_rows[0]) - ry), min(h, int(in_rows[-1]) + ry + 1)
        cs = np.ascontiguousarray(c[y0:y1, a:b])
        cw = cs if weights is None else np.ascontiguousarray(weights[y0:y1, a:b], np.float32)
        block_cut, block_cand = cut[y0:y1, a:b], cand[y0:y1, a:b]
        # OpenCV's filters take a row's last few columns (its width modulo the vector width) in
        # scalar code, a last bit off the vector code's: a block as wide as a whole number of the
        # widest vectors (the outside uncertain, as the image's) gives each pixel the same bits
        # wherever the block starts - which follows the row band's cut pixels (measured: the
        # right border's pixels 1 ulp apart between 1 and 2 bands on scenes/robust_printed.toml)
        padded = np.zeros((y1 - y0, -(-(b - a) // CENTROID_BLOCK_ALIGN) * CENTROID_BLOCK_ALIGN), np.float32)
        padded[:, : b - a] = cw
        dxs = [_centroid(padded, sx, sigma_y_px)[:, : b - a] for sx in sigmas]
        with np.errstate(invalid="ignore"):
            # a wholly uncertain window (a shadow wider than it) has no phase to step: its fit
            # returns 0, which would pull the rate towards 0
            centred = (~block_cut & (cs > np.float32(0.5))) | (np.abs(dxs[0]) <= np.float32(CENTRED_PX))
        needs = []
        for psi, dx in zip(psis, dxs):
            with np.errstate(invalid="ignore"):
                needs.append(block_cand & (np.abs(dx) > np.float32(CENTRED_PX)) & np.isfinite(psi[y0:y1, a:b]))
        rows = np.flatnonzero(np.logical_or.reduce([n.any(axis=1) for n in needs]))
        if rows.size == 0:
            continue
        # the rate's steps on the rows some fit needs, once for all fits (each row's sums its own):
        # the steps in fixed point (2^-20 rad), summed as integers, so that a window's sum is exact
        # wherever its block starts and the result does not follow the block's extent; then each
        # fit's pixels: [x, x + reach] where the centre lies right of the pixel, [x - reach, x]
        # left, within the block (simbench/_ckernels.c: the bits of the numpy form,
        # centroid_corrected in tests/numpy_reference.py; ~5x faster on a printed chart, whose
        # skipped step pixels cut windows everywhere)
        sq, sn = _kernels.centroid_rate_sums(
            np.ascontiguousarray(psis[0][y0:y1, a:b][rows]), np.ascontiguousarray(centred[rows]), STEP_SCALE
        )
        row_of = np.full(y1 - y0, -1, np.int64)
        row_of[rows] = np.arange(rows.size)
        for psi, out, dx, need in zip(psis, outs, dxs, needs):
            if need.any():
                _kernels.centroid_apply(
                    np.ascontiguousarray(need),
                    np.ascontiguousarray(dx, np.float32),
                    row_of,
                    sq,
                    sn,
                    reach,
                    omega,
                    STEP_SCALE,
                    y0,
                    a,
                    psi,
                    out,
                )
    return outs
