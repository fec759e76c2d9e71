"""A Kinect-v1-like speckle structured-light sensor, simulated the way the device works.

Device (numbers from the literature where they exist, otherwise stated assumptions):

- An 830 nm laser behind a diffractive element projects a fixed pseudo-random dot pattern: a
  3x3 tiling of one 211x165-position tile, each tile with a brighter centre dot (the pattern's
  structure as reverse-engineered from IR captures; position count and ~10 % lit share are
  assumptions of that order).  Here it is Mitsuba's ``projector`` emitter textured with the dots
  (each dot one texel of a 3x3 cell, so a dot is smaller than a camera pixel), 75 mm to the
  camera's +x (baseline: Khoshelham & Oude Elberink 2012).
- A monochrome IR camera, 640x480, f = 571 px (the competitor issue; Khoshelham & Oude Elberink
  2012 calibrate ~580 px), Aptina MT9M001 5.2 um pixels binned 2x2 (5.2 um and the 10-bit ADC:
  the MT9M001 data sheet; the 2x2 binning to 640x480 is our assumption).
- Time (moving scenes): 30 frames/s (Sarbolandi et al. 2015) on the MT9M001's electronic rolling
  shutter (data sheet: ERS, one sensor row every 31.75 us at the recommended 48 MHz clock).
  Output row r (two sensor rows, top first) integrates over [r t_row, r t_row + T_exp), t_row =
  63.5 us, so the 480 rows start 30.5 ms apart from top to bottom.  T_exp is not published:
  assumption: the whole frame time, 1/30 s (the laser shines continuously and the sensor may
  integrate for as long as a frame lasts; a shorter exposure is a ``KinectModel`` field away).
  A moving scene is rendered in time slices over the whole readout and each row takes the slices
  of its own window (:func:`rolling_weights`); the speckle stays the static one, an approximation
  (a moving surface carries its speckle along and averages it over the exposure).
- The scene's NIR reflectance is taken as the mean of its RGB reflectance (assumption: no NIR
  spectra are known for the scene materials), and a translucent object's NIR subsurface
  scattering as the mean of its three bands' (:func:`simbench.sim.capture.with_translucency`; the
  speckle statistics are kept those of a surface scatterer, an approximation: volume scattering
  lowers speckle contrast); the 830 nm band-pass filter removes ambient light.
- Laser speckle: coherent light gives each camera pixel a multiplicative speckle intensity,
  integrated over ``M = P (pixel pitch / speckle grain)^2`` grains of diameter ``2.44 lambda N``,
  with ``P = 2`` polarisation states for depolarising matte surfaces (Goodman, *Speckle
  Phenomena in Optics*, subjective speckle): gamma distributed with mean 1 and variance
  ``1/M``.  It is frozen to the surface (the same in every frame of a static scene) and
  decorrelates between the reference plane and the scene, which is what limits the matching.
  This is the speckle and detector noise Landau et al. (2015) identify; their fitted values
  could not be re-checked here, so the grain statistics come from the optics instead.
- Detector: Poisson shot noise, Gaussian read noise, full well and a 10-bit ADC (EMVA 1288); a
  fixed exposure set once so that the reference plane's brightest dots reach 70 % of the full
  well (assumption), kept for every capture (so returns fall off as 1/Z^2).

Matching as the device does it: a 9x9 normalised cross-correlation window along rows against
the reference image recorded at a known depth, 64 integer disparity positions, parabolic
sub-pixel refinement quantised to 1/8 px, 11-bit disparity codes (2047 = invalid), depth from
``1/Z = 1/Z_ref + d / (f B)``, valid over 0.8-4 m.  Pixels are invalid where the window has no
dot contrast (projector shadow), the best correlation is weak, a second peak nearly equals it
(ambiguous), or the disparity falls outside the search range.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import cv2
import numpy as np

from simbench import validate
from simbench.literature import KINECT_BASELINE_M, KINECT_FOCAL_PX, KINECT_FPS, MT9M001_ROW_TIME_S
from simbench.rig import Intrinsics, Rig
from simbench.sim.scene import SceneSpec, reference_scene
from simbench.seeds import RngLike, child_seed

if TYPE_CHECKING:
    from simbench.cache import RenderCache

__all__ = [
    "KinectModel",
    "KinectCalibration",
    "KinectDepth",
    "kinect_rig",
    "dot_pattern",
    "device_scene",
    "speckle",
    "record_ir",
    "match",
    "calibrate",
    "capture",
    "row_windows_s",
    "rolling_weights",
]


@dataclass(frozen=True)
class KinectModel:
    """Kinect-v1-like device parameters (module docstring for their sources)."""

    width_px: int = 640
    height_px: int = 480
    focal_px: float = KINECT_FOCAL_PX
    baseline_m: float = KINECT_BASELINE_M
    # assumption: the factory reference plane; chosen so the 64 disparity positions centre on
    # the 0.8-4 m range (1/Z_ref = mean of 1/0.8 and 1/4)
    reference_depth_m: float = 4.0 / 3.0
    min_depth_m: float = 0.8
    max_depth_m: float = 4.0
    window_px: int = 9
    disparities: int = 64
    subpixel_steps: int = 8
    code_bits: int = 11
    tile_wh: tuple[int, int] = (211, 165)
    tiles_wh: tuple[int, int] = (3, 3)
    dot_fraction: float = 0.10  # assumption: ~10 % of the positions lit (order of the real pattern)
    centre_gain: float = 3.0  # assumption: the tile's centre dot is ~3x brighter
    texels_per_dot: int = 4
    # assumption: the 633 x 495 positions spread over a wider field than the camera's 640 x 480
    # (the projector must light the whole view at every depth of the range, and the factory
    # reference must be lit edge to edge): 1.25 camera px per position
    dot_pitch_px: float = 1.25
    # assumption: each diffracted spot is a Gaussian of sigma 0.4 position (FWHM ~ one camera
    # pixel at any depth: spot and pattern scale together with distance)
    dot_sigma: float = 0.4
    pattern_seed: int = 2010
    wavelength_nm: float = 830.0
    f_number: float = 2.0  # assumption: a fast small-format IR lens
    pixel_pitch_um: float = 10.4  # MT9M001 5.2 um (data sheet), 2x2 binned (assumption)
    # matte paint and plaster depolarise: two independent speckle patterns add (Goodman)
    polarisation_states: int = 2
    psf_sigma_px: float = 0.5  # assumption: lens blur + pixel crosstalk, Gaussian sigma
    full_well_e: float = 20000.0  # assumption: binned MT9M001 pixel
    read_noise_e: float = 10.0  # assumption
    bits: int = 10  # MT9M001 ADC (data sheet)
    exposure_fraction: float = 0.7
    # the time model (module docstring): assumption, the exposure fills the 30 Hz frame; the
    # rolling shutter's row delay, two MT9M001 rows per binned output row (0: a global shutter)
    exposure_s: float = 1.0 / KINECT_FPS
    row_time_s: float = 2 * MT9M001_ROW_TIME_S
    speckle: bool = True
    noise: bool = True
    min_ncc: float = 0.5  # assumption: below it the match is not trusted
    ambiguity_ratio: float = 0.9  # assumption: second peak >= 0.9 x best = ambiguous
    speckle_area_px: int = 40  # assumption: blobs below ~ half a 9x9 window are outliers
    min_contrast_e: float = 200.0  # assumption: window std below this (e-) = no dots (shadow)

    def __post_init__(self) -> None:
        for name in (
            "focal_px",
            "baseline_m",
            "reference_depth_m",
            "min_depth_m",
            "max_depth_m",
            "wavelength_nm",
            "f_number",
            "pixel_pitch_um",
            "full_well_e",
        ):
            # finite and positive; depths within the scenes' 100 m (simbench.sim.scene.SCENE_EXTENT_M)
            hi = 100.0 if name.endswith("depth_m") else None
            validate.number(getattr(self, name), f"kinect {name}", lo=0.0, lo_open=True, hi=hi)
        validate.number(self.exposure_s, "kinect exposure_s", lo=0.0, lo_open=True, hi=1.0)
        validate.number(self.row_time_s, "kinect row_time_s", lo=0.0, hi=1e-3)
        if not self.min_depth_m < self.max_depth_m:
            raise ValueError("kinect min_depth_m must be below max_depth_m")
        if self.window_px < 3 or self.window_px % 2 == 0:
            raise ValueError(f"kinect window_px must be odd and >= 3, got {self.window_px}")
        if self.disparities < 3:
            raise ValueError(f"kinect disparities must be >= 3, got {self.disparities}")
        if self.disparities * self.subpixel_steps >= 1 << self.code_bits:
            raise ValueError(
                f"{self.disparities} disparities x {self.subpixel_steps} steps do not fit {self.code_bits}-bit codes"
            )
        if not 0 < self.dot_fraction <= 1:
            raise ValueError(f"kinect dot_fraction must be in (0, 1], got {self.dot_fraction}")

    @property
    def camera(self) -> Intrinsics:
        return Intrinsics.centred(self.width_px, self.height_px, self.focal_px)

    @property
    def fb_px_m(self) -> float:
        """f * B (px m): disparity (px) per unit inverse depth (1/m)."""
        return self.focal_px * self.baseline_m

    @property
    def first_disparity_px(self) -> int:
        """The smallest searched disparity; the 64 positions cover 0.8-4 m."""
        lo = self.fb_px_m * (1 / self.max_depth_m - 1 / self.reference_depth_m)
        hi = self.fb_px_m * (1 / self.min_depth_m - 1 / self.reference_depth_m)
        return int(math.floor((lo + hi) / 2 - (self.disparities - 1) / 2))

    @property
    def speckle_grains_per_pixel(self) -> float:
        grain_um = 2.44 * self.wavelength_nm * 1e-3 * self.f_number
        return max(1.0, self.polarisation_states * (self.pixel_pitch_um / grain_um) ** 2)


def kinect_rig(model: KinectModel) -> Rig:
    """IR camera and dot projector (one texel = ``1/texels_per_dot`` of a dot position)."""
    t = model.texels_per_dot
    w = model.tile_wh[0] * model.tiles_wh[0] * t
    h = model.tile_wh[1] * model.tiles_wh[1] * t
    # the dot positions a fixed angle apart (dot_pitch_px camera pixels at any depth)
    projector = Intrinsics.centred(w, h, model.focal_px / model.dot_pitch_px * t)
    return Rig(camera=model.camera, projector=projector, position_m=(model.baseline_m, 0.0, 0.0), name="kinect_v1")


def dot_pattern(model: KinectModel) -> np.ndarray:
    """The projector's dot texture, shape (Hp, Wp), float32 in [0, 1] (seeded)."""
    tw, th = model.tile_wh
    rng = np.random.default_rng(model.pattern_seed)
    tile = (rng.random((th, tw)) < model.dot_fraction).astype(np.float32) / model.centre_gain
    tile[th // 2, tw // 2] = 1.0
    dots = np.tile(tile, (model.tiles_wh[1], model.tiles_wh[0]))
    t = model.texels_per_dot
    tex = np.zeros((dots.shape[0] * t, dots.shape[1] * t), np.float32)
    tex[t // 2 :: t, t // 2 :: t] = dots
    if model.dot_sigma > 0:
        sigma = model.dot_sigma * t
        tex = cv2.GaussianBlur(tex, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
        tex *= 2 * np.pi * sigma**2  # peak of an isolated dot stays its value
    # a black border: Mitsuba's texture lookup clamps beyond the frustum, which would smear
    # the edge texels into row-invariant streaks outside it
    tex[[0, -1], :] = 0.0
    tex[:, [0, -1]] = 0.0
    return np.clip(tex, 0.0, 1.0)


def device_scene(scene: SceneSpec, model: KinectModel) -> SceneSpec:
    """``scene`` seen by the Kinect: its rig, no lens model, no ambient (IR band-pass)."""
    return dataclasses.replace(
        scene,
        rig=kinect_rig(model),
        camera_lens=None,
        ambient_rgb=(0.0, 0.0, 0.0),
        projector_scale=1.0,
        reference_depth_m=model.reference_depth_m,
    )


def speckle(shape: tuple[int, int], *, grains_per_pixel: float, rng: RngLike) -> np.ndarray:
    """Integrated speckle intensity per pixel: gamma(M, 1/M), mean 1, variance 1/M.

    References
    ----------
    .. [1] J. W. Goodman, "Speckle Phenomena in Optics", Roberts & Co., 2007 (fully developed
       speckle integrated over a pixel).
    """
    m = float(grains_per_pixel)
    return np.random.default_rng(rng).gamma(m, 1.0 / m, size=shape).astype(np.float32)


def record_ir(
    radiance: np.ndarray, *, model: KinectModel, electrons_per_radiance: float, speckle_rng: RngLike, rng: RngLike
) -> np.ndarray:
    """IR radiance (H, W) -> recorded frame (H, W) uint16 DN: optics blur, speckle, EMVA noise."""
    rad = np.asarray(radiance, dtype=np.float32)
    if rad.shape != (model.height_px, model.width_px):
        raise ValueError(f"IR radiance must have shape {(model.height_px, model.width_px)}, got {rad.shape}")
    if model.psf_sigma_px > 0:
        rad = cv2.GaussianBlur(rad, (0, 0), model.psf_sigma_px, borderType=cv2.BORDER_REFLECT)
    if model.speckle:
        rad = rad * speckle(rad.shape, grains_per_pixel=model.speckle_grains_per_pixel, rng=speckle_rng)
    mean_e = np.clip(rad, 0, None).astype(np.float64) * electrons_per_radiance
    if model.noise:
        gen = np.random.default_rng(rng)
        e = gen.poisson(np.minimum(mean_e, 1e9)).astype(np.float64) + gen.normal(0.0, model.read_noise_e, mean_e.shape)
    else:
        e = mean_e
    max_dn = (1 << model.bits) - 1
    return np.clip(np.rint(np.minimum(e, model.full_well_e) * max_dn / model.full_well_e), 0, max_dn).astype(np.uint16)


@dataclass(frozen=True)
class KinectCalibration:
    """The factory calibration: the recorded reference image at ``reference_depth_m`` and the
    fixed exposure (electrons per unit rendered radiance)."""

    reference: np.ndarray
    electrons_per_radiance: float


@dataclass(frozen=True)
class KinectDepth:
    """Matching output at IR-camera pixels.

    depth_m : (H, W) float32, NaN invalid; disparity_px : (H, W) float32, quantised to
    1/8 px, NaN invalid; code : (H, W) uint16 11-bit disparity code (2047 invalid);
    ncc : (H, W) float32 best correlation; valid : (H, W) bool.
    """

    depth_m: np.ndarray
    disparity_px: np.ndarray
    code: np.ndarray
    ncc: np.ndarray
    valid: np.ndarray


def _parallel(fill, n: int) -> None:
    """Run ``fill(j)`` for ``j`` in ``range(n)`` on ``n`` threads (OpenCV and NumPy release the
    GIL on whole-image operations); each writes its own outputs, so the result does not depend
    on the scheduling."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=n) as pool:
        list(pool.map(fill, range(n)))


def _box_stats(img: np.ndarray, w: int) -> tuple[np.ndarray, np.ndarray]:
    mean = cv2.boxFilter(img, cv2.CV_32F, (w, w), borderType=cv2.BORDER_REFLECT)
    sq = cv2.boxFilter(img * img, cv2.CV_32F, (w, w), borderType=cv2.BORDER_REFLECT)
    return mean, np.sqrt(np.maximum(sq - mean * mean, 0.0))


def match(ir: np.ndarray, reference: np.ndarray, *, model: KinectModel) -> KinectDepth:
    """Block matching of an IR frame against the reference (module docstring).

    Parameters
    ----------
    ir, reference : ndarray, shape (H, W), integer DN or float

    References
    ----------
    .. [1] K. Khoshelham, S. Oude Elberink, "Accuracy and Resolution of Kinect Depth Data for
       Indoor Mapping Applications", Sensors 12(2), 1437-1454, 2012.
    """
    h, w = model.height_px, model.width_px
    for name, a in (("IR frame", ir), ("reference", reference)):
        if np.shape(a) != (h, w):
            raise ValueError(f"{name} must have shape {(h, w)}, got {np.shape(a)}")
    img = np.asarray(ir, dtype=np.float32)
    ref = np.asarray(reference, dtype=np.float32)
    if not (np.all(np.isfinite(img)) and np.all(np.isfinite(ref))):
        raise ValueError("IR frame and reference must be finite")
    win = model.window_px
    mi, si = _box_stats(img, win)
    mr, sr = _box_stats(ref, win)
    inv_si = np.where(si > 0, 1.0 / np.maximum(si, 1e-12), 0.0).astype(np.float32)
    inv_sr = np.where(sr > 0, 1.0 / np.maximum(sr, 1e-12), 0.0).astype(np.float32)
    d0 = model.first_disparity_px
    n = model.disparities
    border = win // 2
    # only pixels whose every candidate window lies inside the reference are matched:
    # elsewhere the true match may be missing and a wrong one win (the real device's invalid
    # band at the image side)
    x_lo = max(border + d0 + n - 1, border)
    x_hi = min(w - 1 - border + d0, w - 1 - border)
    if x_hi < x_lo:
        raise ValueError("the disparity search range is wider than the image")
    cols_c = slice(x_lo, x_hi + 1)
    wc = x_hi + 1 - x_lo
    scores = np.empty((n, h, wc), np.float32)
    inv_si_c = inv_si[:, cols_c]
    # the product is box-filtered over the matched columns and half a window either side (inside
    # the image: x_lo >= border + s, x_hi <= w - 1 - border + s), so that every matched column's
    # window holds image pixels, as the statistics' do; box-filtered on the matched columns alone,
    # the border rule reflected them and the NCC of the 4 outermost columns a side read up to 2.2
    # (a third audit; exact: 0.84-0.88), picking wrong matches there
    img_e = img[:, x_lo - border : x_hi + 1 + border]
    p_c = (mi * inv_si)[:, cols_c]
    q = mr * inv_sr

    halves = (range(0, n, 2), range(1, n, 2))
    bests = [np.full((h, wc), -np.inf, np.float32) for _ in halves]
    idxs = [np.zeros((h, wc), np.int64) for _ in halves]

    def fill(j: int) -> None:
        best, idx = bests[j], idxs[j]
        mask = np.empty((h, wc), bool)
        tmp = np.empty((h, wc), np.float32)
        for k in halves[j]:
            s = d0 + k  # the capture's pixel x matches the reference's x - s
            rs = slice(x_lo - s, x_hi + 1 - s)
            re_ = slice(x_lo - border - s, x_hi + 1 + border - s)
            # over the full image height, its rows' border handling is the statistics'
            box = cv2.boxFilter(cv2.multiply(img_e, ref[:, re_]), cv2.CV_32F, (win, win), borderType=cv2.BORDER_REFLECT)
            # (box(I R) - mean_I mean_R) / (sigma_I sigma_R) = box(I R) a b - (mean_I a)(mean_R b)
            cv2.multiply(inv_si_c, inv_sr[:, rs], dst=tmp)
            num = cv2.multiply(box[:, border : border + wc], tmp)
            cv2.multiply(p_c, q[:, rs], dst=tmp)
            cv2.subtract(num, tmp, dst=scores[k])
            np.greater(scores[k], best, out=mask)  # ascending k: ties keep the smaller index
            np.copyto(best, scores[k], where=mask)
            np.copyto(idx, k, where=mask)

    _parallel(fill, 2)
    # merge the two halves; on a tie the smaller disparity index wins
    take_odd = (bests[1] > bests[0]) | ((bests[1] == bests[0]) & (idxs[1] < idxs[0]))
    c0 = np.where(take_odd, bests[1], bests[0])
    best = np.where(take_odd, idxs[1], idxs[0])
    rows, cols = np.indices((h, wc))
    inner = (best > 0) & (best < n - 1)
    cm = scores[np.maximum(best - 1, 0), rows, cols]
    cp = scores[np.minimum(best + 1, n - 1), rows, cols]
    # Gaussian (log-parabola) peak fit: the correlation peak of ~1 px dots is narrower than
    # the 1-px sampling, where a plain parabola locks onto integers (bias up to ~0.2 px)
    lm, l0, lp = (np.log(np.maximum(c, 1e-3)) for c in (cm, c0, cp))
    curv = lm - 2 * l0 + lp
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(inner & (curv < 0), 0.5 * (lm - lp) / curv, 0.0)
    delta = np.clip(delta, -0.5, 0.5)
    # the second-best peak away from the best one (ambiguity)
    for off in (-1, 0, 1):
        scores[np.clip(best + off, 0, n - 1), rows, cols] = -1.0
    second = scores.max(axis=0)
    steps = model.subpixel_steps
    code_c = np.rint((best + delta) * steps).astype(np.int64)
    with np.errstate(divide="ignore", invalid="ignore"):
        disp_c = d0 + code_c / steps
        depth_c = 1.0 / (1.0 / model.reference_depth_m + disp_c / model.fb_px_m)
        contrast_e = si[:, cols_c] * (model.full_well_e / ((1 << model.bits) - 1))
        ok = (
            inner
            & (c0 >= model.min_ncc)
            & (second < model.ambiguity_ratio * c0)
            & (contrast_e >= model.min_contrast_e)
            & (depth_c >= model.min_depth_m)
            & (depth_c <= model.max_depth_m)
        )
    ok[:border] = ok[h - border :] = False
    valid = np.zeros((h, w), bool)
    valid[:, cols_c] = ok
    code = np.zeros((h, w), np.int64)
    code[:, cols_c] = code_c
    disparity = np.full((h, w), np.nan)
    disparity[:, cols_c] = disp_c
    depth = np.full((h, w), np.nan)
    depth[:, cols_c] = depth_c
    ncc = np.full((h, w), np.nan, np.float32)
    ncc[:, cols_c] = c0
    invalid_code = (1 << model.code_bits) - 1
    # outlier removal as stereo matchers do it (OpenCV filterSpeckles): connected regions of
    # consistent disparity smaller than speckle_area_px are wrong matches, not surfaces
    if model.speckle_area_px > 0:
        codes = np.where(valid, code, -1).astype(np.int16)
        cv2.filterSpeckles(codes, -1, model.speckle_area_px, steps)
        valid &= codes >= 0
    return KinectDepth(
        depth_m=np.where(valid, depth, np.nan).astype(np.float32),
        disparity_px=np.where(valid, disparity, np.nan).astype(np.float32),
        code=np.where(valid, code, invalid_code).astype(np.uint16),
        ncc=ncc,
        valid=valid,
    )


def _ir(radiance_rgb: np.ndarray) -> np.ndarray:
    # NIR reflectance = mean of the RGB reflectances (module docstring).  Written out, the bits of
    # mean(axis=2) on float32 ((r + g) + b, then / 3 in float32); numpy's reduction over the short
    # last axis took 55-70 ms the first time after each Mitsuba render here (7 ms after), the sum
    # 1-1.5 ms: a moving capture does one per time slice (256 in the Kinect shear test)
    rgb = np.asarray(radiance_rgb, dtype=np.float32)
    return (rgb[..., 0] + rgb[..., 1] + rgb[..., 2]) / np.float32(3)


@lru_cache(maxsize=2)
def _dot_drive(model: KinectModel) -> np.ndarray:
    """The dot texture as the projector's RGB drive (the same in the three channels), made once
    per process and model (read-only): a moving capture renders it in every time slice, and making
    it each time was ~40 ms a slice (Kinect shear test: 18 s of 81)."""
    drive = np.repeat(dot_pattern(model)[..., None], 3, axis=2)
    drive.setflags(write=False)
    return drive


@lru_cache(maxsize=4)
def _dot_drive_digest(model: KinectModel) -> str:
    """:func:`simbench.cache.array_digest` of :func:`_dot_drive`, once per process and model:
    making and hashing the drive was ~150 ms per render lookup."""
    from simbench.cache import array_digest

    return array_digest(_dot_drive(model))


def _render(
    scene: SceneSpec, model: KinectModel, *, spp: int, seed: int, max_depth: int, sampler: str, cache
) -> np.ndarray:
    from simbench.sim.drive import DriveImage
    from simbench.sim.capture import cached_radiance, opaque, with_translucency

    # the drive by its digest, made only for a render the cache does not hold
    drive = DriveImage(_dot_drive_digest(model), lambda: _dot_drive(model))
    rad = cached_radiance(opaque(scene), drive, spp=spp, seed=seed, max_depth=max_depth, sampler=sampler, cache=cache)
    return _ir(with_translucency(rad, scene, cache=cache))


def row_windows_s(model: KinectModel) -> np.ndarray:
    """Each image row's exposure (start, end) in seconds, shape (H, 2): the rolling shutter's
    rows start ``row_time_s`` apart, top first, and integrate ``exposure_s`` each."""
    start = np.arange(model.height_px, dtype=np.float64) * model.row_time_s
    return np.stack([start, start + model.exposure_s], axis=1)


def rolling_weights(windows_s: np.ndarray, edges_s: np.ndarray) -> np.ndarray:
    """The share of each row's exposure that falls in each time slice, shape (H, n): the overlap
    of row window ``windows_s[r]`` with slice ``[edges_s[i], edges_s[i + 1])`` over the window's
    length - a row's image is the weighted sum of the slice renders (each slice's render standing
    for its whole sub-window: the midpoint rule), and a row's weights add up to one when the
    slices cover its window."""
    w = np.asarray(windows_s, dtype=np.float64)
    e = np.asarray(edges_s, dtype=np.float64)
    lo = np.maximum(w[:, :1], e[None, :-1])
    hi = np.minimum(w[:, 1:], e[None, 1:])
    return np.clip(hi - lo, 0.0, None) / (w[:, 1:] - w[:, :1])


def capture_window_s(model: KinectModel) -> tuple[float, float]:
    """The whole frame's capture, first row's start to last row's end (seconds)."""
    rows = row_windows_s(model)
    return (float(rows[0, 0]), float(rows[-1, 1]))


def _moving_render(scene: SceneSpec, model: KinectModel, *, spp: int, seed: int, max_depth: int, cache) -> np.ndarray:
    """The IR radiance (H, W) of a moving scene through the rolling shutter: time slices over the
    whole readout (:func:`simbench.sim.timeline.slice_count`: <= 0.25 px of motion each), each
    row the :func:`rolling_weights` sum of the slices in its own window.  A row's window spans
    ``exposure_s`` of the readout, so the samples are split over the slices one exposure holds
    (every row sees about ``spp``; the frame costs readout / exposure, ~1.9x, a static render's)."""
    from simbench.seeds import slice_seed
    from simbench.sim.timeline import scene_at, slice_count, slice_spp

    span = capture_window_s(model)
    n = slice_count(scene, model.camera, span)
    edges = np.linspace(span[0], span[1], n + 1)
    weights = rolling_weights(row_windows_s(model), edges)
    per_exposure = max(1, math.ceil(n * model.exposure_s / (span[1] - span[0])))
    per = slice_spp(spp, per_exposure)
    out = np.zeros((model.height_px, model.width_px), dtype=np.float64)
    for i in range(n):
        if not weights[:, i].any():
            continue
        posed = scene_at(scene, 0.5 * float(edges[i] + edges[i + 1]))
        ir = _render(
            posed, model, spp=per, seed=slice_seed(seed, i), max_depth=max_depth, sampler="independent", cache=cache
        )
        out += weights[:, i, None] * ir
    return out.astype(np.float32)


def calibrate(
    model: KinectModel,
    *,
    spp: int,
    seed: int,
    max_depth: int = 6,
    sampler: str = "independent",
    cache: RenderCache | None = None,
    albedo: float = 0.8,
) -> KinectCalibration:
    """Record the factory reference: a white plane (``albedo``) at ``reference_depth_m``; the
    exposure is set so that its brightest dots (99.9th percentile) reach ``exposure_fraction``
    of the full well.  Seeds: render ``seed``; speckle and noise derived from it."""
    from simbench.sim.scene import SceneObject

    placeholder = SceneSpec(
        name="kinect_reference",
        rig=kinect_rig(model),
        objects=(SceneObject("plane", "p", (("center_m", (0.0, 0.0, 1.0)), ("size_m", (1.0, 1.0)))),),
    )
    ref_scene = reference_scene(device_scene(placeholder, model), albedo=albedo)
    rad = _render(ref_scene, model, spp=spp, seed=seed, max_depth=max_depth, sampler=sampler, cache=cache)
    blurred = cv2.GaussianBlur(rad, (0, 0), model.psf_sigma_px) if model.psf_sigma_px > 0 else rad
    peak = float(np.percentile(blurred, 99.9))
    if not peak > 0:
        raise ValueError("the Kinect reference render is dark: no dots reached the camera")
    k = model.exposure_fraction * model.full_well_e / peak
    seq = child_seed(seed, "kinect_calibration_frames")
    speckle_seed, noise_seed = (int(s.generate_state(1)[0]) for s in seq.spawn(2))
    ref = record_ir(rad, model=model, electrons_per_radiance=k, speckle_rng=speckle_seed, rng=noise_seed)
    return KinectCalibration(reference=ref, electrons_per_radiance=k)


def capture(
    scene: SceneSpec,
    model: KinectModel,
    calibration: KinectCalibration,
    *,
    spp: int,
    seed: int,
    noise_seeds: list[int],
    max_depth: int = 6,
    sampler: str = "independent",
    cache: RenderCache | None = None,
) -> list[np.ndarray]:
    """IR frames of ``scene`` (already :func:`device_scene`): one render (``seed``; the speckle,
    frozen to the static scene, derives from it) recorded once per noise seed; a moving scene
    through the rolling shutter (:func:`_moving_render`)."""
    from simbench.sim.timeline import is_moving

    if is_moving(scene):
        rad = _moving_render(scene, model, spp=spp, seed=seed, max_depth=max_depth, cache=cache)
    else:
        rad = _render(scene, model, spp=spp, seed=seed, max_depth=max_depth, sampler=sampler, cache=cache)
    speckle_seed = int(child_seed(seed, "kinect_speckle").generate_state(1)[0])
    return [
        record_ir(
            rad, model=model, electrons_per_radiance=calibration.electrons_per_radiance, speckle_rng=speckle_seed, rng=s
        )
        for s in noise_seeds
    ]


class KinectSystem:
    """The Kinect-v1-like sensor as a depth system (:mod:`simbench.systems`): its own camera
    and dot projector, the factory reference recorded once, the device's matching."""

    name = "kinect"
    seed_prefix = "kinect/"

    def __init__(self, options=None, *, model: KinectModel | None = None) -> None:
        self.model = model if model is not None else KinectModel()

    def info(self):
        from simbench.systems import SystemInfo

        m = self.model
        return SystemInfo(
            name=self.name,
            label="Kinect v1 (simulated)",
            recording_options=(),  # its own device: no sensor model, pattern or calibration frames
            size_hw=(m.height_px, m.width_px),
            captures=1,
            confidence=(
                f"normalised cross-correlation of the best speckle match (-1 to 1); pixels below {m.min_ncc:g} are "
                "holes"
            ),
            numbers={
                "focal_px": (m.focal_px, "Khoshelham & Oude Elberink 2012 (~580 px calibrated)"),
                "baseline_m": (m.baseline_m, "Khoshelham & Oude Elberink 2012"),
                "range_m": ((m.min_depth_m, m.max_depth_m), "Khoshelham & Oude Elberink 2012"),
                "wavelength_nm": (m.wavelength_nm, "Khoshelham & Oude Elberink 2012"),
            },
        )

    def prepare(self, scene: SceneSpec) -> SceneSpec:
        return device_scene(scene, self.model)

    def calibration_key(self, scene: SceneSpec):
        return "factory"  # one factory reference, whatever the scene

    def calibrate(self, scene: SceneSpec, *, seeds, render) -> KinectCalibration:
        label = f"{self.seed_prefix}calibration"
        seed = seeds.seed(label)
        seeds.record(label, {"render": seed})
        return calibrate(
            self.model,
            spp=render.spp,
            seed=seed,
            max_depth=render.max_depth,
            sampler=render.sampler,
            cache=render.cache,
        )

    def acquire(
        self, scene: SceneSpec, calibration: KinectCalibration, *, render_seed: int, noise_seeds: list[int], render
    ) -> list[np.ndarray]:
        if calibration is None:
            raise ValueError("the Kinect needs its calibration (reference image): calibrate first")
        return capture(
            scene,
            self.model,
            calibration,
            spp=render.spp,
            seed=render_seed,
            noise_seeds=noise_seeds,
            max_depth=render.max_depth,
            sampler=render.sampler,
            cache=render.cache,
        )

    def capture_window_s(self, scene: SceneSpec) -> tuple[float, float]:
        """The time model (module docstring): one exposure per row of the rolling shutter, the
        first row's start to the last row's end (63.7 ms)."""
        return capture_window_s(self.model)

    def decode(self, raw: np.ndarray, calibration: KinectCalibration, *, scene: SceneSpec | None = None):
        from simbench.systems import SystemDepth

        if calibration is None:
            raise ValueError("the Kinect needs its reference image to decode")
        r = match(raw, calibration.reference, model=self.model)
        return SystemDepth(depth_m=r.depth_m, valid=r.valid, confidence=r.ncc, detail=r)

    def bench_inputs(self, *, scene: str = "plane", seed: int = 0):
        """(IR frame, calibration, scene) of a plane at 1.1 m made in numpy without the renderer
        (deterministic for a seed): the dot texture box-resampled onto the camera grid (the
        reference at its depth, the capture shifted by the plane's disparity), with speckle and
        detector noise."""
        if scene != "plane":
            raise ValueError(f"the {self.name} benchmark has only the plane, not {scene!r}")
        model = self.model
        rng = np.random.default_rng(seed)
        tex = dot_pattern(model)
        cam = model.camera
        scale = model.texels_per_dot / model.dot_pitch_px  # texels per camera pixel
        cu, cv = (tex.shape[1] - 1) / 2, (tex.shape[0] - 1) / 2
        blurred = cv2.GaussianBlur(tex, (0, 0), scale / 2)

        def view(shift_px: float) -> np.ndarray:
            # x_tex = scale * (x - cx - shift) + cu: the pattern displaced by shift_px
            xs = (np.arange(cam.width_px) - cam.cx_px - shift_px) * scale + cu
            ys = (np.arange(cam.height_px) - cam.cy_px) * scale + cv
            mx, my = np.meshgrid(xs.astype(np.float32), ys.astype(np.float32))
            return cv2.remap(blurred, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

        d = model.fb_px_m * (1 / 1.1 - 1 / model.reference_depth_m)
        ref_view = view(0.0)
        k = model.exposure_fraction * model.full_well_e / float(np.percentile(ref_view, 99.9))
        ref = record_ir(ref_view, model=model, electrons_per_radiance=k, speckle_rng=rng, rng=rng)
        cap = record_ir(view(d), model=model, electrons_per_radiance=k, speckle_rng=rng, rng=rng)
        return (
            cap,
            KinectCalibration(reference=ref, electrons_per_radiance=k),
            SceneSpec(name="bench_plane", rig=kinect_rig(model), objects=()),
        )

    def write_recording(
        self,
        out_dir,
        raw: np.ndarray,
        calibration: KinectCalibration,
        *,
        scene: SceneSpec,
        gt,
        meta: dict,
        overwrite: bool = False,
    ):
        """``ir.png`` + ``reference.png`` (16-bit grey), ground truth, ``device.json``."""
        from simbench.systems.recording import write_device_recording
        from simbench.io import save_png

        writers = {
            "ir": lambda d: save_png(d / "ir.png", np.asarray(raw, np.uint16)),
            "reference": lambda d: save_png(d / "reference.png", np.asarray(calibration.reference, np.uint16)),
        }
        info = {**meta, "electrons_per_radiance": calibration.electrons_per_radiance}
        return write_device_recording(out_dir, self.name, self.model, writers, gt=gt, info=info, overwrite=overwrite)

    def read_recording(self, in_dir):
        """(IR frame, calibration, scene) of a folder written by :meth:`write_recording`; the
        system's model becomes the recorded one."""
        from pathlib import Path

        from simbench import validate
        from simbench.systems.recording import read_device_info
        from simbench.io import load_image

        d = Path(in_dir)
        self.model, info = read_device_info(d, self.name, KinectModel)
        ir, ref = (
            load_image(d / f, expected_size_hw=self.model.camera.size_hw, channels=1)
            for f in ("ir.png", "reference.png")
        )
        k = validate.number(
            info.get("electrons_per_radiance", 1.0),
            f"{d / 'device.json'}: electrons_per_radiance",
            lo=0.0,
            lo_open=True,
        )
        return (
            ir,
            KinectCalibration(reference=ref, electrons_per_radiance=k),
            self.prepare(SceneSpec(name=str(info.get("scene", d.name)), rig=kinect_rig(self.model), objects=())),
        )
