"""What the camera records from the rendered radiance.

Two camera steps: the *minimal* one (exposure, shot and read noise, full-well clipping,
quantisation), :func:`simple_camera`, and the physical one, :func:`emva_camera` (EMVA 1288 with
a Bayer colour filter array and OpenCV demosaicing).  Their parameters and the rest of the
physics (crosstalk, projector, lenses, ambient light) are configured by
:class:`simbench.sim.sensor.SensorModel` and chained by :func:`simbench.sim.capture.record`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from simbench import native, validate
from simbench.io import ADC_BITS
from simbench.seeds import RngLike

if TYPE_CHECKING:
    from simbench.sim.sensor import PhysicalCamera

__all__ = [
    "SimpleCamera",
    "simple_camera",
    "CFA_PATTERNS",
    "DEMOSAIC_METHODS",
    "bayer_mosaic",
    "fixed_pattern",
    "demosaic",
    "emva_camera",
    "photon_transfer",
]


# Physical bounds of a camera's numbers, shared by both camera models (each far outside any
# camera sold, inside what the model means; simbench.sim.sensor.PhysicalCamera argues them):
# full well at most 1e7 e- (large-pixel CCDs hold ~1 Me-), temporal and fixed-pattern noise at
# most 1e4 e-, exposure at most an hour, pixels at least half a micrometre (the smallest made
# are ~0.56 um)
MAX_FULL_WELL_E = 1e7
MAX_NOISE_E = 1e4
MAX_EXPOSURE_S = 3600.0
MIN_PIXEL_PITCH_UM = 0.5


@dataclass(frozen=True)
class SimpleCamera:
    """Parameters of the minimal camera step.

    Attributes
    ----------
    exposure : float
        Fraction of full scale reached per unit of rendered radiance (exposure time, aperture
        and gain folded together).
    full_well_e : float
        Electrons at full scale; sets the shot-noise level.
    read_noise_e : float
        Temporal dark noise, electrons RMS.
    bits : int
        ADC bit depth of the recorded image.
    noise : bool
        False gives the expected value, clipped and quantised (the 'ideal' camera).
    """

    exposure: float
    full_well_e: float
    read_noise_e: float
    bits: int = 8
    noise: bool = True

    def __post_init__(self) -> None:
        v = validate
        values = {
            "exposure": v.number(self.exposure, "exposure", lo=0.0, lo_open=True),
            # the physical camera's bounds (an audit: full_well_e = 1e30 and read_noise_e = 1e25 were
            # taken here, refused by the emva model); ``exposure`` is a ratio, not a time: unbounded
            "full_well_e": v.number(self.full_well_e, "full_well_e", lo=0.0, lo_open=True, hi=MAX_FULL_WELL_E),
            "read_noise_e": v.number(self.read_noise_e, "read_noise_e", lo=0.0, hi=MAX_NOISE_E),
            "bits": v.choice(v.integer(self.bits, "bits"), "bits", ADC_BITS),
            "noise": v.boolean(self.noise, "noise"),
        }
        for name, value in values.items():
            object.__setattr__(self, name, value)

    @property
    def max_dn(self) -> int:
        return (1 << self.bits) - 1


def simple_camera(radiance: np.ndarray, *, camera: SimpleCamera, rng: RngLike = None) -> np.ndarray:
    """Radiance -> recorded image: exposure, Poisson shot noise, Gaussian read noise,
    full-well clipping and ADC quantisation.

    Parameters
    ----------
    radiance : ndarray, shape (H, W, 3), float32
        Linear radiance from :func:`simbench.sim.render.render_radiance`.
    camera : SimpleCamera
    rng : numpy.random.Generator | int | None
        Noise seed; the same seed gives the same image.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8 (bits = 8) or uint16
    """
    rad = np.asarray(radiance, dtype=np.float64)
    if rad.ndim != 3 or rad.shape[2] != 3:
        raise ValueError(f"radiance must have shape (H, W, 3), got {rad.shape}")
    if not np.all(np.isfinite(rad)):
        raise ValueError("radiance contains NaN or inf")
    electrons = np.clip(rad, 0.0, None) * camera.exposure * camera.full_well_e
    if camera.noise:
        gen = np.random.default_rng(rng)
        electrons = gen.poisson(np.minimum(electrons, 1e9)).astype(np.float64)
        if camera.read_noise_e > 0:
            electrons += gen.normal(0.0, camera.read_noise_e, size=electrons.shape)
    electrons = np.clip(electrons, 0.0, camera.full_well_e)
    dn = np.rint(electrons / camera.full_well_e * camera.max_dn)
    return dn.astype(np.uint8 if camera.bits == 8 else np.uint16)


# ---------------------------------------------------------------------------------------
# EMVA 1288 camera model (the physical-sensor issue, part 1)

CFA_PATTERNS = {
    # colour of the 2x2 cell's pixels (0,0), (0,1), (1,0), (1,1) -> OpenCV's name for it
    # (OpenCV names a Bayer layout by the second row's second and third pixels; the mapping
    # is checked by tests/test_camera.py)
    "none": None,
    "RGGB": "BayerBG",
    "BGGR": "BayerRG",
    "GRBG": "BayerGB",
    "GBRG": "BayerGR",
}
DEMOSAIC_METHODS = {"bilinear": "", "edge_aware": "_EA", "vng": "_VNG"}
_CHANNEL = {"R": 0, "G": 1, "B": 2}


def _opencv_bayer(pattern: str) -> str:
    """OpenCV's name of a Bayer layout; ValueError listing the layouts otherwise."""
    stem = CFA_PATTERNS.get(pattern)
    if stem is None:
        raise ValueError(f"unknown Bayer pattern {pattern!r}; valid: {[k for k in CFA_PATTERNS if k != 'none']}")
    return stem


def bayer_mosaic(img: np.ndarray, *, pattern: str) -> np.ndarray:
    """Keep, at each pixel, only the channel its colour filter passes.

    Parameters
    ----------
    img : ndarray, shape (H, W, 3)
    pattern : str, one of :data:`CFA_PATTERNS` but 'none' (e.g. 'RGGB': R at (0, 0))

    Returns
    -------
    ndarray, shape (H, W), same dtype
    """
    _opencv_bayer(pattern)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image must have shape (H, W, 3), got {img.shape}")
    raw = np.empty(img.shape[:2], dtype=img.dtype)
    for colour, (dy, dx) in zip(pattern, ((0, 0), (0, 1), (1, 0), (1, 1))):
        raw[dy::2, dx::2] = img[dy::2, dx::2, _CHANNEL[colour]]
    return raw


def demosaic(raw: np.ndarray, *, pattern: str, method: str) -> np.ndarray:
    """OpenCV demosaicing of a Bayer image into RGB (H, W, 3).

    ``bilinear``: OpenCV's default; ``edge_aware``: its edge-aware method (``_EA``); ``vng``:
    variable number of gradients (8-bit only).
    """
    import cv2

    if method not in DEMOSAIC_METHODS:
        raise ValueError(f"unknown demosaic method {method!r}; valid: {list(DEMOSAIC_METHODS)}")
    stem = _opencv_bayer(pattern)
    if method == "vng" and raw.dtype != np.uint8:
        raise ValueError("VNG demosaicing takes 8-bit images only")
    return cv2.cvtColor(raw, getattr(cv2, f"COLOR_{stem}2RGB{DEMOSAIC_METHODS[method]}"))


@lru_cache(maxsize=4)
def fixed_pattern(shape: tuple[int, ...], *, seed: int, prnu: float, dsnu_e: float) -> tuple[np.ndarray, np.ndarray]:
    """A sensor's fixed-pattern noise (:func:`emva_camera`): the per-pixel gain factor
    ``max(1 + prnu N, 0)`` and dark offset ``dsnu_e N'`` (e-), N, N' standard normal drawn in that
    order from ``seed``.  A property of the sensor, the same in every frame, so it is drawn once
    per process and shape and returned read-only."""
    fp = np.random.default_rng(seed)
    gain = np.clip(1.0 + prnu * fp.standard_normal(shape), 0.0, None)
    dark = dsnu_e * fp.standard_normal(shape)
    for a in (gain, dark):
        a.setflags(write=False)
    return gain, dark


def emva_camera(
    radiance: np.ndarray,
    *,
    camera: PhysicalCamera,
    electrons_per_radiance: float | np.ndarray,
    exposure_s: float,
    white_balance: np.ndarray | None = (1.0, 1.0, 1.0),
    rng: RngLike = None,
) -> np.ndarray:
    """Rendered radiance -> recorded image through the EMVA 1288 model and the colour filter
    array of ``camera`` (a :class:`simbench.sim.sensor.PhysicalCamera`).

    Mean electrons ``e_c = radiance_c * electrons_per_radiance[c]`` (+ dark current x
    exposure); Poisson shot noise, temporal dark noise ``sigma_d`` (Gaussian), full-well
    clipping, ``y = K g_c e + offset`` rounded to the ADC range (EMVA 1288 release 4.0, Sec. 2;
    ``g_c`` the white-balance gain of the pixel's colour, applied before the ADC).
    Optional PRNU (relative gain spread) and DSNU (offset spread, e-) are drawn once from
    ``camera.fixed_pattern_seed``: a property of the sensor, the same in every frame.  With a
    colour filter array, each pixel keeps its filter's channel before the noise, and the raw
    frame is demosaiced by OpenCV.  ``camera.noise = False`` records the expected value.

    Parameters
    ----------
    radiance : ndarray, shape (H, W, 3), float
    electrons_per_radiance : sequence of 3 float
        Mean electrons per unit radiance in each channel during this exposure.
    exposure_s : float
        Exposure time (dark current).
    white_balance : sequence of 3 float
        Analogue gain of each colour channel (:func:`simbench.sim.photometry.white_balance_gains`).
    rng : numpy.random.Generator | int | None
        Temporal-noise seed.

    Returns
    -------
    ndarray, shape (H, W, 3), uint8 (8 bits) or uint16

    References
    ----------
    .. [1] EMVA Standard 1288, Release 4.0, "Standard for Characterization of Image Sensors and
       Cameras", 2021.
    """
    rad = np.asarray(radiance)
    if rad.ndim != 3 or rad.shape[2] != 3:
        raise ValueError(f"radiance must have shape (H, W, 3), got {rad.shape}")
    # float32 (what renders give) read as it is, anything else as float64: the same values
    rad = np.ascontiguousarray(rad, dtype=np.float32 if rad.dtype == np.float32 else np.float64)
    scale = np.asarray(electrons_per_radiance, dtype=np.float64)
    if scale.shape != (3,) or not np.all(np.isfinite(scale) & (scale > 0)):
        raise ValueError(f"electrons_per_radiance must be three finite numbers > 0, got {electrons_per_radiance!r}")
    wb = np.asarray(white_balance, dtype=np.float64)
    if wb.shape != (3,) or not np.all(np.isfinite(wb) & (wb > 0)):
        raise ValueError(f"white_balance must be three finite numbers > 0, got {white_balance!r}")
    gain = np.ascontiguousarray(camera.gain * wb, dtype=np.float64)
    h, w = rad.shape[:2]
    chan = None
    if camera.cfa != "none":
        _opencv_bayer(camera.cfa)
        chan = np.array([_CHANNEL[c] for c in camera.cfa], dtype=np.int64)  # (0, 0), (0, 1), (1, 0), (1, 1)
    shape = (h, w) if chan is not None else (h, w, 3)
    gain_fp = dark_fp = None
    if camera.prnu > 0 or camera.dsnu_e > 0:
        gain_fp, dark_fp = fixed_pattern(shape, seed=camera.fixed_pattern_seed, prnu=camera.prnu, dsnu_e=camera.dsnu_e)
    # mean electrons e_c = radiance_c * electrons_per_radiance[c], the pixel's filter's channel
    # kept, times the pixel's PRNU gain, plus dark current x exposure (one C loop over the pixels,
    # simbench/_lens.c: the bits of the numpy form, tests/numpy_reference.py)
    mean_e = np.empty(shape, np.float64)
    lib = native.bind(_EMVA)
    bad = lib.emva_mean(
        h,
        w,
        native.ptr(rad, "radiance", rad.dtype, rad.shape),
        int(rad.dtype == np.float64),
        native.ptr(scale, "scale", np.float64, (3,)),
        None if chan is None else native.ptr(chan, "chan", np.int64, (4,)),
        None if gain_fp is None else native.ptr(gain_fp, "gain_fp", np.float64, shape),
        float(camera.dark_current_e_s * exposure_s),
        native.ptr(mean_e, "mean_e", np.float64, shape, writable=True),
    )
    if bad > 0:
        raise ValueError("radiance contains NaN or inf")
    if bad < 0:
        raise ValueError(
            f"{-bad} pixels' mean electrons are not finite (radiance x electrons_per_radiance "
            f"{electrons_per_radiance!r} x PRNU gain + dark current x exposure_s {exposure_s!r})"
        )
    if camera.noise:
        gen = np.random.default_rng(rng)
        electrons = gen.poisson(np.minimum(mean_e, 1e12)).astype(np.float64)
        if camera.dark_noise_e > 0:
            electrons += gen.normal(0.0, camera.dark_noise_e, size=shape)
    else:
        electrons = mean_e
    # full-well clipping, the gain and offset, rounded to the ADC's range
    out = np.empty(shape, np.uint8 if camera.bits == 8 else np.uint16)
    lib.emva_dn(
        h,
        w,
        native.ptr(electrons, "electrons", np.float64, shape),
        None if dark_fp is None else native.ptr(dark_fp, "dark_fp", np.float64, shape),
        None if chan is None else native.ptr(chan, "chan", np.int64, (4,)),
        native.ptr(gain, "gain", np.float64, (3,)),
        float(camera.full_well_e),
        float(camera.offset_dn),
        float(camera.max_dn),
        int(camera.bits == 8),
        native.ptr(out, "out", out.dtype, shape, writable=True),
    )
    if camera.cfa != "none":
        out = demosaic(out, pattern=camera.cfa, method=camera.demosaic)
    return out


_P, _I, _D = native.P, native.I64, native.F64
_EMVA = {
    "emva_mean": (_I, [_I, _I, _P, _I, _P, _P, _P, _D, _P]),
    "emva_dn": (None, [_I, _I, _P, _P, _P, _P, _D, _D, _D, _I, _P]),
}


def photon_transfer(
    frame_a: np.ndarray, frame_b: np.ndarray, dark_a: np.ndarray, dark_b: np.ndarray
) -> tuple[float, float]:
    """EMVA 1288 photon-transfer point from two frames at one exposure and two dark frames:
    (mean signal above dark, temporal variance above dark), both in DN / DN^2.

    The temporal variance is ``var(a - b) / 2`` (the difference cancels fixed-pattern noise).

    References
    ----------
    .. [1] EMVA Standard 1288, Release 4.0, 2021 (the photon transfer method).
    """
    a, b, da, db = (np.asarray(x, dtype=np.float64) for x in (frame_a, frame_b, dark_a, dark_b))
    mean = 0.5 * (a.mean() + b.mean()) - 0.5 * (da.mean() + db.mean())
    var = 0.5 * np.var(a - b) - 0.5 * np.var(da - db)
    return float(mean), float(var)
