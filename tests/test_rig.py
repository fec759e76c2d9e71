import numpy as np
import pytest

from simbench.rig import Intrinsics, Rig, load_rig, paper_rig, projector_column_at_depth, save_rig, triangulate_columns


def test_paper_preset():
    rig = paper_rig()
    assert rig.camera.size_hw == (960, 1280) and rig.projector.size_hw == (1140, 1824)
    assert rig.camera.focal_px == 2312.5320 and rig.projector.focal_px == 2227.9948
    assert rig.baseline_m == pytest.approx(0.093) and rig.is_rectified
    assert rig.camera.cx_px == 639.5 and rig.camera.cy_px == 479.5


def test_toml_round_trip(tmp_path):
    rig = Rig(
        Intrinsics(640, 480, 500.0, 300.25, 250.0),
        Intrinsics(800, 600, 700.0, 410.0, 290.5),
        (0.1, 0.01, -0.02),
        (1.0, -4.0, 0.5),
        "x",
    )
    path = save_rig(rig, tmp_path / "r.toml")
    assert load_rig(path) == rig
    assert "# simbench rig file" in path.read_text()


@pytest.mark.parametrize(
    "text, match",
    [
        (
            "[camera]\nwidth_px=10\nheight_px=10\nfocal_px=-1\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n",
            "focal_px",
        ),
        (
            "[camera]\nwidth_px=10\nheight_px=10\nfocal_px=5\nfoo=1\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n",
            "unknown key",
        ),
        ("[camera]\nwidth_px=10\nheight_px=10\nfocal_px=5\n", "missing key"),
        ("[camera\n", "not valid TOML"),
        (
            "[camera]\nwidth_px=10.5\nheight_px=10\nfocal_px=5\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n",
            "width_px",
        ),
        (
            '[camera]\nwidth_px=10\nheight_px=10\nfocal_px=5\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n[pose]\nposition_m=[0,0,"a"]\n',
            "position_m",
        ),
    ],
)
def test_invalid_rig_files_name_the_problem(tmp_path, text, match):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ValueError, match=match):
        load_rig(p)


def test_missing_rig_file(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_rig(tmp_path / "nope.toml")


@pytest.mark.parametrize("rot", [(0, 0, 0), (0, 5, 0), (2, -3, 1)])
def test_triangulation_inverts_projection(rot):
    rig = Rig(Intrinsics.centred(320, 240, 400.0), Intrinsics.centred(400, 300, 380.0), (0.08, 0.005, 0.01), rot)
    depth = 0.7 + 0.5 * np.random.default_rng(0).random((240, 320))
    col = projector_column_at_depth(depth, rig)
    assert np.allclose(triangulate_columns(col, rig), depth, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "rotation_deg, position_m",
    [((0.0, 0.0, 0.0), (0.093, 0.0, 0.0)), ((0.3, -0.5, 0.2), (0.093, 0.002, -0.001))],
)
def test_triangulation_through_projector_distortion_in_any_rig(rotation_deg, position_m):
    """Exact tier: columns projected through a distorted projector (tangential terms too) in a
    rectified and in a misaligned rig (what a calibration returns) triangulate back to depth."""
    import dataclasses

    from simbench.rig import Rig, pixel_rays, project_to_projector, triangulate_columns

    base = paper_rig()
    proj = dataclasses.replace(base.projector, distortion=(-0.02, 0.01, 0.001, -0.0005, 0.0))
    rig = Rig(base.camera, proj, position_m, rotation_deg, "t")
    z = 1.0 + 0.2 * np.sin(np.arange(1280) / 100.0)[None, :] * np.ones((960, 1))
    u, _, _ = project_to_projector(pixel_rays(rig.camera) * z[..., None], rig)
    assert np.nanmax(np.abs(triangulate_columns(u, rig) - z)) < 1e-9
