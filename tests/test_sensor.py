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
