"""Spectral crosstalk: data alignment, normalisation, recovery and the physics it predicts."""

import warnings

import numpy as np
import pytest

from simbench.sim.scene import paint_reflectance
from simbench.sim.spectral import (
    METALS,
    conductor_fresnel,
    metal_crosstalk,
    metal_ior_rgb,
    metal_reflectance,
    camera_sensitivities,
    crosstalk_matrix,
    projector_primaries,
    reflectance_spectrum,
    wavelengths_nm,
)


def test_spectra_share_one_grid_and_peak_where_stated():
    wl = wavelengths_nm()
    p = projector_primaries()
    assert p.shape == (wl.size, 3) and camera_sensitivities().shape == (wl.size, 3)
    assert np.allclose(wl[p.argmax(axis=0)], (620, 522, 455), atol=5)


def test_perfect_white_has_unit_diagonal_and_positive_crosstalk():
    k = crosstalk_matrix([1.0, 1.0, 1.0])
    assert np.allclose(np.diag(k), 1.0, atol=0.02)  # Mallett's white is ~1 across the spectrum
    off = k[~np.eye(3, dtype=bool)]
    assert np.all(off > 0) and np.all(off < 0.5)


def test_recovered_spectrum_reproduces_its_rgb():
    """Mallett & Yuksel 2019 round trip: the recovered reflectance, lit by D65 and seen by the
    CIE observer, gives back its linear sRGB within 0.01."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        import colour
    for rgb in ([0.8, 0.04, 0.04], [0.04, 0.8, 0.8], [0.5, 0.3, 0.2]):
        sd = colour.SpectralDistribution(dict(zip(wavelengths_nm(), reflectance_spectrum(rgb))))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            xyz = colour.sd_to_XYZ(sd, illuminant=colour.SDS_ILLUMINANTS["D65"]) / 100
            back = colour.XYZ_to_RGB(xyz, colour.RGB_COLOURSPACES["sRGB"], apply_cctf_encoding=False)
        assert np.allclose(back, rgb, atol=0.01), (rgb, back)


def test_crosstalk_is_linear_in_the_reflectance():
    a, b = np.array([0.8, 0.04, 0.04]), np.array([0.04, 0.3, 0.7])
    assert np.allclose(
        crosstalk_matrix(0.5 * a + 0.5 * b), 0.5 * crosstalk_matrix(a) + 0.5 * crosstalk_matrix(b), atol=1e-9
    )


def test_red_surface_under_a_green_stripe_records_a_small_nonzero_signal():
    """Issue 3: the red board reflects little of the green LED's light, and the red channel
    barely sees that light, but neither is zero."""
    red = crosstalk_matrix(paint_reflectance([255, 0, 0]))
    white = crosstalk_matrix(paint_reflectance([255, 255, 255]))
    g = 1  # the green primary
    assert 0 < red[0, g] < 0.05 * white[0, 0]  # camera R under the green stripe
    assert 0 < red[1, g] < 0.1 * white[1, g]  # camera G: the paint absorbs green
    assert red[0, 0] > 0.9 * white[0, 0]  # under the red stripe the red channel sees ~ white


def test_bad_reflectance_is_rejected():
    with pytest.raises(ValueError, match="reflectance"):
        reflectance_spectrum([1.2, 0, 0])


_MEMO_PROBE = """
import json, sys
import numpy as np
from simbench.sim import spectral
values = [
    spectral.watts_per_lux(),
    spectral.crosstalk_matrix((0.8, 0.3, 0.1)),
    spectral.material_crosstalk((0.5, 0.5, 0.5), "ColorChecker N Ohta/dark skin"),
    np.asarray(spectral.measured_linear_srgb("BabelColor Average/foliage")),
]
print(json.dumps({"bits": [np.asarray(v, np.float64).tobytes().hex() for v in values],
                  "colour": "colour" in sys.modules, "path": str(spectral.memo_path())}))
"""


def _probe(cache_dir) -> dict:
    import json
    import os
    import subprocess
    import sys

    env = {**os.environ, "SIMBENCH_CACHE_DIR": str(cache_dir)}
    res = subprocess.run([sys.executable, "-c", _MEMO_PROBE], capture_output=True, text=True, env=env, timeout=300)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def test_spectral_memo_skips_colour_on_a_rerun_with_the_same_bits(tmp_path):
    """A render needs a few numbers from colour-science; the memo keeps them, so a second process
    neither imports colour (~1.3 s) nor gets other values; a damaged memo is recomputed; an empty
    SIMBENCH_CACHE_DIR turns the memo off."""
    first = _probe(tmp_path)
    assert first["colour"]
    memo = tmp_path / first["path"].rsplit("/", 1)[-1]
    assert memo.exists() and "colour" in memo.name
    again = _probe(tmp_path)
    assert not again["colour"] and again["bits"] == first["bits"]
    memo.write_text("{not json")
    damaged = _probe(tmp_path)
    assert damaged["colour"] and damaged["bits"] == first["bits"]
    assert _probe(tmp_path)["bits"] == first["bits"]  # rewritten whole
    off = _probe("")
    assert off["colour"] and off["path"] == "None" and off["bits"] == first["bits"]


# --- metals --------------------------------------------------------------------------------


def test_conductor_fresnel_matches_its_closed_forms():
    # normal incidence: ((n-1)^2 + k^2) / ((n+1)^2 + k^2) (Born & Wolf 14.2)
    n, k = 1.2, 7.1
    assert conductor_fresnel(n, k, 1.0) == pytest.approx(((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2), rel=1e-12)
    # k = 0 is a dielectric: glass (n = 1.5) at 45 deg reflects Rs = 0.0920, Rp = 0.0085
    c = np.cos(np.radians(45.0))
    t = np.sqrt(1 - (np.sin(np.radians(45.0)) / 1.5) ** 2)
    rs = ((c - 1.5 * t) / (c + 1.5 * t)) ** 2
    rp = ((1.5 * c - t) / (1.5 * c + t)) ** 2
    assert conductor_fresnel(1.5, 0.0, c) == pytest.approx(0.5 * (rs + rp), rel=1e-12)
    assert 0.5 * (rs + rp) == pytest.approx(0.0503, abs=2e-4)
    # grazing incidence reflects everything; a metal's reflectance dips a little before it
    angles = np.cos(np.radians([0.0, 60.0, 80.0, 89.999]))
    r = conductor_fresnel(n, k, angles)
    assert r[-1] == pytest.approx(1.0, abs=1e-3) and r[2] < r[0] + 0.02


def test_metal_reflectances_are_the_handbook_values():
    lam = wavelengths_nm()
    at = {w: int(np.argmin(np.abs(lam - w))) for w in (450, 550, 650)}
    al = metal_reflectance("aluminium")
    # aluminium reflects ~91-92 % across the visible (Rakic 1995; Bass, Handbook of Optics)
    assert 0.89 < al[at[550]] < 0.94 and np.ptp(al[at[450] : at[650]]) < 0.03
    ag = metal_reflectance("silver")
    assert ag[at[650]] > 0.95
    au = metal_reflectance("gold")
    # gold: yellow - reflects red (~95 %) far better than blue (~38 %)
    assert au[at[650]] > 0.9 and au[at[450]] < 0.45
    with pytest.raises(ValueError, match="unknown metal"):
        metal_reflectance("unobtainium")


@pytest.mark.parametrize("metal", sorted(METALS))
def test_per_primary_optical_constants_reflect_the_spectral_crosstalk(metal):
    """The per-primary render of a metal (simbench.sim.capture._primary_scene): the white's
    crosstalk as tint and the optical constants averaged over the primary's band.  At normal
    incidence it must reflect the spectral K of the metal's R0: within 1 % for gold and copper, the most
    coloured metals, 0.3 % for the others (metal_ior_rgb's docstring)."""
    white = crosstalk_matrix((1.0, 1.0, 1.0))
    k_metal = metal_crosstalk(metal)
    tol = 0.011 if metal in ("gold", "copper") else 0.003
    for p in range(3):
        eta, k = metal_ior_rgb(metal, primary=p)
        rendered = white[:, p] * conductor_fresnel(np.asarray(eta), np.asarray(k), 1.0)
        np.testing.assert_allclose(rendered, k_metal[:, p], rtol=tol)
