"""Subsurface scattering of translucent materials, by the dipole diffusion model.

Light entering a translucent surface leaves it displaced: a point of irradiance comes back as a
spot whose radial profile, for a semi-infinite homogeneous medium, is the dipole diffuse
reflectance ``R_d(r)`` of Jensen, Marschner, Levoy & Hanrahan (2001, Eq. 4-5)::

    sigma_t' = sigma_s' + sigma_a,  alpha' = sigma_s' / sigma_t',  sigma_tr = sqrt(3 sigma_a sigma_t')
    z_r = 1 / sigma_t',  z_v = z_r (1 + 4 A / 3),  A = (1 + F_dr) / (1 - F_dr)
    F_dr = -1.440 / eta^2 + 0.710 / eta + 0.668 + 0.0636 eta
    R_d(r) = alpha' / (4 pi) [z_r (1 + sigma_tr d_r) e^(-sigma_tr d_r) / d_r^3
                              + z_v (1 + sigma_tr d_v) e^(-sigma_tr d_v) / d_v^3],  d = sqrt(r^2 + z^2)

Each term is ``-d/dz`` of ``e^(-sigma_tr d) / d``, whose 2-D Fourier transform is
``2 pi e^(-z q) / q`` with ``q = sqrt(sigma_tr^2 + k^2)``, so the profile's transform has the
closed form ``alpha' / 2 [e^(-z_r q) + e^(-z_v q)]``: a fringe of angular spatial frequency ``k``
on a translucent plane keeps the fraction :func:`dipole_mtf` of its contrast (tested against the
numerical transform and against a fringe blurred by :func:`subsurface_image`).

The render keeps each material's diffuse reflectance (its ``rgb``, the total the profile
integrates to) and redistributes the light it reflects with the normalised profile
(:func:`subsurface_image`): on the camera's image, per object and per colour channel, with the
profile scaled by the object's pixel footprint at its median depth, never across objects: exact
for a fronto-parallel face away from its outline; an approximation on curved and oblique faces
(the footprint grows by 1 / cos of the tilt across the profile) and within a profile's reach of
an outline, where each pixel averages the object's light it can reach (the light that would leave
the object through its outline stays in it instead).  Single scattering and the specular interface
are left out (a matte surface's reflection is diffuse).

Media (:data:`MEDIA`): measured coefficients of Jensen et al. 2001 (their Table 1, in mm^-1 for
the red, green and blue bands; relative index 1.3 as they use), and ``plaster``, for which no
measurement is known to us: the geometric mean of the reduced scattering of marble and
Spectralon (a translucent stone and the least translucent white diffuser measured) with marble's
absorption (both gypsum and calcite are near-white minerals), an assumption; Table 3's what-if
rows bracket it with marble and Spectralon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from simbench import validate

__all__ = [
    "Medium",
    "MEDIA",
    "get_medium",
    "dipole_profile",
    "dipole_mtf",
    "modulation_transfer",
    "subsurface_image",
]


@dataclass(frozen=True)
class Medium:
    """A homogeneous scattering medium: reduced scattering and absorption coefficients per colour
    band (R, G, B), mm^-1, and the relative index of refraction of its surface."""

    sigma_s_prime_per_mm: tuple[float, float, float]
    sigma_a_per_mm: tuple[float, float, float]
    eta: float = 1.3

    def __post_init__(self) -> None:
        v = validate
        object.__setattr__(
            self,
            "sigma_s_prime_per_mm",
            v.numbers(list(self.sigma_s_prime_per_mm), "sigma_s'", 3, lo=0.0, lo_open=True),
        )
        object.__setattr__(self, "sigma_a_per_mm", v.numbers(list(self.sigma_a_per_mm), "sigma_a", 3, lo=0.0))
        object.__setattr__(self, "eta", v.number(self.eta, "eta", lo=1.0, hi=3.0))

    def dipole(self, channel: int) -> tuple[float, float, float, float]:
        """(alpha', sigma_tr, z_r, z_v) of one colour band (module docstring)."""
        ss, sa = self.sigma_s_prime_per_mm[channel], self.sigma_a_per_mm[channel]
        st = ss + sa
        f_dr = -1.440 / self.eta**2 + 0.710 / self.eta + 0.668 + 0.0636 * self.eta
        a = (1.0 + f_dr) / (1.0 - f_dr)
        zr = 1.0 / st
        return ss / st, math.sqrt(3.0 * sa * st), zr, zr * (1.0 + 4.0 * a / 3.0)


def _between(a: Medium, b: Medium) -> Medium:
    """The geometric mean of two media's reduced scattering, with the first one's absorption."""
    return Medium(
        tuple(math.sqrt(x * y) for x, y in zip(a.sigma_s_prime_per_mm, b.sigma_s_prime_per_mm)), a.sigma_a_per_mm
    )


# Jensen, Marschner, Levoy & Hanrahan, "A Practical Model for Subsurface Light Transport",
# SIGGRAPH 2001, Table 1 (sigma_s', sigma_a in mm^-1 for R, G, B)
MEDIA: dict[str, Medium] = {
    "marble": Medium((2.19, 2.62, 3.00), (0.0021, 0.0041, 0.0071)),
    "spectralon": Medium((11.6, 20.4, 14.9), (0.0, 0.0, 0.0)),
    "skin1": Medium((0.74, 0.88, 1.01), (0.032, 0.17, 0.48)),
    "wholemilk": Medium((2.55, 3.21, 3.77), (0.0011, 0.0024, 0.014)),
}
MEDIA["plaster"] = _between(MEDIA["marble"], MEDIA["spectralon"])  # assumption, module docstring


def get_medium(name: str) -> Medium:
    """A medium of :data:`MEDIA` by name; the error lists the valid names."""
    if not isinstance(name, str) or name not in MEDIA:
        raise ValueError(f"unknown subsurface medium {name!r}; valid: {sorted(MEDIA)}")
    return MEDIA[name]


def dipole_profile(r_mm: np.ndarray, medium: Medium, channel: int) -> np.ndarray:
    """The dipole diffuse reflectance ``R_d(r)`` (mm^-2) of one colour band (module docstring)."""
    alpha, tr, zr, zv = medium.dipole(channel)
    r2 = np.asarray(r_mm, dtype=np.float64) ** 2
    out = np.zeros_like(r2)
    for z in (zr, zv):
        d = np.sqrt(r2 + z * z)
        out += z * (1.0 + tr * d) * np.exp(-tr * d) / d**3
    return alpha / (4.0 * math.pi) * out


def dipole_mtf(k_per_mm: np.ndarray, medium: Medium, channel: int) -> np.ndarray:
    """The fraction of a fringe's contrast left at angular spatial frequency ``k`` (rad/mm): the
    profile's 2-D Fourier transform over its total (module docstring)."""
    _, tr, zr, zv = medium.dipole(channel)
    q = np.sqrt(tr * tr + np.asarray(k_per_mm, dtype=np.float64) ** 2)
    return (np.exp(-zr * q) + np.exp(-zv * q)) / (math.exp(-zr * tr) + math.exp(-zv * tr))


def modulation_transfer(medium: Medium, channel: int, *, frequency_hz: float) -> complex:
    """What a translucent surface does to intensity-modulated light (a time-of-flight camera's):
    the complex ratio of its diffuse reflectance at modulation frequency ``f`` to its steady
    one, whose argument is the phase lag of the light that paths inside the medium delay.

    In time, the diffusion equation's absorption term is ``sigma_a v`` (``v = c / eta``, the
    speed in the medium), so the transform of the dipole's time-resolved total reflectance at
    ``-i omega`` (Patterson, Chance & Wilson 1989: ``R(t) ~ sum_z z t^-3/2 exp(-sigma_a v t -
    z^2 / 4 D v t)``, ``D = 1 / 3 sigma_t'``) replaces ``sigma_a`` by ``sigma_a - i omega
    eta / c`` in ``sigma_tr``: ``R(omega) / R(0) = [e^(-z_r s) + e^(-z_v s)] / [e^(-z_r sigma_tr)
    + e^(-z_v sigma_tr)]``, ``s = sqrt(3 sigma_t' (sigma_a - i omega eta / c))`` (``D`` held at
    its steady value, the source depths as in :meth:`Medium.dipole`).  Positive argument = delay,
    the sign of a path's phase ``2 pi f L / c``; a pixel's distance reads ``arg c / (4 pi f)``
    long.  Tested against the quadrature of ``R(t)``.
    """
    from simbench.sim.photometry import LIGHT_M_S

    _, tr, zr, zv = medium.dipole(channel)
    ss, sa = medium.sigma_s_prime_per_mm[channel], medium.sigma_a_per_mm[channel]
    omega_per_mm = 2.0 * math.pi * float(frequency_hz) * medium.eta / (LIGHT_M_S * 1000.0)
    s = np.sqrt(3.0 * (ss + sa) * complex(sa, -omega_per_mm))
    return complex((np.exp(-zr * s) + np.exp(-zv * s)) / (math.exp(-zr * tr) + math.exp(-zv * tr)))


# the profile is cut where its remaining energy is below this share (tail of the kernel), and
# each pixel of the kernel integrates the profile over SUBSAMPLES x SUBSAMPLES points (its peak
# is narrower than a pixel for dense media)
TAIL_ENERGY = 1e-3
SUBSAMPLES = 8
MAX_KERNEL_PX = 401


@lru_cache(maxsize=64)
def _kernel(medium: Medium, channel: int, mm_per_px: float) -> np.ndarray:
    _, tr, zr, zv = medium.dipole(channel)
    # radius holding all but ~TAIL_ENERGY of the profile: its exponential decay, or for an
    # absorption-free medium its 1/r^3 fall-off, whose energy beyond R is ~z_v / R (capped at
    # MAX_KERNEL_PX: a Spectralon-like medium then loses ~0.3 % of its tail at 1 m)
    radius_mm = max(10.0 * zv, math.log(1.0 / TAIL_ENERGY) / tr if tr > 0 else zv / TAIL_ENERGY)
    half = int(min(math.ceil(radius_mm / mm_per_px), MAX_KERNEL_PX // 2))
    offs = (np.arange(SUBSAMPLES) + 0.5) / SUBSAMPLES - 0.5
    grid = np.arange(-half, half + 1, dtype=np.float64)
    k = np.zeros((2 * half + 1, 2 * half + 1))
    for dy in offs:
        for dx in offs:
            r = np.hypot((grid[:, None] + dy) * mm_per_px, (grid[None, :] + dx) * mm_per_px)
            k += dipole_profile(r, medium, channel)
    out = (k / k.sum()).astype(np.float32)
    out.setflags(write=False)
    return out


def subsurface_image(
    image: np.ndarray,
    *,
    object_id: np.ndarray,
    depth_m: np.ndarray,
    media: dict[int, Medium],
    focal_px: float,
) -> np.ndarray:
    """``image`` with the light each translucent object reflects redistributed by its dipole
    profile (module docstring).

    Parameters
    ----------
    image : ndarray, shape (H, W, 3), float32; radiance on the camera's ideal pixel grid
    object_id : ndarray, shape (H, W), int; the object seen at each pixel (-1: none)
    depth_m : ndarray, shape (H, W), float; z-depth (NaN where nothing is seen)
    media : {object index: Medium}; objects not named are left as they are
    focal_px : float; the camera's focal length (pixels)

    Returns
    -------
    ndarray, shape (H, W, 3), float32 (``image`` itself when ``media`` is empty)
    """
    import cv2

    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 3 or img.shape[2] != 3 or img.shape[:2] != np.shape(object_id) or img.shape[:2] != np.shape(depth_m):
        raise ValueError(f"image {img.shape}, object_id {np.shape(object_id)} and depth {np.shape(depth_m)} differ")
    if not media:
        return image
    out = img.copy()
    for idx, medium in media.items():
        mask = np.asarray(object_id) == idx
        if not mask.any():
            continue
        depths = np.asarray(depth_m, dtype=np.float64)[mask]
        depths = depths[np.isfinite(depths) & (depths > 0)]
        if not depths.size:
            continue  # nothing of it has a depth: no footprint to scale the profile by
        mm_per_px = round(1000.0 * float(np.median(depths)) / float(focal_px), 9)
        m = mask.astype(np.float32)
        for c in range(3):
            k = _kernel(medium, c, mm_per_px)
            num = cv2.filter2D(img[..., c] * m, -1, k, borderType=cv2.BORDER_CONSTANT)
            den = cv2.filter2D(m, -1, k, borderType=cv2.BORDER_CONSTANT)
            with np.errstate(divide="ignore", invalid="ignore"):
                spread = np.where(den > 1e-6, num / den, img[..., c])
            out[..., c] = np.where(mask, spread, out[..., c])
    return out
