"""Multi-shot structured light: N-step phase shifting with complementary Gray-code unwrapping.

The accuracy reference of the field for static scenes, decoded pixel by pixel from a sequence of
captures: ``N`` cosine fringes shifted by ``2 pi / N`` (period ``T`` projector px, the same
phase convention as the paper's pattern, :func:`simbench.pattern.phase_from_column`) give the
wrapped phase, the mean intensity ``A`` and the modulation ``B`` at every pixel; ``bits + 1``
binary Gray-code frames, thresholded at ``A``, number the half periods, and the complementary
choice between the period number and the half-period-shifted one removes the order errors at
period borders, where a Gray-code transition and the phase wrap never coincide exactly in a
real image.

References
----------
.. [1] J. H. Bruning, D. R. Herriott, J. E. Gallagher, D. P. Rosenfeld, A. D. White, D. J.
   Brangaccio, "Digital wavefront measuring interferometer for testing optical surfaces and
   lenses", Applied Optics 13(11), 2693-2703, 1974 (N-step phase shifting).
.. [2] Q. Zhang, X. Su, L. Xiang, X. Sun, "3-D shape measurement based on complementary
   Gray-code light", Optics and Lasers in Engineering 50(4), 574-579, 2012.
"""

from __future__ import annotations

import math
import statistics
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from simbench import validate
from simbench.literature import PAPER_PERIOD_PX
from simbench.pattern import checked_size_and_period, column_from_phase, phase_from_column

__all__ = [
    "AXES",
    "grey_frame",
    "PhaseShiftSpec",
    "phase_shift_frames",
    "wrapped_phase",
    "drift_phase_error",
    "gray_order",
    "fit_noise",
    "gray_code_min_snr",
    "decode_phase_shift",
    "TemporalResult",
]


AXES = ("columns", "rows")

# The square window (px) over which fit_noise pools the N-step fit's residuals: 25 (N - 3) degrees
# of freedom, so that the noise is known to ~14 % (one standard deviation) at N = 4, from pixels
# at most 2 px apart (a surface's own, but beside its edges).
NOISE_WINDOW_PX = 5


@dataclass(frozen=True)
class PhaseShiftSpec:
    """A phase-shifting + Gray-code sequence.

    size_hw : projector pattern size (height, width), px
    period_px : fringe period T, projector px (default: the paper's 21 px, so both systems
        sample the surface at the same spatial frequency; assumption: a lab would choose
        about this for this projector)
    steps : phase steps N (>= 4; N steps are blind to the fringe's harmonics up to N - 2, which
        a projector's gamma or a camera's saturation bring)
    min_modulation : modulation ``B`` (image units, 0-1) below which a pixel is invalid (no
        fringe: shadow, black surface; assumption: 2 % of full scale, a few times an 8-bit
        camera's noise in a fringe fitted over N frames).  An absolute level: it also drops a
        dark surface whose fringe stands well clear of its noise (a 20:1 print's ink, B ~ 0.017
        at 11 times the noise); ``min_snr`` judges against the noise instead
    min_snr : modulation SNR ``B / sigma`` below which a pixel is invalid (0: not used), with
        ``sigma`` each frame's noise as the N-step fit's residual shows it
        (:func:`fit_noise`); :data:`GRAY_CODE_MIN_SNR` is what the Gray code needs
    axis : ``"columns"`` (vertical fringes: every pixel gets its projector column, what
        triangulation needs) or ``"rows"`` (horizontal fringes, projector rows: with the
        columns, a projector pixel per camera pixel, what calibrating the projector needs)
    """

    size_hw: tuple[int, int] = (1140, 1824)
    period_px: int = PAPER_PERIOD_PX
    steps: int = 4
    min_modulation: float = 0.02
    axis: str = "columns"
    min_snr: float = 0.0

    def __post_init__(self) -> None:
        # size and period checked as the single-shot pattern's are (not its De Bruijn window's
        # width: a phase-shift period may be as wide as the pattern)
        size_hw, period = checked_size_and_period(self.size_hw, self.period_px)
        object.__setattr__(self, "size_hw", size_hw)
        object.__setattr__(self, "period_px", period)
        object.__setattr__(self, "steps", validate.integer(self.steps, "steps", lo=4, hi=64))
        object.__setattr__(
            self, "min_modulation", validate.number(self.min_modulation, "min_modulation", lo=0.0, hi=1.0)
        )
        object.__setattr__(self, "axis", validate.choice(self.axis, "axis", AXES))
        object.__setattr__(self, "min_snr", validate.number(self.min_snr, "min_snr", lo=0.0, hi=1e6))

    @property
    def extent_px(self) -> int:
        """Projector pixels along the coded axis (the width for columns, the height for rows)."""
        return self.size_hw[1] if self.axis == "columns" else self.size_hw[0]

    @property
    def gray_bits(self) -> int:
        """Gray-code frames: enough bits to number every half period of the width."""
        half_periods = math.ceil(2 * self.extent_px / self.period_px)
        return max(1, math.ceil(math.log2(half_periods)))

    @property
    def captures(self) -> int:
        """Camera exposures per depth map: N fringes + the Gray-code frames."""
        return self.steps + self.gray_bits


def _half_period_index(spec: PhaseShiftSpec) -> np.ndarray:
    """j = floor(2 s / T) of every projector column (or row), s = u + 0.5 the column's centre
    measured from the pattern's left edge (the phase convention of :func:`phase_from_column`)."""
    s = np.arange(spec.extent_px, dtype=np.float64) + 0.5
    return np.floor(2.0 * s / spec.period_px).astype(np.int64)


def phase_shift_frames(spec: PhaseShiftSpec) -> np.ndarray:
    """The projector frames, shape (N + bits, H, W), float32 in [0, 1]: the N shifted fringes
    ``0.5 + 0.5 cos(phi(u) - 2 pi n / N)``, then the Gray code of the half-period index,
    most significant bit first (white = 1); ``u`` is the column (or, ``axis = "rows"``, the
    row)."""
    h, w = spec.size_hw
    phi = phase_from_column(np.arange(spec.extent_px, dtype=np.float64), period_px=spec.period_px)
    rows = [0.5 + 0.5 * np.cos(phi - 2.0 * np.pi * n / spec.steps) for n in range(spec.steps)]
    j = _half_period_index(spec)
    gray = j ^ (j >> 1)
    bits = spec.gray_bits
    rows += [((gray >> (bits - 1 - b)) & 1).astype(np.float64) for b in range(bits)]
    profile = np.stack(rows)[:, None, :] if spec.axis == "columns" else np.stack(rows)[:, :, None]
    return np.broadcast_to(profile, (len(rows), h, w)).astype(np.float32, order="C")  # K order: column-major


def wrapped_phase(frames: np.ndarray, *, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(wrapped phase in [-pi, pi), mean intensity A, modulation B) of N phase-shifted images
    ``I_n = A + B cos(phi - 2 pi n / N)``, shape (N, H, W) -> each (H, W) float64.

    The least-squares estimate: ``phi = atan2(sum I_n sin d_n, sum I_n cos d_n)``; with
    independent noise of standard deviation sigma in every image its phase noise is
    ``sqrt(2 / N) sigma / B``.
    """
    i = np.asarray(frames, dtype=np.float64)
    if i.ndim != 3 or i.shape[0] != steps:
        raise ValueError(f"need {steps} phase-shifted images of shape (H, W), got {i.shape}")
    d = 2.0 * np.pi * np.arange(steps) / steps
    s = np.tensordot(np.sin(d), i, axes=1)
    c = np.tensordot(np.cos(d), i, axes=1)
    phi = np.arctan2(s, c)
    phi = np.where(phi >= np.pi, phi - 2.0 * np.pi, phi)
    return phi, i.mean(axis=0), 2.0 / steps * np.hypot(s, c)


def drift_phase_error(phi: np.ndarray, *, drift_rad: float, steps: int) -> np.ndarray:
    """The error of :func:`wrapped_phase` when the fringe phase moves by ``drift_rad`` from one
    image to the next (``I_n = A + B cos(phi + n eps - 2 pi n / N)``: a surface moving during an
    N-step sequence, or a miscalibrated phase shifter), wrapped to [-pi, pi).

    With ``psi = phi + (N - 1) eps / 2`` (the phase at the sequence's middle) the sums of the
    estimator give, exactly, ``phi_hat = psi + arg(1 - r exp(-i (2 psi + 2 pi / N)))`` with
    ``r = sin(eps / 2) / sin(2 pi / N - eps / 2)``: the mid-sequence phase plus a ripple at twice
    the fringe frequency of relative size ``r`` (~ eps N / 4 pi for small drifts) - the standard
    analysis of a linear phase-shift error (J. Schwider et al., "Digital wave-front measuring
    interferometry: some systematic error sources", Appl. Opt. 22(21), 3421-3432, 1983;
    K. Creath, "Phase-measurement interferometry techniques", Prog. Opt. 26, 349-393, 1988).

    Parameters
    ----------
    phi : ndarray, the true phase at the first image (rad)
    drift_rad : the phase change per image (rad)
    steps : N
    """
    phi = np.asarray(phi, dtype=np.float64)
    eps = float(drift_rad)
    psi = phi + 0.5 * (steps - 1) * eps
    r = np.sin(0.5 * eps) / np.sin(2.0 * np.pi / steps - 0.5 * eps)
    est = psi + np.angle(1.0 - r * np.exp(-1j * (2.0 * psi + 2.0 * np.pi / steps)))
    return np.angle(np.exp(1j * (est - phi)))


def gray_order(bit_images: np.ndarray, threshold: np.ndarray) -> np.ndarray:
    """The half-period index j of every pixel from its Gray-code images (MSB first) read
    against ``threshold`` (the mean intensity), shape (bits, H, W) -> (H, W) int64."""
    images = np.asarray(bit_images)
    if images.dtype.kind != "f":
        images = images.astype(np.float64)
    # float32 images are compared with the float64 threshold in float64, element by element
    # (exact), without a float64 copy of the whole stack
    threshold = np.asarray(threshold, dtype=np.float64)
    gray = np.zeros(images.shape[1:], np.int64)
    for plane in images:
        gray <<= 1
        gray |= plane > threshold
    return _gray_to_binary(images.shape[0])[gray] if images.shape[0] <= 16 else _gray_to_binary_loop(gray)


def _gray_to_binary_loop(gray: np.ndarray) -> np.ndarray:
    """Binary-reflected Gray code to binary: j = g ^ (g >> 1) ^ (g >> 2) ^ ..."""
    j = gray.copy()
    shift = gray >> 1
    while shift.any():
        j ^= shift
        shift >>= 1
    return j


@lru_cache(maxsize=4)
def _gray_to_binary(bits: int) -> np.ndarray:
    """:func:`_gray_to_binary_loop` of every ``bits``-bit code, as a look-up table (int64)."""
    table = _gray_to_binary_loop(np.arange(1 << bits, dtype=np.int64))
    table.setflags(write=False)
    return table


def grey_frame(image: np.ndarray) -> np.ndarray:
    """A recorded colour frame (H, W, 3), integer or float, as the grey image the sequences are
    decoded from: the mean of its channels in [0, 1], float32 (grey frames light the three
    primaries alike)."""
    img = np.asarray(image)
    scale = float(np.iinfo(img.dtype).max) if np.issubdtype(img.dtype, np.integer) else 1.0
    f = img.astype(np.float32) / np.float32(scale)
    if f.shape[-1] != 3:
        return f.mean(axis=-1)
    # the channel mean as numpy's float32 mean over the last axis adds and divides,
    # ((0 + R) + G) + B then / 3, in whole-image passes (the axis-(-1) reduction over 3 values
    # per pixel was 6x slower)
    grey = f[..., 0] + np.float32(0.0)
    grey += f[..., 1]
    grey += f[..., 2]
    grey /= np.float32(3)
    return grey


@dataclass(frozen=True)
class TemporalResult:
    """column_px (H, W) float64, NaN invalid; valid (H, W) bool; modulation (H, W) float64
    (``B``); wrapped (H, W) float64; order (H, W) int64, the period number; snr (H, W) float64,
    the modulation SNR ``B / sigma`` (:func:`fit_noise`; NaN where both are 0)."""

    column_px: np.ndarray
    valid: np.ndarray
    modulation: np.ndarray
    wrapped: np.ndarray
    order: np.ndarray
    snr: np.ndarray


def fit_noise(frames: np.ndarray, phi: np.ndarray, mean: np.ndarray, mod: np.ndarray) -> np.ndarray:
    """Each frame's noise (standard deviation, image units) as the N-step fit leaves it: the
    residual sum of squares of ``I_n = A + B cos(phi - 2 pi n / N)`` at every pixel, whose
    expectation is ``(N - 3) sigma**2`` for independent noise of standard deviation ``sigma``,
    averaged over :data:`NOISE_WINDOW_PX` x :data:`NOISE_WINDOW_PX` pixels (the image's ends
    replicated) and divided by ``N - 3``.

    It measures what the fringe model does not explain, whatever its cause: the camera's noise,
    and also a fringe harmonic that N steps alias onto the residual (the second, at N = 4: a
    projector's gamma, a clipped fringe) and a surface that moved between frames, each of which
    makes the phase less certain too.  ``frames`` (N, H, W); ``phi``, ``mean``, ``mod`` of
    :func:`wrapped_phase` on them.  Returns (H, W) float64."""
    import cv2

    f = np.asarray(frames, dtype=np.float64)
    n = f.shape[0]
    if n < 4:
        raise ValueError(f"the noise needs N >= 4 steps (N - 3 degrees of freedom a pixel), got {n}")
    rss = np.zeros(f.shape[1:], np.float64)
    for k in range(n):
        r = f[k] - mean - mod * np.cos(phi - 2.0 * np.pi * k / n)
        rss += r * r
    pooled = cv2.blur(rss, (NOISE_WINDOW_PX, NOISE_WINDOW_PX), borderType=cv2.BORDER_REPLICATE)
    return np.sqrt(np.maximum(pooled, 0.0) / (n - 3))


def gray_code_min_snr(*, steps: int, bits: int, error_rate: float = 1e-3) -> float:
    """The modulation SNR ``B / sigma`` (``sigma`` each frame's noise) above which a pixel's
    ``bits`` Gray-code frames misread its period number with probability at most
    ``error_rate`` (default: the 0.1 % of pixels more than 5 mm wrong that issue 35 allows).

    A Gray-code frame reads ``A +- M`` where ``2 M`` is the pixel's step between a white and a
    black projector pixel, and the N fringe frames' modulation is ``B = c M`` with ``c <= 1``
    their contrast at the fringe's frequency (defocus and blur lower a fine fringe's, not a
    broad stripe's): ``M >= B``.  The bit is read against ``A``, the mean of the N frames, so the
    noise of ``I - A`` is ``sigma sqrt(1 + 1 / N)`` and a bit flips with probability at most
    ``Phi(-SNR / sqrt(1 + 1 / N))``; a pixel's ``bits`` frames, at most ``bits`` times that.  (A
    bit next to its own transition reads less, but there the complementary choice takes the
    other period number, whose transitions are a quarter period away; and the phase, whose noise
    is ``sqrt(2 / N) / SNR`` rad, 0.17 rad at N = 4 and SNR 4.1, is wrong by the quarter period
    that would change the period number at 9 standard deviations.)  4.09 at N = 4, 8 bits."""
    z = -statistics.NormalDist().inv_cdf(error_rate / bits)
    return z * math.sqrt(1.0 + 1.0 / steps)


def decode_phase_shift(frames: np.ndarray, *, spec: PhaseShiftSpec) -> TemporalResult:
    """Projector column (or row, ``spec.axis``) of every pixel from the images of
    :func:`phase_shift_frames` (same order), shape (N + bits, H, W) float in [0, 1].

    The wrapped phase gives the position inside a period, ``f = (phi + pi) / 2 pi``; the Gray
    code numbers the half periods ``j``, so that ``k1 = j // 2`` changes at period borders and
    ``k2 = (j + 1) // 2`` in their middles.  Near a border (``f < 1/4``: ``k2``; ``f > 3/4``:
    ``k2 - 1``) the period number comes from ``k2``, elsewhere from ``k1``: each is read where
    its own transitions are a quarter period away, so a Gray-code edge blurred or shifted by up
    to a quarter period causes no order error (complementary Gray code, Zhang et al. 2012).

    References
    ----------
    .. [1] Q. Zhang, X. Su, L. Xiang, X. Sun, "3-D shape measurement based on complementary
       Gray-code light", Optics and Lasers in Engineering 50(4), 574-579, 2012.
    """
    f = np.asarray(frames)
    if f.ndim != 3 or f.shape[0] != spec.captures:
        raise ValueError(
            f"need {spec.captures} images (N = {spec.steps} fringes + {spec.gray_bits} Gray-code frames), "
            f"got shape {f.shape}"
        )
    phi, mean, mod = wrapped_phase(f[: spec.steps], steps=spec.steps)
    j = gray_order(f[spec.steps :], mean)
    frac = (phi + np.pi) / (2.0 * np.pi)
    k1, k2 = j >> 1, (j + 1) >> 1
    k = np.where(frac < 0.25, k2, np.where(frac > 0.75, k2 - 1, k1))
    column = column_from_phase(phi + 2.0 * np.pi * k, period_px=spec.period_px)
    w = spec.extent_px
    with np.errstate(divide="ignore", invalid="ignore"):
        # (no noise and no fringe: 0 / 0, NaN, invalid; no noise and a fringe: inf, valid)
        snr = mod / fit_noise(f[: spec.steps], phi, mean, mod)
        valid = np.isfinite(column) & (mod >= spec.min_modulation) & (column >= -0.5) & (column <= w - 0.5)
        if spec.min_snr > 0:
            valid &= snr >= spec.min_snr
    return TemporalResult(
        column_px=np.where(valid, column, np.nan), valid=valid, modulation=mod, wrapped=phi, order=k, snr=snr
    )
