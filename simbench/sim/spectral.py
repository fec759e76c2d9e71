"""Spectral crosstalk between the projector's primaries and the camera's colour channels.

For a diffuse surface of spectral reflectance rho, the camera channel c records from projector
primary p in proportion to ``integral S_c(l) rho(l) P_p(l) dl``.  We normalise by the matching
channel's response to the same primary on a perfect white, so that a white surface has ones on
the diagonal and its off-diagonal entries are the crosstalk ratios:

    K[c, p] = integral S_c rho P_p / integral S_p P_p

(the operator balances the projector's primaries for the camera on a white board).

Data and assumptions (nothing here is fitted to the paper's results):

* Projector primaries: LED spectra from colour-science's ``sd_single_led`` (Ohno 2005 model)
  peaking at 620 / 522 / 455 nm with full widths at half maximum of 20 / 35 / 20 nm.
  **Assumption**: typical red, green and blue LEDs of DLP pico projectors; TI does not publish
  the DLP LightCrafter 4500's LED spectra.
* Camera: ``Nikon 5100 (NPL)`` from colour-science's camera sensitivity datasets, standing in
  for the Flea3 FL3-U3-13E4C (e2v EV76C560 with a Bayer filter), whose spectral curves are not
  in any public dataset we can use.  Both are CMOS sensors with an RGB Bayer mosaic behind an
  IR-cut filter; the other dataset (Sigma SD Merrill) is a stacked Foveon sensor, a different
  principle, hence the choice.  **Assumption** with that reasoning.
* Measured surfaces: the reflectance spectra of colour-science's ColorChecker datasets
  (:data:`MEASURED_DATASETS`), named ``"<dataset>/<patch>"`` in scene files.
* Other surface spectra from a material's linear RGB reflectance by Mallett & Yuksel 2019
  (``RGB_to_sd_Mallett2019``): a bounded, smooth reflectance in [0, 1] that reproduces the RGB
  under sRGB/D65, linear in the RGB, so crosstalk of any material is a fixed blend of three
  basis matrices.
* Metals (:data:`METALS`): the complex refractive index n + ik of the bulk metal, tabulated over
  wavelength in the optical-constants files Mitsuba ships (``mitsuba/data/ior``: the luxpop.com
  database and Palik's *Handbook of Optical Constants of Solids*, as their headers say).  A
  metal reflects at the surface only; its reflectance at normal incidence is the Fresnel
  ``R0 = ((n-1)^2 + k^2) / ((n+1)^2 + k^2)`` (Born & Wolf, *Principles of Optics*, Sec. 14.2),
  and its crosstalk is that of the spectrum R0 (:func:`metal_crosstalk`).
"""

from __future__ import annotations

import functools
import hashlib
import json
import warnings
from collections.abc import Callable, Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np

from simbench.cache import user_cache_dir
from simbench.io import atomic_write_text, read_json_dict

__all__ = [
    "memo_path",
    "watts_per_lux",
    "MEASURED_DATASETS",
    "measured_reflectance",
    "measured_linear_srgb",
    "material_crosstalk",
    "PRIMARY_PEAKS_NM",
    "PRIMARY_FWHM_NM",
    "CAMERA_DATASET",
    "wavelengths_nm",
    "projector_primaries",
    "camera_sensitivities",
    "reflectance_spectrum",
    "crosstalk_matrix",
    "METALS",
    "metal_ior",
    "metal_ior_rgb",
    "conductor_fresnel",
    "metal_reflectance",
    "metal_crosstalk",
]

PRIMARY_PEAKS_NM = (620.0, 522.0, 455.0)  # assumption, see module docstring
PRIMARY_FWHM_NM = (20.0, 35.0, 20.0)  # assumption
CAMERA_DATASET = "Nikon 5100 (NPL)"  # stands in for the Flea3 FL3-U3-13E4C (module docstring)


# What the renders need from colour-science - a few numbers per material and sensor - is kept on
# disk, so that a rerun does not import it (~1.3 s: colour imports SciPy and matplotlib).  The
# memo file is named by colour-science's version and this file's bytes (constants and code), its
# entries by function and arguments; values are stored as Python floats (exact round trip).
# SIMBENCH_CACHE_DIR sets its folder (default: $XDG_CACHE_HOME/simbench or ~/.cache/simbench);
# set to an empty string it turns the memo off.
_MEMO: dict | None = None


def memo_path() -> Path | None:
    """The file of the spectral memo (see above), or None when it is off."""
    root = user_cache_dir()
    if root is None:
        return None
    from importlib import metadata

    try:
        version = metadata.version("colour-science")
    except metadata.PackageNotFoundError:
        return None
    # simbench.cache._MEMO_RE knows this name (a render cache in the same folder tolerates it)
    return Path(root) / f"spectral-colour{version}-{_source_digest()}.json"


@lru_cache(maxsize=1)
def _source_digest() -> str:
    return hashlib.sha256(Path(__file__).read_bytes()).hexdigest()[:16]


def _persistent(fn: Callable) -> Callable:
    """``fn`` (hashable arguments; an array or a tuple of floats out) remembered in the memo
    file: computed at most once per colour-science version and version of this module."""

    @functools.wraps(fn)
    def wrapper(*args):
        global _MEMO
        path = memo_path()
        key = f"{fn.__name__}{args!r}"
        if path is not None:
            if _MEMO is None:
                _MEMO = read_json_dict(path)
            hit = _MEMO.get(key)
            if isinstance(hit, dict) and hit.get("kind") in ("array", "tuple"):
                if hit["kind"] == "tuple":
                    return tuple(float(x) for x in hit["value"])
                out = np.asarray(hit["value"], dtype=np.float64)
                out.setflags(write=False)
                return out
        value = fn(*args)
        if path is not None:
            entry = {"kind": "tuple" if isinstance(value, tuple) else "array", "value": np.asarray(value).tolist()}
            _MEMO[key] = entry
            try:  # merge with what other processes wrote meanwhile; replace atomically
                atomic_write_text(path, json.dumps({**read_json_dict(path), key: entry}))
            except OSError:
                pass  # an unwritable cache folder costs time, not results
        return value

    return wrapper


def _colour():
    """colour-science, imported so that it cannot poison the interpreter.

    Without SciPy, colour-science puts a ``MagicMock`` into ``sys.modules["scipy"]`` and makes
    its spline interpolators subclasses of it; a package imported later that reads SciPy's
    version (numba, scikit-image) then fails on the mock, and colour's SciPy-backed features
    would return mocks instead of numbers.
    SciPy is therefore a dependency of simbench; if it is missing anyway we fail here, with the
    fix, instead of later with a riddle.
    """
    import sys
    import types

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    if not isinstance(sys.modules.get("scipy"), types.ModuleType):
        for name in [n for n in sys.modules if n == "scipy" or n.startswith("scipy.")]:
            if not isinstance(sys.modules[name], types.ModuleType):
                del sys.modules[name]
        raise ImportError(
            "colour-science could not import SciPy, which simbench needs; install it: pip install 'scipy>=1.13'"
        )
    return colour


@lru_cache(maxsize=1)
def _shape():
    return _colour().SpectralShape(380, 780, 5)


def wavelengths_nm() -> np.ndarray:
    """The common wavelength grid, 380-780 nm in 5 nm steps."""
    return np.asarray(_shape().wavelengths, dtype=np.float64)


@lru_cache(maxsize=4)
def projector_primaries() -> np.ndarray:
    """Relative spectral power of the R, G, B primaries on :func:`wavelengths_nm`, shape (N, 3)."""
    colour = _colour()
    cols = []
    for peak, fwhm in zip(PRIMARY_PEAKS_NM, PRIMARY_FWHM_NM):
        sd = colour.sd_single_led(peak, half_spectral_width=fwhm, shape=colour.SpectralShape(360, 830, 1))
        cols.append(np.asarray(sd.copy().align(_shape()).values, dtype=np.float64))
    out = np.stack(cols, axis=1)
    out.setflags(write=False)
    return out


@lru_cache(maxsize=4)
def camera_sensitivities() -> np.ndarray:
    """Relative spectral sensitivities of the camera's R, G, B channels, shape (N, 3)."""
    colour = _colour()
    from colour.characterisation import MSDS_CAMERA_SENSITIVITIES

    msds = MSDS_CAMERA_SENSITIVITIES[CAMERA_DATASET].copy().align(_shape())
    out = np.asarray(msds.values, dtype=np.float64)
    out.setflags(write=False)
    del colour
    return out


def reflectance_spectrum(rgb: Sequence[float]) -> np.ndarray:
    """Spectral reflectance (on :func:`wavelengths_nm`) of a linear-RGB diffuse reflectance."""
    v = np.asarray(rgb, dtype=np.float64)
    if v.shape != (3,) or not np.all((v >= 0) & (v <= 1)):
        raise ValueError(f"rgb reflectance must be three numbers in [0, 1], got {rgb!r}")
    _colour()
    from colour.recovery import RGB_to_sd_Mallett2019

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sd = RGB_to_sd_Mallett2019(v)
    return np.asarray(sd.copy().align(_shape()).values, dtype=np.float64)


def crosstalk_matrix(rgb: Sequence[float]) -> np.ndarray:
    """K[c, p]: camera channel c's response to projector primary p reflected by a diffuse
    surface of linear RGB reflectance ``rgb``, relative to channel p's response to primary p
    on a perfect white (module docstring).  Shape (3, 3), rows = camera R, G, B."""
    # a hashable key for the cache; reflectance_spectrum validates it
    return _crosstalk_matrix(tuple(float(x) for x in np.ravel(rgb))).copy()


@lru_cache(maxsize=256)
@_persistent
def _crosstalk_matrix(rgb: tuple[float, float, float]) -> np.ndarray:
    return _crosstalk_of(reflectance_spectrum(rgb))


def _crosstalk_of(rho: np.ndarray) -> np.ndarray:
    """K of a spectral reflectance ``rho`` on :func:`wavelengths_nm` (module docstring)."""
    s = camera_sensitivities()
    p = projector_primaries()
    resp = np.einsum("lc,l,lp->cp", s, rho, p)
    white = np.einsum("lc,lp->cp", s, p)
    return resp / np.diag(white)[None, :]


# measured reflectance datasets a scene material can name (colour-science's
# SDS_COLOURCHECKERS: "ColorChecker N Ohta" are N. Ohta's spectrophotometer measurements of a
# ColorChecker; "BabelColor Average" the average of 30 charts measured by BabelColor)
MEASURED_DATASETS = ("ColorChecker N Ohta", "BabelColor Average")


def _measured_sd(name: str):
    colour = _colour()
    dataset, sep, patch = str(name).partition("/")
    if not sep or dataset not in MEASURED_DATASETS:
        raise ValueError(
            f"measured spectrum must be '<dataset>/<patch>' with dataset one of {list(MEASURED_DATASETS)}, got {name!r}"
        )
    patches = colour.SDS_COLOURCHECKERS[dataset]
    if patch not in patches:
        raise ValueError(f"{dataset} has no patch {patch!r}; patches: {list(patches)}")
    return patches[patch]


@lru_cache(maxsize=64)
def _measured_values(name: str) -> np.ndarray:
    sd = _measured_sd(name).copy()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        v = np.asarray(sd.align(_shape()).values, dtype=np.float64)
    v = np.clip(v, 0.0, 1.0)
    v.setflags(write=False)
    return v


def measured_reflectance(name: str) -> np.ndarray:
    """Spectral reflectance of a measured patch ``"<dataset>/<patch>"`` on :func:`wavelengths_nm`."""
    return _measured_values(name).copy()


@lru_cache(maxsize=64)
@_persistent
def measured_linear_srgb(name: str) -> tuple[float, float, float]:
    """Linear sRGB reflectance (D65, CIE 1931 2 deg) of a measured patch, clipped to [0, 1]:
    what a renderer without spectra shows for it."""
    colour = _colour()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sd = colour.SpectralDistribution(dict(zip(wavelengths_nm(), _measured_values(name))))
        xyz = (
            colour.sd_to_XYZ(sd, colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"], colour.SDS_ILLUMINANTS["D65"])
            / 100.0
        )
        rgb = colour.XYZ_to_RGB(xyz, "sRGB", apply_cctf_encoding=False)
    return tuple(float(round(x, 6)) for x in np.clip(rgb, 0.0, 1.0))


def material_crosstalk(rgb: Sequence[float], spectrum: str | None = None) -> np.ndarray:
    """:func:`crosstalk_matrix` of a material: from its measured spectrum when it names one,
    else from its linear RGB reflectance."""
    if spectrum is None:
        return crosstalk_matrix(rgb)
    return _spectrum_crosstalk(spectrum).copy()


@lru_cache(maxsize=64)
@_persistent
def _spectrum_crosstalk(name: str) -> np.ndarray:
    return _crosstalk_of(_measured_values(name))


# metals a scene material can name -> (the stem of Mitsuba's optical-constants files, what it is)
METALS = {
    "aluminium": ("Al", "machined or brushed aluminium (luxpop)"),
    "silver": ("Ag", "silver (luxpop)"),
    "gold": ("Au", "gold (luxpop)"),
    "copper": ("Cu", "copper (luxpop)"),
    "chromium": ("Cr", "chromium, as chrome plating (luxpop)"),
    "nickel": ("Ni_palik", "nickel, as nickel plating (Palik)"),
}


def _metal_file(name: str) -> str:
    if name not in METALS:
        raise ValueError(f"unknown metal {name!r}; valid: {list(METALS)}")
    return METALS[name][0]


def _read_spd(path: Path) -> tuple[np.ndarray, np.ndarray]:
    rows = [line.split() for line in path.read_text().splitlines() if line.strip() and not line.startswith("#")]
    data = np.asarray(rows, dtype=np.float64)
    return data[:, 0], data[:, 1]


@lru_cache(maxsize=16)
def _metal_ior(name: str) -> tuple[np.ndarray, np.ndarray]:
    import mitsuba  # its data only: no variant is set

    # once imported, the package's module is Mitsuba's alias library, still in its folder
    folder = Path(mitsuba.__file__).parent / "data" / "ior"
    stem = _metal_file(name)
    out = []
    for part in ("eta", "k"):
        path = folder / f"{stem}.{part}.spd"
        if not path.is_file():
            raise FileNotFoundError(f"Mitsuba's optical constants of {name} are missing: {path}")
        lam, v = _read_spd(path)
        # the files tabulate the visible range; np.interp holds the end values beyond it
        out.append(np.interp(wavelengths_nm(), lam, v))
    for a in out:
        a.setflags(write=False)
    return out[0], out[1]


def metal_ior(name: str) -> tuple[np.ndarray, np.ndarray]:
    """Refractive index ``n`` and extinction coefficient ``k`` of a metal of :data:`METALS` on
    :func:`wavelengths_nm` (module docstring), two arrays of shape (N,)."""
    n, k = _metal_ior(name)
    return n.copy(), k.copy()


def conductor_fresnel(n: np.ndarray | float, k: np.ndarray | float, cos_theta: np.ndarray | float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a conductor of complex index ``n + ik`` (from air)
    at incidence angle ``arccos(cos_theta)``: the mean of the s and p reflectances of the exact
    complex Fresnel equations (Born & Wolf, Sec. 14.2).

    Examples
    --------
    Glass (n = 1.5, k = 0) reflects 4 % at normal incidence; aluminium at 550 nm (n = 0.96,
    k = 6.69) about 92 %:

    >>> round(float(conductor_fresnel(1.5, 0.0, 1.0)), 4)
    0.04
    >>> round(float(conductor_fresnel(0.96, 6.69, 1.0)), 3)
    0.921
    """
    eta = np.asarray(n, dtype=np.complex128) + 1j * np.asarray(k, dtype=np.float64)
    c = np.asarray(cos_theta, dtype=np.float64)
    sin2 = 1.0 - c * c
    ct = np.sqrt(eta * eta - sin2) / eta  # cosine of the (complex) refraction angle (Snell)
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return 0.5 * (np.abs(rs) ** 2 + np.abs(rp) ** 2)


def metal_reflectance(name: str) -> np.ndarray:
    """Normal-incidence reflectance ``R0`` of a metal on :func:`wavelengths_nm`, shape (N,)."""
    n, k = _metal_ior(name)
    return conductor_fresnel(n, k, 1.0)


def metal_ior_rgb(
    name: str, *, primary: int | None = None
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A metal's ``n`` and ``k`` for an RGB renderer: per camera channel, their means weighted
    by what the channel records of the projector's light (its sensitivity times the white's
    primaries, or only primary ``primary``'s), rounded to 6 digits.  A render through them keeps
    the Fresnel rise towards grazing angles; at normal incidence, per primary, it reflects the
    spectral :func:`metal_crosstalk` over the white's to within 1 % (gold and copper, the most
    coloured of :data:`METALS`; 0.3 % for the others - tests/test_spectral.py)."""
    n, k = _metal_ior(name)
    light = projector_primaries()
    light = light.sum(axis=1) if primary is None else light[:, int(primary)]
    w = camera_sensitivities() * light[:, None]
    w = w / w.sum(axis=0)
    return (
        tuple(float(round(x, 6)) for x in n @ w),
        tuple(float(round(x, 6)) for x in k @ w),
    )


def metal_crosstalk(name: str) -> np.ndarray:
    """:func:`crosstalk_matrix` of a metal at normal incidence: ``K`` of its spectrum ``R0``."""
    return _crosstalk_of(metal_reflectance(name))


@lru_cache(maxsize=1)
@_persistent
def watts_per_lux() -> np.ndarray:
    """W/m^2 of each primary per lux of the D65-balanced white (see
    :func:`simbench.sim.photometry.primary_irradiance_w_m2`), shape (3,)."""
    colour = _colour()
    cmfs = np.asarray(
        colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(_shape()).values, dtype=np.float64
    )
    xy = np.asarray(colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"], dtype=np.float64)
    d65 = np.array([xy[0] / xy[1], 1.0, (1.0 - xy[0] - xy[1]) / xy[1]])
    prim = projector_primaries()
    xyz = cmfs.T @ prim  # (3 xyz, 3 primaries), per unit spectral power sum
    mix = np.linalg.solve(xyz, d65)  # power of each primary for a D65 white of Y = 1
    lum = mix * xyz[1]  # luminance share of each primary
    share = lum / lum.sum()
    efficacy = 683.0 * xyz[1] / prim.sum(axis=0)  # lm/W of each LED spectrum (5 nm grid)
    out = share / efficacy
    out.setflags(write=False)
    return out
