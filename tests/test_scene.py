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
        (
            {
                "object": [
                    {"type": "sphere", "radius_m": 1, "name": "a"},
                    {"type": "sphere", "radius_m": 1, "name": "a"},
                ]
            },
            "unique",
        ),
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

    scene = scene_from_dict(
        {
            "object": [
                {"type": "plane", "name": "board", "center_m": [0, 0, 1.0], "size_m": [1, 1]},
                {"type": "box", "name": "cube", "center_m": [0, 0, 0.9], "size_m": [0.1, 0.1, 0.1]},
                {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
            ]
        }
    )
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
    for bad, match in (
        ({"spectrum": "ColorChecker N Ohta/nope"}, "no patch"),
        ({"spectrum": "Nope/blue"}, "dataset"),
        ({"spectrum": 3}, "string"),
        ({"spectrum": "ColorChecker N Ohta/blue", "rgb": [1, 1, 1]}, "not rgb and spectrum"),
    ):
        with pytest.raises(ValueError, match=match):
            scene_from_dict({"object": [{"type": "plane", "size_m": [1, 1], **bad}]})


def test_board_form_against_its_definition():
    """The bow sags by bow_m_per_m over a 1 m chord through the centre whatever the board's
    size, the board's mean height stays 0 (its center_m is its mean plane), and the ripple has
    its amplitude and period across x only."""
    from simbench.scene import board_form_m

    for size in ((2.0, 1.6), (0.4, 0.3)):
        cells = [(np.arange(n) + 0.5) / n * s - s / 2 for n, s in ((800, size[0]), (600, size[1]))]  # cell centres
        h = board_form_m(*np.meshgrid(*cells), size_m=size, bow_m_per_m=0.001)
        assert abs(h.mean()) < 1e-5 * np.abs(h).max()  # the midpoint rule's error on a quadratic: ~1/n^2
        centre = board_form_m(0.0, 0.0, size_m=size, bow_m_per_m=0.001)
        for px, py in ((0.5, 0.0), (0.0, -0.5), (0.3, 0.4)):  # 0.5 m from the centre
            assert centre - board_form_m(px, py, size_m=size, bow_m_per_m=0.001) == pytest.approx(0.001, rel=1e-12)
    x = np.linspace(-0.2, 0.2, 4001)
    w = board_form_m(
        x, np.full_like(x, 0.1), size_m=(0.4, 0.4), waviness_m=1e-4, waviness_period_m=0.05, waviness_phase_rad=1.0
    )
    assert w.max() == pytest.approx(1e-4, rel=1e-4) and w.min() == pytest.approx(-1e-4, rel=1e-4)
    assert board_form_m(x + 0.05, 0.0, size_m=(0.4, 0.4), waviness_m=1e-4) == pytest.approx(
        board_form_m(x, 0.0, size_m=(0.4, 0.4), waviness_m=1e-4), abs=1e-15
    )
    assert board_form_m(0.1, 0.2, size_m=(0.4, 0.4), waviness_m=1e-4) == board_form_m(
        0.1, -0.1, size_m=(0.4, 0.4), waviness_m=1e-4
    )


@pytest.mark.parametrize(
    "extra, match",
    [
        ({"bow_m_per_m": 0.5}, "bow_m_per_m"),
        ({"waviness_m": -1e-4}, "waviness_m"),
        ({"waviness_m": 1e-4, "waviness_period_m": 0.0}, "waviness_period_m"),
        ({"bow_m_per_m": "flat"}, "bow_m_per_m"),
    ],
)
def test_board_form_keys_are_validated(extra, match):
    with pytest.raises(ValueError, match=match):
        scene_from_dict({"object": [{"type": "plane", "size_m": [1, 1], **extra}]})
    with pytest.raises(ValueError, match="unknown key"):
        scene_from_dict({"object": [{"type": "box", "size_m": [1, 1, 1], "bow_m_per_m": 0.001}]})


def test_board_form_placement_keeps_the_poses_and_flat_boards_their_keys():
    """Formed boards sit in the same seeded poses as flat ones (the form is drawn after every
    placement); a flat board's parameters, and so its render-cache key, do not change."""
    from simbench.cache import scene_fingerprint
    from simbench.scene import Placement, place_objects

    scene = scene_from_dict(
        {
            "object": [
                {"type": "plane", "name": "board", "center_m": [0, 0, 1.0], "size_m": [1, 1]},
                {"type": "box", "name": "cube", "center_m": [0, 0, 0.9], "size_m": [0.1, 0.1, 0.1]},
            ]
        }
    )
    flat, off_flat = place_objects(scene, ["board", "cube"], placement=Placement(), rng=3)
    formed, off = place_objects(
        scene, ["board", "cube"], placement=Placement(bow_m_per_m=0.001, waviness_m=5e-5), rng=3
    )
    board = dict(formed.objects[0].params)
    assert (
        abs(board["bow_m_per_m"]) == 0.001
        and board["waviness_m"] == 5e-5
        and 0 <= board["waviness_phase_rad"] < 2 * np.pi
    )
    for k in ("center_m", "rotation_deg"):
        assert board[k] == dict(flat.objects[0].params)[k]
    assert formed.objects[1] == flat.objects[1]  # boxes do not bow
    assert (
        off["board"]["depth_m"] == off_flat["board"]["depth_m"] and off["board"]["bow_m_per_m"] == board["bow_m_per_m"]
    )
    explicit = scene_from_dict(
        {
            "object": [
                {
                    "type": "plane",
                    "name": "board",
                    "center_m": [0, 0, 1.0],
                    "size_m": [1, 1],
                    "bow_m_per_m": 0.0,
                    "waviness_m": 0.0,
                }
            ]
        }
    )
    plain = scene_from_dict({"object": [{"type": "plane", "name": "board", "center_m": [0, 0, 1.0], "size_m": [1, 1]}]})
    assert scene_fingerprint(explicit) == scene_fingerprint(plain)
    with pytest.raises(ValueError, match="bow_m_per_m"):
        Placement(bow_m_per_m=-0.001)


def test_placement_moves_spheres_and_meshes_too(tmp_path):
    """Every object kind can be placed (the ablations place every object of a scene): a mesh
    moves by its translation and tilts, a sphere moves in depth only; the draws of the objects
    after them do not depend on their kind."""
    from simbench.scene import Placement, place_objects

    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    scene = scene_from_dict(
        {
            "object": [
                {"type": "mesh", "name": "bust", "file": "m.obj", "translate_m": [0, 0, 1.0]},
                {"type": "sphere", "name": "ball", "center_m": [0, 0, 0.9], "radius_m": 0.1},
                {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
            ]
        },
        base_dir=tmp_path,
    )
    placed, off = place_objects(scene, ["bust", "ball", "wall"], placement=Placement(), rng=4)
    mesh, ball, wall = (dict(o.params) for o in placed.objects)
    assert mesh["translate_m"][2] == pytest.approx(1.0 + off["bust"]["depth_m"]) and mesh["rotation_deg"][
        :2
    ] == pytest.approx(tuple(off["bust"]["tilt_deg"]))
    assert ball["center_m"][2] == pytest.approx(0.9 + off["ball"]["depth_m"]) and off["ball"]["tilt_deg"] == [0.0, 0.0]
    assert off["ball"]["depth_m"] != 0.0 and off["bust"]["tilt_deg"] != [0.0, 0.0]
    boxed = scene_from_dict(
        {
            "object": [
                {"type": "box", "name": "bust", "center_m": [0, 0, 1.0], "size_m": [0.1, 0.1, 0.1]},
                {"type": "box", "name": "ball", "center_m": [0, 0, 0.9], "size_m": [0.1, 0.1, 0.1]},
                {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
            ]
        }
    )
    assert place_objects(boxed, ["bust", "ball", "wall"], placement=Placement(), rng=4)[1]["wall"] == off["wall"]
