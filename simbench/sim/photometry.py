"""Photometry: from the projector's lumens to electrons in each camera pixel.

The chain of the ``emva`` camera (:mod:`simbench.sim.sensor` holds the sensor model): the
projector's white gives ``lumens / A`` lux at 1 m (:func:`white_lux_at_1m`, ``A`` = its
frustum's cross-section at 1 m), split into primaries balanced to D65
(:func:`primary_irradiance_w_m2`); a rendered radiance of 1 for primary ``p`` is the radiance
``E_p / pi`` of a white Lambertian surface 1 m in front of it, which the camera equation turns
into photons per pixel (:func:`photons_per_unit_radiance`) and the channel's quantum efficiency
into electrons (:func:`electrons_per_radiance_s`).  The auto exposure (:func:`exposure_s`) and
the One Push white balance (:func:`white_balance_gains`) are set once on the white reference
board at Z0.

References
----------
.. [1] EMVA Standard 1288, Release 4.0, "Standard for Characterization of Image Sensors and
   Cameras", 2021 (the camera equation, photon transfer).
.. [2] Point Grey, "Flea3 USB 3.0 Technical Reference", Sec. 7.8 (One Push white balance).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from simbench.sim.camera import MAX_EXPOSURE_S
from simbench.sim.sensor import PhysicalCamera, SensorModel
from simbench.rig import Rig

if TYPE_CHECKING:
    from simbench.sim.scene import SceneSpec

REFERENCE_ALBEDO = 0.8  # assumption: a matte white board as the reference plane


def white_board(scene: SceneSpec) -> dict:
    """The white reference board the camera's exposure and white balance are set on: the
    keyword arguments of :func:`exposure_s` and :func:`white_balance_gains` for ``scene``."""
    return {
        "reference_depth_m": scene.reference_depth_m,
        "reference_albedo": REFERENCE_ALBEDO,
        "projector_scale": scene.projector_scale,
    }


__all__ = [
    "PLANCK_J_S",
    "LIGHT_M_S",
    "photons_per_unit_radiance",
    "primary_irradiance_w_m2",
    "white_lux_at_1m",
    "electrons_per_radiance_s",
    "white_balance_gains",
    "exposure_s",
    "channel_weights",
]

# SI defining constants (exact since the 2019 redefinition)
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
    sends back under full drive (see :func:`simbench.sim.render.render_radiance`): physical radiance
    ``L = E_1m / pi`` for a projector irradiance ``E_1m`` at 1 m.  A lens of f-number N and
    transmission tau focused far away puts ``E_s = pi * tau * L / (4 N^2)`` on the sensor
    (camera equation, on axis, magnification and cos^4 fall-off neglected); a pixel of area
    A collects ``E_s * A * t`` joules, i.e. that divided by ``h c / lambda`` photons.

    References
    ----------
    .. [1] EMVA Standard 1288, Release 4.0, 2021, Sec. 2 (the camera equation).
    """
    for name, v in (
        ("irradiance_1m_w_m2", irradiance_1m_w_m2),
        ("wavelength_nm", wavelength_nm),
        ("f_number", f_number),
        ("pixel_pitch_um", pixel_pitch_um),
        ("exposure_s", exposure_s),
    ):
        if not v > 0:
            raise ValueError(f"{name} must be > 0, got {v}")
    if not 0 < lens_transmission <= 1:
        raise ValueError(f"lens_transmission must be in (0, 1], got {lens_transmission}")
    sensor_irradiance = lens_transmission * irradiance_1m_w_m2 / (4.0 * f_number**2)
    energy = sensor_irradiance * (pixel_pitch_um * 1e-6) ** 2 * exposure_s
    return float(energy * wavelength_nm * 1e-9 / (PLANCK_J_S * LIGHT_M_S))


def primary_irradiance_w_m2(white_lux: float) -> np.ndarray:
    """Radiometric irradiance (W/m^2) of each primary when the projector's full white gives
    ``white_lux`` lux.

    The white is assumed balanced to D65 (**assumption**: the usual white point of DLP
    projectors' video modes; TI does not publish the LightCrafter 4500's): the three primaries'
    luminances are the mix whose CIE 1931 XYZ has D65's chromaticity, and each primary's lux
    are turned into watts by its LED spectrum's luminous efficacy (683 lm/W x V-weighted,
    :func:`simbench.sim.spectral.watts_per_lux`).

    Returns
    -------
    ndarray, shape (3,), float64 (R, G, B primaries)
    """
    from simbench.sim.spectral import watts_per_lux

    if not white_lux > 0:
        raise ValueError(f"white_lux must be > 0, got {white_lux}")
    return white_lux * watts_per_lux()


def white_lux_at_1m(sensor: SensorModel, rig: Rig) -> float:
    """Illuminance (lux) of the projector's full white on a surface facing it at 1 m: its
    luminous flux over the frustum's cross-section there (uniform field assumed)."""
    prj = rig.projector
    area_m2 = (prj.width_px / prj.focal_px) * (prj.height_px / prj.focal_px)
    return sensor.projector.lumens / area_m2


def electrons_per_radiance_s(sensor: SensorModel, rig: Rig) -> np.ndarray:
    """Electrons per second in camera channel ``p`` per unit rendered radiance of primary ``p``
    (module docstring), shape (3,).  Needs the physical camera."""
    from simbench.sim.spectral import PRIMARY_PEAKS_NM

    cam = sensor.camera
    if not isinstance(cam, PhysicalCamera):
        raise ValueError("photometry needs the physical (emva) camera model")
    irr = primary_irradiance_w_m2(white_lux_at_1m(sensor, rig))
    lens = sensor.camera_lens
    photons = np.array(
        [
            photons_per_unit_radiance(
                irradiance_1m_w_m2=e,
                wavelength_nm=wl,
                f_number=lens.f_number,
                pixel_pitch_um=cam.pixel_pitch_um,
                exposure_s=1.0,
                lens_transmission=lens.transmission,
            )
            for e, wl in zip(irr, PRIMARY_PEAKS_NM)
        ]
    )
    return photons * np.asarray(cam.qe)


def _reference_matrix(sensor: SensorModel, albedo: float) -> np.ndarray:
    if sensor.crosstalk:
        from simbench.sim.spectral import crosstalk_matrix

        return crosstalk_matrix((albedo,) * 3)
    return albedo * np.eye(3)


def _white_board_electrons_s(
    sensor: SensorModel, rig: Rig, *, reference_depth_m: float, reference_albedo: float, projector_scale: float
) -> np.ndarray:
    """Electrons per second in each camera channel from the white board at Z0 under the
    projector's full white, shape (3,)."""
    rate = electrons_per_radiance_s(sensor, rig)
    k = _reference_matrix(sensor, reference_albedo)
    return (k * rate[None, :]).sum(axis=1) * projector_scale / reference_depth_m**2


def white_balance_gains(
    sensor: SensorModel, rig: Rig, *, reference_depth_m: float, reference_albedo: float, projector_scale: float = 1.0
) -> np.ndarray:
    """The camera's analogue gain per colour channel relative to green, shape (3,).

    ``off``: (1, 1, 1).  ``one_push``: the Flea3's One Push on the white reference board at Z0
    under the projector's full white (the room light, of the same white in our model, does not
    change the ratios): red and blue scaled so that the board reads 1:1:1 (Point Grey Flea3
    USB 3.0 Technical Reference, Sec. 7.8), green left at 1.  The gain acts before the ADC (the
    PxGA white-balance stage of the Flea3's A/D converter, ibid. "Gain"), so a boosted channel
    reaches the top of the ADC range before its pixels reach full well.
    """
    cam = sensor.camera
    if not isinstance(cam, PhysicalCamera) or cam.white_balance == "off":
        return np.ones(3)
    board = _white_board_electrons_s(
        sensor,
        rig,
        reference_depth_m=reference_depth_m,
        reference_albedo=reference_albedo,
        projector_scale=projector_scale,
    )
    return board[1] / board


def exposure_s(
    sensor: SensorModel, rig: Rig, *, reference_depth_m: float, reference_albedo: float, projector_scale: float = 1.0
) -> float:
    """The camera's exposure time: the configured one, or auto exposure (module docstring),
    which brings the brightest white-balanced channel of the board to the set fraction."""
    cam = sensor.camera
    if not isinstance(cam, PhysicalCamera):
        raise ValueError("exposure time needs the physical (emva) camera model")
    if cam.exposure_s is not None:
        return cam.exposure_s
    kw = {
        "reference_depth_m": reference_depth_m,
        "reference_albedo": reference_albedo,
        "projector_scale": projector_scale,
    }
    board = _white_board_electrons_s(sensor, rig, **kw) * white_balance_gains(sensor, rig, **kw)
    t = float(cam.auto_exposure_fraction * cam.full_well_e / board.max())
    if t > MAX_EXPOSURE_S:
        # (an audit: a pixel pitch written in mm made it 13106 s, and the capture all dark current)
        raise ValueError(
            f"sensor {sensor.name!r}: the auto exposure comes to {t:.4g} s, longer than an exposure_s may be "
            f"({MAX_EXPOSURE_S:g} s): the white board at {reference_depth_m:g} m gets {board.max():.3g} e-/s - check "
            f"the camera's pixel_pitch_um ({cam.pixel_pitch_um:g} um), qe and lens f_number, and the projector's lumens"
        )
    return t


def channel_weights(sensor: SensorModel, rig: Rig) -> np.ndarray:
    """W[c, p] = e_p / e_c: how much primary ``p``'s rendered radiance in camera channel ``c``
    weighs relative to channel ``c``'s own primary (1 for the simple camera), shape (3, 3)."""
    if not sensor.is_physical:
        return np.ones((3, 3))
    e = electrons_per_radiance_s(sensor, rig)
    return e[None, :] / e[:, None]
