import dataclasses

import numpy as np
import pytest

from simbench.sim.scene import load_scene, scene_from_dict

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
        ({"object": [{"type": "sphere", "center_m": [0, 0, 1]}]}, "missing radius_m"),
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
    from simbench.sim.scene import Placement, place_objects, scene_from_dict

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
    from simbench.sim.scene import scene_from_dict
    from simbench.sim.spectral import material_crosstalk, measured_linear_srgb

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
    from simbench.sim.scene import board_form_m

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
    from simbench.sim.scene import scene_fingerprint
    from simbench.sim.scene import Placement, place_objects

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
    from simbench.sim.scene import Placement, place_objects

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


# ---------------------------------------------------------------------------------------
# Meshes are checked before Mitsuba sees them (issue 33: a face indexing a missing vertex made
# `simbench render` segfault in some runs and exit 0 in others).


def _ply_text(vertices, faces) -> str:
    head = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(vertices)}",
        "property float x",
        "property float y",
        "property float z",
        f"element face {len(faces)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    rows = [" ".join(repr(float(c)) for c in v) for v in vertices]
    rows += ["3 " + " ".join(str(int(i)) for i in f) for f in faces]
    return "\n".join(head + rows) + "\n"


def _mesh_scene(tmp_path, text: str, name: str = "m.ply"):
    (tmp_path / name).write_text(text)
    return {"name": "m", "object": [{"type": "mesh", "file": name, "translate_m": [0, 0, 1]}]}


_TRI = [(0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.0, 0.1, 0.0), (0.1, 0.1, 0.0)]


@pytest.mark.parametrize(
    "vertices, faces, match",
    [
        (_TRI, [(0, 1, 2), (0, 1, 99999)], "face 1 indexes vertex 99999, but the mesh has 4 vertices"),
        (_TRI, [(0, 1, 2), (1, 2, -5)], "face 1 indexes vertex -5"),
        (_TRI, [(0, 1, 4)], "indexes vertex 4"),  # one past the end
        ([(0.0, 0.0, 0.0), (float("nan"), 0.0, 0.0), (0.0, 0.1, 0.0)], [(0, 1, 2)], "vertex 1 is not finite"),
        ([(0.0, 0.0, 0.0), (float("inf"), 0.0, 0.0), (0.0, 0.1, 0.0)], [(0, 1, 2)], "vertex 1 is not finite"),
        (_TRI, [(0, 0, 1), (2, 2, 2)], "every one of its 2 faces has zero area"),
        ([(0.0, 0.0, 0.0), (0.1, 0.0, 0.0), (0.2, 0.0, 0.0)], [(0, 1, 2)], "zero area"),  # collinear
        (_TRI, [], "no triangle faces"),
    ],
)
def test_a_bad_mesh_is_refused_with_one_line(tmp_path, vertices, faces, match):
    with pytest.raises(ValueError, match=match) as info:
        scene_from_dict(_mesh_scene(tmp_path, _ply_text(vertices, faces)), base_dir=tmp_path)
    assert "\n" not in str(info.value) and "m.ply" in str(info.value) and "object[0]" in str(info.value)


def test_mesh_files_that_are_no_mesh(tmp_path):
    import os

    os.mkfifo(tmp_path / "pipe.ply")  # reading it would block for ever; said "not found" before
    with pytest.raises(ValueError, match="pipe.ply is not a regular file"):
        scene_from_dict({"object": [{"type": "mesh", "file": "pipe.ply"}]}, base_dir=tmp_path)
    (tmp_path / "d.ply").mkdir()
    with pytest.raises(ValueError, match="d.ply is a folder"):
        scene_from_dict(
            _mesh_scene(tmp_path, "", "x.obj") | {"object": [{"type": "mesh", "file": "d.ply"}]}, base_dir=tmp_path
        )
    for text in ("", "ply\nformat ascii 1.0\nelement vertex 2\nend_header\n", "\x00\xff" * 50):
        with pytest.raises(ValueError, match="m.ply: (not a readable PLY mesh|no triangle faces)"):
            scene_from_dict(_mesh_scene(tmp_path, text), base_dir=tmp_path)


def test_a_missing_mesh_says_where_a_relative_path_is_taken_from(tmp_path):
    """A library scene copied elsewhere (an audit, 2026-12-05): its relative mesh path reads from
    the scene file's folder, which the error names; an absolute path is named alone."""
    with pytest.raises(
        FileNotFoundError,
        match=r"mesh file not found: .*meshes/bust.ply \(a relative mesh path is taken from the scene file's folder, ",
    ):
        scene_from_dict({"object": [{"type": "mesh", "file": "meshes/bust.ply"}]}, base_dir=tmp_path)
    with pytest.raises(FileNotFoundError, match=r"mesh file not found: /nowhere/bust.ply$"):
        scene_from_dict({"object": [{"type": "mesh", "file": "/nowhere/bust.ply"}]}, base_dir=tmp_path)


def test_mesh_size_bounds(tmp_path, monkeypatch):
    import simbench.sim.scene as scene_module

    monkeypatch.setattr(scene_module, "MESH_MAX_FACES", 1)
    scene_module.check_mesh_file.cache_clear()
    with pytest.raises(ValueError, match="4 vertices and 2 faces; at most"):
        scene_from_dict(_mesh_scene(tmp_path, _ply_text(_TRI, [(0, 1, 2), (1, 3, 2)])), base_dir=tmp_path)
    scene_module.check_mesh_file.cache_clear()
    with pytest.raises(ValueError, match="GiB, larger than"):
        scene_module.check_mesh_file(str(tmp_path / "m.ply"), 0, 3 << 30)


def test_a_mesh_with_some_zero_area_faces_loads(tmp_path):
    """Scanned meshes carry a few degenerate faces; Mitsuba never hits them: legal."""
    scene = scene_from_dict(_mesh_scene(tmp_path, _ply_text(_TRI, [(0, 1, 2), (1, 1, 3)])), base_dir=tmp_path)
    assert scene.objects[0].kind == "mesh"


def test_an_edited_mesh_file_is_checked_again(tmp_path):
    import os

    data = _mesh_scene(tmp_path, _ply_text(_TRI, [(0, 1, 2)]))
    scene_from_dict(data, base_dir=tmp_path)
    (tmp_path / "m.ply").write_text(_ply_text(_TRI, [(0, 1, 7)]))
    os.utime(tmp_path / "m.ply", ns=(1, 1))  # the memo is keyed by the file's time and size too
    with pytest.raises(ValueError, match="indexes vertex 7"):
        scene_from_dict(data, base_dir=tmp_path)


def test_fuzzed_meshes_are_refused_cleanly_or_load(tmp_path_factory):
    """Hypothesis: random triangle meshes, some with one index or one coordinate corrupted.
    Every one either loads (nothing corrupted, some face of non-zero area) or raises one
    ValueError line naming the file; never another exception."""
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    coords = st.floats(-1.0, 1.0, allow_nan=False, width=32)
    corrupt = st.one_of(
        st.none(),
        st.tuples(st.just("index"), st.integers(-(2**31), 2**31 - 1)),
        st.tuples(st.just("coord"), st.sampled_from([float("nan"), float("inf"), -float("inf")])),
    )

    @settings(max_examples=60, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
    @given(
        nv=st.integers(3, 12),
        data=st.data(),
        corruption=corrupt,
    )
    def run(nv, data, corruption):
        import simbench.sim.scene as scene_module

        folder = tmp_path_factory.mktemp("mesh")
        vertices = [tuple(data.draw(coords) for _ in range(3)) for _ in range(nv)]
        faces = data.draw(st.lists(st.tuples(*[st.integers(0, nv - 1)] * 3), min_size=1, max_size=8))
        bad = False
        if corruption is not None:
            kind, value = corruption
            if kind == "index" and not 0 <= value < nv:
                f = list(faces[0])
                f[data.draw(st.integers(0, 2))] = value
                faces[0] = tuple(f)
                bad = True
            elif kind == "coord":
                v = list(vertices[0])
                v[data.draw(st.integers(0, 2))] = value
                vertices[0] = tuple(v)
                bad = True
        scene_module.check_mesh_file.cache_clear()
        try:
            scene_from_dict(_mesh_scene(folder, _ply_text(vertices, faces)), base_dir=folder)
        except ValueError as exc:
            assert "\n" not in str(exc) and "m.ply" in str(exc)
            if not bad:
                assert "zero area" in str(exc)  # the one refusal a clean random mesh can earn
        else:
            assert not bad, "a corrupted mesh loaded"

    run()


def test_a_bad_mesh_never_reaches_the_renderer(tmp_path):
    """In a fresh process, as a user runs it: one error line and exit 2, every time (the
    segfault was intermittent: three runs)."""
    import subprocess
    import sys
    from pathlib import Path

    data = _mesh_scene(tmp_path, _ply_text(_TRI, [(0, 1, 2), (0, 1, 99999)]))
    (tmp_path / "s.toml").write_text('name = "m"\n[[object]]\ntype = "mesh"\nfile = "m.ply"\ntranslate_m = [0, 0, 1]\n')
    assert data["object"][0]["file"] == "m.ply"
    exe = Path(sys.executable).parent / "simbench"
    for _ in range(3):
        res = subprocess.run(
            [str(exe), "render", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"), "--no-cache"],
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert res.returncode == 2, (res.returncode, res.stderr)
        assert res.stderr.count("\n") == 1 and "indexes vertex 99999" in res.stderr
    assert not (tmp_path / "out").exists()


def test_placements_no_view_could_mean_are_warned_of_and_the_shipped_scenes_have_none(tmp_path):
    """A new user's audit: a mesh in millimetres (200 "m" across, the camera inside it), an object
    wholly behind the camera and a camera inside a sphere each rendered without a word."""
    import shutil

    from simbench.sim.timeline import placement_warnings

    for path in sorted(SCENES.glob("*.toml")):
        assert placement_warnings(load_scene(path)) == [], path.name
    shutil.copy(SCENES / "meshes" / "cone.ply", tmp_path / "cone.ply")
    scene = scene_from_dict(
        {
            "name": "odd",
            "rig": "paper",
            "object": [
                {
                    "type": "mesh",
                    "name": "mm",
                    "file": str(tmp_path / "cone.ply"),
                    "translate_m": [0, 0, 1.0],
                    "scale": 1000.0,
                },
                {"type": "sphere", "name": "behind", "center_m": [0, 0, -2.0], "radius_m": 0.5},
                {"type": "sphere", "name": "around", "center_m": [0, 0, 0.1], "radius_m": 0.5},
                # its bounding box holds the camera, the ball does not (a review: warned by the box)
                {"type": "sphere", "name": "beside", "center_m": [0.3, 0.3, 0.3], "radius_m": 0.5},
                {
                    "type": "box",
                    "name": "turned",
                    "center_m": [0, 0, 0.4],
                    "size_m": [0.2, 0.2, 0.2],
                    "rotation_deg": [0, 45, 0],
                },
                {"type": "plane", "name": "wall", "center_m": [0, 0, 1.5], "size_m": [2.0, 2.0]},
            ],
        }
    )
    told = placement_warnings(scene)
    assert any("'mm': the mesh spans" in t and "`scale = 0.001`" in t for t in told)
    assert any("'behind' lies wholly behind the camera" in t for t in told)
    assert any("inside the bounds of object 'around'" in t for t in told)
    assert any("inside the bounds of object 'mm'" in t for t in told)
    assert not any("'wall'" in t or "'beside'" in t or "'turned'" in t for t in told)


def test_a_recording_warns_of_objects_no_pixel_sees_and_of_lit_surface_beyond_the_working_range():
    """A new user's audit (2026-11-30): a blob moved 3 m aside rendered without a word, and a wall
    at 2.5 m - beyond the decoder's 0.75-1.75 m, where the code repeats - decoded at 0.83 m, 78 %
    of it at confidence 6, exit 0.  The ground truth tells both (simbench.api.recording_warnings)."""
    from simbench.api import recording_warnings
    from simbench.decode import DecoderParams
    from simbench.sim.truth import GroundTruth

    scene = scene_from_dict(
        {
            "name": "s",
            "rig": "paper",
            "object": [
                {"type": "sphere", "name": "ball", "center_m": [0, 0, 1.0], "radius_m": 0.1},
                {"type": "sphere", "name": "aside", "center_m": [3.0, 0, 1.0], "radius_m": 0.1},
                {"type": "plane", "name": "wall", "center_m": [0, 0, 1.5], "size_m": [2.0, 2.0]},
            ],
        }
    )
    oid = np.full((100, 100), 2, np.int16)
    oid[40:60, 40:60] = 0
    depth = np.where(oid == 0, 1.0, 1.5).astype(np.float32)
    gt = GroundTruth(depth_m=depth, column_px=np.zeros(depth.shape), object_id=oid, lit=np.ones(depth.shape, bool))
    told = recording_warnings(scene, gt, DecoderParams())
    assert len(told) == 1 and "no pixel sees object(s) 'aside'" in told[0]
    # the wall at 2.5 m: 96 % of the lit pixels beyond the far end
    far = GroundTruth(
        depth_m=np.where(oid == 0, 1.0, 2.5).astype(np.float32), column_px=gt.column_px, object_id=oid, lit=gt.lit
    )
    told = recording_warnings(scene, far, DecoderParams())
    assert "96.0 % of the lit pixels lie outside the decoder's working range 0.75-1.75 m" in told[1]
    assert "1-2.5 m" in told[1] and "--near/--far" in told[1]
    # unlit pixels beyond it do not count, nor does a competitor (no decoder range), nor a sliver under 0.1 %
    assert len(recording_warnings(scene, dataclasses.replace(far, lit=oid == 0), DecoderParams())) == 1
    assert len(recording_warnings(scene, far)) == 1
    sliver = far.depth_m.copy()
    sliver[:] = 1.0
    sliver[0, :5] = 2.5  # 0.05 %
    assert len(recording_warnings(scene, dataclasses.replace(far, depth_m=sliver), DecoderParams())) == 1


def test_meshes_mitsubas_loader_would_not_read_as_they_are_go_to_it_as_arrays(tmp_path, variant):
    """A new user's audit (2026-11-30): a PLY of quads and an OBJ with relative indices - legal
    files - failed inside Mitsuba with its loader's messages, and a mesh without vertex normals
    was not the same bits between cold renders.  Such files go to Mitsuba as arrays (trimesh's
    triangles, our angle-weighted normals, which the mesh keeps as given); the library's meshes,
    triangles with normals, go as files, as before (their cache keys unchanged)."""
    import mitsuba as mi
    import trimesh

    from simbench.sim.scene import mesh_arrays, object_to_mitsuba, scene_fingerprint, vertex_normals
    from simbench.sim.truth import ground_truth

    for path in sorted((SCENES / "meshes").glob("*.ply")):
        assert mesh_arrays(str(path)) is None, path.name
    # a cube's corner: the angle-weighted normal points along the diagonal
    cube = trimesh.creation.box(extents=(1, 1, 1))
    n = vertex_normals(cube.vertices, cube.faces)
    assert np.allclose(np.abs(n), 1 / np.sqrt(3)) and np.allclose(np.sign(n), np.sign(cube.vertices))
    # a ball without normals: given as arrays, the normals radial, and the Mitsuba mesh holds them as given
    ball = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    (tmp_path / "ball.ply").write_bytes(trimesh.exchange.ply.export_ply(ball, include_attributes=False))
    assert b"nx" not in (tmp_path / "ball.ply").read_bytes()[:400]
    vertices, faces, normals = mesh_arrays(str(tmp_path / "ball.ply"))
    assert np.all(np.einsum("ij,ij->i", normals, vertices / np.linalg.norm(vertices, axis=1, keepdims=True)) > 0.995)
    quad = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    quad += "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    quad += "-0.1 -0.1 0\n0.1 -0.1 0\n0.1 0.1 0\n-0.1 0.1 0\n4 0 1 2 3\n"
    (tmp_path / "quad.ply").write_text(quad)
    (tmp_path / "neg.obj").write_text("v -0.1 -0.1 0\nv 0.1 -0.1 0\nv 0 0.1 0\nf -3 -2 -1\n")
    objects = []
    for name, x in (("ball.ply", 0.0), ("quad.ply", -0.16), ("neg.obj", 0.16)):
        objects.append({"type": "mesh", "name": name.replace(".", "_"), "file": name, "translate_m": [x, 0, 1.0]})
        objects[-1]["scale"] = 0.05 if name == "ball.ply" else 1.0
    scene = scene_from_dict({"name": "own", "rig": "paper", "object": objects}, base_dir=tmp_path)
    mesh = object_to_mitsuba(scene.objects[0])
    got = np.asarray(mi.traverse(mesh)["vertex_normals"]).reshape(-1, 3)
    assert np.array_equal(got, normals.astype(np.float32))  # no normals of Mitsuba's own
    assert "read" in scene_fingerprint(scene)["objects"][1]["params"]["file"]
    # the ball (its front at 0.95 m), the quad and the triangle of relative indices all render, each whole
    gt = ground_truth(scene)
    assert gt.depth_m[480, 640] == pytest.approx(0.95, abs=1e-3)
    cam = scene.rig.camera
    for k, (half, area_m2) in enumerate(((0.05, np.pi * 0.05**2), (0.1, 0.04), (0.1, 0.02))):
        seen = (gt.object_id == k).sum() * (1.0 / cam.focal_px) ** 2  # m^2 at 1 m
        assert seen == pytest.approx(area_m2, rel=0.05), (k, seen)
