import numpy as np
import pytest

from simbench.scene import load_scene, scene_from_dict

from .conftest import SCENES


@pytest.mark.parametrize("path", sorted(SCENES.glob("*.toml")), ids=lambda p: p.stem)
def test_shipped_scenes_load(path):
    s = load_scene(path)
    assert s.objects and s.rig.camera.width_px == 1280


@pytest.mark.parametrize(
    "data, match",
    [
        ({"object": []}, "at least one"),
        ({"object": [{"type": "cone"}]}, "unknown type 'cone'"),
        ({"object": [{"type": "plane", "size_m": [1, 1], "colour": [1, 1, 1]}]}, "unknown key"),
        ({"object": [{"type": "plane"}]}, "missing size_m"),
        ({"object": [{"type": "plane", "size_m": [1, 1], "rgb": [2, 0, 0]}]}, "rgb"),
        ({"object": [{"type": "sphere", "radius_m": -1}]}, "radius_m"),
        ({"object": [{"type": "mesh", "file": "nope.ply"}]}, "not found"),
        ({"rig": "nope", "object": [{"type": "sphere", "radius_m": 1}]}, "unknown rig"),
        ({"object": [{"type": "sphere", "radius_m": 1}], "bogus": 1}, "unknown key"),
        ({"object": [{"type": "sphere", "radius_m": 1, "name": "a"}, {"type": "sphere", "radius_m": 1, "name": "a"}]}, "unique"),
    ],
)
def test_broken_scenes_name_the_problem(data, match):
    with pytest.raises((ValueError, FileNotFoundError), match=match):
        scene_from_dict(data)


def test_scene_file_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_scene(tmp_path / "none.toml")
    (tmp_path / "b.toml").write_text("object = [")
    with pytest.raises(ValueError, match="not valid TOML"):
        load_scene(tmp_path / "b.toml")


def test_placement_is_seeded_bounded_and_leaves_other_objects():
    from simbench.scene import Placement, place_objects, scene_from_dict

    scene = scene_from_dict({"object": [
        {"type": "plane", "name": "board", "center_m": [0, 0, 1.0], "size_m": [1, 1]},
        {"type": "box", "name": "cube", "center_m": [0, 0, 0.9], "size_m": [0.1, 0.1, 0.1]},
        {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
    ]})
    pl = Placement(depth_m=0.01, tilt_deg=2.0)
    a, off_a = place_objects(scene, ["board", "cube"], placement=pl, rng=5)
    b, off_b = place_objects(scene, ["board", "cube"], placement=pl, rng=5)
    c, _ = place_objects(scene, ["board", "cube"], placement=pl, rng=6)
    assert a == b and off_a == off_b and a != c
    assert a.objects[2] == scene.objects[2]  # the wall stays
    for name, o in off_a.items():
        assert abs(o["depth_m"]) <= 0.01 and all(abs(t) <= 2.0 for t in o["tilt_deg"])
    board = dict(a.objects[0].params)
    assert board["center_m"][2] == pytest.approx(1.0 + off_a["board"]["depth_m"])
    assert board["rotation_deg"][:2] == pytest.approx(tuple(off_a["board"]["tilt_deg"]))
    # independent errors per object
    assert off_a["board"]["depth_m"] != off_a["cube"]["depth_m"]
    none, _ = place_objects(scene, ["board"], placement=Placement(0.0, 0.0), rng=5)
    assert none == scene
    with pytest.raises(ValueError, match="no object"):
        place_objects(scene, ["nope"], placement=pl, rng=1)
    with pytest.raises(ValueError, match="placement tilt_deg"):
        Placement(tilt_deg=-1)


def test_measured_spectrum_material():
    from simbench.scene import scene_from_dict
    from simbench.spectral import material_crosstalk, measured_linear_srgb

    s = scene_from_dict({"object": [{"type": "plane", "size_m": [1, 1], "spectrum": "ColorChecker N Ohta/blue"}]})
    m = s.objects[0].material
    assert m.spectrum == "ColorChecker N Ohta/blue" and m.rgb == measured_linear_srgb("ColorChecker N Ohta/blue")
    assert m.rgb[2] > 3 * max(m.rgb[:2])  # a blue patch
    # the white patch is a near-neutral ~0.88 reflector
    w = measured_linear_srgb("ColorChecker N Ohta/white 9.5 (.05 D)")
    assert all(0.85 < x < 0.92 for x in w)
    # narrow-band primaries: the surface acts on each primary alone, so K(surface) = K(white) @
    # diag(rho at the primaries) up to the primaries' bandwidth
    k_white = material_crosstalk((1.0, 1.0, 1.0))
    d = np.linalg.solve(k_white, material_crosstalk(None, "ColorChecker N Ohta/blue"))
    assert np.all(np.abs(d - np.diag(np.diag(d))) < 0.02)
    for bad, match in (({"spectrum": "ColorChecker N Ohta/nope"}, "no patch"), ({"spectrum": "Nope/blue"}, "dataset"), ({"spectrum": 3}, "string"), ({"spectrum": "ColorChecker N Ohta/blue", "rgb": [1, 1, 1]}, "not rgb and spectrum")):
        with pytest.raises(ValueError, match=match):
            scene_from_dict({"object": [{"type": "plane", "size_m": [1, 1], **bad}]})
