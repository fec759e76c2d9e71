import numpy as np
import pytest

from simbench.sensor import SimpleCamera, get_camera, simple_camera


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
    cam = get_camera("minimal")
    a, b = simple_camera(rad, camera=cam, rng=5), simple_camera(rad, camera=cam, rng=5)
    assert np.array_equal(a, b) and a.dtype == np.uint8
    assert not np.array_equal(a, simple_camera(rad, camera=cam, rng=6))
    assert a.max() == 255  # radiance 2 * exposure 0.8 clips


def test_ideal_camera_is_deterministic_quantisation():
    rad = np.full((2, 2, 3), 0.5, np.float32)
    img = simple_camera(rad, camera=get_camera("ideal"), rng=None)
    assert np.all(img == round(0.5 * 0.8 * 255))


@pytest.mark.parametrize("bad", [np.full((4, 4), 0.5), np.full((4, 4, 3), np.nan)])
def test_bad_radiance(bad):
    with pytest.raises(ValueError):
        simple_camera(bad, camera=get_camera("minimal"), rng=0)


def test_unknown_preset():
    with pytest.raises(ValueError, match="minimal"):
        get_camera("nope")


def test_photons_per_unit_radiance_matches_the_camera_equation():
    # 1 W/m^2 at 1 m, f/2, tau 1, 5.3 um pixel, 10 ms, 520 nm, by hand:
    # E_s = 1/16 W/m^2; energy = E_s * (5.3e-6)^2 * 0.01 J; photons = energy * lambda / (h c)
    from simbench.sensor import photons_per_unit_radiance

    expected = (1 / 16) * (5.3e-6) ** 2 * 0.01 * 520e-9 / (6.62607015e-34 * 299792458.0)
    got = photons_per_unit_radiance(irradiance_1m_w_m2=1.0, wavelength_nm=520, f_number=2.0, pixel_pitch_um=5.3, exposure_s=0.01, lens_transmission=1.0)
    assert got == pytest.approx(expected, rel=1e-12)
    assert got == pytest.approx(45_970, rel=1e-3)
    # inverse-square in the f-number, linear in exposure
    half = photons_per_unit_radiance(irradiance_1m_w_m2=1.0, wavelength_nm=520, f_number=4.0, pixel_pitch_um=5.3, exposure_s=0.02, lens_transmission=1.0)
    assert half == pytest.approx(got / 2)
    with pytest.raises(ValueError, match="f_number"):
        photons_per_unit_radiance(irradiance_1m_w_m2=1.0, wavelength_nm=520, f_number=0, pixel_pitch_um=5.3, exposure_s=0.01)


def test_emva_photon_transfer_returns_gain_and_dark_noise():
    """Issue 3's acceptance: over a range of exposures the photon-transfer curve (temporal
    variance against mean, EMVA 1288 Sec. 6) returns the configured system gain within 5 % and
    the configured dark noise within 10 %; PRNU/DSNU do not disturb it (frame differences)."""
    from simbench.sensor import EmvaCamera, emva_camera, photon_transfer

    cam = EmvaCamera(qe=(0.5, 0.6, 0.45), photons_per_radiance=20_000.0, full_well_e=10_500.0, dark_noise_e=20.0, gain_dn_per_e=0.35, bits=12, offset_dn=40.0, dark_current_e_s=50.0, exposure_s=0.01, prnu=0.01, dsnu_e=5.0, fixed_pattern_seed=3)
    shape = (200, 200, 3)
    dark = [emva_camera(np.zeros(shape), camera=cam, rng=100 + k) for k in range(2)]
    means, variances = [], []
    for i, level in enumerate(np.linspace(0.02, 0.8, 10)):
        a, b = (emva_camera(np.full(shape, level), camera=cam, rng=2 * i + k) for k in range(2))
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
    sigma_total = np.sqrt(cam.dark_noise_e**2 + cam.dark_current_e_s * cam.exposure_s)  # dark shot noise adds
    assert sigma_d == pytest.approx(sigma_total, rel=0.10)
    # the QE and photon scale set the mean: mu_y - mu_dark = K * eta * mu_p
    assert means[0] == pytest.approx(cam.gain_dn_per_e * cam.qe[1] * cam.photons_per_radiance * 0.02, rel=0.01)


def test_emva_saturation_fixed_pattern_and_seeds():
    from simbench.sensor import EmvaCamera, emva_camera

    cam = EmvaCamera(qe=(0.5, 0.5, 0.5), photons_per_radiance=1e5, full_well_e=10_000.0, dark_noise_e=10.0, gain_dn_per_e=255 / 10_000, prnu=0.02, fixed_pattern_seed=1)
    bright = emva_camera(np.full((8, 8, 3), 1.0), camera=cam, rng=0)
    assert np.all(bright == 255)  # 50 000 e- mean clips at the full well
    rad = np.full((64, 64, 3), 0.1)
    a, b = emva_camera(rad, camera=cam, rng=1), emva_camera(rad, camera=cam, rng=1)
    assert np.array_equal(a, b) and not np.array_equal(a, emva_camera(rad, camera=cam, rng=2))
    with pytest.raises(ValueError, match="qe"):
        EmvaCamera(qe=(0.5, 0.5, 1.5), photons_per_radiance=1, full_well_e=1, dark_noise_e=0, gain_dn_per_e=1)
    with pytest.raises(ValueError, match="radiance"):
        emva_camera(np.full((4, 4), 0.1), camera=cam, rng=0)
