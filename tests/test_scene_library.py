"""The scene library: paint colours, materials, shipped meshes and scene files."""

import subprocess
import sys

import numpy as np
import pytest

from simbench.sim.scene import (
    PAINT_MAX_REFLECTANCE,
    PAINT_MIN_REFLECTANCE,
    linear_srgb8,
    load_scene,
    paint_reflectance,
    scene_from_dict,
)

from .conftest import ROOT, SCENES

PLANE = {"type": "plane", "size_m": [1, 1]}


def test_paint_reflectance_end_points_and_srgb_curve():
    assert paint_reflectance([255, 255, 255]) == pytest.approx((PAINT_MAX_REFLECTANCE,) * 3)
    assert paint_reflectance([0, 0, 0]) == pytest.approx((PAINT_MIN_REFLECTANCE,) * 3)
    assert paint_reflectance([255, 0, 0]) == pytest.approx((0.80, 0.04, 0.04))
    # sRGB 128 decodes to linear 0.2158 (IEC 61966-2-1)
    assert paint_reflectance([128, 128, 128])[0] == pytest.approx(0.04 + 0.76 * 0.21586, abs=1e-4)


def test_linear_srgb8_is_the_srgb_decoding_curve():
    """The paper's-simulation material colour: 255 -> 1, 0 -> 0, 128 -> 0.21586, 10 -> 10/255/12.92
    (the curve's linear toe)."""
    assert linear_srgb8([255, 0, 128]) == pytest.approx((1.0, 0.0, 0.21586), abs=1e-5)
    assert linear_srgb8([10, 10, 10])[0] == pytest.approx(10 / 255 / 12.92, abs=1e-6)


@pytest.mark.parametrize("bad", [[256, 0, 0], [-1, 0, 0], [1, 2], [np.nan, 0, 0], [0.5, 0, 0]])
@pytest.mark.parametrize("fn", [paint_reflectance, linear_srgb8])
def test_srgb8_colours_reject_bad_values(bad, fn):
    with pytest.raises(ValueError, match="srgb8"):
        fn(bad)


@pytest.mark.parametrize(
    "extra, match",
    [
        ({"rgb": [0.5, 0.5, 0.5], "srgb8": [1, 2, 3]}, "not rgb and srgb8"),
        ({"roughness": 0.1}, "roughness applies"),
        ({"material": "plastic", "roughness": 0}, "roughness"),
        ({"material": "glass"}, "unknown material"),
        ({"material": "metal", "metal": "unobtainium"}, "unknown metal"),
        ({"material": "metal", "rgb": [0.5, 0.5, 0.5]}, "colour is its metal"),
        ({"material": "metal", "subsurface": "marble"}, "opaque"),
        ({"metal": "gold"}, "metal applies"),
        ({"material": "metal", "metal": 3}, "metal must be a name"),
        ({"srgb8": [300, 0, 0]}, "srgb8"),
    ],
)
def test_material_errors_name_the_problem(extra, match):
    with pytest.raises(ValueError, match=match):
        scene_from_dict({"object": [{**PLANE, **extra}]})


def test_rgb_is_three_reflectances_or_one_for_a_grey():
    """scenes/README.md writes plaster as ``rgb = 0.85``: a user's audit (2026-11-30) found such a
    file refused with "'float' object is not iterable"; anything else names the key."""
    grey = scene_from_dict({"object": [{**PLANE, "rgb": 0.85}]}).objects[0].material
    assert grey.rgb == (0.85, 0.85, 0.85)
    for bad in (True, "white", [0.5, 0.5], 2.0, {"r": 1}):
        with pytest.raises(ValueError, match=r"object\[0\] .*rgb reflectance"):
            scene_from_dict({"object": [{**PLANE, "rgb": bad}]})


def test_srgb8_and_plastic_reach_the_material():
    s = scene_from_dict({"object": [{**PLANE, "srgb8": [0, 255, 255], "material": "plastic", "roughness": 0.2}]})
    m = s.objects[0].material
    assert m.kind == "plastic" and m.roughness == 0.2 and m.rgb == pytest.approx((0.04, 0.8, 0.8))


def test_plastic_becomes_roughplastic(variant):
    from simbench.sim.scene import object_to_mitsuba

    s = scene_from_dict({"object": [{**PLANE, "rgb": [0.2, 0.3, 0.4], "material": "plastic", "roughness": 0.05}]})
    bsdf = object_to_mitsuba(s.objects[0])["bsdf"]["bsdf"]
    assert (
        bsdf["type"] == "roughplastic"
        and bsdf["alpha"] == 0.05
        and bsdf["diffuse_reflectance"]["value"] == [0.2, 0.3, 0.4]
    )


def test_metal_reaches_the_material_with_its_reflectance():
    s = scene_from_dict({"object": [{**PLANE, "material": "metal", "metal": "gold", "roughness": 0.2}]})
    m = s.objects[0].material
    assert m.kind == "metal" and m.metal == "gold" and m.roughness == 0.2
    # gold's normal-incidence reflectance per camera channel: red high, blue low
    assert m.rgb[0] > 0.85 and m.rgb[2] < 0.45
    assert scene_from_dict({"object": [{**PLANE, "material": "metal"}]}).objects[0].material.metal == "aluminium"


@pytest.mark.parametrize("roughness", [0.05, 0.3])
@pytest.mark.parametrize("theta_deg", [(0.0, 0.0), (30.0, -10.0), (60.0, -50.0)])
def test_metal_bsdf_is_the_ggx_microfacet_model(variant, roughness, theta_deg):
    """Mitsuba's evaluation of a scene's metal equals the closed-form Cook-Torrance model
    F(wi.h) D(h) G1(wi) G1(wo) / (4 cos_i cos_o) with GGX D and Smith G1 (Walter et al. 2007,
    Eq. 33-34) and the exact conductor Fresnel of the metal's optical constants."""
    import drjit as dr
    import mitsuba as mi

    from simbench.sim.scene import object_to_mitsuba
    from simbench.sim.spectral import conductor_fresnel, metal_ior_rgb

    s = scene_from_dict({"object": [{**PLANE, "material": "metal", "metal": "copper", "roughness": roughness}]})
    bsdf = mi.load_dict(object_to_mitsuba(s.objects[0])["bsdf"])
    ti, to = np.radians(theta_deg)
    wi = np.array([np.sin(ti), 0.0, np.cos(ti)])
    wo = np.array([np.sin(to), 0.0, np.cos(to)])
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.n = mi.Normal3f(0.0, 0.0, 1.0)
    si.sh_frame = mi.Frame3f(si.n)
    si.wi = mi.Vector3f(*map(float, wi))
    got = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*map(float, wo)))).ravel()
    a = roughness
    h = (wi + wo) / np.linalg.norm(wi + wo)
    d = a * a / (np.pi * (h[2] ** 2 * (a * a - 1) + 1) ** 2)

    def g1(c):
        return 2.0 / (1.0 + np.sqrt(1.0 + a * a * (1 - c * c) / (c * c)))

    eta, k = metal_ior_rgb("copper")
    f = conductor_fresnel(np.asarray(eta), np.asarray(k), float(wi @ h)) * d * g1(wi[2]) * g1(wo[2])
    # Mitsuba returns the BSDF times the cosine of the outgoing direction
    np.testing.assert_allclose(got, f / (4 * wi[2] * wo[2]) * wo[2], rtol=1e-4)


def test_per_primary_metal_keeps_its_band_and_its_cache_key():
    from simbench.sim.scene import scene_fingerprint
    from simbench.sim.capture import _primary_scene

    s = scene_from_dict({"object": [{**PLANE, "material": "metal", "metal": "gold"}]})
    prim = [_primary_scene(s, p).objects[0].material for p in range(3)]
    assert [m.metal_primary for m in prim] == [0, 1, 2]
    keys = {str(scene_fingerprint(_primary_scene(s, p))) for p in range(3)}
    other = scene_from_dict({"object": [{**PLANE, "material": "metal", "metal": "silver"}]})
    assert len(keys) == 3 and str(scene_fingerprint(other)) != str(scene_fingerprint(s))


@pytest.mark.parametrize("name", ["discontinuity", "geometries", "bust", "clutter_pink_cyan", "clutter_pear_hat"])
def test_paper_scenes_have_their_objects_in_view(name):
    """Every object's centre projects inside the camera image (the scene shows what it claims)."""
    s = load_scene(SCENES / f"{name}.toml")
    cam = s.rig.camera
    for o in s.objects:
        c = np.asarray(o.get("center_m") if o.kind != "mesh" else o.get("translate_m"), float)
        if o.kind == "mesh":
            c = c + np.array([0.0, -0.05, 0.0])  # meshes stand on their base: look a little above it
        x = cam.focal_px * c[0] / c[2] + cam.cx_px
        y = cam.focal_px * c[1] / c[2] + cam.cy_px
        assert 0 <= x < cam.width_px and 0 <= y < cam.height_px, (name, o.name, x, y)


def test_table1_and_fig9_scene_sets_are_complete():
    from simbench.experiments.fig9 import DEPTHS_M
    from simbench.experiments.table1 import PAPER_TABLE1

    for colour, (srgb, _) in PAPER_TABLE1.items():
        s = load_scene(SCENES / f"plane_{colour}.toml")
        assert s.objects[0].material.rgb == pytest.approx(paint_reflectance(srgb))
        assert s.objects[0].get("center_m")[2] == 1.0
    for z in DEPTHS_M:
        s = load_scene(SCENES / f"plane_depth_{int(round(z * 100)):03d}cm.toml")
        assert s.objects[0].get("center_m")[2] == pytest.approx(z)


@pytest.mark.slow
def test_meshes_are_regenerated_identically(tmp_path):
    """scenes/make_meshes.py reproduces the shipped PLY files: byte for byte where this machine's
    numpy takes the SIMD loops of the one that wrote a file (hat.ply: an AVX2-only AMD EPYC; the
    others: an AVX-512 one), and elsewhere the same header and faces with the float32 vertices
    and normals within two float32 steps (6e-8 m at the meshes' <= 0.5 m coordinates, 2.4e-7 in a
    unit normal).  numpy's float64 sin, arctan2 and power differ in the last bit between its
    AVX-512 and AVX2 loops, which can tip a float32 rounding (measured: 20 of the old hat's
    vertices 2.9e-17 m apart, in components next to zero); a real change to a shape moves them
    by orders of magnitude more (a camera pixel spans ~0.5 mm at 1 m)."""
    import trimesh

    subprocess.run(
        [sys.executable, str(SCENES / "make_meshes.py"), str(tmp_path)], check=True, capture_output=True, cwd=ROOT
    )
    shipped = sorted((SCENES / "meshes").glob("*.ply"))
    assert shipped and sorted(p.name for p in tmp_path.glob("*.ply")) == [p.name for p in shipped]
    for p in shipped:
        made, ours = (tmp_path / p.name).read_bytes(), p.read_bytes()
        if made == ours:
            continue
        head = ours[: ours.index(b"end_header")]
        assert made[: made.index(b"end_header")] == head, p.name
        a, b = (trimesh.load(f, process=False) for f in (p, tmp_path / p.name))
        assert np.array_equal(a.faces, b.faces), p.name
        np.testing.assert_allclose(b.vertices, a.vertices, rtol=0, atol=6e-8, err_msg=p.name)
        np.testing.assert_allclose(b.vertex_normals, a.vertex_normals, rtol=0, atol=2.4e-7, err_msg=p.name)


def test_the_straw_hat_has_its_weave_relief():
    """scenes/meshes/hat.ply's crown side stands off its smooth profile by the weave's +-0.5 mm
    (the weave once sat on its own zeros at every vertex: a relief of 4e-9 m)."""
    import trimesh

    v = trimesh.load(SCENES / "meshes" / "hat.ply", process=False).vertices
    height, radius = -v[:, 1], np.hypot(v[:, 0], v[:, 2])  # camera frame: y down, the crown's axis
    side = (height > 0.02) & (height < 0.09)
    relief = radius[side] - (0.085 - 0.01 * ((height[side] - 0.012) / 0.088) ** 2)  # make_meshes.hat's profile
    assert 0.0004 < np.abs(relief).max() <= 0.00051
    assert relief.std() > 0.0002


def test_malformed_mesh_gives_one_clear_error(tmp_path):
    """Caught when the scene is read (simbench.sim.scene.check_mesh_file), before Mitsuba loads it."""
    (tmp_path / "broken.ply").write_text("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n")
    with pytest.raises(ValueError, match=r"object\[0\] 'statue'.*broken.ply"):
        scene_from_dict(
            {"name": "mine", "object": [{"type": "mesh", "name": "statue", "file": "broken.ply"}]}, base_dir=tmp_path
        )
