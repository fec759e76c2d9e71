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
            "[camera]\nwidth_px=10\nheight_px=10\nfocal_px=-1\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n"
            "[pose]\nposition_m=[0.093, 0.0, 0.0]\n",
            "focal_px",
        ),
        (
            "[camera]\nwidth_px=10\nheight_px=10\nfocal_px=5\nfoo=1\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n"
            "[pose]\nposition_m=[0.093, 0.0, 0.0]\n",
            "unknown key",
        ),
        ("[camera]\nwidth_px=10\nheight_px=10\nfocal_px=5\n", "missing key"),
        ("[camera\n", "not valid TOML"),
        (
            "[camera]\nwidth_px=10.5\nheight_px=10\nfocal_px=5\n[projector]\nwidth_px=10\nheight_px=10\nfocal_px=5\n"
            "[pose]\nposition_m=[0.093, 0.0, 0.0]\n",
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


@pytest.mark.parametrize(
    "distortion, rotation_deg, position_m",
    [
        ((0.0,) * 5, (0.0, 0.0, 0.0), (0.093, 0.0, 0.0)),
        ((0.0,) * 5, (0.4, -0.6, 0.1), (0.093, 0.003, -0.002)),
        ((-0.08, 0.12, 0.0007, -0.0004, 0.01), (0.0, 0.0, 0.0), (0.093, 0.0, 0.0)),
        ((-0.08, 0.12, 0.0007, -0.0004, 0.01), (0.3, -0.8, 0.2), (0.093, 0.002, -0.003)),
    ],
)
def test_compiled_triangulation_gives_the_bits_of_the_numpy_form(distortion, rotation_deg, position_m):
    """Exact tier: the C loop (early exits, lanes, skipped unknown columns) equals the numpy form
    of tests/numpy_reference.py bit for bit, on the image grid, on a band, on listed pixels;
    unknown, infinite and far-off columns included."""
    import dataclasses

    from tests.numpy_reference import triangulate_columns as numpy_triangulate

    base = paper_rig()
    rig = Rig(base.camera, dataclasses.replace(base.projector, distortion=distortion), position_m, rotation_deg, "t")
    rng = np.random.default_rng(7)
    h, w = 240, 1280  # a band of the paper camera's rows
    depth = rng.uniform(0.5, 2.0, (h, w))
    rays = np.stack(np.broadcast_arrays(*np.meshgrid(np.arange(w), np.arange(300, 300 + h)), 1.0), axis=-1)
    rays = (rays - [base.camera.cx_px, base.camera.cy_px, 0.0]) / [base.camera.focal_px, base.camera.focal_px, 1.0]
    from simbench.rig import project_to_projector

    col = project_to_projector(rays * depth[..., None], rig)[0].astype(np.float32).astype(np.float64)
    col[rng.random(col.shape) < 0.2] = np.nan
    col[0, :6] = [np.inf, -np.inf, -1e12, 1e12, 0.0, rig.projector.cx_px]
    rows = np.broadcast_to(np.arange(300, 300 + h)[:, None], (h, w))
    cols = np.broadcast_to(np.arange(w)[None, :], (h, w))
    with np.errstate(all="ignore"):
        want = numpy_triangulate(col, rig, rows=rows, cols=cols)
    assert np.array_equal(triangulate_columns(col, rig, row0=300), want, equal_nan=True)
    assert np.array_equal(triangulate_columns(col, rig, rows=rows, cols=cols), want, equal_nan=True)
    pick = rng.permutation(h * w)[:4099]  # not a multiple of the lane count
    got = triangulate_columns(col.ravel()[pick], rig, rows=rows.ravel()[pick], cols=cols.ravel()[pick])
    assert np.array_equal(got, want.ravel()[pick], equal_nan=True)
    finite = np.isfinite(want[1:])
    assert finite.mean() > 0.75 and np.allclose(want[1:][finite], depth[1:][finite], rtol=1e-5)


def test_triangulation_refuses_a_band_without_rows():
    with pytest.raises(ValueError, match=r"\(H, W\)"):
        triangulate_columns(np.zeros(5), paper_rig())


def test_a_rig_from_an_opencv_stereo_calibration_projects_as_opencv_does():
    """rig_from_opencv: R, T of cv2.stereoCalibrate (camera first: X_p = R X_c + T, T in mm) give the
    rig whose projector pixels are those cv2.projectPoints computes with R, T and the projector's
    matrix and distortion, to 1e-6 px, for a toed-in, rolled and raised projector; R as a Rodrigues
    vector the same; the pose is the inverse of OpenCV's (position -R^T T, rotation R^T); fx != fy
    beyond 0.5 %, skew, and rational-model coefficients refused (a lab user's audit, 2026-11-30:
    the conversion was documented nowhere, and each mistake in it decoded silently wrong)."""
    import cv2

    from simbench.rig import project_to_projector, rig_from_opencv, rotation_xyz_deg

    r_rig = rotation_xyz_deg((1.5, -6.0, 0.8))  # projector axes in camera axes
    position = np.array([0.093, -0.012, 0.004])  # m, the projector's centre in the camera frame
    r_cv = r_rig.T
    t_mm = -r_cv @ position * 1000.0
    k_cam = np.array([[2312.0, 0.0, 641.2], [0.0, 2313.1, 478.9], [0.0, 0.0, 1.0]])
    k_prj = np.array([[2228.0, 0.0, 905.0], [0.0, 2227.0, 1130.5], [0.0, 0.0, 1.0]])
    d_cam, d_prj = np.array([-0.08, 0.1, 0.001, -0.0005, 0.0]), np.array([-0.02, 0.01, 0.0, 0.0, 0.0])
    kw = dict(
        camera_matrix=k_cam,
        camera_distortion=d_cam,
        camera_size_wh=(1280, 960),
        projector_matrix=k_prj,
        projector_distortion=d_prj,
        projector_size_wh=(1824, 1140),
        translation=t_mm,
        translation_unit_m=0.001,
    )
    rig = rig_from_opencv(rotation=r_cv, **kw)
    assert np.allclose(rig.position_m, position, atol=1e-12) and np.allclose(rig.rotation, r_rig, atol=1e-12)
    assert rig.camera.focal_px == pytest.approx(2312.55) and rig.projector.cx_px == 905.0
    assert rig.camera.distortion == tuple(d_cam) and rig.projector.size_hw == (1140, 1824)
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-0.3, 0.3, 200), rng.uniform(-0.2, 0.2, 200), rng.uniform(0.7, 1.5, 200)])
    want = cv2.projectPoints(pts, cv2.Rodrigues(r_cv)[0], t_mm / 1000.0, k_prj, d_prj)[0][:, 0]
    u, v, _ = project_to_projector(pts, rig)
    # (the rig's one focal length is fx's and fy's mean: compare with OpenCV at that focal length)
    want_sq = cv2.projectPoints(pts, cv2.Rodrigues(r_cv)[0], t_mm / 1000.0, _square(k_prj), d_prj)[0][:, 0]
    assert np.allclose(np.column_stack([u, v]), want_sq, atol=1e-6)
    assert np.abs(np.column_stack([u, v]) - want).max() < 0.6  # fy 0.045 % off the mean: < 1 px at the edge
    same = rig_from_opencv(rotation=cv2.Rodrigues(r_cv)[0], **kw)
    assert np.allclose(same.rotation, rig.rotation, atol=1e-12) and same.position_m == pytest.approx(rig.position_m)
    with pytest.raises(ValueError, match="fx = 2312 and fy = 2400 px differ by more than 0.5 %"):
        rig_from_opencv(rotation=r_cv, **{**kw, "camera_matrix": np.diag([2312.0, 2400.0, 1.0])})
    with pytest.raises(ValueError, match="skew"):
        rig_from_opencv(
            rotation=r_cv, **{**kw, "projector_matrix": k_prj + np.array([[0, 3.0, 0], [0, 0, 0], [0, 0, 0]])}
        )
    with pytest.raises(ValueError, match="8 distortion coefficients"):
        rig_from_opencv(rotation=r_cv, **{**kw, "camera_distortion": np.r_[d_cam, 0.01, 0.0, 0.0]})
    # OpenCV's 8-coefficient vector with its rational terms 0 is its 5
    assert rig_from_opencv(rotation=r_cv, **{**kw, "camera_distortion": np.r_[d_cam, 0.0, 0.0, 0.0]}) == rig
    with pytest.raises(ValueError, match="translation_unit_m"):
        rig_from_opencv(rotation=r_cv, **{**kw, "translation_unit_m": 0.0})
    # T in mm read as metres, or in metres read as mm: the unit named, not a range of position_m
    for unit, far in ((1.0, "93.8563 m"), (1e-6, "9.38563e-05 m")):
        with pytest.raises(ValueError, match=f"the projector would be {far}.* is translation_unit_m the metres"):
            rig_from_opencv(rotation=r_cv, **{**kw, "translation_unit_m": unit})
    # a projector calibrated on its native half-width grid: the message names the conversion
    native = k_prj.copy()
    native[0] = [k_prj[0, 0] / 2, 0.0, (k_prj[0, 2] + 0.5) / 2 - 0.5]
    with pytest.raises(ValueError, match=r"fx' = 2 fx, cx' = 2 \(cx \+ 0\.5\) - 0\.5"):
        rig_from_opencv(rotation=r_cv, **{**kw, "projector_matrix": native})


def _square(k: np.ndarray) -> np.ndarray:
    out = k.copy()
    out[0, 0] = out[1, 1] = 0.5 * (k[0, 0] + k[1, 1])
    return out
