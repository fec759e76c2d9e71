import numpy as np
import pytest

from simbench.sim.sensor import get_sensor
from simbench.sim.camera import SimpleCamera, simple_camera


def test_photon_transfer_mean_and_variance():
    """Statistical tier: mean and variance per level follow Poisson + read noise (in DN^2)."""
    cam = SimpleCamera(exposure=1.0, full_well_e=4000.0, read_noise_e=12.0, bits=16)
    gain = cam.max_dn / cam.full_well_e  # DN per electron
    levels = np.array([0.05, 0.2, 0.5, 0.8])
    rad = np.broadcast_to(levels[:, None, None], (4, 20000, 3)).copy()
    img = simple_camera(rad, camera=cam, rng=1).astype(np.float64)
    for i, lv in enumerate(levels):
        e = lv * cam.full_well_e
        m, v = img[i].mean(), img[i].var()
        assert m == pytest.approx(e * gain, rel=2e-3)
        # variance estimate from 60000 samples: relative sd ~ sqrt(2/n) = 0.6 %; 3 % tolerance
        assert v == pytest.approx((e + cam.read_noise_e**2) * gain**2 + 1 / 12, rel=0.03)


def test_seeded_and_clipped():
    rad = np.random.default_rng(0).random((50, 60, 3)).astype(np.float32) * 2
    cam = get_sensor("minimal").camera
    a, b = simple_camera(rad, camera=cam, rng=5), simple_camera(rad, camera=cam, rng=5)
    assert np.array_equal(a, b) and a.dtype == np.uint8
    assert not np.array_equal(a, simple_camera(rad, camera=cam, rng=6))
    assert a.max() == 255  # radiance 2 * exposure 0.8 clips


def test_ideal_camera_is_deterministic_quantisation():
    rad = np.full((2, 2, 3), 0.5, np.float32)
    img = simple_camera(
        rad, camera=SimpleCamera(exposure=0.8, full_well_e=1e4, read_noise_e=0.0, noise=False), rng=None
    )
    assert np.all(img == round(0.5 * 0.8 * 255))


@pytest.mark.parametrize("bad", [np.full((4, 4), 0.5), np.full((4, 4, 3), np.nan)])
def test_bad_radiance(bad):
    with pytest.raises(ValueError):
        simple_camera(bad, camera=get_sensor("minimal").camera, rng=0)


def test_unknown_preset():
    with pytest.raises(ValueError, match="minimal"):
        get_sensor("nope")


def test_photons_per_unit_radiance_matches_the_camera_equation():
    # 1 W/m^2 at 1 m, f/2, tau 1, 5.3 um pixel, 10 ms, 520 nm, by hand:
    # E_s = 1/16 W/m^2; energy = E_s * (5.3e-6)^2 * 0.01 J; photons = energy * lambda / (h c)
    from simbench.sim.photometry import photons_per_unit_radiance

    expected = (1 / 16) * (5.3e-6) ** 2 * 0.01 * 520e-9 / (6.62607015e-34 * 299792458.0)
    base = {"irradiance_1m_w_m2": 1.0, "wavelength_nm": 520, "f_number": 2.0, "pixel_pitch_um": 5.3, "exposure_s": 0.01}
    got = photons_per_unit_radiance(**base, lens_transmission=1.0)
    assert got == pytest.approx(expected, rel=1e-12)
    assert got == pytest.approx(45_970, rel=1e-3)
    # inverse-square in the f-number, linear in exposure
    half = photons_per_unit_radiance(**{**base, "f_number": 4.0, "exposure_s": 0.02}, lens_transmission=1.0)
    assert half == pytest.approx(got / 2)
    with pytest.raises(ValueError, match="f_number"):
        photons_per_unit_radiance(**{**base, "f_number": 0})


def test_emva_photon_transfer_returns_gain_and_dark_noise():
    """Issue 3's acceptance: over a range of exposures the photon-transfer curve (temporal
    variance against mean, EMVA 1288 Sec. 6) returns the configured system gain within 5 % and
    the configured dark noise within 10 %; PRNU/DSNU do not disturb it (frame differences)."""
    from simbench.sim.sensor import PhysicalCamera
    from simbench.sim.camera import emva_camera, photon_transfer

    cam = PhysicalCamera(
        pixel_pitch_um=5.3,
        qe=(0.5, 0.6, 0.45),
        full_well_e=10_500.0,
        dark_noise_e=20.0,
        gain_dn_per_e=0.35,
        bits=12,
        offset_dn=40.0,
        dark_current_e_s=50.0,
        prnu=0.01,
        dsnu_e=5.0,
        fixed_pattern_seed=3,
    )
    photons = 20_000.0
    kw = {"camera": cam, "electrons_per_radiance": np.array(cam.qe) * photons, "exposure_s": 0.01}
    shape = (200, 200, 3)
    dark = [emva_camera(np.zeros(shape), rng=100 + k, **kw) for k in range(2)]
    means, variances = [], []
    for i, level in enumerate(np.linspace(0.02, 0.8, 10)):
        a, b = (emva_camera(np.full(shape, level), rng=2 * i + k, **kw) for k in range(2))
        m, v = photon_transfer(a[..., 1], b[..., 1], dark[0][..., 1], dark[1][..., 1])
        means.append(m)
        variances.append(v)
    means, variances = np.array(means), np.array(variances)
    ok = means < 0.7 * cam.full_well_e * cam.gain_dn_per_e  # the linear range (EMVA: up to 70 % of saturation)
    slope, _ = np.polyfit(means[ok], variances[ok], 1)
    assert slope == pytest.approx(cam.gain_dn_per_e, rel=0.05)
    # dark noise from the dark frames' temporal variance: K^2 sigma_d^2 + quantisation 1/12
    dark_var = 0.5 * np.var(dark[0][..., 1].astype(float) - dark[1][..., 1].astype(float))
    sigma_d = np.sqrt(max(dark_var - 1 / 12, 0) / slope**2)
    sigma_total = np.sqrt(cam.dark_noise_e**2 + cam.dark_current_e_s * kw["exposure_s"])  # dark shot noise adds
    assert sigma_d == pytest.approx(sigma_total, rel=0.10)
    # the QE and photon scale set the mean: mu_y - mu_dark = K * eta * mu_p
    assert means[0] == pytest.approx(cam.gain_dn_per_e * cam.qe[1] * photons * 0.02, rel=0.01)


def test_emva_saturation_fixed_pattern_and_seeds():
    from simbench.sim.sensor import PhysicalCamera
    from simbench.sim.camera import emva_camera

    cam = PhysicalCamera(
        pixel_pitch_um=5.3, qe=(0.5, 0.5, 0.5), full_well_e=10_000.0, dark_noise_e=10.0, prnu=0.02, fixed_pattern_seed=1
    )
    assert cam.gain == pytest.approx(255 / 10_000)  # default: full well = full scale
    kw = {"camera": cam, "electrons_per_radiance": (5e4, 5e4, 5e4), "exposure_s": 0.01}
    bright = emva_camera(np.full((8, 8, 3), 1.0), rng=0, **kw)
    assert np.all(bright == 255)  # 50 000 e- mean clips at the full well
    rad = np.full((64, 64, 3), 0.1)
    a, b = emva_camera(rad, rng=1, **kw), emva_camera(rad, rng=1, **kw)
    assert np.array_equal(a, b) and not np.array_equal(a, emva_camera(rad, rng=2, **kw))
    with pytest.raises(ValueError, match="qe"):
        PhysicalCamera(pixel_pitch_um=5.3, qe=(0.5, 0.5, 1.5), full_well_e=1, dark_noise_e=0)
    with pytest.raises(ValueError, match="radiance"):
        emva_camera(np.full((4, 4), 0.1), rng=0, **kw)


@pytest.mark.parametrize("pattern", ["RGGB", "BGGR", "GRBG", "GBRG"])
@pytest.mark.parametrize("method", ["bilinear", "edge_aware", "vng"])
def test_bayer_mosaic_and_demosaic_round_trip_a_smooth_image(pattern, method):
    """A smooth colour image survives mosaic + OpenCV demosaicing within ~1 DN inside the
    border (interpolation error of slowly varying colour), for every layout: checks our
    layout -> OpenCV code table."""
    from simbench.sim.camera import bayer_mosaic, demosaic

    yy, xx = np.mgrid[0:64, 0:64]
    img = np.stack([100 + 50 * np.sin(xx / 9), 120 + 40 * np.cos(yy / 8), 80 + 30 * np.sin((xx + yy) / 11)], -1).astype(
        np.uint8
    )
    raw = bayer_mosaic(img, pattern=pattern)
    assert raw.shape == (64, 64)
    out = demosaic(raw, pattern=pattern, method=method)
    err = np.abs(out[4:-4, 4:-4].astype(int) - img[4:-4, 4:-4])
    assert err.mean() < 1.0, err.mean()


def test_bayer_bad_inputs():
    from simbench.sim.camera import bayer_mosaic, demosaic

    with pytest.raises(ValueError, match="RGGB"):
        bayer_mosaic(np.zeros((4, 4, 3)), pattern="XYZW")
    with pytest.raises(ValueError, match="edge_aware"):
        demosaic(np.zeros((4, 4), np.uint8), pattern="RGGB", method="magic")
    with pytest.raises(ValueError, match="8-bit"):
        demosaic(np.zeros((4, 4), np.uint16), pattern="RGGB", method="vng")


def test_cfa_keeps_shot_noise_per_pixel():
    """With a Bayer filter each pixel's noise is its own channel's: the raw frame's variance
    at the green sites equals the no-CFA green variance (Poisson)."""
    from simbench.sim.sensor import PhysicalCamera
    from simbench.sim.camera import bayer_mosaic, emva_camera

    base = dict(
        pixel_pitch_um=5.3, qe=(0.5, 0.5, 0.5), full_well_e=10_000.0, dark_noise_e=0.0, bits=16, gain_dn_per_e=1.0
    )
    kw = {"electrons_per_radiance": (2000.0, 4000.0, 1000.0), "exposure_s": 0.01}
    rad = np.ones((200, 200, 3))
    full = emva_camera(rad, camera=PhysicalCamera(**base), rng=0, **kw).astype(float)
    assert full[..., 1].var() == pytest.approx(4000.0, rel=0.05)
    raw_green = bayer_mosaic(full, pattern="RGGB")[0::2, 1::2]
    assert raw_green.mean() == pytest.approx(4000.0, rel=0.01)


def test_fixed_pattern_is_drawn_once_with_the_bits_of_a_fresh_draw():
    """The per-process fixed-pattern cache changes nothing: the same numbers as drawing from the
    sensor's seed, read-only so no frame can alter the sensor."""
    from simbench.sim.camera import fixed_pattern

    gain, dark = fixed_pattern((6, 8), seed=123, prnu=0.01, dsnu_e=5.0)
    fp = np.random.default_rng(123)
    assert np.array_equal(gain, np.clip(1.0 + 0.01 * fp.standard_normal((6, 8)), 0.0, None))
    assert np.array_equal(dark, 5.0 * fp.standard_normal((6, 8)))
    assert fixed_pattern((6, 8), seed=123, prnu=0.01, dsnu_e=5.0)[0] is gain
    with pytest.raises(ValueError):
        gain[0, 0] = 2.0


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize(
    "changes",
    [
        {},  # the paper sensor: Bayer RGGB, noise, PRNU and DSNU, 8 bits
        {"noise": False},
        {"cfa": "none", "prnu": 0.0, "dsnu_e": 0.0},
        {"cfa": "GBRG", "bits": 12, "offset_dn": 3.5, "dark_current_e_s": 40.0},
        {"cfa": "none", "bits": 16, "noise": False, "dark_noise_e": 0.0},
        {"cfa": "RGGB", "bits": 14, "offset_dn": 16.0},
        {"cfa": "BGGR", "dark_noise_e": 0.0, "prnu": 0.05, "dsnu_e": 0.0},
    ],
)
def test_emva_camera_gives_the_bits_of_its_numpy_form(changes, dtype):
    """The C loops (simbench/_lens.c: emva_mean, emva_dn) against the whole-image numpy form they
    replaced (tests/numpy_reference.py), bit for bit, with a seed: on an odd-sized frame (the Bayer
    cell cut at the edges) whose radiance spans dark (negative render noise included), mid-range,
    saturating and half-DN rounding ties."""
    import dataclasses

    from simbench.sim.camera import emva_camera

    from .numpy_reference import emva_camera as emva_numpy

    cam = dataclasses.replace(get_sensor("paper").camera, **changes)
    rng = np.random.default_rng(3)
    rad = (rng.random((37, 51, 3)) * 2.4 - 0.2).astype(dtype)
    rad[0, :6] = [[0.0] * 3, [-0.0] * 3, [1e-30] * 3, [0.5] * 3, [1.0] * 3, [100.0] * 3]
    kw = dict(
        camera=cam, electrons_per_radiance=(4100.0, 5200.0, 3900.0), exposure_s=0.012, white_balance=(1.3, 1.0, 1.7)
    )
    for seed in (0, 1):
        a = emva_camera(rad, rng=seed, **kw)
        b = emva_numpy(rad, rng=seed, **kw)
        assert a.dtype == b.dtype and a.shape == b.shape == (37, 51, 3)
        assert np.array_equal(a, b)
    assert np.unique(a).size > 20  # not all clipped or dark
    # ties round to even, as numpy's rint: 1 DN per electron, 1 electron per unit radiance
    tie = dataclasses.replace(cam, gain_dn_per_e=1.0, noise=False, prnu=0.0, dsnu_e=0.0, offset_dn=0.0, bits=12)
    flat = np.full((2, 2, 3), 10.5, dtype)
    flat[1] = 11.5
    got = emva_camera(flat, camera=tie, electrons_per_radiance=(1.0, 1.0, 1.0), exposure_s=0.0)
    assert np.array_equal(got, emva_numpy(flat, camera=tie, electrons_per_radiance=(1.0, 1.0, 1.0), exposure_s=0.0))
    assert cam.cfa != "none" or (got[0] == 10).all() and (got[1] == 12).all()
    bad = rad.copy()
    bad[5, 7, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or inf"):
        emva_camera(bad, rng=0, **kw)
    # where the numpy form went on with NaN (0 x inf: huge float64 radiance on a PRNU gain of 0;
    # an infinite scale) and recorded 0, a clear error
    with pytest.raises(ValueError, match="three finite numbers"):
        emva_camera(rad, rng=0, **dict(kw, electrons_per_radiance=(np.inf, 1.0, 1.0)))
    dead = dataclasses.replace(cam, prnu=1.0, dsnu_e=0.0, noise=False)
    with pytest.raises(ValueError, match="mean electrons are not finite"):
        emva_camera(np.full((37, 51, 3), 1e306), **dict(kw, camera=dead))
