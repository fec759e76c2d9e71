"""Alternative phase stages for ablations: Fourier transform profilometry and windowed Fourier ridges.

Both take and return what :func:`simbench.decode.phase.gabor_phase` does, so the pipeline can
swap them (``DecoderParams(phase_method="ftp" | "wfr")``) and every later stage, threshold and
metric stays the same.  The wrapped phase follows the convention of :mod:`simbench.pattern`: for
``I = A + B cos(psi)`` with ``psi`` growing along +x, the result is ``psi`` wrapped to [-pi, pi).

* **FTP** (Takeda, Ina & Kobayashi, JOSA 72(1), 1982): per image row, the spectrum's positive
  fundamental lobe is kept by a Hann band-pass over (0, 2 f0) (zero at DC and at the second
  harmonic, one at the nominal carrier f0) and transformed back; the result is the analytic
  fringe ``(B/2) exp(i psi)``.  This is Takeda's original one-dimensional method: one row at a
  time, no smoothing across rows, a global (whole-row) filter instead of a local window.
* **WFR** (windowed Fourier ridges; Kemao, Opt. Lasers Eng. 45, 2007): at every pixel, the
  windowed Fourier transform with the decoder's Gaussian window is evaluated on a grid of
  candidate frequencies around the carrier (along x, and tilted by +-dxi along y); the candidate
  with the largest magnitude (the ridge) gives the local frequency, its phase the wrapped phase
  and its magnitude the amplitude.  Unlike the Gabor stage, the frequency adapts to the surface
  (chirp from slanted surfaces); unlike FTP, the analysis is local.

Samples with zero certainty (unlit, clipped) are replaced by the local background before the
transform, so they contribute no fringe; the background ``A`` is a certainty-weighted Gaussian
mean along the row with sigma T/2, which passes exp(-pi^2 / 2) = 0.7 % of the fringe at the
carrier.  ``residual`` and ``support`` mean what they mean for the Gabor stage (see
:class:`~simbench.decode.phase.PhaseResult`); the residual is averaged along the row only, so
that each row's result depends on no more neighbouring rows than the phase window reaches (the
decoder's row bands carry exactly that halo, and results do not depend on the thread count).
"""

from __future__ import annotations

from functools import lru_cache

import cv2
import numpy as np

from simbench.decode.phase import PhaseResult, check_phase_inputs, gaussian_kernel, magnitude, window_share

__all__ = ["ftp_phase", "wfr_phase", "ridge_frequencies"]

_ROW = np.ones(1, np.float32)


def _prepare(intensity: np.ndarray, certainty: np.ndarray, period_px: float):
    """Checked float32 inputs, the background A and the fringe ``c * (I - A)`` (0 where uncertain)."""
    check_phase_inputs(intensity, certainty, period_px)
    intensity = intensity.astype(np.float32, copy=False)
    c = certainty.astype(np.float32, copy=False)
    background = _background(intensity, c, period_px=period_px)
    return intensity, c, background, c * (intensity - background)


def _background(intensity: np.ndarray, certainty: np.ndarray, *, period_px: float) -> np.ndarray:
    """Certainty-weighted local mean along each row (normalised convolution, sigma = T)."""
    k = gaussian_kernel(period_px)
    num = cv2.sepFilter2D(certainty * intensity, cv2.CV_32F, k, _ROW, borderType=cv2.BORDER_CONSTANT)
    den = cv2.sepFilter2D(certainty, cv2.CV_32F, k, _ROW, borderType=cv2.BORDER_CONSTANT)
    out = np.zeros_like(num)
    np.divide(num, den, out=out, where=den > 1e-3)
    return out


def _result(intensity, certainty, *, background, analytic_re, analytic_im, support, sigma_x_px, offset) -> PhaseResult:
    """PhaseResult from the analytic fringe ``(B/2) exp(i psi)`` (normalised to a full window)."""
    kx = gaussian_kernel(sigma_x_px)
    wrapped = cv2.phase(analytic_re, analytic_im)
    wrapped[wrapped >= np.pi] -= np.float32(2 * np.pi)
    amplitude = 2.0 * magnitude(analytic_re, analytic_im)
    good = (support > 0.05) & (amplitude > 0)
    amplitude = np.where(good, amplitude, np.float32(0))
    # per-pixel misfit of A + B cos(psi), its certainty-weighted RMS over the window along the row
    misfit = intensity - background - amplitude * np.cos(wrapped)
    num = cv2.sepFilter2D(certainty * misfit * misfit, cv2.CV_32F, kx, _ROW, borderType=cv2.BORDER_CONSTANT)
    den = cv2.sepFilter2D(certainty, cv2.CV_32F, kx, _ROW, borderType=cv2.BORDER_CONSTANT)
    residual = np.full_like(support, np.inf)
    ok = good & (den > 1e-3)
    np.divide(
        np.sqrt(np.maximum(num, 0) / np.where(ok, den, 1)), amplitude * np.float32(np.sqrt(0.5)), out=residual, where=ok
    )
    return PhaseResult(
        wrapped=wrapped,
        amplitude=amplitude,
        offset=background if offset else None,
        residual=residual,
        support=support,
    )


@lru_cache(maxsize=8)
def _ftp_filter(n: int, period_px: float) -> np.ndarray:
    """Hann band-pass on the rfft bins of an n-sample row: 1 at 1/T, 0 at DC and at 2/T.

    Keeping only the positive lobe with unit gain gives ``(B/2) exp(i psi)``."""
    f0 = 1.0 / period_px
    f = np.fft.rfftfreq(n)
    h = np.where((f > 0) & (f < 2 * f0), 0.5 * (1 + np.cos(np.pi * (f - f0) / f0)), 0.0)
    out = h.astype(np.float32)
    out.setflags(write=False)
    return out


def ftp_phase(
    intensity: np.ndarray,
    *,
    certainty: np.ndarray,
    period_px: float,
    sigma_x_px: float,
    sigma_y_px: float,
    offset: bool = True,
) -> PhaseResult:
    """Wrapped phase by Fourier transform profilometry (Takeda et al. 1982), row by row.

    Parameters
    ----------
    intensity : ndarray, shape (H, W), float32
    certainty : ndarray, shape (H, W), float32 in [0, 1]
    period_px : float
        Nominal fringe period in camera pixels (the carrier f0 = 1/T of the band-pass).
    sigma_x_px, sigma_y_px : float
        The decoder's analysis window; FTP's filter is global, so they set only the windows of
        ``support`` and ``residual`` (as for the Gabor stage).
    offset : bool
        Whether to return the background (``PhaseResult.offset``; None otherwise).

    Returns
    -------
    PhaseResult

    References
    ----------
    .. [1] M. Takeda, H. Ina, S. Kobayashi, "Fourier-transform method of fringe-pattern analysis
       for computer-based topography and interferometry", JOSA 72(1), 156-160, 1982.
    """
    intensity, c, background, fringe = _prepare(intensity, certainty, period_px)
    h, w = intensity.shape
    # zero padding by at least two periods: the row is not periodic, and the circular wrap of the
    # DFT would otherwise join its two ends
    n = cv2.getOptimalDFTSize(w + 2 * int(np.ceil(period_px)))
    spectrum = np.fft.rfft(fringe, n=n, axis=1)
    spectrum *= _ftp_filter(n, float(period_px))
    full = np.zeros((h, n), np.complex64)
    full[:, : spectrum.shape[1]] = spectrum
    analytic = np.fft.ifft(full, axis=1)[:, :w]
    return _result(
        intensity,
        c,
        background=background,
        analytic_re=np.ascontiguousarray(analytic.real, dtype=np.float32),
        analytic_im=np.ascontiguousarray(analytic.imag, dtype=np.float32),
        support=window_share(c, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px),
        sigma_x_px=sigma_x_px,
        offset=offset,
    )


def _modulated(sigma: float, xi: float) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian window times cos / sin of ``xi * u`` (unit-sum window, same support as :func:`gaussian_kernel`)."""
    g = gaussian_kernel(sigma).astype(np.float64)
    u = np.arange(g.size) - g.size // 2
    return (g * np.cos(xi * u)).astype(np.float32), (g * np.sin(xi * u)).astype(np.float32)


def ridge_frequencies(
    *, period_px: float, sigma_x_px: float, sigma_y_px: float, span: float = 0.35
) -> tuple[np.ndarray, float]:
    """Candidate frequencies (rad/px) of the ridge search.

    Along x: the carrier ``w = 2 pi / T`` and steps up to ``(1 +- span) w``, no coarser than
    half the window's frequency resolution ``1 / sigma_x``; along y: 0 and ``+-dxi_y`` with
    ``dxi_y = min(0.5 / sigma_y, span * w)`` (fringes turned by slanted surfaces).  A plane
    slanted by theta about the vertical axis changes the camera frequency by the factor
    ``1 + B tan(theta) / Z0`` (Z0 = its depth on the optical axis), so ``span`` = 0.35 covers
    slants up to 70 deg at 0.75 m in the paper's rig (B = 93 mm).

    Returns
    -------
    xi_x : ndarray, shape (K,), float64
    xi_y : float
    """
    omega = 2.0 * np.pi / period_px
    steps = max(1, int(np.ceil(span * omega * sigma_x_px / 0.5)))
    xi_x = omega * (1.0 + span * np.arange(-steps, steps + 1) / steps)
    return xi_x, float(min(0.5 / sigma_y_px, span * omega))


def wfr_phase(
    intensity: np.ndarray,
    *,
    certainty: np.ndarray,
    period_px: float,
    sigma_x_px: float,
    sigma_y_px: float,
    offset: bool = True,
) -> PhaseResult:
    """Wrapped phase by windowed Fourier ridges (Kemao 2007) with the decoder's Gaussian window.

    Parameters
    ----------
    intensity : ndarray, shape (H, W), float32
    certainty : ndarray, shape (H, W), float32 in [0, 1]
    period_px : float
        Nominal fringe period in camera pixels (centre of the frequency search).
    sigma_x_px, sigma_y_px : float
        Standard deviations of the Gaussian window.
    offset : bool
        Whether to return the background (``PhaseResult.offset``; None otherwise).

    Returns
    -------
    PhaseResult

    References
    ----------
    .. [1] Q. Kemao, "Windowed Fourier transform for fringe pattern analysis", Applied Optics
       43(13), 2695-2702, 2004.
    """
    if not (sigma_x_px > 0 and sigma_y_px > 0):
        raise ValueError("sigma_x_px and sigma_y_px must be > 0")
    intensity, c, background, fringe = _prepare(intensity, certainty, period_px)
    xi_x, xi_y = ridge_frequencies(period_px=period_px, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px)
    gy = gaussian_kernel(sigma_y_px)
    cy, sy = _modulated(sigma_y_px, xi_y)

    def corr(kx, ky):
        return cv2.sepFilter2D(fringe, cv2.CV_32F, kx, ky, borderType=cv2.BORDER_CONSTANT)

    best = np.full(fringe.shape, -1.0, np.float32)
    best_re, best_im, best_eps = np.zeros_like(best), np.zeros_like(best), np.zeros_like(best)
    gx = gaussian_kernel(sigma_x_px)
    u_x, u_y = np.arange(gx.size) - gx.size // 2, np.arange(gy.size) - gy.size // 2
    for xi in xi_x:
        cx, sx = _modulated(sigma_x_px, float(xi))
        # correlation with the kernel g(u, v) exp(-i (xi u + s xi_y v)); at the ridge its phase is psi
        # at the window centre for a locally linear phase (the window is symmetric)
        leak_x = float(np.sum(gx * np.cos(2 * xi * u_x)))
        candidates = [(corr(cx, gy), -corr(sx, gy), leak_x)]
        p, q, r, t = corr(cx, cy), corr(sx, sy), corr(sx, cy), corr(cx, sy)
        leak_xy = leak_x * float(np.sum(gy * np.cos(2 * xi_y * u_y)))
        for s in (1.0, -1.0):
            candidates.append((p - s * q, -(r + s * t), leak_xy))
        for re, im, leak in candidates:
            mag = re * re + im * im
            better = mag > best
            np.copyto(best, mag, where=better)
            np.copyto(best_re, re, where=better)
            np.copyto(best_im, im, where=better)
            np.copyto(best_eps, np.float32(leak), where=better)
    # the response is S = a + eps * conj(a) with a = (B/2) exp(i psi): the window passes a share
    # eps = G^(2 xi) of the fringe's negative-frequency half (0.7 % for the default window); undo it
    best_re /= 1 + best_eps
    best_im /= 1 - best_eps
    # the window moments of the certainty turn the sums into a full-window fringe estimate
    support = window_share(c, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px)
    scale = np.zeros_like(support)
    np.divide(np.float32(1), support, out=scale, where=support > 0.05)
    return _result(
        intensity,
        c,
        background=background,
        analytic_re=best_re * scale,
        analytic_im=best_im * scale,
        support=support,
        sigma_x_px=sigma_x_px,
        offset=offset,
    )
