"""Subsurface scattering (simbench.sim.subsurface): the dipole model against its closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest

from simbench.sim.subsurface import MEDIA, dipole_mtf, dipole_profile, get_medium, subsurface_image


@pytest.mark.parametrize("name", ["marble", "skin1", "plaster"])
@pytest.mark.parametrize("k", [0.3, 0.667, 2.0])
def test_the_mtf_is_the_profiles_fourier_transform(name, k):
    """The closed form of the dipole profile's 2-D Fourier transform (module docstring) against
    the numerical Hankel transform of the profile, within 1e-6."""
    from scipy import integrate, special

    m = MEDIA[name]
    for c in range(3):
        total = integrate.quad(lambda r: dipole_profile(r, m, c) * 2 * math.pi * r, 0, 500, limit=1000)[0]
        ft = integrate.quad(
            lambda r: dipole_profile(r, m, c) * special.j0(k * r) * 2 * math.pi * r, 0, 500, limit=1000
        )[0]
        assert ft / total == pytest.approx(float(dipole_mtf(k, m, c)), abs=1e-6)


def test_jensens_total_diffuse_reflectance():
    """At k = 0 the transform is the total diffuse reflectance of Jensen et al. 2001 (their Eq. 6),
    alpha'/2 (1 + e^(-4/3 A sqrt(3(1 - alpha')))) e^(-sqrt(3(1 - alpha'))), and the MTF is 1."""
    from scipy import integrate

    m = MEDIA["marble"]
    alpha, _, _, _ = m.dipole(1)
    f = -1.440 / m.eta**2 + 0.710 / m.eta + 0.668 + 0.0636 * m.eta
    a = (1 + f) / (1 - f)
    s = math.sqrt(3 * (1 - alpha))
    expected = alpha / 2 * (1 + math.exp(-4 / 3 * a * s)) * math.exp(-s)
    total = integrate.quad(lambda r: dipole_profile(r, m, 1) * 2 * math.pi * r, 0, 2000, limit=2000)[0]
    assert total == pytest.approx(expected, rel=1e-4)
    assert float(dipole_mtf(0.0, m, 1)) == pytest.approx(1.0)


@pytest.mark.parametrize("name", ["marble", "spectralon"])
def test_a_fringe_on_a_translucent_plane_keeps_the_mtf_of_its_contrast(name):
    """A cosine fringe of 21.8 camera px on a fronto-parallel plane at 1 m (0.43 mm per pixel)
    through subsurface_image keeps dipole_mtf of its amplitude (within 1 %: the kernel's
    truncation and pixel sampling), its mean and its phase."""
    h, w, period, focal = 120, 400, 21.8, 2312.5
    x = np.arange(w)
    img = np.broadcast_to((0.5 + 0.4 * np.cos(2 * np.pi * x / period))[None, :, None], (h, w, 3)).astype(np.float32)
    out = subsurface_image(
        img, object_id=np.zeros((h, w), int), depth_m=np.ones((h, w)), media={0: MEDIA[name]}, focal_px=focal
    )
    xs = x[100:300]
    basis = np.stack([np.ones(xs.size), np.cos(2 * np.pi * xs / period), np.sin(2 * np.pi * xs / period)], axis=1)
    k = 2 * math.pi / (period * 1000.0 / focal)
    for c in range(3):
        a = np.linalg.lstsq(basis, out[60, 100:300, c].astype(np.float64), rcond=None)[0]
        assert math.hypot(a[1], a[2]) / 0.4 == pytest.approx(float(dipole_mtf(k, MEDIA[name], c)), rel=0.01)
        assert a[0] == pytest.approx(0.5, abs=1e-3) and abs(a[2]) < 1e-3


def test_light_does_not_cross_objects_and_opaque_ones_are_untouched():
    h, w = 60, 80
    img = np.zeros((h, w, 3), np.float32)
    img[:, :40] = 1.0
    oid = np.zeros((h, w), int)
    oid[:, 40:] = 1
    out = subsurface_image(img, object_id=oid, depth_m=np.ones((h, w)), media={1: MEDIA["marble"]}, focal_px=2000.0)
    assert np.array_equal(out[:, :40], img[:, :40]) and np.all(out[:, 40:] == 0)
    assert subsurface_image(img, object_id=oid, depth_m=np.ones((h, w)), media={}, focal_px=2000.0) is img
    with pytest.raises(ValueError, match="differ"):
        subsurface_image(img, object_id=oid[:10], depth_m=np.ones((h, w)), media={}, focal_px=2000.0)


def test_media_by_name_and_in_scene_files():
    from simbench.sim.scene import scene_fingerprint
    from simbench.sim.scene import scene_from_dict

    assert get_medium("plaster") is MEDIA["plaster"]
    with pytest.raises(ValueError, match="unknown subsurface medium 'chalk'.*marble"):
        get_medium("chalk")
    base = {"rig": "paper", "object": [{"type": "plane", "size_m": [1, 1], "center_m": [0, 0, 1]}]}
    opaque = scene_from_dict(base)
    plaster = scene_from_dict({**base, "object": [{**base["object"][0], "subsurface": "plaster"}]})
    assert plaster.objects[0].material.subsurface == "plaster"
    assert "subsurface" not in str(scene_fingerprint(opaque))  # opaque scenes keep their cache keys
    assert scene_fingerprint(plaster) != scene_fingerprint(opaque)
    with pytest.raises(ValueError, match="subsurface medium"):
        scene_from_dict({**base, "object": [{**base["object"][0], "subsurface": ["marble"]}]})


def test_with_subsurface_sets_the_named_objects_medium_only():
    from pathlib import Path

    from simbench.sim.scene import load_scene, with_subsurface

    scene = load_scene(Path(__file__).resolve().parents[1] / "scenes" / "discontinuity.toml")
    # Table 3's plaster objects are translucent as the file says, the wall opaque
    assert [o.material.subsurface for o in scene.objects] == ["plaster", "plaster", None]
    names = [o.name for o in scene.objects]
    one = with_subsurface(scene, "marble", names=names[:1])
    assert [o.material.subsurface for o in one.objects] == ["marble", "plaster", None]
    every = with_subsurface(scene, "marble")
    assert all(o.material.subsurface == "marble" for o in every.objects)
    assert with_subsurface(with_subsurface(every, None), "plaster", names=names[:2]) == scene


@pytest.mark.parametrize("name", ["marble", "plaster", "skin1", "spectralon"])
def test_modulation_transfer_is_the_transform_of_the_time_resolved_dipole(name):
    """The closed form against the quadrature of the dipole's time-resolved total reflectance
    (Patterson, Chance & Wilson 1989): R(t) ~ sum_z z t^-3/2 exp(-sigma_a v t - z^2 / 4 D v t),
    transformed at the SR4000's 30 MHz; to 1e-4 (the quadrature's own accuracy)."""
    import math

    from simbench.sim.photometry import LIGHT_M_S
    from simbench.sim.subsurface import modulation_transfer

    medium = MEDIA[name]
    f = 30e6
    v = LIGHT_M_S * 1000.0 / medium.eta  # mm/s
    t = np.exp(np.linspace(math.log(1e-17), math.log(1e-3), 400_001))
    for ch in range(3):
        _, _, zr, zv = medium.dipole(ch)
        ss, sa = medium.sigma_s_prime_per_mm[ch], medium.sigma_a_per_mm[ch]
        d = 1.0 / (3.0 * (ss + sa))
        r = sum(z * t**-1.5 * np.exp(-sa * v * t - z * z / (4.0 * d * v * t)) for z in (zr, zv))
        w = r * t  # d t = t d(log t)
        got = np.trapezoid(w * np.exp(2j * math.pi * f * t), np.log(t)) / np.trapezoid(w, np.log(t))
        want = modulation_transfer(medium, ch, frequency_hz=f)
        assert abs(got - want) < 1e-4, (ch, got, want)
    # the delay is a delay: the light reads as having travelled farther
    assert np.angle(modulation_transfer(medium, 0, frequency_hz=f)) > 0
    assert modulation_transfer(medium, 0, frequency_hz=0.0) == pytest.approx(1.0)
