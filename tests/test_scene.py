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
