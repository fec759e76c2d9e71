"""Calibration in the loop (simbench.calibration): the target, the poses, the projector's
local homographies, the OpenCV solve against exact observations, and rendered calibrations
checked against the true rig."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from simbench.calibration import CalibrationTarget, CalibrationView, calibration_poses, get_target, rig_errors
from simbench.calibration.procedure import projector_points, solve_calibration
from simbench.calibration.target import target_from_dict
from simbench.rig import Intrinsics, Rig, angles_xyz_deg, paper_rig, rotation_xyz_deg

TARGET = get_target("checkerboard")


def _distorted_rig() -> Rig:
    """The paper's rig with the paper sensor's lenses and a small misalignment."""
    base = paper_rig()
    cam = dataclasses.replace(base.camera, distortion=(-0.08, 0.10, 0.0, 0.0, 0.0))
    proj = dataclasses.replace(base.projector, distortion=(-0.02, 0.0, 0.0, 0.0, 0.0))
    return Rig(cam, proj, (0.093, 0.002, -0.001), (0.3, -0.5, 0.2), "truth")


def _project(points_m: np.ndarray, intr: Intrinsics) -> np.ndarray:
    import cv2

    p, _ = cv2.projectPoints(points_m, np.zeros(3), np.zeros(3), intr.matrix, np.asarray(intr.distortion))
    return p.reshape(-1, 2)


def _exact_views(rig: Rig, count: int) -> list[CalibrationView]:
    """Observations as a perfect detector and decoder would give them."""
    views = []
    for pose in calibration_poses(TARGET, rig, count=count, rng=3):
        world = TARGET.object_points().astype(np.float64) @ pose.rotation.T + np.asarray(pose.center_m)
        in_projector = (world - np.asarray(rig.position_m)) @ rig.rotation
        views.append(CalibrationView(pose, _project(world, rig.camera), _project(in_projector, rig.projector)))
    return views


# --- the target ------------------------------------------------------------------------------


def test_preset_target_and_its_corners():
    assert TARGET.squares == (11, 8) and TARGET.pattern_size == (10, 7)
    pts = TARGET.object_points()
    assert pts.shape == (70, 3) and pts.dtype == np.float32 and np.all(pts[:, 2] == 0)
    # row by row, x fastest, one square apart, centred on the board
    assert np.allclose(pts[1] - pts[0], [TARGET.square_m, 0, 0])
    assert np.allclose(pts[10] - pts[0], [0, TARGET.square_m, 0])
    assert np.allclose(pts.mean(axis=0), 0, atol=1e-7)
    assert np.allclose(TARGET.size_m, (0.39, 0.30))


@pytest.mark.parametrize(
    "change, message",
    [
        ({"squares": [11]}, "squares"),
        ({"squares": [11.5, 8]}, "whole numbers"),
        ({"square_m": 0}, "square_m"),
        ({"ink_rgb": [0.9, 0.9, 0.9]}, "must reflect more"),
        ({"kind": "charuco"}, "target kind"),
        ({"colour": 1}, "unknown key"),
        ({"flatness": {"twist": 1}}, "flatness"),
    ],
)
def test_bad_target_files_are_refused(change, message):
    data = {**TARGET.to_dict(), **change}
    with pytest.raises(ValueError, match=message):
        target_from_dict(data, where="t.toml")


def test_target_round_trips_and_unknown_names_fail(tmp_path):
    import tomli_w

    path = tmp_path / "t.toml"
    path.write_text(tomli_w.dumps(TARGET.to_dict()))
    assert get_target(path) == TARGET
    with pytest.raises(ValueError, match="unknown target"):
        get_target("chequer")
    with pytest.raises(FileNotFoundError):
        get_target(tmp_path / "missing.toml")


def test_target_texture_and_scene_object():
    from simbench.sim.scene import scene_from_dict, target_texture

    tex = target_texture((3, 2), 1, paper_rgb=(0.8,) * 3, ink_rgb=(0.04,) * 3)
    assert tex.shape == (4, 5, 3)
    assert np.all(tex[0] == np.float32(0.8)) and np.all(tex[:, 0] == np.float32(0.8))  # the margin
    assert tex[1, 1, 0] == np.float32(0.04) and tex[1, 2, 0] == np.float32(0.8) and tex[2, 2, 0] == np.float32(0.04)
    obj = TARGET.scene_object(center_m=(0, 0, 1), rotation_deg=(10, 0, 0))
    scene = scene_from_dict({"object": [obj]})
    assert scene.objects[0].kind == "target" and scene.objects[0].get("size_m") == TARGET.size_m
    with pytest.raises(ValueError, match="squares"):
        scene_from_dict({"object": [{**obj, "squares": 3}]})


def test_crosstalk_maps_the_ink_like_a_material():
    """The paper sensor's crosstalk path sees the ink through the camera's channels too."""
    from simbench.sim.scene import scene_from_dict
    from simbench.sim.capture import _primary_scene

    scene = scene_from_dict({"object": [TARGET.scene_object(center_m=(0, 0, 1), rotation_deg=(0, 0, 0))]})
    for p in range(3):
        obj = _primary_scene(scene, p).objects[0]
        ink, paper = np.asarray(obj.get("ink_rgb")), np.asarray(obj.material.rgb)
        assert np.allclose(ink / paper, 0.04 / 0.8, rtol=1e-6)  # grey stays grey, scaled like the paper


# --- poses ------------------------------------------------------------------------------------


def test_poses_are_seeded_varied_and_inside_both_views():
    rig = paper_rig()
    a = calibration_poses(TARGET, rig, count=12, rng=5)
    assert a == calibration_poses(TARGET, rig, count=12, rng=5)
    assert a != calibration_poses(TARGET, rig, count=12, rng=6)
    tilts = [p.tilt_deg for p in a]
    assert min(tilts) >= 19.0 and max(tilts) <= 45.0
    normals = np.array([p.rotation[:, 2] for p in a])
    assert np.min(np.linalg.norm(np.cross(normals[:, None], normals[None]), axis=2) + np.eye(12)) > 0.05
    sx, sy = TARGET.size_m
    outline = np.array([[-sx / 2, -sy / 2, 0], [sx / 2, -sy / 2, 0], [sx / 2, sy / 2, 0], [-sx / 2, sy / 2, 0]])
    for p in a:
        corners = outline @ p.rotation.T + np.asarray(p.center_m)
        for intr, pts in ((rig.camera, corners), (rig.projector, (corners - rig.position_m) @ rig.rotation)):
            uv = pts[:, :2] / pts[:, 2:] * intr.focal_px + [intr.cx_px, intr.cy_px]
            assert np.all((uv >= 0) & (uv <= [intr.width_px - 1, intr.height_px - 1]))


def test_a_target_too_large_for_the_views_is_refused():
    huge = CalibrationTarget(squares=(30, 20), square_m=0.05)
    with pytest.raises(ValueError, match="does not fit"):
        calibration_poses(huge, paper_rig(), count=3, rng=0)


def test_angles_invert_the_rotation():
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = rng.uniform(-80, 80, 3)
        assert np.allclose(angles_xyz_deg(rotation_xyz_deg(a)), a, atol=1e-9)
    with pytest.raises(ValueError, match="not a rotation"):
        angles_xyz_deg(np.diag([1.0, 1.0, -1.0]))


# --- the corners ----------------------------------------------------------------------------


def _board_image(seed: int, size_wh: tuple[int, int] = (640, 480)) -> np.ndarray:
    """A seeded synthetic view of the target: squares warped by a perspective, area-averaged,
    with noise, 8 bits (a stand-in for a rendered white frame)."""
    import cv2

    rng = np.random.default_rng(seed)
    cols, rows = TARGET.squares
    s = 40
    board = ((np.indices((rows * s, cols * s)) // s).sum(0) % 2 * 200 + 30).astype(np.float32)
    board = cv2.copyMakeBorder(board, s, s, s, s, cv2.BORDER_CONSTANT, value=230)
    h, w = board.shape
    width, height = size_wh
    quad = np.float32([[0.18, 0.2], [0.83, 0.25], [0.8, 0.84], [0.15, 0.77]]) * np.float32([width, height])
    quad += rng.uniform(-10, 10, (4, 2)).astype(np.float32)
    homography = cv2.getPerspectiveTransform(np.float32([[0, 0], [w, 0], [w, h], [0, h]]), quad)
    img = cv2.warpPerspective(board, homography, size_wh, flags=cv2.INTER_AREA) + rng.normal(0, 3.0, (height, width))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", [4, 5])
def test_corners_do_not_depend_on_intel_ipp(seed):
    """The corner search runs without Intel IPP, whose code is chosen by the CPU.  On board 4
    cv2.cornerSubPix moved corners by 1.5e-5 px with IPP on against off, and this test failed
    without the switch (2026-11-27, an AMD EPYC, OpenCV 5.0 with IPP 2026.0 k0; an Intel Xeon
    had given the calibrated rig ~1e-5 of its values apart).  Where this OpenCV has no IPP the
    test still checks that the caller's settings come back."""
    import cv2

    from simbench.calibration.procedure import find_corners

    img = _board_image(seed)
    ipp, threads = cv2.ipp.useIPP(), cv2.getNumThreads()
    try:
        found = {}
        for use in (True, False):
            cv2.ipp.setUseIPP(use)
            before = cv2.ipp.useIPP()  # False whatever was asked where this OpenCV has no IPP
            found[use] = find_corners(img, target=TARGET)
            assert cv2.ipp.useIPP() == before and cv2.getNumThreads() == threads
        assert found[True] is not None and found[True].shape == (70, 2)
        assert found[True].tobytes() == found[False].tobytes()
    finally:
        cv2.ipp.setUseIPP(ipp)
        cv2.setNumThreads(threads)


# --- the projector's coordinates: local homographies -------------------------------------------


def test_local_homography_maps_corners_exactly():
    """Decoded maps made by a known homography: every corner lands where it maps (exact tier),
    dark squares (low modulation) and a stray order error are ignored, thin windows give NaN."""
    h_true = np.array([[0.9, 0.05, 120.0], [-0.03, 1.1, 40.0], [1e-5, -2e-5, 1.0]])
    yy, xx = np.mgrid[0:200, 0:300].astype(np.float64)
    w = h_true[2, 0] * xx + h_true[2, 1] * yy + 1.0
    col = (h_true[0, 0] * xx + h_true[0, 1] * yy + h_true[0, 2]) / w
    row = (h_true[1, 0] * xx + h_true[1, 1] * yy + h_true[1, 2]) / w
    mod = np.where(((xx // 25) + (yy // 25)) % 2 == 0, 0.3, 0.01)  # white and dark squares
    col[100, 100] += 21.0  # one pixel with an order error
    corners = np.array([[100.0, 100.0], [150.3, 74.8], [40.2, 160.7], [299.0, 100.0]])
    got = projector_points(corners, col, row, mod, window_px=12, min_modulation=0.02)
    p = np.c_[corners, np.ones(4)] @ h_true.T
    want = p[:, :2] / p[:, 2:]
    assert np.allclose(got[:3], want[:3], atol=1e-6)
    assert np.isnan(got[3]).all() or np.allclose(got[3], want[3], atol=1e-6)
    holes = np.where(np.hypot(xx - 40, yy - 160) < 20, np.nan, col)
    assert np.isnan(projector_points(corners[2:3], holes, row, mod, window_px=12, min_modulation=0.02)).all()


# --- the solve ---------------------------------------------------------------------------------


def test_solve_recovers_the_rig_from_exact_observations():
    """Exact tier: corners projected through a distorted, misaligned rig (OpenCV's model) give
    that rig back - conventions of R, t, angles and distortion included."""
    truth = _distorted_rig()
    res = solve_calibration(
        _exact_views(truth, 10), target=TARGET, camera_hw=truth.camera.size_hw, projector_hw=truth.projector.size_hw
    )
    err = rig_errors(res.rig, truth)
    assert res.rms_px["camera"] < 1e-3 and res.rms_px["projector"] < 1e-3 and res.rms_px["stereo"] < 1e-3
    assert abs(err["camera_focal_pct"]) < 1e-4 and abs(err["projector_focal_pct"]) < 1e-4
    assert max(abs(err[k]) for k in ("camera_cx_px", "camera_cy_px", "projector_cx_px", "projector_cy_px")) < 1e-3
    assert abs(err["camera_k1"]) < 1e-5 and abs(err["projector_k1"]) < 1e-5
    assert err["position_mm"] < 1e-4 and err["rotation_deg"] < 1e-5
    assert res.used_views == tuple(range(10))


def test_solve_gives_the_same_bits_whatever_the_blas_thread_count():
    """The solve runs BLAS on one thread (and OpenCV): a multi-threaded OpenBLAS sums in an
    order set by its thread count, so the rig would depend on the machine's core count
    (measured: noisy views gave another rig with 2 threads than with 1)."""
    from threadpoolctl import threadpool_limits

    from simbench.rig import rig_to_dict

    truth = _distorted_rig()
    rng = np.random.default_rng(5)
    views = [
        dataclasses.replace(
            v,
            camera_px=v.camera_px + rng.normal(0, 0.3, v.camera_px.shape),
            projector_px=v.projector_px + rng.normal(0, 0.3, v.projector_px.shape),
        )
        for v in _exact_views(truth, 12)
    ]

    def solve(threads: int) -> tuple:
        with threadpool_limits(threads, user_api="blas"):
            res = solve_calibration(
                views, target=TARGET, camera_hw=truth.camera.size_hw, projector_hw=truth.projector.size_hw
            )
        return rig_to_dict(res.rig), res.rms_px

    assert solve(1) == solve(2)


def test_solve_needs_three_views_and_leaves_out_missing_ones():
    truth = paper_rig()
    views = _exact_views(truth, 5)
    missing = [dataclasses.replace(v, camera_px=None, projector_px=None) for v in views[:3]] + views[3:]
    with pytest.raises(ValueError, match="found in 2 of 5 views"):
        solve_calibration(missing, target=TARGET, camera_hw=(960, 1280), projector_hw=(1140, 1824))
    blind = [dataclasses.replace(v, projector_px=np.full_like(v.projector_px, np.nan)) for v in views]
    with pytest.raises(ValueError, match="projector's coordinates were decoded in 0 views"):
        solve_calibration(blind, target=TARGET, camera_hw=(960, 1280), projector_hw=(1140, 1824))
    res = solve_calibration(
        views[:1] + missing[1:2] + views[2:], target=TARGET, camera_hw=(960, 1280), projector_hw=(1140, 1824)
    )
    assert res.used_views == (0, 2, 3, 4) and math.isnan(res.view_rms_px["camera"][1])


def test_processes_sharing_a_cache_share_the_poses(monkeypatch):
    """calibrate_rig observes first the poses no other process is observing (``wait=False``),
    then waits for the others; the views reach the solve in pose order whatever the order they
    were observed in, so the rig is the one a lone process finds."""
    import simbench.calibration.procedure as procedure
    from simbench.sim.mitsuba_dict import RenderSettings

    truth = paper_rig()
    exact = _exact_views(truth, 5)
    calls, busy = [], {1, 3}  # poses another process is observing when this one comes to them

    def observe(target, pose, rig, *, index, wait, **kw):
        calls.append((index, wait))
        return None if (index in busy and not wait) else dataclasses.replace(exact[index], pose=pose)

    monkeypatch.setattr(procedure, "observe_pose", observe)
    render = RenderSettings(spp=1, sampler="multijitter", max_depth=2, cache=None)
    progress = []
    shared = procedure.calibrate_rig(
        truth, target=TARGET, sensor=None, poses=5, seed=3, render=render, progress=lambda k, n: progress.append((k, n))
    )
    assert calls == [(0, False), (1, False), (2, False), (3, False), (4, False), (1, True), (3, True)]
    assert progress == [(k, 5) for k in range(1, 6)]
    busy.clear()
    calls.clear()
    alone = procedure.calibrate_rig(truth, target=TARGET, sensor=None, poses=5, seed=3, render=render)
    assert calls == [(k, False) for k in range(5)]
    assert shared.rig == alone.rig and shared.view_rms_px == alone.view_rms_px


def test_rig_errors_signs():
    truth = paper_rig()
    longer = Rig(truth.camera, truth.projector, (0.094, 0.0, 0.0), (0.0, 0.0, 1.0), "x")
    err = rig_errors(longer, truth)
    assert err["baseline_mm"] == pytest.approx(1.0) and err["rotation_deg"] == pytest.approx(1.0)
    assert rig_errors(truth, truth)["camera_focal_pct"] == 0.0


def test_rows_sequence_codes_projector_rows():
    from simbench.decode.temporal import PhaseShiftSpec, decode_phase_shift, phase_shift_frames

    spec = PhaseShiftSpec(size_hw=(114, 182), axis="rows")
    frames = phase_shift_frames(spec)
    assert spec.extent_px == 114 and frames.shape == (spec.captures, 114, 182)
    assert np.all(frames[:, :, :1] == frames)  # constant along each row
    got = decode_phase_shift(frames, spec=spec).column_px
    assert np.allclose(got, np.arange(114, dtype=np.float64)[:, None], atol=1e-4)
    with pytest.raises(ValueError, match="axis"):
        PhaseShiftSpec(axis="diagonal")


# --- rendered calibrations -------------------------------------------------------------------


@pytest.mark.slow
def test_noise_free_calibration_recovers_the_true_rig(tmp_path, variant):
    """The issue's tolerances from noise-free renders (`ideal` sensor: no noise, lenses ideal;
    12 poses): focal lengths within 0.1 %, principal points within 0.5 px, baseline within
    0.5 mm - with every view's corners found and decoded."""
    from simbench.calibration import calibrate_rig, true_rig
    from simbench.sim.sensor import get_sensor
    from simbench.sim.mitsuba_dict import RenderSettings

    sensor = get_sensor("ideal")
    render = RenderSettings(spp=1, sampler="multijitter", max_depth=2, cache=None)
    res = calibrate_rig(paper_rig(), target=TARGET, sensor=sensor, poses=12, render=render)
    err = rig_errors(res.rig, true_rig(paper_rig(), sensor))
    assert len(res.used_views) == 12, res.used_views
    assert abs(err["camera_focal_pct"]) < 0.1 and abs(err["projector_focal_pct"]) < 0.1, err
    for k in ("camera_cx_px", "camera_cy_px", "projector_cx_px", "projector_cy_px"):
        assert abs(err[k]) < 0.5, (k, err)
    assert abs(err["baseline_mm"]) < 0.5, err
    assert res.rms_px["camera"] < 0.1 and res.rms_px["projector"] < 0.1, res.rms_px


@pytest.mark.slow
def test_cli_calibrates_under_the_paper_sensor(tmp_path, variant, capsys):
    """`simbench calibrate` through the paper sensor (noise, Bayer mosaic, crosstalk, lens
    distortion; 3 poses, the minimum): reprojection RMS in the published range, the camera's
    distortion found, the report written, a rerun from the cache with the same rig.  (The
    README runs `simbench decode FOLDER --rig` on such a rig; `make quick` checks the tables'
    calibrated-rig columns against thresholds.)"""
    from simbench.calibration.report import PUBLISHED_RMS_PX
    from simbench.cli import main

    out, cache = tmp_path / "cal", tmp_path / "cache"
    argv = ["calibrate", "--poses", "3", "--out", str(out), "--cache", str(cache)]
    assert main(argv) == 0
    captured = capsys.readouterr()
    first = captured.out
    # the poses counted, not the cache's look-ups (each pose also reads its projector depth map)
    assert "reprojection RMS" in first and "0 of 3 poses from the cache" in first, first
    assert "replaced an earlier calibration" not in first
    # fewer poses than OpenCV asks for: the user is told what such a rig is good for
    assert captured.err.startswith("simbench: warning: a rig from 3 poses (OpenCV asks for >= 10)"), captured.err
    assert captured.err.count("warning: a rig from") == 1  # before the poses' renders, once
    info = json.loads((out / "calibration.json").read_text())
    lo, hi = PUBLISHED_RMS_PX
    assert lo <= info["rms_px"]["camera"] <= hi and lo <= info["rms_px"]["projector"] <= hi, info["rms_px"]
    # the paper sensor's camera lens: k1 = -0.08 (simbench/presets/paper.toml), found to 0.02
    assert abs(info["errors"]["camera_k1"]) < 0.02 and abs(info["errors"]["baseline_mm"]) < 1.0, info["errors"]
    assert (out / "calibration.png").stat().st_size > 10_000
    assert (out / "calibration.pdf").read_bytes().startswith(b"%PDF-")
    report = (out / "report.md").read_text()
    assert "Estimated rig against the true rig" in report and "camera focal" in report
    assert main(argv + ["--overwrite"]) == 0
    again = capsys.readouterr().out
    assert "3 of 3 poses from the cache" in again and "(replaced an earlier calibration there)" in again
    assert json.loads((out / "calibration.json").read_text())["rig"] == info["rig"]  # deterministic
    from simbench.rig import load_rig

    assert load_rig(out / "rig.toml").camera.has_distortion
