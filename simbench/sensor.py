"""What the camera records from the rendered radiance.

This module holds the *minimal* camera step (exposure, shot and read noise, full-well clipping,
quantisation) as one replaceable function, :func:`simple_camera`; the full physical model
(EMVA 1288, Bayer mosaic, spectral crosstalk, projector gamma and defocus) is a separate issue
and will live beside it with the same signature.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "SimpleCamera",
    "CAMERA_PRESETS",
    "get_camera",
    "simple_camera",
    "project_drive",
    "EmvaCamera",
    "photons_per_unit_radiance",
    "emva_camera",
    "photon_transfer",
]


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
        if not self.exposure > 0:
            raise ValueError(f"exposure must be > 0, got {self.exposure}")
        if not self.full_well_e > 0:
            raise ValueError(f"full_well_e must be > 0, got {self.full_well_e}")
        if not self.read_noise_e >= 0:
            raise ValueError(f"read_noise_e must be >= 0, got {self.read_noise_e}")
        if self.bits not in (8, 10, 12, 16):
            raise ValueError(f"bits must be one of 8, 10, 12, 16; got {self.bits}")

    @property
    def max_dn(self) -> int:
        return (1 << self.bits) - 1


# The exposure is an assumption: the operator sets it so that the paper's white board at the
# 1 m reference distance (albedo 0.8, rendered peak radiance 0.8) reaches ~65 % of full scale,
# leaving head-room for the 0.9 m plane of Fig. 9.  Full well and read noise are the order of
# magnitude of the Flea3 FL3-U3-13E4C's e2v EV76C560 CMOS sensor (~10 ke-, ~10 e-); the
# physical-camera issue replaces them with cited EMVA 1288 figures.
CAMERA_PRESETS = {
    "minimal": SimpleCamera(exposure=0.8, full_well_e=10_000.0, read_noise_e=10.0, bits=8, noise=True),
    "ideal": SimpleCamera(exposure=0.8, full_well_e=10_000.0, read_noise_e=0.0, bits=8, noise=False),
}


def get_camera(name: str) -> SimpleCamera:
    try:
        return CAMERA_PRESETS[name]
    except KeyError:
        raise ValueError(f"unknown camera preset {name!r}; valid: {sorted(CAMERA_PRESETS)}") from None


def project_drive(pattern: np.ndarray) -> np.ndarray:
    """Projector drive from an 8-bit pattern: linear response (LightCrafter pattern mode).

    Returns
    -------
    ndarray, shape (H, W, 3), float32 in [0, 1]
    """
    if pattern.dtype != np.uint8:
        raise ValueError(f"the projector takes 8-bit patterns, got {pattern.dtype}")
    return pattern.astype(np.float32) / 255.0


def simple_camera(radiance: np.ndarray, *, camera: SimpleCamera, rng=None) -> np.ndarray:
    """Radiance -> recorded image: exposure, Poisson shot noise, Gaussian read noise,
    full-well clipping and ADC quantisation.

    Parameters
    ----------
    radiance : ndarray, shape (H, W, 3), float32
        Linear radiance from :func:`simbench.render.render_radiance`.
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

PLANCK_J_S = 6.62607015e-34
LIGHT_M_S = 299_792_458.0


def photons_per_unit_radiance(
    *,
    irradiance_1m_w_m2: float,
    wavelength_nm: float,
    f_number: float,
    pixel_pitch_um: float,
    exposure_s: float,
    lens_transmission: float = 0.9,
) -> float:
    """Mean photons reaching one pixel during the exposure per unit of *rendered* radiance.

    A rendered radiance of 1 is what a white Lambertian surface facing the projector at 1 m
    sends back under full drive (see :func:`simbench.render.render_radiance`): physical radiance
    ``L = E_1m / pi`` for a projector irradiance ``E_1m`` at 1 m.  A lens of f-number N and
    transmission tau focused far away puts ``E_s = pi * tau * L / (4 N^2)`` on the sensor
    (camera equation, on axis, magnification and cos^4 fall-off neglected); a pixel of area
    A collects ``E_s * A * t`` joules, i.e. that divided by ``h c / lambda`` photons.
    """
    for name, v in (("irradiance_1m_w_m2", irradiance_1m_w_m2), ("wavelength_nm", wavelength_nm), ("f_number", f_number), ("pixel_pitch_um", pixel_pitch_um), ("exposure_s", exposure_s)):
        if not v > 0:
            raise ValueError(f"{name} must be > 0, got {v}")
    if not 0 < lens_transmission <= 1:
        raise ValueError(f"lens_transmission must be in (0, 1], got {lens_transmission}")
    sensor_irradiance = lens_transmission * irradiance_1m_w_m2 / (4.0 * f_number**2)
    energy = sensor_irradiance * (pixel_pitch_um * 1e-6) ** 2 * exposure_s
    return float(energy * wavelength_nm * 1e-9 / (PLANCK_J_S * LIGHT_M_S))


@dataclass(frozen=True)
class EmvaCamera:
    """A linear camera after the EMVA 1288 model (release 3.1/4.0, Sec. 2).

    photons ``mu_p`` -> electrons ``eta * mu_p`` (Poisson) + dark electrons (Poisson, dark
    current x exposure) + temporal dark noise ``sigma_d`` (Gaussian, e-) -> clipped at the
    full well -> ``y = K * e + offset`` DN, rounded and clipped to the ADC range.  Optional
    fixed-pattern noise: PRNU (relative gain spread) and DSNU (offset spread, e-), drawn once
    from ``fixed_pattern_seed`` - a property of the sensor, the same in every frame.

    Attributes
    ----------
    qe : tuple of 3 float
        Quantum efficiency eta per colour channel (R, G, B) at the light's wavelength.
    photons_per_radiance : float
        Mean photons per pixel per unit rendered radiance (:func:`photons_per_unit_radiance`).
    full_well_e : float
        Saturation capacity, electrons.
    dark_noise_e : float
        Temporal dark noise sigma_d, electrons RMS.
    gain_dn_per_e : float
        Overall system gain K, DN per electron.
    bits : int
        ADC bit depth.
    offset_dn : float
        Dark offset (black level), DN.
    dark_current_e_s, exposure_s : float
        Dark current (e-/s) and exposure time (s).
    prnu, dsnu_e : float
        Photo-response non-uniformity (relative, 1 sigma) and dark-signal non-uniformity (e-).
    fixed_pattern_seed : int
    """

    qe: tuple[float, float, float]
    photons_per_radiance: float
    full_well_e: float
    dark_noise_e: float
    gain_dn_per_e: float
    bits: int = 8
    offset_dn: float = 0.0
    dark_current_e_s: float = 0.0
    exposure_s: float = 0.01
    prnu: float = 0.0
    dsnu_e: float = 0.0
    fixed_pattern_seed: int = 0

    def __post_init__(self) -> None:
        if len(self.qe) != 3 or not all(0 < q <= 1 for q in self.qe):
            raise ValueError(f"qe must be three numbers in (0, 1], got {self.qe}")
        for name in ("photons_per_radiance", "full_well_e", "gain_dn_per_e", "exposure_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        for name in ("dark_noise_e", "offset_dn", "dark_current_e_s", "prnu", "dsnu_e"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if self.bits not in (8, 10, 12, 16):
            raise ValueError(f"bits must be one of 8, 10, 12, 16; got {self.bits}")
        object.__setattr__(self, "qe", tuple(float(q) for q in self.qe))

    @property
    def max_dn(self) -> int:
        return (1 << self.bits) - 1


def emva_camera(radiance: np.ndarray, *, camera: EmvaCamera, rng=None) -> np.ndarray:
    """Rendered radiance -> recorded image through the EMVA 1288 model (:class:`EmvaCamera`).

    Parameters
    ----------
    radiance : ndarray, shape (H, W, 3), float
    camera : EmvaCamera
    rng : numpy.random.Generator | int | None
        Temporal-noise seed (the fixed pattern comes from ``camera.fixed_pattern_seed``).

    Returns
    -------
    ndarray, shape (H, W, 3), uint8 (8 bits) or uint16
    """
    rad = np.asarray(radiance, dtype=np.float64)
    if rad.ndim != 3 or rad.shape[2] != 3:
        raise ValueError(f"radiance must have shape (H, W, 3), got {rad.shape}")
    if not np.all(np.isfinite(rad)):
        raise ValueError("radiance contains NaN or inf")
    gen = np.random.default_rng(rng)
    mean_e = np.clip(rad, 0.0, None) * camera.photons_per_radiance * np.asarray(camera.qe)
    if camera.prnu > 0 or camera.dsnu_e > 0:
        fp = np.random.default_rng(camera.fixed_pattern_seed)
        mean_e = mean_e * np.clip(1.0 + camera.prnu * fp.standard_normal(rad.shape), 0.0, None)
        dark_fp = camera.dsnu_e * fp.standard_normal(rad.shape)
    else:
        dark_fp = 0.0
    dark_e = camera.dark_current_e_s * camera.exposure_s
    electrons = gen.poisson(np.minimum(mean_e + dark_e, 1e12)).astype(np.float64)
    electrons += dark_fp
    if camera.dark_noise_e > 0:
        electrons += gen.normal(0.0, camera.dark_noise_e, size=rad.shape)
    electrons = np.minimum(electrons, camera.full_well_e)
    dn = np.clip(np.rint(camera.gain_dn_per_e * electrons + camera.offset_dn), 0, camera.max_dn)
    return dn.astype(np.uint8 if camera.bits == 8 else np.uint16)


def photon_transfer(frame_a: np.ndarray, frame_b: np.ndarray, dark_a: np.ndarray, dark_b: np.ndarray) -> tuple[float, float]:
    """EMVA 1288 photon-transfer point from two frames at one exposure and two dark frames:
    (mean signal above dark, temporal variance above dark), both in DN / DN^2.

    The temporal variance is ``var(a - b) / 2`` (the difference cancels fixed-pattern noise).
    """
    a, b, da, db = (np.asarray(x, dtype=np.float64) for x in (frame_a, frame_b, dark_a, dark_b))
    mean = 0.5 * (a.mean() + b.mean()) - 0.5 * (da.mean() + db.mean())
    var = 0.5 * np.var(a - b) - 0.5 * np.var(da - db)
    return float(mean), float(var)
