"""The paper's decoder (Sec. 5) as one function chaining the stages, each stage's output kept."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import TypeVar

import numpy as np

from simbench.decode import _kernels
from simbench.decode.color import (
    ALBEDO_MAX_GAIN,
    COLUMN_SKIP_PX,
    color_code,
    mixing_matrix,
    albedo_gain,
    albedo_step_pixels,
    column_albedo_gain,
    column_flattened,
    column_step_pixels,
    mixed_pixel_gain,
    normalize_channels,
    overlay_weight_reach_rows,
    code_at_row_ends,
    normalized_color_code,
    overlay_weights,
    pool_code_rows,
    segment_stripes,
    unmix,
    vote_codes,
)
from simbench.decode.integrity import (
    CLIPPED_SHARE_WARN,
    block_artifacts,
    clipped_share,
    clipping_doubt,
    compression_doubt,
)
from simbench.decode.debruijn import (
    CODE_VOTE_PERIODS,
    contested_positions,
    drop_broken_links,
    keep_certain_sides,
    keep_straddler_parts,
    neighbour_correct,
    stripe_floor,
    uncertain_positions,
    window_positions_of_stripes,
)
from simbench.decode.depth import (
    absolute_column,
    crease_apex_bias,
    crease_trusted,
    inverse_column_table,
    match_reference,
)
from simbench.decode.phase import (
    CARRIER_BANK,
    MIN_WINDOW_WEIGHT,
    PhaseResult,
    bank_fit,
    centroid_corrected,
    certainty_map,
    certainty_window_px,
    fringe_snr,
    off_discontinuity,
    overlay_intensity,
    shadow_margin,
    weighted_fit,
    window_share,
)
from simbench.decode.profile import stage
from simbench.decode.registration import (
    encoding_doubt,
    fringe_harmonic_ratio,
    registration_cap,
    registration_change,
    registration_doubt,
    registration_px,
)
from simbench.decode.params import (
    CREASE_APEX_MIN_PX,
    CREASE_APEX_PERIODS,
    CREASE_APEX_SHARE,
    CREASE_BIAS_RATIO,
    CREASE_LOBE_SHARE,
    CREASE_PEAK_PERIODS,
    CREASE_SCALE_PERIODS,
    EDGE_BEND_FIT_PERIODS,
    EDGE_BEND_REACH_SIGMAS,
    MIN_CAMERA_PERIOD_PX,
    DecoderParams,
    PHASE_METHODS,
    phase_method_code,
    reference_inverse_fb,
    STABILITY_KAPPA_RAD,
    STABILITY_WINDOW_SCALE,
)
from simbench.decode.bands import code_pool_rows, fit_halo_rows, run_bands
from simbench.optics import undistort_image
from simbench.pattern import (
    check_channels,
    code_sequence,
    window_positions,
)
from simbench.rig import (
    Rig,
    check_stripe_baseline,
    projector_column_at_depth,
    triangulate_columns,
    triangulation_steps,
    triangulation_values,
)

__all__ = [
    "phase_change",
    "apply_min_confidence",
    "ReferenceMap",
    "DecodeResult",
    "LazyStages",
    "as_float_image",
    "decode_reference",
    "reference_plane_offset",
    "reference_plane_extent",
    "REFERENCE_Z0_TOLERANCE",
    "REFERENCE_Z0_WARNING",
    "REFERENCE_EXTENT_PERCENTILES",
    "code_order_doubt",
    "code_succession_doubt",
    "registration_warning",
    "reference_warnings",
    "without_depth",
    "MIN_WINDOW_SUCCESSION",
    "decode",
]


@dataclass(frozen=True)
class ReferenceMap:
    """A decoded reference-plane capture.

    column_px : ndarray, shape (H, W), float32; projector column per camera pixel, NaN unknown
    expected_px : ndarray, shape (H, W), float32; ``column_px`` with the gaps filled from the
        rig's prediction for a plane at Z0 (what the cycle number is chosen against)
    inverse : ndarray, shape (H, Wp + 1), float32; x showing each integer column per row
    z0_m : float
    mixing : ndarray, shape (3, 3), float64, or None; the projector-to-camera coupling matrix
        K (:func:`simbench.decode.color.mixing_matrix`), when calibration captures under each
        primary came with the reference
    registration_px : ndarray, shape (TY, TX), float64, or None; the reference capture's colour
        registration per tile (:func:`simbench.decode.registration.registration_px`), what a
        capture's is compared with in reference mode (None: with 0)
    """

    column_px: np.ndarray
    expected_px: np.ndarray
    inverse: np.ndarray
    z0_m: float
    mixing: np.ndarray | None = None
    registration_px: np.ndarray | None = None


@dataclass(frozen=True)
class DecodeResult:
    """Decoder output, on the camera's ideal pinhole pixel grid (a capture from a camera with
    lens distortion in the rig is undistorted first).

    depth_m : ndarray, shape (H, W), float32; NaN where invalid
    valid : ndarray, shape (H, W), bool
    confidence : ndarray, shape (H, W), float32; the fringe SNR
        (:func:`simbench.decode.phase.fringe_snr`; with ``params.phase_stability`` capped at
        :data:`STABILITY_KAPPA_RAD` over the phase's change, and the other terms of
        :func:`simbench.decode.robust_params`) of every pixel the decoder found a depth for,
        those below ``params.min_confidence`` (now holes) included; 0 where it found none, on a
        stripe whose position is contested (``params.position_doubt``) and beside a shadow
        (``params.shadow_doubt``)
    column_px : ndarray, shape (H, W), float32; decoded projector column, NaN if invalid
    stripe_index : ndarray, shape (H, W), int32; n of Eq. 14, -1 if invalid
    stages : Mapping of str -> ndarray; intermediate images (paper Fig. 6), made on first access
    window_succession : (pairs, as read, swapped, mirrored, mirrored and swapped); the linked
        neighbouring stripes whose De Bruijn windows both read, and how many of them read
        successive windows as the capture is, with red and green swapped, read right to left, and
        both - the last three counted only where fewer than :data:`ALTERNATIVES_BELOW` read as
        the capture is (0 otherwise); before the neighbour correction (:func:`code_order_doubt`)
    registration_px : ndarray, shape (TY, TX), float64, or None; with
        ``params.registration_doubt``, the code channels' fringe position against the fringe
        channel's per tile, camera px, less the reference capture's in reference mode
        (:func:`simbench.decode.registration.registration_change`); None when not measured
    """

    depth_m: np.ndarray
    valid: np.ndarray
    confidence: np.ndarray
    column_px: np.ndarray
    stripe_index: np.ndarray
    stages: Mapping = field(default_factory=dict)
    window_succession: tuple[int, int, int, int, int] = (0, 0, 0, 0, 0)
    registration_px: np.ndarray | None = None


class LazyStages(Mapping):
    """Stage images computed on first access, so a decode only pays for the ones it needs.

    A stage made from another stage takes the mapping as its argument (``put(..., derived=True)``)
    instead of closing over it: a closure over the mapping that holds it is a reference cycle,
    which kept every band's intermediate images (~40 MB a decode) alive until Python's cyclic
    collector ran, so each decode wrote into freshly faulted memory and a process grew to ~1 GB.
    """

    def __init__(self) -> None:
        self._make: dict[str, tuple[Callable, bool]] = {}
        self._done: dict[str, np.ndarray] = {}

    def put(self, name: str, value, *, derived: bool = False) -> None:
        """``value``: an image, a function of no arguments making it, or with ``derived`` a
        function of this mapping making it."""
        if derived and not callable(value):
            raise TypeError(f"stage {name!r}: a derived stage needs a function of the stages")
        if callable(value):
            self._make[name] = (value, derived)
        else:
            self._make[name] = (lambda v=value: v, False)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._done:
            make, derived = self._make[name]
            self._done[name] = make(self) if derived else make()
        return self._done[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._make)

    def __len__(self) -> int:
        return len(self._make)


def _check_capture(image: np.ndarray, expected_size_hw: tuple[int, int] | None) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"capture must have shape (H, W, 3), got {img.shape}")
    if expected_size_hw is not None and img.shape[:2] != tuple(expected_size_hw):
        raise ValueError(
            f"capture is {img.shape[1]}x{img.shape[0]} (WxH); the rig's camera is "
            f"{expected_size_hw[1]}x{expected_size_hw[0]}"
        )
    if img.dtype in (np.uint8, np.uint16):
        return img
    if np.issubdtype(img.dtype, np.floating):
        if not np.isfinite(img.sum(dtype=np.float64)):
            raise ValueError("capture contains NaN or inf")
        return img
    raise ValueError(f"unsupported capture dtype {img.dtype}; use uint8, uint16 or float")


def _ideal_image(image: np.ndarray, rig: Rig) -> np.ndarray:
    """The capture resampled onto the ideal pinhole grid when the rig's camera has lens
    distortion (every later stage, and the output, live on that grid), as float32 in [0, 1]
    (:func:`_to_float`) first.

    Not in its own dtype: OpenCV's bilinear remap of an integer image weighs its pixels in
    steps of 1/32 px and rounds the result to the image's integer levels again - a second
    quantisation of every 8-bit capture, on a fringe that a dark print holds in ~2.5 DN (a new
    user's audit, 2026-11-30: the 20:1 chart's capture decoded 96.5 % complete as its 8-bit PNG,
    97.2 % as the same values in 16 bits or as floats)."""
    if not rig.camera.has_distortion:
        return image
    return undistort_image(_to_float(image), rig.camera)


def _to_float(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return np.multiply(img, np.float32(1 / 255), dtype=np.float32)
    if img.dtype == np.uint16:
        return np.multiply(img, np.float32(1 / 65535), dtype=np.float32)
    return img.astype(np.float32)


def as_float_image(image: np.ndarray, *, expected_size_hw: tuple[int, int] | None = None) -> np.ndarray:
    """A capture as float32 RGB in [0, 1]: uint8 / 255, uint16 / 65535, floats as they are.

    Raises
    ------
    ValueError
        Wrong shape or size, unsupported dtype, or non-finite float values.
    """
    return _to_float(_check_capture(image, expected_size_hw))


def _per_pixel(per_stripe: np.ndarray, labels: np.ndarray, fill) -> np.ndarray:
    """Spread one value per stripe over its pixels; ``fill`` where the label is -1."""
    out = np.empty(labels.shape, per_stripe.dtype)
    _kernels.gather(np.ascontiguousarray(per_stripe), np.ascontiguousarray(labels), per_stripe.dtype.type(fill), out)
    return out


def _fused_front_end(params: DecoderParams, unmixing: np.ndarray | None, image: np.ndarray) -> bool:
    """Whether a band takes the one-pass front end (:func:`simbench.decode._kernels.front_end`):
    the paper's channels as they are (no unmixing or normalisation), intensity by Eq. 9 or the
    fringe channel, a contiguous uint8/uint16/float32 capture."""
    return (
        unmixing is None
        and not params.color_normalize
        and params.intensity_mode in _FUSED_INTENSITY
        and image.dtype in _FUSED_DTYPES
        and image.flags.c_contiguous
    )


_FUSED_INTENSITY = {"overlay": 0, "blue": 1}
_FUSED_DTYPES = (np.uint8, np.uint16, np.float32)


@dataclass(frozen=True)
class BandStripes:
    """What the stripe stages leave for the absolute column (paper Eq. 14) of a band's rows.

    labels : ndarray, shape (h, W), int32; stripe of each pixel, -1 none
    position : ndarray, shape (n_stripes,), int32; W of each stripe after the neighbour
        correction, -1 unknown
    wrapped, expected, confidence : ndarray, shape (h, W), float32; the wrapped phase, the
        column the cycle number is chosen against, the fringe SNR (:func:`fringe_snr`)
    """

    labels: np.ndarray
    position: np.ndarray
    wrapped: np.ndarray
    expected: np.ndarray
    confidence: np.ndarray
    period_px: int
    cycle: int
    # DecodeResult.window_succession's counts for the band
    window_succession: tuple[int, int, int, int, int] = (0, 0, 0, 0, 0)

    def position_map(self) -> np.ndarray:
        """W per pixel, -1 unknown."""
        return _per_pixel(self.position, self.labels, -1)

    @cached_property
    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(column_px, stripe_index) per pixel, before the depth range is applied
        (:func:`simbench.decode.depth.absolute_column`)."""
        return absolute_column(
            self.position_map(), self.wrapped, self.expected, period_px=self.period_px, cycle=self.cycle
        )


def _columns(
    image: np.ndarray,
    order: list[int],
    expected_column: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams,
    crop: slice,
    unmixing: np.ndarray | None = None,
) -> tuple[BandStripes, LazyStages]:
    """Stages 1-3 for one band of rows.

    ``image`` is the band of the checked capture (any dtype :func:`as_float_image` takes,
    channels in the capture's order; ``order`` lists the indices of code 1, code 0 and the
    fringe) plus a halo of rows above and below for the phase fit, with ``pool_code`` the rows
    whose code votes on the band's (and their own fit's rows) and, with the albedo flattening,
    the rows its gain reads (:func:`simbench.decode.bands.row_bands`); ``crop`` selects the band's
    own rows, to which everything after the fit is restricted.
    Returns (:class:`BandStripes`, stages) for the cropped rows; the stage images of the
    absolute column (``position``, ``column``, ``unwrapped_phase``) are made on access.
    """
    t_cam = params.camera_period(rig)
    # with normalised channels a stripe whose colour the surface absorbs is still usable, so
    # "lit" looks across the neighbouring stripes: twice the normalisation window, so that
    # at the image border, where only one side is in view, both stripe colours still are
    window = 2 * (params.order + 1) if params.color_normalize else 1
    skipped = mixed = None  # the albedo-edge skip's pixels, and the certainty of those it leaves out
    gain = None  # the albedo flattening's gain, where it found a step in the band
    print_gain = None  # its part down the columns, where it found one: a print's (column_albedo_gain)
    extrema = None  # the gain the normalisation's running extrema read, where not the gain
    if _fused_front_end(params, unmixing, image):
        # the same bits as the general path below, in one pass over the capture
        with stage("front end (float, lit/clipped, Eq. 9, Eq. 13)"):
            hb, wb = image.shape[:2]
            intensity = np.empty((hb, wb), np.float32)
            certainty = np.empty((hb, wb), np.float32)
            lit = np.empty((hb, wb), bool)
            code_full = np.empty((hb, wb), bool)
            _kernels.front_end(
                image,
                order,
                _FUSED_INTENSITY[params.intensity_mode],
                certainty_window_px(t_cam, window),
                params.dark_level,
                params.saturation_level,
                intensity,
                certainty,
                lit,
                code_full,
            )
            # the rows the pooled code reads too (ext = crop without pooling)
            ext = _pool_rows(crop, hb, params, rig)
            code_ext = code_full[ext]
    else:
        with stage("to float"):
            rgb = _to_float(image if order == [0, 1, 2] else image[..., order])
        raw = rgb
        weights = span = gain = None
        with stage("colour unmixing and normalisation"):
            if unmixing is not None:
                rgb = unmix(rgb, unmixing)
            if params.color_normalize:
                norm = dict(period_px=t_cam, order=params.order, min_span=0.25 * params.dark_level, return_span=True)
                normed, span = normalize_channels(rgb, **norm)
                if params.albedo_flatten:
                    columns = None
                    if params.albedo_columns:
                        # the print's steps down the columns first: the steps along the rows are
                        # then looked for in the light they leave (and the gains multiply)
                        columns = column_albedo_gain(rgb, period_px=t_cam, floor=params.dark_level)
                    if columns is None:
                        gain = albedo_gain(rgb, span, period_px=t_cam, order=params.order)
                    else:
                        flat = column_flattened(rgb, columns)
                        gain = albedo_gain(
                            flat, normalize_channels(flat, **norm)[1], period_px=t_cam, order=params.order
                        )
                        gain *= columns
                    # the band holds the rows the gain reads beyond the fit's (bands.row_bands); the
                    # rest of the work needs the fit's rows only: copies of them, so that the band's
                    # images are freed (the memory a band thread holds at once decides whether the
                    # allocator hands it fresh pages every decode: ~8 ms more a decode when it did)
                    halo = fit_halo_rows(params, rig) + code_pool_rows(params, rig)
                    fit = slice(max(0, crop.start - halo), min(image.shape[0], crop.stop + halo))
                    # the overlay's weights of the fit's rows are means down the columns over
                    # rows beyond them (weights_down_columns): those rows are normalised too
                    if params.weights_down_columns:
                        halo += overlay_weight_reach_rows(t_cam, params.order)
                    band_rows = slice(max(0, crop.start - halo), min(image.shape[0], crop.stop + halo))
                    crop = slice(crop.start - fit.start, crop.stop - fit.start)
                    # before the cut: the step tests down a column mark the first and last rows
                    # from the rows beyond them (the band carries them: column_gain_reach_rows)
                    beyond = 1 if columns is None else COLUMN_SKIP_PX
                    wide = slice(max(0, band_rows.start - beyond), min(gain.shape[0], band_rows.stop + beyond))
                    # a gain of exactly 1 (no step near: most bands of most scenes) has no step to
                    # skip beside (~3.5 ms a band at the paper's resolution saved)
                    if params.albedo_edge_skip and not (gain[wide] == 1.0).all():
                        mixed = albedo_step_pixels(gain[wide])
                        if columns is not None:
                            mixed |= column_step_pixels(columns[wide])
                        # nor do they lift the normalisation's running extrema (mixed_pixel_gain; a
                        # mixed pixel's lower side is within `beyond` of it)
                        extrema = mixed_pixel_gain(gain[wide], mixed, reach_px=beyond)
                        mixed = mixed[fit.start - wide.start :][: fit.stop - fit.start]
                        extrema = extrema[band_rows.start - wide.start :][: band_rows.stop - band_rows.start]
                    if columns is not None and not (columns[fit] == 1.0).all():
                        print_gain = columns[fit].copy()
                    # (the rows beyond the fit's are cut once the weights are made, below)
                    image, gain, raw = image[band_rows], gain[band_rows].copy(), raw[band_rows].copy()
                    rgb = raw if unmixing is None else rgb[band_rows].copy()
                    # with no step anywhere the gain is exactly 1 and the normalisation stands
                    if (gain == 1.0).all():
                        gain = None
                        normed, span = normed[band_rows].copy(), span[band_rows].copy()
                    else:
                        normed, span = normalize_channels(rgb, gain=gain, extrema_gain=extrema, **norm)
                    if params.intensity_mode == "weighted":
                        weights = overlay_weights(
                            raw,
                            span,
                            unmixing=unmixing,
                            period_px=t_cam,
                            order=params.order,
                            floor=params.dark_level,
                            down_columns=params.weights_down_columns,
                        )
                    if band_rows != fit:
                        keep = slice(fit.start - band_rows.start, fit.stop - band_rows.start)
                        image, raw = image[keep], raw[keep].copy()
                        rgb = raw if unmixing is None else rgb[keep].copy()
                        normed, span = normed[keep].copy(), span[keep].copy()
                        gain = None if gain is None else gain[keep].copy()
                        extrema = None if extrema is None else extrema[keep].copy()
                        weights = None if weights is None else tuple(w[keep].copy() for w in weights)
        with stage("lit and clipped pixels"):
            if image.dtype in _FUSED_DTYPES and image.flags.c_contiguous:
                # the fused front end's lit and clipped pixels (the same bits as certainty_map);
                # its fringe and code are not these channels' and are dropped
                hb, wb = image.shape[:2]
                certainty = np.empty((hb, wb), np.float32)
                lit = np.empty((hb, wb), bool)
                _kernels.front_end(
                    image,
                    order,
                    _FUSED_INTENSITY["blue"],
                    certainty_window_px(t_cam, window),
                    params.dark_level,
                    params.saturation_level,
                    np.empty((hb, wb), np.float32),
                    certainty,
                    lit,
                    np.empty((hb, wb), bool),
                )
            else:
                certainty, lit = certainty_map(
                    raw,
                    period_px=t_cam,
                    dark_level=params.dark_level,
                    saturation_level=params.saturation_level,
                    window_periods=window,
                )
        if mixed is not None and mixed.any():  # (a band whose own gain is all 1 may border a step)
            with stage("albedo edges skipped"):
                # (mixed has the fit's rows, as certainty: image and gain were cut to them together)
                skipped = np.where(mixed, certainty, np.float32(0.0))
                certainty = np.where(mixed, np.float32(0.0), certainty)
        unmixed = rgb
        if span is not None:
            rgb = normed
            if params.intensity_mode == "weighted" and weights is None:
                with stage("colour unmixing and normalisation"):
                    weights = overlay_weights(
                        raw,
                        span,
                        unmixing=unmixing,
                        period_px=t_cam,
                        order=params.order,
                        floor=params.dark_level,
                        down_columns=params.weights_down_columns,
                    )
        with stage("intensity overlay (Eq. 9)"):
            intensity = overlay_intensity(rgb, mode=params.intensity_mode, weights=weights)
        with stage("colour code (Eq. 13)"):
            # the rows the pooled code reads too (ext = crop without pooling)
            ext = _pool_rows(crop, image.shape[0], params, rig)
            if span is None:
                code_ext = color_code(rgb[ext])
            else:
                code_ext = code_at_row_ends(
                    unmixed[ext],
                    normalized_color_code(rgb[ext], span[ext]),
                    period_px=t_cam,
                    order=params.order,
                    min_span=norm["min_span"],
                    gain=None if gain is None else gain[ext],
                )
    sx = params.sigma_periods * t_cam
    user_code = phase_method_code(params.phase_method)  # (first: it imports an installed package's methods)
    method = PHASE_METHODS[params.phase_method]
    if user_code is not None:
        method = _checked_phase_method(method, params.phase_method)
    carrier = None
    fit_certainty = certainty
    # (print_gain is set only with a gain: the gain down the columns is a factor of it)
    if print_gain is not None and params.phase_method == "gabor":
        # A flattened sample is its capture times the gain, so is its noise: on a 20:1 print the
        # ink's few-DN fringe comes back ~20x, its noise with it, and a window over paper and ink
        # that weighs both alike takes the ink's noise into the paper's phase (measured on
        # scenes/hard_chart_fine.toml: the phase's spread 0.045-0.055 rad on paper and ink alike,
        # ~3.5x what the paper's own samples give).  Only the gain down the columns counts here:
        # its steps passed the scaled-copy test of a print's edge, where the steps along the rows
        # are any brightness step, a depth edge's too - weighed down, the far side of a depth edge
        # fits its window alone and the pixels on the near side take its phase at full confidence
        # (with the whole gain: the motion study's still board, 320x240, 62 -> 77 pixels more than
        # 5 mm wrong, all on the first column past its side edge).  Each certain sample weighs 1/gain (an
        # assumption between the inverse variances of shot-noise-limited samples, 1/gain, and of
        # read-noise-limited ones, 1/gain^2: 1/gain^2 makes the windows beside every print edge so
        # lopsided that the centroid correction, which reads the fringe's rate only from whole
        # windows, leaves their bias - the 5:1 turned chart's MAE 0.30 -> 0.57 mm; docs/decoder.md).
        # Paper weighs exactly 1: a window without ink fits as the plain fit does, bit for bit, so
        # a row band without a print (the plain fit) and one with it give its pixels one result.
        fit_certainty = flattened_fit_weights(certainty, print_gain)
        method = weighted_fit(method, min_weight=MIN_WINDOW_WEIGHT / ALBEDO_MAX_GAIN)
    with stage(f"phase ({params.phase_method}, Eq. 10-11)"):
        # no offset: no stage reads it, and not writing it saves a fifth of the Gabor kernel's output
        fit = dict(certainty=fit_certainty, period_px=t_cam, sigma_y_px=sx * params.sigma_y_ratio)
        if params.carrier_bank:
            phase, carrier = bank_fit(
                method,
                intensity,
                sigma_x_px=sx,
                max_residual=params.max_residual,
                candidates=lit,
                min_support=params.min_window_support,
                **fit,
            )
        else:
            phase = method(intensity, sigma_x_px=sx, offset=False, **fit)
    if skipped is not None and skipped.any():
        with stage("albedo edges skipped"):
            # the support test guards against windows reaching off the lit surface (a shadow, the
            # image's border); a sample left out for its mixed light is on it: it still counts
            # (support = the share of the window's weight on certain samples, used or not)
            share = _window_shares(skipped, carrier, sigma_x_px=sx, sigma_y_px=fit["sigma_y_px"])
            phase = dataclasses.replace(phase, support=np.minimum(phase.support + share, np.float32(1.0)))
    inner = slice(crop.start - ext.start, crop.stop - ext.start)  # crop's rows within ext
    with stage("validity"):
        # over ext, which the pooled code reads; the centroid correction below moves the phase
        # only, not what this reads
        valid_ext = np.empty(lit[ext].shape, bool)
        _kernels.validity(
            lit[ext],
            phase.support[ext],
            phase.amplitude[ext],
            phase.residual[ext],
            params.min_window_support,
            params.min_amplitude,
            params.max_residual,
            valid_ext,
        )
    code = code_ext
    if params.pool_code:
        with stage("colour code pooled down the stripes"):
            code = pool_code_rows(
                code_ext, phase.wrapped[ext], valid_ext, rows=code_pool_rows(params, rig), out_rows=inner
            )
    narrow = None
    if params.phase_stability:
        with stage(f"phase stability ({params.phase_method} at {STABILITY_WINDOW_SCALE:g} x the window)"):
            nx = sx * STABILITY_WINDOW_SCALE
            if carrier is not None:  # each pixel's own fit of the bank, narrower
                narrow, _ = bank_fit(method, intensity, sigma_x_px=nx, max_residual=0.0, choice=carrier, **fit)
            else:
                narrow = method(intensity, sigma_x_px=nx, offset=False, **fit)
            narrow_residual = narrow.residual[crop]
            narrow = narrow.wrapped[crop]
    if params.centroid_correction:
        with stage("window centroid correction"):
            phase, narrow = _centroid_correction(phase, narrow, certainty, carrier, crop, fit, sx, t_cam)
    with stage("validity"):
        intensity, certainty, lit = intensity[crop], certainty[crop], lit[crop]
        wrapped, amplitude, residual, support_w = (
            phase.wrapped[crop],
            phase.amplitude[crop],
            phase.residual[crop],
            phase.support[crop],
        )
        valid = valid_ext[inner]
    with stage("stripe segmentation and voting"):
        stripes = segment_stripes(
            wrapped,
            valid,
            period_px=t_cam,
            min_step_ratio=params.stripe_step_ratio[0],
            max_step_ratio=params.stripe_step_ratio[1],
            max_gap_px=int(params.bridge_gap_periods * t_cam),
        )
        stripe_code, agreement, votes = vote_codes(code, stripes, voting=params.voting)
    lab = stripes.labels
    with stage("confidence"):
        confidence = fringe_snr(residual)
        if narrow is not None and params.narrow_snr:
            off = off_discontinuity(residual, sigma_x_px=sx)
            if carrier is not None:
                # a bank fit stands on a stretch the nominal window misfits, beside no edge: the
                # narrow window's reason to count (less of an edge's far side) does not apply
                off &= carrier[crop] == 0
            np.fmax(confidence, fringe_snr(narrow_residual), out=confidence, where=off)
        shift = None
        if narrow is not None:
            shift = phase_change(wrapped, narrow)
            with np.errstate(divide="ignore", invalid="ignore"):
                # fmin: where the narrow fit has no phase the fringe SNR stands
                np.fmin(confidence, np.float32(STABILITY_KAPPA_RAD) / shift, out=confidence)
    with stage("De Bruijn windows and neighbour correction"):
        table = _window_table(params.order, params.sequence)
        raw_w = window_positions_of_stripes(
            stripe_code, stripes.linked_prev, order=params.order, table=table, cycle=params.cycle
        )
        w_fixed, support = neighbour_correct(
            raw_w, stripes.linked_prev, cycle=params.cycle, reach=params.neighbour_reach, min_support=params.min_support
        )
        if params.link_check:
            dropped = drop_broken_links(w_fixed, stripes.linked_prev, cycle=params.cycle)
            # the stripe floors only where a link broke (most bands of a smooth scene have none)
            if params.link_keep_certain > 0.0 and not np.array_equal(dropped, w_fixed):
                floor = stripe_floor(confidence, stripes)
                dropped = keep_certain_sides(
                    w_fixed,
                    dropped,
                    stripes.linked_prev,
                    floor,
                    cycle=params.cycle,
                    min_confidence=params.link_keep_certain,
                )
                if params.link_split:
                    dropped, lab = keep_straddler_parts(
                        w_fixed,
                        dropped,
                        stripes.linked_prev,
                        stripes,
                        confidence,
                        floor,
                        cycle=params.cycle,
                        min_confidence=params.link_keep_certain,
                    )
            w_fixed = dropped
            support = np.where(w_fixed >= 0, support, 0)
    contested = None
    if params.position_doubt:
        with stage("contested positions"):
            # after the link check, which reads the confidence: the term moves no stripe
            contested = contested_positions(
                raw_w,
                w_fixed,
                stripes.linked_prev,
                cycle=params.cycle,
                # one cycle either side: a run of misread stripes up to a cycle long is bracketed
                # (measured, JPEG 50 of the dark measured blue board: 0.017 % wrong at a reach of 5,
                # 0.018 % at 8, 0.019 % at 12 - 89.7, 87.8 and 82.6 % complete; noise 8 DN on it:
                # 1.6, 0.7 and 0.7 % wrong)
                reach=params.cycle,
                min_support=params.min_support,
            )
            if contested.any():
                confidence[_per_pixel(contested, lab, False)] = 0.0
    uncertain = None
    if params.code_doubt:
        with stage("uncertain codes"):
            # after the link check, as the contested positions: it moves no stripe
            # the net vote, a whole number (agreement is a float32 share of the votes)
            margin = np.rint(votes * (np.float32(2.0) * agreement - np.float32(1.0)))
            uncertain = uncertain_positions(
                raw_w,
                w_fixed,
                stripes.linked_prev,
                margin >= np.float32(CODE_VOTE_PERIODS * t_cam),
                order=params.order,
                cycle=params.cycle,
                reach=params.neighbour_reach,
                # one window of read codes suffices: the correction's min_support votes are had
                # already (requiring them of read codes alone doubted 2 % of a noisy dark board
                # that decodes with no wrong pixel: tests/test_robust_decoder.py)
                min_support=1,
            )
            if uncertain.any():
                confidence[_per_pixel(uncertain, lab, False)] = 0.0
    beside_shadow = None
    if params.shadow_doubt:
        with stage("shadow margin"):
            # after the link check, as the contested positions: it moves no stripe
            beside_shadow = shadow_margin(intensity, period_px=t_cam, sigma_x_px=sx)
            confidence[beside_shadow] = 0.0
    succession = _window_succession(raw_w, stripe_code, stripes.linked_prev, params=params)
    band = BandStripes(
        labels=lab,
        position=w_fixed.astype(np.int32, copy=False),
        wrapped=wrapped,
        expected=np.ascontiguousarray(expected_column, dtype=np.float32),
        confidence=confidence,
        period_px=params.period_px,
        cycle=params.cycle,
        window_succession=succession,
    )
    st = LazyStages()
    st.put("intensity", intensity)
    st.put("certainty", certainty)
    st.put("lit", lit)
    st.put("window_support", support_w)
    st.put("wrapped_phase", wrapped)
    st.put("amplitude", amplitude)
    st.put("fit_residual", residual)
    st.put("confidence", confidence)
    if carrier is not None:
        st.put("carrier", carrier[crop])
    if shift is not None:
        st.put("phase_change", shift)
        st.put("narrow_fit_residual", narrow_residual)
    st.put("phase_valid", valid)
    st.put("code", code)
    st.put("stripe_label", lab)
    st.put("stripe_code", lambda: _per_pixel(stripe_code.astype(np.int8), lab, -1))
    st.put("stripe_agreement", lambda: _per_pixel(agreement, lab, 0.0))
    st.put("position_raw", lambda: _per_pixel(raw_w, lab, -1))
    st.put("position", band.position_map)
    st.put("support", lambda: _per_pixel(support, lab, 0))
    if contested is not None:
        st.put("contested", lambda: _per_pixel(contested, lab, False))
    if uncertain is not None:
        st.put("uncertain_code", lambda: _per_pixel(uncertain, lab, False))
    if beside_shadow is not None:
        st.put("shadow_margin", beside_shadow)
    st.put("column", lambda: band.columns[0])

    def unwrapped():
        index = band.columns[1]
        return np.where(index >= 0, wrapped + np.float32(2 * np.pi) * index, np.float32(np.nan))

    st.put("unwrapped_phase", unwrapped)
    return band, st


def _pool_rows(crop: slice, height: int, params: DecoderParams, rig: Rig) -> slice:
    """``crop`` with the rows above and below it that the pooled code reads (``crop`` itself
    without ``pool_code``), within the ``height`` rows at hand."""
    k = code_pool_rows(params, rig)
    return slice(max(0, crop.start - k), min(height, crop.stop + k))


def flattened_fit_weights(certainty: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """The phase fit's sample weights where the albedo flattening multiplied the capture by
    ``gain`` ((H, W) float32 in [1, ALBEDO_MAX_GAIN]: the gain down the columns): ``certainty /
    gain`` (see ``_columns``; :func:`simbench.decode.phase.weighted_fit` takes them)."""
    return (certainty / gain).astype(np.float32, copy=False)


def _window_shares(weights, carrier, *, sigma_x_px: float, sigma_y_px: float) -> np.ndarray:
    """Each pixel's window's share of its weight on ``weights`` (:func:`window_share`), the window
    its own fit used: the nominal one, or its carrier bank entry's (``carrier`` > 0)."""
    share = window_share(weights, sigma_x_px=sigma_x_px, sigma_y_px=sigma_y_px)
    if carrier is not None:
        for k, (scale_x, scale_y) in enumerate(CARRIER_BANK, 1):
            mine = carrier == k
            if mine.any():
                own = window_share(weights, sigma_x_px=sigma_x_px * scale_x, sigma_y_px=sigma_y_px * scale_y)
                share = np.where(mine, own, share)
    return share


def _centroid_correction(phase, narrow, certainty, carrier, crop, fit, sx, t_cam) -> tuple:
    """The wide fit (whole band) and the narrow one (``crop``'s rows) with the window-centroid
    bias taken out (:attr:`DecoderParams.centroid_correction`), the fringe's rate read on the
    wide fit's phase; a carrier bank's pixels keep their phase (their carrier is another) but
    lend their steps to the rate (a phase's steps are the fringe's whatever carrier fitted it;
    whether their windows are whole is judged with the nominal window)."""
    fits = [(phase.wrapped, sx)]
    if narrow is not None:
        band = np.full(phase.wrapped.shape, np.nan, np.float32)
        band[crop] = narrow
        fits.append((band, sx * STABILITY_WINDOW_SCALE))
    bank = None if carrier is None else carrier != 0
    # the windows' centres as the fit weighed them (fit["certainty"]: the flattened prints' weights
    # where it has them), which are cut and which centred as the 0/1 certainty says
    weights = None if fit["certainty"] is certainty else fit["certainty"]
    out = centroid_corrected(fits, certainty, sigma_y_px=fit["sigma_y_px"], period_px=t_cam, keep=bank, weights=weights)
    return dataclasses.replace(phase, wrapped=out[0]), (out[1][crop] if narrow is not None else None)


_R = TypeVar("_R")


def apply_min_confidence(result: _R, min_confidence: float) -> _R:
    """``result`` - a :class:`DecodeResult` decoded with no threshold, or any depth result with
    ``depth_m``, ``valid`` and ``confidence`` (and optionally ``column_px``, ``stripe_index``),
    e.g. :class:`simbench.systems.SystemDepth` - with the valid pixels whose confidence is not
    at least ``min_confidence`` made holes, their confidence kept: for a DecodeResult the same
    bits :func:`decode` gives with that ``min_confidence`` (tests/test_decode.py), without
    decoding again."""
    conf = np.asarray(result.confidence, np.float32)
    with np.errstate(invalid="ignore"):
        doubtful = result.valid & ~(conf >= np.float32(min_confidence))
    changes = {
        "depth_m": np.where(doubtful, np.float32(np.nan), result.depth_m).astype(np.float32, copy=False),
        "valid": result.valid & ~doubtful,
        "confidence": conf,
    }
    if getattr(result, "column_px", None) is not None:
        changes["column_px"] = np.where(doubtful, np.float32(np.nan), result.column_px)
    if getattr(result, "stripe_index", None) is not None:
        changes["stripe_index"] = np.where(doubtful, np.int32(-1), result.stripe_index)
    return dataclasses.replace(result, **changes)


def phase_change(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| of two wrapped phases, wrapped to [0, pi] (float32, rad; NaN where either is)."""
    d = np.abs(np.asarray(a, np.float32) - np.asarray(b, np.float32))
    return np.minimum(d, np.float32(2 * np.pi) - d)


# A capture read in the wrong order - mirrored (or rotated 180 degrees), its red and green channels
# swapped, or both - still reads valid De Bruijn windows: about half its stripes decode, each to a
# wrong column a neighbour confirms (a new user's audit, 2026-11-28: 125-474 mm MAE, exit 0).  So
# each decode counts, over linked neighbouring stripes whose windows both read, the pairs whose
# windows succeed each other as the capture is; where that share is under ALTERNATIVES_BELOW,
# also as the capture would read swapped, mirrored and both (the windows looked up reversed or
# complemented, ~free).  A capture of the pattern reads best as it is: on the 509 recordings of a
# render cache of every target (2026-11-28, the paper's decoder) every capture of the pattern read
# >= 0.925 as it is, and a mirrored one reads 0.50 as it is and 1.00 mirrored.  The doubt needs
# the other reading to hold (>= MIN_WINDOW_SUCCESSION) and to beat the capture's own by a margin,
# so a capture whose codes are merely poor (a saturated board, a high window order) is never
# called mirrored.
ALTERNATIVES_BELOW = 0.9
MIN_WINDOW_SUCCESSION = 0.75
WINDOW_SUCCESSION_MARGIN = 0.2
# fewer pairs than this say nothing either way (a nearly dark capture)
MIN_WINDOW_PAIRS = 200
# Read in order but not as the pattern decoded with: a capture of another pattern of the same
# period - another window order or sequence - reads valid windows that succeed each other about
# half the time (orders 4 and 5 read as B(2,3): 0.48 of the pairs; the benchmark plane, both
# decoders), and the paper's decoder decodes 66-76 % of its pixels there, most of them wrong.  A
# capture of the pattern that decodes reads far more: on the quick run of every target, hard scenes
# included (2026-12-01, 344 decodes at 640x480 and 4 spp), every capture of which either decoder
# decoded over 3 % read >= 0.93 (the paper's decoder) and >= 0.976 (the colour-robust one), every
# reference 1.00; under MIN_AS_READ only boards of saturated primaries that neither decodes (<= 3 %:
# Table 1's pure red, green and blue, its paint cyan), whose codes their colour defeats - which
# the doubt names as its other cause.  At full resolution (2026-11-28, the paper's decoder, 509
# recordings) every capture of the pattern read >= 0.925.  A reference refused for it is one the
# coverage check would pass: in noise a reference plane reads whole or not at all (the benchmark's
# reference under Gaussian noise up to 0.3 of full scale and washed out to 0.1 of its contrast:
# >= 0.997 in succession wherever it decodes, under 200 linked pairs where it does not).
MIN_AS_READ = 0.8
_READINGS = ("with its red and green channels swapped", "mirrored (or rotated 180 degrees)", "mirrored and swapped")


@lru_cache(maxsize=16)
def _alternative_tables(order: int, sequence: tuple[int, ...] | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The window table looked up with each window's codes complemented (red and green swapped),
    reversed (read right to left) and both: a window's code is MSB first (``window_positions``)."""
    table = _window_table(order, sequence)
    codes = np.arange(table.size)
    rev = np.zeros_like(codes)
    for j in range(order):
        rev |= ((codes >> j) & 1) << (order - 1 - j)
    mask = (1 << order) - 1
    out = (table[codes ^ mask], table[rev], table[rev ^ mask])
    for t in out:
        t.setflags(write=False)
    return out


def _window_succession(
    positions: np.ndarray, stripe_code: np.ndarray, linked_prev: np.ndarray, *, params: DecoderParams
) -> tuple[int, int, int, int, int]:
    """:attr:`DecodeResult.window_succession` of one band (``positions``: the raw window
    positions of its stripes)."""
    linked = np.asarray(linked_prev, bool)
    w = np.asarray(positions)
    if w.size < 2:
        return (0, 0, 0, 0, 0)
    cycle = params.cycle
    both = linked[1:] & (w[1:] >= 0) & (w[:-1] >= 0)
    pairs = int(both.sum())
    as_read = int((both & (w[1:] == (w[:-1] + 1) % cycle)).sum())
    if not pairs or as_read >= ALTERNATIVES_BELOW * pairs:
        return (pairs, as_read, 0, 0, 0)
    counts = []
    for table, step in zip(_alternative_tables(params.order, params.sequence), (1, -1, -1)):
        a = window_positions_of_stripes(stripe_code, linked, order=params.order, table=table, cycle=cycle)
        ok = linked[1:] & (a[1:] >= 0) & (a[:-1] >= 0)
        counts.append(int((ok & (a[1:] == (a[:-1] + step) % cycle)).sum()))
    return (pairs, as_read, *counts)


def _checked_phase_method(method: Callable[..., PhaseResult], name: str) -> Callable[..., PhaseResult]:
    """A phase method registered from outside simbench, its result checked against the contract
    of :class:`simbench.decode.phase.PhaseResult` (an extender's audit, 2026-11-30: a method
    returning its phase in [0, 2 pi), as ``cv2.phase`` does, decoded 71 % of the pixels 39 mm off
    without a word; a wrong shape failed on an internal array's name)."""

    def checked(intensity: np.ndarray, **kw) -> PhaseResult:
        out = method(intensity, **kw)
        if not isinstance(out, PhaseResult):
            raise ValueError(f"phase method {name!r} returned {type(out).__name__}, not a PhaseResult")
        for field_name in ("wrapped", "amplitude", "residual", "support"):
            a = getattr(out, field_name)
            if not (isinstance(a, np.ndarray) and a.shape == intensity.shape and a.dtype == np.float32):
                got = f"{a.dtype} {a.shape}" if isinstance(a, np.ndarray) else type(a).__name__
                raise ValueError(
                    f"phase method {name!r}: its {field_name} must be float32 of the image's shape "
                    f"{intensity.shape}, got {got}"
                )
        with np.errstate(invalid="ignore"):
            outside = np.abs(out.wrapped) > np.float32(np.pi + 1e-4)
        if outside.any():
            raise ValueError(
                f"phase method {name!r}: its wrapped phase must lie in [-pi, pi) radians; "
                f"{int(outside.sum())} pixels lie outside (up to {float(np.nanmax(np.abs(out.wrapped))):.3g}): "
                "a phase in [0, 2 pi) or in degrees decodes to wrong columns"
            )
        return out

    return checked


def code_order_doubt(window_succession: tuple[int, ...], *, what: str = "capture") -> str:
    """Why a decode reads its pattern in the wrong order, from its
    :attr:`DecodeResult.window_succession`, or "" when it reads best as it is (or too few
    stripes to tell).  The paper's decoder has no such check (its results are not changed); the
    command line and :func:`simbench.depth` apply it, and :func:`decode_reference` refuses."""
    pairs, as_read, *others = (tuple(window_succession) + (0, 0, 0))[:5]
    if pairs < MIN_WINDOW_PAIRS:
        return ""
    best = max(others)
    if best < MIN_WINDOW_SUCCESSION * pairs or best - as_read < WINDOW_SUCCESSION_MARGIN * pairs:
        return ""
    ways = [name for name, n in zip(_READINGS, others) if n == best]
    return (
        f"the {what} reads as if {' or '.join(ways)}: {100 * best / pairs:.0f} % of {pairs} neighbouring "
        f"stripes read successive De Bruijn windows that way, {100 * as_read / pairs:.0f} % as it is - is the "
        "image mirrored or rotated 180 degrees, or are its red and green channels swapped (--channels)?"
    )


def code_succession_doubt(
    window_succession: tuple[int, ...], *, what: str = "capture", pattern_known: bool = False
) -> str:
    """Why a decode's stripes seem not to follow the pattern decoded with, from its
    :attr:`DecodeResult.window_succession`, or "": fewer than :data:`MIN_AS_READ` of its
    neighbouring stripes read successive De Bruijn windows, and no other reading
    (:func:`code_order_doubt`, which says more) explains it.  A doubt, not a proof: codes that the
    scene's colours defeat read poorly too, so the command line and :func:`simbench.depth` warn
    and keep the depth, and :func:`decode_reference` - a flat board, whose codes read whole -
    refuses.  ``pattern_known``: the capture's pattern is recorded (a recording folder), so only
    its colours are named as the cause."""
    pairs, as_read, *_ = (tuple(window_succession) + (0, 0, 0))[:5]
    if pairs < MIN_WINDOW_PAIRS or as_read >= MIN_AS_READ * pairs or code_order_doubt(window_succession):
        return ""
    said = (
        f"only {100 * as_read / pairs:.0f} % of {pairs} neighbouring stripes of the {what} read successive "
        "De Bruijn windows of the pattern decoded with (a capture of it that decodes: over 90 %)"
    )
    if pattern_known:
        return said + ": its colours defeat the stripe code (a code channel dark or saturated); its depth is doubtful"
    said += " - was it lit by another pattern, of another window order or sequence (--order/--sequence)?"
    if what.startswith("reference"):
        return said + " A flat board lit by the pattern reads it whole"
    return said + " Otherwise its colours defeat the stripe code; either way its depth is doubtful"


# per channel, the power along the rows in the fringe's band over that in the code's (relative to
# the camera's fringe frequency): a cosine of the period sits in the first, the code stripes (a
# square wave of at least twice the period, whose even harmonics vanish) in the second
_FRINGE_BAND = (0.8, 1.25)
_CODE_BAND = (0.3, 0.65)
# the fringe channel is doubted when its ratio is under _FRINGE_RATIO_LOW, another channel's is
# over _FRINGE_RATIO_MARGIN times it, and that channel holds over _FRINGE_POWER_MARGIN times the
# fringe channel's power in the fringe's band.  Measured on captures of every shipped scene (paper
# sensor, 4 spp) and of the audit's 130 perturbed ones (36 spp): the fringe channel's ratio 13.5
# (white step), 75 (blue board), 21 (red paint), 3.7 (the 20:1 chart, its other channels' 1.6), 2.0
# (the green board: dark in blue, whose red channel, 68, holds the fringe's crosstalk alone - at 0.14
# of blue's power); with red and blue swapped, or green and blue, the blue channel's is 2.0-4.5, the
# channel holding the fringe 6-17 times it at 1.7-48 times its power.  The margin was 3 until a new
# user's audit (2026-11-30) swapped the 20:1 chart's red and blue: its printed edges lift every
# channel's code band, the channel holding the fringe read only 2.4 times the blue one's ratio, and
# 871 pixels decoded > 5 mm wrong without a word.  Measured again on the 64 scenes of scenes/ (the
# quick run's 640x480, 4 spp) and the hard scenes at full resolution, R/B and G/B swapped: a capture
# in order whose fringe ratio is under _FRINGE_RATIO_LOW, with another channel over the power margin,
# reads at most 1.31 times its fringe channel's ratio there (the yellow-green paint), a swap at least
# 2.22 (the 20:1 chart, G/B, quick; the 3:1 chart 2.9-3.4, the deep stairs 3.7); 1.75 lies between
# (their geometric mean, 1.7, rounded up).  The 10 mm chart (1.0-1.1 either way) and swaps on boards
# that absorb a channel (power under the margin, or the fringe channel's ratio over 6) stay unseen:
# 34 of the 128 swaps.
_FRINGE_RATIO_LOW = 6.0
_FRINGE_RATIO_MARGIN = 1.75
_FRINGE_POWER_MARGIN = 1.2
_NAMES = "red", "green", "blue"


def channel_order_doubt(capture: np.ndarray, *, rig: Rig, params: DecoderParams, rows: int = 64) -> str:
    """Why ``capture``'s channels seem out of the pattern's order (a capture saved BGR as RGB, say),
    or "": over ``rows`` rows evenly spaced, each channel's power in the fringe's frequency band
    over its power in the code's; the pattern's fringe channel should lead (constants above).  A
    warning, not a refusal: a dark, noisy fringe channel beside a channel that carries the fringe by
    crosstalk could trip it.  A new user's audit: R and B swapped gave 2-9 % of the colour-robust
    decoder's pixels 0.1-0.7 m wrong at full confidence, without a word."""
    img = np.asarray(capture)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[1] < 8:
        return ""
    period = params.camera_period(rig)
    pick = np.unique(np.linspace(0, img.shape[0] - 1, min(rows, img.shape[0])).astype(int))
    lines = img[pick].astype(np.float64)  # (R, W, 3)
    lines -= lines.mean(axis=1, keepdims=True)
    spectrum = np.abs(np.fft.rfft(lines, axis=1)) ** 2
    freq = np.fft.rfftfreq(img.shape[1]) * period  # in fringe frequencies

    def power(band: tuple[float, float]) -> np.ndarray:
        return spectrum[:, (freq >= band[0]) & (freq <= band[1])].sum(axis=(0, 1))

    in_band = power(_FRINGE_BAND)
    ratio = in_band / np.maximum(power(_CODE_BAND), 1e-30)
    fringe = check_channels(params.pattern.channels)[2]
    other = max((c for c in range(3) if c != fringe), key=lambda c: ratio[c])
    if not (
        ratio[fringe] < _FRINGE_RATIO_LOW
        and ratio[other] > _FRINGE_RATIO_MARGIN * ratio[fringe]
        and in_band[other] > _FRINGE_POWER_MARGIN * in_band[fringe]
    ):
        return ""
    return (
        f"the fringe seems to be in the {_NAMES[other]} channel, not in the {_NAMES[fringe]} the pattern puts it in "
        f"(the fringe's frequency over the code's: {ratio[other]:.1f} there, {ratio[fringe]:.1f} in "
        f"{_NAMES[fringe]}): are the image's channels out of order (BGR saved as RGB), or the pattern's (--channels)? "
        "Depths decoded so may be a whole stripe order off"
    )


# The fringe's period measured along the rows against the rig's prediction (fringe_period_doubt): a
# capture whose strongest repetition lies beyond this ratio either way, with no more than
# FRINGE_NEAR_SHARE of that peak's power anywhere within it, is doubted.  Measured (2026-11-30, every
# library scene at 4 spp, 320x240): the strongest repetition within 0.86-1.17 of the prediction but
# the 10 mm chart's (2.1: its squares, a period wide, repeat every two), whose fringe still holds 0.65
# of that peak's power within the ratio; a projector focal length on another pixel grid (a DLP4500
# calibrated on its 912-px native grid, the pattern drawn on 1824) is off 2x, with 0.007 there.
FRINGE_PERIOD_TOLERANCE = 1.35
FRINGE_NEAR_SHARE = 0.1
# ... only where the peak stands out of its band this many times the band's median power (a capture
# with no fringe to speak of - dark, unlit - is left to the other checks)
FRINGE_PEAK_PROMINENCE = 10.0


def _row_spectrum(image: np.ndarray, rows: int) -> tuple[np.ndarray, np.ndarray]:
    """(frequency in cycles per camera px, power) along ``image``'s rows: ``rows`` rows evenly
    spaced, the channels summed (the paper's pattern's R + G + B is twice its fringe, whatever the
    code), each row's mean removed and a Hann window applied, the rows' power summed."""
    img = np.asarray(image, dtype=np.float64)
    if img.ndim == 3:
        img = img.sum(axis=2)
    h, w = img.shape
    pick = np.unique(np.linspace(0, h - 1, min(rows, h)).astype(int))
    lines = img[pick]
    lines = np.nan_to_num(lines - np.nanmean(lines, axis=1, keepdims=True))
    return np.fft.rfftfreq(w), (np.abs(np.fft.rfft(lines * np.hanning(w), axis=1)) ** 2).sum(axis=0)


def fringe_period_px(image: np.ndarray, *, period_px: float, rows: int = 64) -> float:
    """The period (camera px) at which ``image``'s light repeats along its rows most strongly
    (:func:`_row_spectrum`), within a factor of 4 of ``period_px`` either way; NaN where no peak
    stands out (:data:`FRINGE_PEAK_PROMINENCE`).  The peak is refined by a parabola through its log
    power."""
    if np.ndim(image) < 2 or np.shape(image)[1] < 16:
        return math.nan
    return _peak_period(*_row_spectrum(image, rows), period_px, width=np.shape(image)[1])


def _peak_period(freq: np.ndarray, power: np.ndarray, period_px: float, *, width: int) -> float:
    """:func:`fringe_period_px` of a row spectrum (:func:`_row_spectrum`) of rows ``width`` px long."""
    w = width
    f0 = 1.0 / period_px
    band = np.flatnonzero((freq >= max(f0 / 4.0, 3.0 / w)) & (freq <= min(4.0 * f0, 0.5)))
    if band.size < 5:
        return math.nan
    k = band[np.argmax(power[band])]
    if not power[k] > FRINGE_PEAK_PROMINENCE * np.median(power[band]):
        return math.nan
    f = freq[k]
    if 0 < k < len(power) - 1 and min(power[k - 1], power[k + 1]) > 0:
        a, b, c = np.log(power[k - 1 : k + 2])
        if a - 2 * b + c < 0:
            f += 0.5 * (a - c) / (a - 2 * b + c) * (freq[1] - freq[0])
    return float(1.0 / f)


def fringe_period_doubt(image: np.ndarray, *, rig: Rig, params: DecoderParams, what: str = "capture") -> str:
    """Why ``image``'s fringe seems not to repeat at the period the rig predicts
    (:meth:`DecoderParams.camera_period`: the pattern's period times the camera's focal length over
    the projector's), or "": its strongest repetition (:func:`fringe_period_px`) off by more than
    :data:`FRINGE_PERIOD_TOLERANCE` either way, with under :data:`FRINGE_NEAR_SHARE` of its power
    within that ratio of the prediction (a print that repeats more strongly than the fringe leaves
    the fringe's peak in place).  The decoder demodulates at the predicted period, so such a capture
    decodes little or wrongly, and the channel-order and encoding checks, which read the spectrum
    there, would blame the wrong thing (a lab user's audit, 2026-11-30: a projector written on its
    native 912-px grid was told its capture's channels were out of order, then its reference decoded
    0 %)."""
    if np.ndim(image) < 2 or np.shape(image)[1] < 16:
        return ""
    predicted = params.camera_period(rig)
    freq, power = _row_spectrum(image, 64)
    measured = _peak_period(freq, power, predicted, width=np.shape(image)[1])
    if not np.isfinite(measured) or 1.0 / FRINGE_PERIOD_TOLERANCE <= measured / predicted <= FRINGE_PERIOD_TOLERANCE:
        return ""
    near = (freq >= 1.0 / (predicted * FRINGE_PERIOD_TOLERANCE)) & (freq <= FRINGE_PERIOD_TOLERANCE / predicted)
    peak = power[np.argmin(np.abs(freq - 1.0 / measured))]
    if near.any() and power[near].max() >= FRINGE_NEAR_SHARE * peak:
        return ""
    if params.camera_period_px is not None:
        # (a pattern designer's audit, 2026-11-30: the override was told as the rig's prediction, beside a
        # product of the rig's numbers that was not it)
        rig_period = dataclasses.replace(params, camera_period_px=None).camera_period(rig)
        return (
            f"the {what}'s fringe repeats every {measured:.1f} camera px along the rows, but the decoder's "
            f"camera_period_px (--decoder) is {predicted:.1f} (the rig predicts {rig_period:.1f}: the pattern's "
            f"{params.period_px:g}-px period x the camera's focal length {rig.camera.focal_px:g} / the projector's "
            f"{rig.projector.focal_px:g}). Depths decoded so are missing or wrong"
        )
    return (
        f"the {what}'s fringe repeats every {measured:.1f} camera px along the rows, but the rig predicts "
        f"{predicted:.1f} (the pattern's {params.period_px:g}-px period x the camera's focal length "
        f"{rig.camera.focal_px:g} / the projector's {rig.projector.focal_px:g}): is the projector's focal length (and "
        "size, principal point) in the pixels of the pattern image it projects - a projector calibrated on another "
        "grid (a DLP4500's 912-px native one for an 1824-px pattern) is off by their ratio - or the pattern's period "
        "(--period)? Depths decoded so are missing or wrong"
    )


# A capture clipped in a channel on more than this share of its pixels decodes under 1 - this
# share of them (a clipped sample is skipped), and the warning for a decode that found almost
# nothing (simbench.systems.files.NOTHING_DECODED_SHARE, 1 %) names the saturation: no clipping
# doubt about "the phase beside a clipped run" before it (a new user's audit, 2026-11-29)
CAPTURE_CLIPPED_UNDECODABLE = 0.99


def capture_warnings(capture: np.ndarray, *, rig: Rig, params: DecoderParams, encoding: str = "linear") -> list[str]:
    """What `simbench decode` and :func:`simbench.depth` warn of before decoding ``capture``: the
    pattern on the rig (:func:`simbench.decode.params.pattern_on_rig_warnings`), the capture's
    channel order (:func:`channel_order_doubt`), its fringe's linearity
    (:func:`simbench.decode.registration.encoding_doubt`; ``encoding``: how it was read,
    :data:`simbench.io.ENCODINGS`), JPEG compression and clipping
    (:mod:`simbench.decode.integrity`)."""
    from simbench.decode.params import pattern_on_rig_warnings

    integrity = _integrity_warnings(capture, params, "capture", refused_clipped=CAPTURE_CLIPPED_UNDECODABLE)
    period = fringe_period_doubt(capture, rig=rig, params=params)
    if period or _unreadable_period(rig, params):
        # the channel-order and encoding checks read the spectrum at the predicted period: not where
        # the fringe does not repeat there, nor where it is too fine to read (pattern_on_rig_warnings
        # says so; a pattern designer's audit, 2026-11-30: a 3.1-px fringe was said to be in the green
        # channel)
        return [*pattern_on_rig_warnings(rig, params), *(t for t in (period, *integrity) if t)]
    told = [channel_order_doubt(capture, rig=rig, params=params), *integrity]
    told.append(
        encoding_doubt(
            fringe_harmonic_ratio(
                capture, order=list(check_channels(params.channels)), period_px=params.camera_period(rig)
            ),
            encoding=encoding,
        )
    )
    return [*pattern_on_rig_warnings(rig, params), *(t for t in told if t)]


def _unreadable_period(rig: Rig, params: DecoderParams) -> bool:
    return params.camera_period(rig) < MIN_CAMERA_PERIOD_PX


def reference_warnings(
    reference: np.ndarray, *, rig: Rig, params: DecoderParams, encoding: str = "linear"
) -> list[str]:
    """What `simbench decode` warns of a reference-plane capture before decoding with it: its
    fringe's linearity (:func:`simbench.decode.registration.encoding_doubt`; the plane faces the
    rig, so its fringe runs at the period demodulated at, and a camera's encoding shows there
    whatever the scene), JPEG compression and clipping (:mod:`simbench.decode.integrity`)."""
    period = fringe_period_doubt(reference, rig=rig, params=params, what="reference capture")
    if period or _unreadable_period(rig, params):
        told = [period]
    else:
        ratio = fringe_harmonic_ratio(
            reference, order=list(check_channels(params.channels)), period_px=params.camera_period(rig)
        )
        told = [encoding_doubt(ratio, what="reference capture", encoding=encoding)]
    # a reference clipped over more than 1 - min_reference_coverage of it is refused (a clipped
    # sample is skipped, and a window under half certain gives no phase), and the refusal says so
    # (decode_reference): no warning line before that error's
    told += _integrity_warnings(
        reference, params, "reference capture", refused_clipped=1.0 - params.min_reference_coverage
    )
    return [t for t in told if t]


def _integrity_warnings(
    image: np.ndarray, params: DecoderParams, what: str, *, refused_clipped: float = np.inf
) -> list[str]:
    """:mod:`simbench.decode.integrity`'s doubts of ``image`` (JPEG blocks, clipped pixels); no
    clipping doubt beyond ``refused_clipped`` of the pixels."""
    clipped = clipped_share(image, saturation_level=params.saturation_level)
    return [
        compression_doubt(block_artifacts(image), what=what),
        clipping_doubt(clipped, what=what) if clipped <= refused_clipped else "",
    ]


def registration_warning(
    capture: np.ndarray,
    result: DecodeResult,
    *,
    rig: Rig,
    params: DecoderParams,
    reference: ReferenceMap | None = None,
) -> str:
    """What `simbench decode` and :func:`simbench.depth` warn of a capture whose colour channels
    seem misregistered (:func:`simbench.decode.registration.registration_doubt`), or "": from
    ``result.registration_px`` where the decode measured it (``params.registration_doubt``),
    else measured here (the paper's decoder); against ``reference``'s registration in reference
    mode (the decode's own reference: a map without one, or none, is compared with 0, as
    :func:`decode` does)."""
    change = result.registration_px
    if not isinstance(reference, ReferenceMap):
        reference = None
    against_reference = params.mode == "reference" and reference is not None and reference.registration_px is not None
    if change is None:
        image = _ideal_image(_check_capture(capture, rig.camera.size_hw), rig)
        t_cam = params.camera_period(rig)
        own = registration_px(image, order=list(check_channels(params.channels)), period_px=t_cam)
        change = registration_change(own, reference.registration_px if against_reference else None, period_px=t_cam)
    return registration_doubt(change, against_reference=against_reference)


def without_depth(result: _R) -> _R:
    """``result`` (a :class:`DecodeResult`, or any result with ``depth_m``, ``valid``,
    ``confidence`` and optionally ``column_px`` and ``stripe_index``) with nothing decoded: NaN
    depth, no valid pixel, confidence 0 - for a capture :func:`code_order_doubt` refuses."""
    out = {
        "depth_m": np.full(result.depth_m.shape, np.nan, np.float32),
        "valid": np.zeros(result.valid.shape, bool),
        "confidence": np.zeros(result.confidence.shape, np.float32),
    }
    if getattr(result, "column_px", None) is not None:
        out["column_px"] = np.full(result.column_px.shape, np.nan, np.float32)
    if getattr(result, "stripe_index", None) is not None:
        out["stripe_index"] = np.full(result.stripe_index.shape, -1, np.int32)
    return dataclasses.replace(result, **out)


@lru_cache(maxsize=16)
def _window_table(order: int, sequence: tuple[int, ...] | None) -> np.ndarray:
    t = window_positions(code_sequence(sequence, order=order), order=order)
    t.setflags(write=False)
    return t


@lru_cache(maxsize=16)
def _plane_lit_share(rig: Rig, z_m: float) -> float:
    """The share of the camera's view (every 8th pixel each way) that the projector's image
    reaches on a fronto-parallel plane at ``z_m``."""
    from simbench.rig import project_to_projector, pixel_rays

    rays = pixel_rays(rig.camera)[::8, ::8]
    u, v, z = project_to_projector(rays * z_m, rig)
    prj = rig.projector
    with np.errstate(invalid="ignore"):
        inside = (z > 0) & (u >= -0.5) & (u < prj.width_px - 0.5) & (v >= -0.5) & (v < prj.height_px - 0.5)
    return float(inside.mean())


@lru_cache(maxsize=16)
def _plane_columns(rig: Rig, z_m: float) -> np.ndarray:
    col = projector_column_at_depth(z_m, rig).astype(np.float32)
    col.setflags(write=False)
    return col


def _merge_stages(parts: list[LazyStages]) -> LazyStages:
    """Stack the bands' stage images; stripe labels are renumbered to stay unique."""
    if len(parts) == 1:
        return parts[0]
    merged = LazyStages()

    def stack(name):
        arrays = [p[name] for p in parts]
        if name == "stripe_label":
            out, offset = [], 0
            for a in arrays:
                out.append(np.where(a >= 0, a + offset, -1))
                offset += int(a.max()) + 1 if a.size and a.max() >= 0 else 0
            arrays = out
        return np.concatenate(arrays, axis=0)

    for name in parts[0]:
        merged.put(name, lambda name=name: stack(name))
    return merged


def _unmixing(mixing: np.ndarray | None, params: DecoderParams) -> np.ndarray | None:
    """The inverse coupling matrix in the stages' channel order (R = code 1, G = code 0,
    B = fringe), or None when ``params.unmix`` is off."""
    if not params.unmix:
        return None
    if mixing is None:
        raise ValueError(
            "unmix=True needs the reference plane's calibration captures under each primary (decode_reference(..., "
            "primaries=, dark=))"
        )
    order = list(check_channels(params.channels))
    inv = np.linalg.inv(np.asarray(mixing, np.float64))
    return inv[np.ix_(order, order)]


def _calibration_region(primaries, dark: np.ndarray) -> np.ndarray:
    """Pixels where every primary lifts its own channel to at least a quarter of its 95th
    percentile over the dark frame: the lit reference plane, away from shadows and borders."""
    d = np.asarray(dark, np.float32)
    region = np.ones(d.shape[:2], bool)
    for p, img in enumerate(primaries):
        lift = np.asarray(img, np.float32)[..., p] - d[..., p]
        region &= lift >= 0.25 * np.percentile(lift, 95)
    return region


def decode_reference(
    reference: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams,
    primaries: Sequence[np.ndarray] | None = None,
    dark: np.ndarray | None = None,
) -> ReferenceMap:
    """Decode a reference-plane capture (a plane at ``params.z0_m``) into its column map.

    Done once per calibration; :func:`decode` then matches captures against it.  With
    ``primaries`` (the plane under the projector's red, green and blue primary at full drive)
    and ``dark`` (under a black frame) the coupling matrix is measured too
    (:func:`simbench.decode.color.mixing_matrix`), which ``params.unmix`` needs.

    Raises
    ------
    ValueError
        When less than ``params.min_reference_coverage`` of the pixels decode (a black,
        saturated or unrelated image is not a reference), when its stripes do not read in the
        pattern's order (:func:`code_order_doubt`: a mirrored or red/green-swapped reference
        passes the coverage and Z0 checks and makes every depth wrong) or follow it too poorly to
        be of the pattern decoded with (:func:`code_succession_doubt`), or calibration captures
        are missing, mis-sized or unusable.
    """
    image = _ideal_image(_check_capture(reference, rig.camera.size_hw), rig)
    mixing = None
    if primaries is not None or dark is not None:
        if primaries is None or dark is None or len(primaries) != 3:
            raise ValueError("the coupling-matrix calibration needs three primary captures and a dark frame")
        cal = [_to_float(_ideal_image(_check_capture(c, rig.camera.size_hw), rig)) for c in (*primaries, dark)]
        mixing = mixing_matrix(cal[:3], cal[3], region=_calibration_region(cal[:3], cal[3]))
    unmixing = _unmixing(mixing, params)
    predicted = _plane_columns(rig, float(params.z0_m))

    def band(img, order, rows, crop):
        stripes = _columns(img, order, predicted[rows], rig=rig, params=params, crop=crop, unmixing=unmixing)[0]
        return stripes.columns[0], stripes.window_succession

    parts = run_bands(band, image, params, rig)
    column = np.concatenate([c for c, _ in parts], axis=0)
    succession = tuple(map(sum, zip(*(w for _, w in parts))))
    doubt = code_order_doubt(succession, what="reference capture") or code_succession_doubt(
        succession, what="reference capture"
    )
    if doubt:
        raise ValueError(doubt)
    coverage = float(np.isfinite(column).mean())
    # of the view the projector lights on a plane at Z0 (a new user's audit: a lens-shifted
    # projector lit 43 % of it, all of which decoded, and was told to check its reference)
    lit = _plane_lit_share(rig, float(params.z0_m))
    if lit < 0.01:
        raise ValueError(
            f"rig {rig.name!r}: its projector lights {100 * lit:.1f} % of the camera's view on a plane at Z0 = "
            f"{params.z0_m:g} m - no reference plane there can be decoded: check the rig's pose and Z0"
        )
    if coverage < params.min_reference_coverage * lit:
        clipped = clipped_share(image, saturation_level=params.saturation_level)
        of_lit = f" of the {100 * lit:.1f} % this rig's projector lights" if lit < 0.995 else ""
        raise ValueError(
            f"the reference capture decodes at only {100 * coverage:.1f} % of its pixels (at least "
            f"{100 * params.min_reference_coverage:.0f} %{of_lit} expected of a plane at Z0 = {params.z0_m:g} m): "
            "is it the reference-plane capture, taken with this pattern and rig?"
            + (f" ({100 * clipped:.0f} % of it is clipped: expose shorter)" if clipped >= CLIPPED_SHARE_WARN else "")
        )
    expected = np.where(np.isfinite(column), column, predicted)
    inverse = inverse_column_table(column, projector_width=rig.projector.width_px)
    registration = registration_px(
        image, order=list(check_channels(params.channels)), period_px=params.camera_period(rig)
    )
    return ReferenceMap(
        column_px=column,
        expected_px=expected,
        inverse=inverse,
        z0_m=params.z0_m,
        mixing=mixing,
        registration_px=registration,
    )


# How far a decoded reference plane may lie from Z0, relative (assumption: a lab places its
# reference board within 1 % of Z0 - simbench.sim.scene.Placement's +-10 mm at 1 m - and a
# calibrated rig adds well under 0.5 %; a reference of another rig lies far outside: a 0.120 m
# baseline read as 0.093 m puts the plane ~29 % off).
REFERENCE_Z0_TOLERANCE = 0.03
# Over this (but within the tolerance) the decode warns: reference-mode depths carry the
# reference's depth error in proportion (Eq. 14: 1/Z = 1/Z0 + d/(f b)), 0.5 % = 5 mm at 1 m,
# ten times the decoder's own error on a board (assumption: a rig from `simbench calibrate`
# triangulates a plane within ~0.1 %: its focal lengths within 0.03 %, baseline within 0.01 mm,
# results/table3.md).
REFERENCE_Z0_WARNING = 0.005
# the reference check reads every 4th row and column (~77 k pixels of a 1280x960 reference, a
# median no different at that tolerance; the whole map took ~0.35 s of every command-line decode)
REFERENCE_CHECK_STRIDE = 4
# The percentiles of the plane's triangulated depth that must lie within the tolerances too (its
# tilt and bend across the image): 2 % of the pixels at each end may be a border's or a defect's.
REFERENCE_EXTENT_PERCENTILES = (2.0, 98.0)


def reference_plane_extent(reference: ReferenceMap, rig: Rig) -> tuple[float, float, float]:
    """Where a decoded reference plane lies relative to Z0 by triangulation with ``rig``, across
    the image: ``(Z - Z0) / Z0`` at the :data:`REFERENCE_EXTENT_PERCENTILES` and the median of the
    triangulated depth Z over its decoded pixels (low, median, high), as
    :func:`reference_plane_offset` reads them; NaN when nothing decoded, inf (all three) when most
    rays meet their columns behind the camera.

    The median alone cannot see a rig whose camera focal length or distortion is off: triangulation
    then tilts and bends the plane about its centre (a new user's audit, 2026-11-30: the focal length
    3.8 % off put the plane's edges -9.5 % and +11.6 % off at a median within 0.01 %, and the chart
    decoded at 54 mm MAE, exit 0, without a word; 1 % off already gives -2.8 / +2.9 %, where the
    true rig gives +-0.15 % and the rig `simbench calibrate` estimates -0.16 / +0.17 %)."""
    z0 = float(reference.z0_m)
    s = REFERENCE_CHECK_STRIDE
    col = np.asarray(reference.column_px)[::s, ::s]
    rows, cols = np.nonzero(np.isfinite(col))
    if rows.size == 0:
        return (float("nan"),) * 3
    z = triangulate_columns(col[rows, cols], rig, rows=rows * s, cols=cols * s)
    ok = np.isfinite(z) & (z > 0)
    if 2 * int(ok.sum()) < z.size:
        # most rays meet their columns behind the camera or not at all (a projector on the other
        # side): no plane in front of this rig
        return (float("inf"),) * 3
    lo, hi = REFERENCE_EXTENT_PERCENTILES
    p_lo, p_hi = np.percentile(z[ok], [lo, hi])
    return float(p_lo) / z0 - 1.0, float(np.median(z[ok])) / z0 - 1.0, float(p_hi) / z0 - 1.0


def reference_plane_offset(reference: ReferenceMap, rig: Rig) -> float:
    """Where a decoded reference plane lies relative to Z0 by triangulation with ``rig``:
    ``(Z - Z0) / Z0`` of the median triangulated depth Z over its decoded pixels (every
    :data:`REFERENCE_CHECK_STRIDE`-th row and column; :func:`simbench.rig.triangulate_columns`,
    exact - a first-order form used before read 1.168 m for a plane at 1.200 m); NaN when
    nothing decoded.

    Reference mode matches captures against the reference and so cannot itself tell a
    reference of another rig, or a wrong Z0: depths then come out wrong everywhere, without a
    word.  Triangulating the reference with the rig can (:data:`REFERENCE_Z0_TOLERANCE`,
    :data:`REFERENCE_Z0_WARNING`).
    """
    return reference_plane_extent(reference, rig)[1]


def decode(
    capture: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams = DecoderParams(),
    reference: ReferenceMap | np.ndarray | None = None,
) -> DecodeResult:
    """Decode one capture into depth (paper Sec. 5).

    Rows are processed in bands on ``params.threads`` threads (each with a halo of the rows its
    2-D windows read: :func:`simbench.decode.bands.row_bands`); the result does not depend on the
    number of threads.

    Parameters
    ----------
    capture : ndarray, shape (H, W, 3), uint8/uint16/float
        RGB capture of the scene under the pattern; (H, W) must match ``rig.camera``.
    rig : Rig
    params : DecoderParams
    reference : ReferenceMap or ndarray, optional
        The reference-plane capture (or its decoded map, to decode many captures against one
        reference); required in ``reference`` mode, and with ``params.unmix`` (for its
        coupling matrix) in either mode.

    Returns
    -------
    DecodeResult
        Never raises on a legal image: what cannot be decoded is NaN in ``depth_m`` and False
        in ``valid``.
    """
    check_stripe_baseline(rig)
    with stage("input check and undistortion"):
        image = _ideal_image(_check_capture(capture, rig.camera.size_hw), rig)
    h, w = image.shape[:2]
    zmin, zmax = params.depth_range_m
    ref = None
    if params.mode == "reference" and reference is None:
        raise ValueError("reference mode needs the reference-plane capture (or use mode='calibrated')")
    if params.unmix and not isinstance(reference, ReferenceMap):
        raise ValueError(
            "unmix=True needs the decoded reference (decode_reference with its calibration captures under each primary)"
        )
    if reference is not None and (params.mode == "reference" or params.unmix):
        ref = reference if isinstance(reference, ReferenceMap) else decode_reference(reference, rig=rig, params=params)
        if ref.column_px.shape != (h, w):
            raise ValueError(f"reference map shape {ref.column_px.shape} does not match the capture {(h, w)}")
    unmixing = _unmixing(ref.mixing if ref is not None else None, params)
    if params.mode == "reference":
        expected = ref.expected_px
    else:
        ref = None  # calibrated mode uses the reference for its coupling matrix only
        expected = _plane_columns(rig, 2.0 / (1.0 / zmin + 1.0 / zmax))
    rig_values = triangulation_values(rig)
    distorted, newton_steps, refine_steps = triangulation_steps(rig)
    depth_out = np.empty((h, w), np.float32)
    valid_out = np.empty((h, w), bool)
    conf_out = np.empty((h, w), np.float32)
    col_out = np.empty((h, w), np.float32)
    index_out = np.empty((h, w), np.int32)
    inv_fb = reference_inverse_fb(rig)
    # the crease and edge terms' kappa over a bias in projector px: kappa T / (2 pi bias), the
    # stability term's scale
    bias_kappa_px = np.float32(STABILITY_KAPPA_RAD * params.period_px / (2.0 * np.pi))
    if params.crease_doubt:
        crease_px = int(round(CREASE_SCALE_PERIODS * params.camera_period(rig)))
        at = dict(rows=np.array([h // 2]), cols=np.array([w // 2]))
        depth_sign = float(np.sign(np.diff([projector_column_at_depth(z, rig, **at)[0] for z in (zmin, zmax)])[0]))

    succession = []  # (pairs, successive) per band (list.append is atomic across the band threads)

    def band(img, order, rows, crop):
        stripes, stages = _columns(img, order, expected[rows], rig=rig, params=params, crop=crop, unmixing=unmixing)
        succession.append(stripes.window_succession)
        # paper Eq. 14-15: a column the reference row never shows (near the image's ends, for
        # surfaces off the reference depth) cannot be matched: it is triangulated with the rig
        how = "reference matching" if ref is not None else "triangulation"
        with stage(f"column, depth, output (Eq. 14-15, {how})"):
            _kernels.decode_tail(
                stripes.labels,
                stripes.position,
                stripes.wrapped,
                stripes.expected,
                stripes.confidence,
                t=params.period_px,
                cycle=params.cycle,
                row0=rows.start,
                table=ref.inverse[rows] if ref is not None else None,
                inv_z0=1.0 / ref.z0_m if ref is not None else 0.0,
                inv_fb=inv_fb,
                rig_values=rig_values,
                distorted=distorted,
                newton_steps=newton_steps,
                refine_steps=refine_steps,
                zmin=zmin,
                zmax=zmax,
                depth_out=depth_out[rows],
                valid_out=valid_out[rows],
                conf_out=conf_out[rows],
                col_out=col_out[rows],
                index_out=index_out[rows],
            )
        if ref is not None:
            stages.put("reference_x", lambda: match_reference(stripes.columns[0], ref.inverse[rows]))
            stages.put(
                "triangulated",
                lambda st: np.isnan(st["reference_x"]) & np.isfinite(stripes.columns[0]),
                derived=True,
            )
        return stages

    parts = run_bands(band, image, params, rig)
    stages = _merge_stages(parts)
    max_step_px = np.float32(params.edge_step_px(rig))
    if params.crease_doubt:
        # after the bands: the break of the column map's slope is averaged down the crease, over
        # rows of neighbouring bands
        with stage("crease doubt"):
            bias = np.empty((h, w), np.float32)
            # conf = fmin(conf, kappa / bias) where valid, in the kernel's pass
            trusted = crease_trusted(valid_out, scale_px=crease_px)
            _kernels.crease_bias(
                col_out,
                crease_px,
                np.float32(-depth_sign * CREASE_BIAS_RATIO),
                max_step_px,
                crease_px,
                bias,
                trusted=trusted,
                cap=(bias_kappa_px, valid_out, conf_out),
            )
            # raised at a fold's apex, where the error's share of the map's bend is larger
            t_cam = params.camera_period(rig)
            apex = crease_apex_bias(
                bias,
                col_out,
                scale_px=crease_px,
                depth_sign=depth_sign,
                peak_px=max(1, int(round(CREASE_PEAK_PERIODS * t_cam))),
                apex_px=max(1, int(round(CREASE_APEX_PERIODS * t_cam))),
                apex_factor=CREASE_APEX_SHARE / CREASE_BIAS_RATIO,
                lobe_share=CREASE_LOBE_SHARE,
                min_px=CREASE_APEX_MIN_PX,
            )
            if apex is not bias:
                raised = valid_out & (apex > bias)
                np.minimum(conf_out, bias_kappa_px / np.maximum(apex, np.float32(1e-30)), out=conf_out, where=raised)
                bias = apex
        stages.put("crease_bias", bias)
    if params.edge_doubt:
        # after the bands too: the bend is read along whole rows of the final column map
        with stage("edge bend"):
            t_cam = params.camera_period(rig)
            bend = np.empty((h, w), np.float32)
            sigma_x = params.sigma_periods * t_cam
            fit_px = int(round(EDGE_BEND_FIT_PERIODS * t_cam))
            _kernels.edge_bend(
                col_out,
                int(np.ceil(EDGE_BEND_REACH_SIGMAS * sigma_x)),
                fit_px,
                max_step_px,
                bend,
                # down the columns too: the window reaches across an edge along the rows
                reach_y=int(np.ceil(EDGE_BEND_REACH_SIGMAS * sigma_x * params.sigma_y_ratio)),
                fit_y=fit_px,
                cap=(bias_kappa_px, valid_out, conf_out),
            )
        stages.put("edge_bend", bend)
    registration = None
    if params.registration_doubt:
        with stage("colour registration"):
            t_cam = params.camera_period(rig)
            own = registration_px(image, order=list(check_channels(params.channels)), period_px=t_cam)
            against = ref.registration_px if ref is not None else None
            registration = registration_change(own, against, period_px=t_cam)
            cap = registration_cap(registration, period_px=t_cam)
            if cap is not None:
                np.minimum(conf_out, np.float32(cap), out=conf_out, where=valid_out)
    if params.min_confidence > 0.0:
        with stage("operating point (min_confidence)"):
            doubtful = valid_out & (conf_out < np.float32(params.min_confidence))
            depth_out[doubtful] = np.nan
            col_out[doubtful] = np.nan
            index_out[doubtful] = -1
            valid_out &= ~doubtful
    return DecodeResult(
        depth_m=depth_out,
        valid=valid_out,
        confidence=conf_out,
        column_px=col_out,
        stripe_index=index_out,
        stages=stages,
        window_succession=tuple(map(sum, zip(*succession))) if succession else (0, 0, 0, 0, 0),
        registration_px=registration,
    )
