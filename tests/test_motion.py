"""Moving scenes (simbench.sim.motion, simbench.sim.timeline): the scene keys, poses against the
rigid-motion formula, image motion against the pinhole's closed form, the time slices, and motion
blur as physics - a moving edge renders as the box-filtered step, converged in its slice count."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest

from simbench.rig import scale_camera
from simbench.sim.motion import MAX_SLICE_MOTION_PX, slice_times
from simbench.sim.scene import load_scene, scene_fingerprint, scene_from_dict
from simbench.sim.timeline import (
    image_motion_px,
    image_speed_px_s,
    is_moving,
    object_at,
    scene_at,
    slice_count,
    slice_spp,
)

from .conftest import SCENES


def _plane_scene(**motion) -> object:
    obj = {"type": "plane", "name": "board", "center_m": [-0.05, 0.0, 1.0], "size_m": [0.1, 0.3], **motion}
    return scene_from_dict({"name": "moving", "object": [obj]})


def test_motion_keys_are_validated_and_a_static_object_keeps_its_cache_key():
    still = _plane_scene()
    assert not is_moving(still) and still.objects[0].motion is None
    zero = _plane_scene(velocity_m_s=[0.0, 0.0, 0.0], angular_velocity_deg_s=0.0)
    assert zero.objects[0].motion is None and scene_fingerprint(zero) == scene_fingerprint(still)
    moving = _plane_scene(velocity_m_s=[0.5, 0.0, 0.0])
    assert is_moving(moving) and scene_fingerprint(moving) != scene_fingerprint(still)
    assert scene_fingerprint(moving)["objects"][0]["motion"]["velocity_m_s"] == [0.5, 0.0, 0.0]
    for bad, match in (
        ({"velocity_m_s": [60.0, 0, 0]}, r"velocity_m_s\[0\] must be a finite number in \[-50, 50\]"),
        ({"velocity_m_s": [1.0, 0]}, "velocity_m_s must be a list of 3 numbers"),
        ({"angular_velocity_deg_s": 10.0, "rotation_axis": [0, 0, 0]}, "rotation_axis must not be zero"),
        ({"rotation_axis": [0, 0, 1]}, "need a non-zero angular_velocity_deg_s"),
        ({"angular_velocity_deg_s": "fast"}, "angular_velocity_deg_s must be a finite number"),
    ):
        with pytest.raises(ValueError, match=match):
            _plane_scene(**bad)


def test_a_file_scene_without_motion_keeps_every_cache_key():
    for name in ("white_plane.toml", "discontinuity.toml", "specular.toml"):
        scene = load_scene(SCENES / name)
        assert scene_at(scene, 0.3) is scene
        assert all("motion" not in o for o in scene_fingerprint(scene)["objects"])


def test_a_pose_is_the_rigid_motion_of_the_object():
    """Every corner of a box at time t is where c + R(w t)(x - c) + v t puts it."""
    from simbench.sim.timeline import _extent_points

    box = scene_from_dict(
        {
            "object": [
                {
                    "type": "box",
                    "name": "b",
                    "center_m": [0.1, -0.05, 1.1],
                    "size_m": [0.1, 0.2, 0.05],
                    "rotation_deg": [10.0, -20.0, 5.0],
                    "velocity_m_s": [0.2, -0.1, 0.3],
                    "angular_velocity_deg_s": 90.0,
                    "rotation_axis": [1.0, 1.0, 0.0],
                    "rotation_centre_m": [0.0, 0.0, 1.0],
                }
            ]
        }
    ).objects[0]
    for t in (0.0, 0.1, 0.37):
        moved = object_at(box, t)
        assert moved.motion is None
        want = box.motion.apply(_extent_points(box), t, centre_m=np.asarray(box.get("center_m")))
        assert np.allclose(np.sort(_extent_points(moved), axis=0), np.sort(want, axis=0), atol=1e-9)
    m = box.motion
    for t in (0.5, 1.0, 2.0):  # a rotation by w t about the axis: orthonormal, the axis fixed, trace 1 + 2 cos(w t)
        r = m.rotation(t)
        assert np.allclose(r @ r.T, np.eye(3)) and np.allclose(r @ np.asarray(m.axis), m.axis)
        assert np.trace(r) == pytest.approx(1 + 2 * math.cos(math.radians(90.0 * t)))


def test_image_motion_is_the_pinholes_closed_form():
    """A plane moving sideways at v for T seconds at depth Z moves f v T / Z pixels."""
    scene = _plane_scene(velocity_m_s=[0.4, 0.0, 0.0])
    cam = scene.rig.camera
    t = 0.01
    assert image_motion_px(scene, cam, 0.0, t) == pytest.approx(cam.focal_px * 0.4 * t / 1.0, rel=1e-9)
    n = slice_count(scene, cam, (0.0, t))
    assert n == math.ceil(cam.focal_px * 0.4 * t / MAX_SLICE_MOTION_PX)
    assert slice_count(_plane_scene(), cam, (0.0, t)) == 1 and slice_count(scene, cam, (0.0, 0.0)) == 1
    assert np.allclose(slice_times((0.0, 1.0), 4), [0.125, 0.375, 0.625, 0.875])


def test_a_segments_length_and_time_in_view_are_the_brute_force_counts():
    """:func:`simbench.sim.timeline._in_view` (cut at the near plane, projected, clipped to the
    image; the clip mapped back to the segment's time) against the segment sampled at 20001
    points evenly in time: the summed steps between consecutive samples both in front and inside
    the image, to 1 % of the image's size, and the share of the samples inside, to 0.001."""
    from simbench.sim.timeline import _in_view

    cam = scale_camera(_plane_scene().rig, 0.25).camera
    rng = np.random.default_rng(5)
    p0 = rng.uniform([-0.4, -0.3, -0.5], [0.4, 0.3, 2.0], (300, 3))
    p1 = p0 + rng.normal(0.0, 0.6, (300, 3))
    got, share = _in_view(p0, p1, cam, near_m=0.05)
    s = np.linspace(0.0, 1.0, 20001)[:, None, None]
    pts = p0 + s * (p1 - p0)  # (S, N, 3)
    z = pts[..., 2]
    uv = cam.focal_px * pts[..., :2] / np.where(z > 0, z, 1.0)[..., None] + (cam.cx_px, cam.cy_px)
    inside = (z >= 0.05) & (uv[..., 0] >= -0.5) & (uv[..., 0] <= cam.width_px - 0.5)
    inside &= (uv[..., 1] >= -0.5) & (uv[..., 1] <= cam.height_px - 0.5)
    both = inside[1:] & inside[:-1]
    want = np.where(both, np.linalg.norm(np.diff(uv, axis=0), axis=-1), 0.0).sum(axis=0)
    assert (got > 0).sum() > 30 and (got == 0).sum() > 30  # both kinds drawn
    assert ((share > 0.05) & (share < 0.95)).sum() > 10  # segments partly in view among them
    assert np.allclose(got, want, atol=0.01 * cam.width_px)
    assert np.allclose(share, inside.mean(axis=0), atol=1e-3)


def test_slices_keep_an_object_in_view_for_part_of_the_window_to_their_bound():
    """A review: the count came from a point's whole in-view travel spread over the whole window,
    so a ball crossing into the view during it moved ~2.5 px a slice (10x the bound).  Measured
    by brute force on the slices' instants: no surface point in view at two consecutive
    instants moves more than MAX_SLICE_MOTION_PX (5 % over: the count's 33 steps)."""
    from simbench.sim.timeline import _surface_points

    scene = scene_from_dict(
        {
            "name": "crossing",
            "rig": "paper",
            "object": [
                {
                    "type": "sphere",
                    "name": "ball",
                    "center_m": [-0.70, 0.0, 2.0],
                    "radius_m": 0.05,
                    "velocity_m_s": [2.0, 0.0, 0.0],
                },
                {"type": "plane", "name": "wall", "center_m": [0.0, 0.0, 2.5], "size_m": [4.0, 4.0]},
            ],
        }
    )
    cam = scale_camera(scene.rig, 0.25).camera
    window = (0.0, 0.08)  # the ball enters the view ~50 ms in
    n = slice_count(scene, cam, window)
    ball = scene.objects[0]
    pts = _surface_points(ball)
    times = np.linspace(*window, n + 1)
    at = np.stack([ball.motion.apply(pts, t, centre_m=np.asarray(ball.get("center_m"))) for t in times])
    uv = cam.focal_px * at[..., :2] / at[..., 2:3] + (cam.cx_px, cam.cy_px)
    inside = (uv[..., 0] >= -0.5) & (uv[..., 0] <= cam.width_px - 0.5)
    step = np.linalg.norm(np.diff(uv, axis=0), axis=-1)
    assert (inside[0] == 0).all() and inside[-1].any()  # out of view at the start, in at the end
    assert step[inside[1:] & inside[:-1]].max() <= 1.05 * MAX_SLICE_MOTION_PX
    assert n < 256


def _floor_scene(**motion):
    return scene_from_dict(
        {
            "name": "floor",
            "rig": "paper",
            "object": [
                # a floor 0.3 m below the camera from 0.5 m behind it to 4.5 m ahead
                {
                    "type": "plane",
                    "name": "floor",
                    "center_m": [0.0, 0.3, 2.0],
                    "size_m": [3.0, 5.0],
                    "rotation_deg": [90.0, 0.0, 0.0],
                    **motion,
                },
                {"type": "plane", "name": "wall", "center_m": [0.0, 0.0, 4.5], "size_m": [4.0, 4.0]},
            ],
        }
    )


def test_a_floor_reaching_behind_the_camera_is_sliced_by_its_part_in_view():
    """An audit (2026-11-30): the motion of points behind the camera was left out, so a floor
    reaching behind it was measured by its far corners (0.50 px a slice in view).  Now its nearest
    visible row - the image's bottom edge, where the floor meets the view - sets the count: a floor
    0.3 m down, seen from the bottom row (depth z_b = 0.3 f / (H - 1 - cy)) moving sideways at v
    for T moves f v T / z_b pixels there."""
    scene = _floor_scene(velocity_m_s=[0.5, 0.0, 0.0])
    cam = scale_camera(scene.rig, 0.25).camera
    t = 0.03
    z_bottom = 0.3 * cam.focal_px / (cam.height_px - 0.5 - cam.cy_px)
    want = cam.focal_px * 0.5 * t / z_bottom
    # the surface samples resolve the bottom row's depth to 1/64 of the floor's length (5 %)
    assert want * 0.95 <= image_motion_px(scene, cam, 0.0, t) <= want * 1.0001
    assert slice_count(scene, cam, (0.0, t)) >= math.ceil(0.95 * want / MAX_SLICE_MOTION_PX)


def test_an_object_behind_the_camera_that_comes_into_view_is_sliced_and_not_called_unseen():
    """An object behind the camera at time 0 that enters the view during the capture was rendered
    as an instant (no slices) and warned of as one no pixel sees."""
    from simbench.sim.timeline import placement_warnings

    scene = scene_from_dict(
        {
            "name": "enters",
            "rig": "paper",
            "object": [
                {
                    "type": "sphere",
                    "name": "ball",
                    "center_m": [0.0, 0.0, -0.2],
                    "radius_m": 0.1,
                    "velocity_m_s": [0.0, 0.0, 40.0],
                },
                {"type": "plane", "name": "wall", "center_m": [0.0, 0.0, 1.5], "size_m": [4.0, 4.0]},
            ],
        }
    )
    cam = scale_camera(scene.rig, 0.25).camera
    window = (0.0, 0.03)  # the ball passes from 0.2 m behind to 1.0 m ahead
    assert slice_count(scene, cam, window) > 1
    assert any("'ball' lies wholly behind the camera" in t for t in placement_warnings(scene))
    assert placement_warnings(scene, window_s=window) == []
    stays = dataclasses.replace(
        scene,
        objects=(
            dataclasses.replace(
                scene.objects[0], motion=scene.objects[0].motion.__class__(velocity_m_s=(0.0, 0.0, -1.0))
            ),
            scene.objects[1],
        ),
    )
    assert any(
        "behind the camera (z <= 0 m) throughout the capture" in t for t in placement_warnings(stays, window_s=window)
    )


def test_the_sample_budget_is_split_across_the_slices():
    assert slice_spp(64, 4) == 16 and slice_spp(64, 3) == 21 and slice_spp(64, 63) == 1
    assert slice_spp(16, 40) == 1  # more slices than samples: one each (40 in all)
    for spp in (4, 16, 36, 64):
        for n in range(1, spp + 1):
            assert spp - n < n * slice_spp(spp, n) <= spp  # within n samples of a static capture's


def test_a_moving_scene_is_never_rendered_as_an_instant_without_saying_so(variant):
    from simbench.sim.capture import cached_ground_truth, render_channels
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.sim.sensor import get_sensor

    scene = _plane_scene(velocity_m_s=[0.4, 0.0, 0.0])
    with pytest.raises(ValueError, match="objects \\['board'\\] move"):
        cached_ground_truth(scene)
    with pytest.raises(ValueError, match="needs the exposure window"):
        render_channels(scene, None, get_sensor("ideal"), seed=1, render=RenderSettings(spp=1, sampler="independent"))


def test_an_exposure_integral_is_one_cache_entry_and_its_slices_none(variant, tmp_path, monkeypatch):
    """The moving scene's integral over the exposure is stored as one ``exposure`` entry (its slices
    are not stored: no other capture renders them, and each slice's file cost a third of its render
    at the motion study's size); read back it is the uncached integral bit for bit and renders
    nothing; a different window or sensor is another entry.  (A small camera, 1 spp a slice.)"""
    import simbench.sim.capture as capture
    from simbench.cache import RenderCache
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.sim.sensor import get_sensor

    sensor = get_sensor("ideal")
    scene = capture.physical_scene(
        dataclasses.replace(_plane_scene(velocity_m_s=[0.5, 0.0, 0.0]), rig=scale_camera(_plane_scene().rig, 0.125)),
        sensor,
    )
    drive = np.ones((*scene.rig.projector.size_hw, 3), np.float32)
    window = (0.0, 0.004)
    assert slice_count(scene, scene.rig.camera, window) > 1
    cache = RenderCache(tmp_path / "cache")
    settings = RenderSettings(spp=4, sampler="independent", max_depth=2)
    cold = capture.render_channels(
        scene, drive, sensor, seed=5, render=dataclasses.replace(settings, cache=cache), window_s=window
    )
    files = sorted(p.name.split("-")[0] for p in (tmp_path / "cache").glob("*.npz"))
    assert files.count("exposure") == 1 and "radiance" not in files, files
    uncached = capture.render_channels(scene, drive, sensor, seed=5, render=settings, window_s=window)
    assert np.array_equal(cold, uncached)

    def no_render(*a, **k):
        raise AssertionError("rendered although the integral is cached")

    monkeypatch.setattr(capture, "render_radiance", no_render)
    warm = capture.render_channels(
        scene, drive, sensor, seed=5, render=dataclasses.replace(settings, cache=cache), window_s=window
    )
    assert np.array_equal(warm, cold)
    with pytest.raises(AssertionError, match="rendered although"):
        capture.render_channels(
            scene, drive, sensor, seed=5, render=dataclasses.replace(settings, cache=cache), window_s=(0.0, 0.005)
        )


def _edge_scene(speed_m_s: float):
    """A white board whose right edge crosses the middle of a small camera's view, lit by a
    uniform projector white, before nothing (black)."""
    scene = _plane_scene(velocity_m_s=[speed_m_s, 0.0, 0.0])
    return dataclasses.replace(scene, rig=scale_camera(scene.rig, 0.25))  # 320 x 240 px


def _row_profile(q: np.ndarray) -> np.ndarray:
    band = q[100:140, :, 1].astype(np.float64)  # rows around the middle, green
    return band.mean(axis=0)


@pytest.mark.slow
def test_a_moving_edge_is_the_box_filtered_step_and_its_slices_are_converged(variant, monkeypatch):
    """Motion blur by time slices against the closed form: over an exposure T the edge at
    e(t) = e0 + s t (s = f v / Z px/s) covers pixel i for clip(e(t) - i + 1/2, 0, 1) of its
    area, so the recorded profile is that coverage's mean over t (a ramp f v T / Z pixels
    wide), within render noise (64 samples a pixel, 40 rows averaged: measured 0.006 of the plateau); and twice the
    slices change it by no more than that noise."""
    from simbench.sim.capture import physical_scene, render_channels
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.sim.sensor import get_sensor

    sensor = get_sensor("ideal")
    speed, window = 0.5, (0.0, 0.02)  # 0.5 m/s over 20 ms: 10 mm, ~5.8 px of the small camera
    scene = physical_scene(_edge_scene(speed), sensor)
    cam = scene.rig.camera
    drive = np.ones((*scene.rig.projector.size_hw, 3), np.float32)
    render = RenderSettings(spp=64, sampler="independent", max_depth=2)
    q = render_channels(scene, drive, sensor, seed=11, render=render, window_s=window)
    profile = _row_profile(q)
    c = int(cam.cx_px)
    plateau = profile[c - 40 : c - 10].mean()  # well inside the board (58 px wide), left of the edge
    measured = profile / plateau
    # the edge's image column at time t: the board's right side, x = -0.05 + 0.05 + v t, at z = 1
    cols = np.arange(cam.width_px)
    t = np.linspace(*window, 4001)
    edge = cam.focal_px * (0.0 + speed * t)[:, None] / 1.0 + cam.cx_px
    expected = np.clip(edge - cols[None, :] + 0.5, 0.0, 1.0).mean(axis=0)
    blur = slice(int(edge.min()) - 4, int(edge.max()) + 5)
    assert np.abs(measured[blur] - expected[blur]).max() < 0.015, (measured[blur], expected[blur])
    assert expected[blur].min() < 0.05 and expected[blur].max() > 0.95  # the window spans the whole ramp
    # a static render of the mid-exposure pose has a sharp edge: the blur is real
    still = _row_profile(render_channels(scene_at(scene, 0.01), drive, sensor, seed=11, render=render)) / plateau
    assert np.abs(still[blur] - expected[blur]).max() > 0.2
    # converged: twice the slices (each with half the samples) agree within the noise
    import simbench.sim.timeline as timeline

    n = slice_count(scene, cam, window)
    monkeypatch.setattr(timeline, "MAX_SLICE_MOTION_PX", MAX_SLICE_MOTION_PX / 2)
    assert slice_count(scene, cam, window) in (2 * n - 1, 2 * n)
    finer = _row_profile(render_channels(scene, drive, sensor, seed=12, render=render, window_s=window)) / plateau
    assert np.abs(finer[blur] - measured[blur]).max() < 0.02


def _board_before_wall(**motion):
    return scene_from_dict(
        {
            "name": "board_before_wall",
            "object": [
                {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
                {"type": "plane", "name": "board", "center_m": [-0.05, 0.0, 1.0], "size_m": [0.2, 0.3], **motion},
            ],
        }
    )


@pytest.mark.slow
def test_the_paper_sensor_records_a_moving_board_over_its_exposure(variant, tmp_path):
    """The proposed sensor's time model is one exposure of its global-shutter camera: the ground
    truth is the board at mid-exposure, each pixel's motion is f v T / Z (the closed form) on the
    board and 0 on the wall, and the recording folder keeps it (gt_motion.npy); a zero velocity
    records bit for bit what the static scene records; a system without a time model refuses."""
    from simbench.seeds import SeedLog
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.systems import SystemOptions, acquire, get_system

    system = get_system("proposed", SystemOptions(camera_scale=0.25))
    render = RenderSettings(spp=4, sampler="multijitter", max_depth=2)
    moving = _board_before_wall(velocity_m_s=[0.5, 0.0, 0.0])
    t0, t1 = system.capture_window_s(system.prepare(moving))
    assert t0 == 0.0 and 0.001 < t1 < 0.1  # the auto exposure on the white board
    rec = acquire(system, moving, "m", seeds=SeedLog(), render=render)[0]
    cam = rec.scene.rig.camera
    board, wall = rec.gt.object_id == 1, rec.gt.object_id == 0
    assert np.allclose(rec.gt.motion_px[board], [cam.focal_px * 0.5 * t1 / 1.0, 0.0], atol=1e-3)
    assert not rec.gt.motion_px[wall].any()
    # the truth is the board at mid-exposure: its right edge at x = 0.05 m + v T / 2 (~4 px from t = 0's)
    edge_col = cam.focal_px * (0.05 + 0.5 * 0.5 * t1) / 1.0 + cam.cx_px
    row = board[cam.height_px // 2]
    assert abs(np.flatnonzero(row).max() + 0.5 - edge_col) <= 0.5
    files = system.write_recording(
        tmp_path / "rec",
        rec.raw,
        system.calibrate(rec.scene, seeds=SeedLog(), render=render),
        scene=rec.scene,
        gt=rec.gt,
        meta={"scene": "board_before_wall"},
    )
    assert np.array_equal(np.load(files["gt_motion"]), rec.gt.motion_px)
    # zero velocity: the static scene's recording, bit for bit
    still = acquire(system, _board_before_wall(), "s", seeds=SeedLog(), render=render)[0]
    zero = acquire(system, _board_before_wall(velocity_m_s=[0.0, 0.0, 0.0]), "s", seeds=SeedLog(), render=render)[0]
    assert np.array_equal(still.raw, zero.raw) and zero.gt.motion_px is None
    from .test_systems import IdealDepthCamera  # a system without capture_window_s

    with pytest.raises(ValueError, match="the ideal_depth system has no time model yet"):
        acquire(IdealDepthCamera(), moving, "k", seeds=SeedLog(), render=render)


@pytest.mark.slow
@pytest.mark.parametrize("speed_m_s", [-0.3, 1.0])
def test_the_tof_bias_of_an_axially_moving_wall_is_the_closed_form(variant, speed_m_s):
    """The ToF camera's four samples are taken one after another (simbench.systems.tof.tap_windows_s),
    so a wall moving along the axis gives each sample its own depth and brightness: with the
    return n(t) ~ 1/z(t)^2 and phase 4 pi f z(t) / c (co-located emitter, the centre pixel),
    sample k is A_k = 1/4 mean over its window of n + m Re(n exp(i(phi - k pi/2))), and the decoded
    distance is c atan2(A1 - A3, A0 - A2) / (4 pi f) - a bias against the truth at mid-capture of
    ~7 mm at 1 m/s, mostly from the brightness change (the leak of the samples' unequal means
    into the phase), not from the phase drift alone (drift_phase_error: ~0.003 rad). The
    simulation (render, footprint trace, per-sample instants) gives it within 0.05 mm."""
    from simbench.seeds import SeedLog
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.sim.photometry import LIGHT_M_S
    from simbench.systems import acquire
    from simbench.systems.tof import ToFModel, ToFSystem, tap_windows_s

    wall = {"type": "plane", "name": "wall", "center_m": [0, 0, 1.0], "size_m": [3, 3]}
    scene = scene_from_dict({"name": "w", "object": [{**wall, "velocity_m_s": [0, 0, -speed_m_s]}]})
    model = ToFModel(noise=False)
    tof = ToFSystem(model=model)
    rec = acquire(tof, scene, "t", seeds=SeedLog(), render=RenderSettings(spp=16, sampler="independent"))[0]
    depth = tof.decode(rec.raw, None, scene=rec.scene).depth_m
    h, w = depth.shape
    centre = (slice(h // 2 - 3, h // 2 + 3), slice(w // 2 - 3, w // 2 + 3))
    simulated = float(np.mean(depth[centre] - rec.gt.depth_m[centre]))
    f, m = model.modulation_hz, model.demodulation_contrast
    samples = []
    for k, (t0, t1) in enumerate(tap_windows_s(model)):
        z = 1.0 - speed_m_s * np.linspace(t0, t1, 2001)
        n, phi = 1.0 / z**2, 4 * np.pi * f * z / LIGHT_M_S
        samples.append(0.25 * np.mean(n + m * np.real(n * np.exp(1j * (phi - 0.5 * np.pi * k)))))
    a = np.array(samples)
    decoded = LIGHT_M_S * np.mod(np.arctan2(a[1] - a[3], a[0] - a[2]), 2 * np.pi) / (4 * np.pi * f)
    ambiguity = LIGHT_M_S / (2 * f)
    predicted = (decoded - (1.0 - speed_m_s * model.integration_s / 2) + ambiguity / 2) % ambiguity - ambiguity / 2
    assert abs(predicted) > 0.002 * abs(speed_m_s)  # millimetres at these speeds: a real effect
    assert simulated == pytest.approx(predicted, abs=5e-5)
    still = acquire(
        tof,
        scene_from_dict({"name": "w", "object": [wall]}),
        "t",
        seeds=SeedLog(),
        render=RenderSettings(spp=16, sampler="independent"),
    )[0]
    assert (
        abs(float(np.mean(tof.decode(still.raw, None, scene=still.scene).depth_m[centre] - still.gt.depth_m[centre])))
        < 1e-3
    )


def test_the_rolling_shutter_rows_and_their_slice_weights():
    """The Kinect's MT9M001 reads its rows one after another: row r integrates [r t_row, r t_row +
    T_exp); a row's slice weights are the overlaps of its window with the slices and add up to one;
    the frame spans T_exp + (H - 1) t_row (30 Hz: 33.3 ms + 30.4 ms)."""
    from simbench.systems.kinect import KinectModel, KinectSystem, rolling_weights, row_windows_s

    model = KinectModel()
    rows = row_windows_s(model)
    assert rows.shape == (480, 2) and rows[0, 0] == 0.0
    assert np.allclose(np.diff(rows[:, 0]), 63.5e-6) and np.allclose(rows[:, 1] - rows[:, 0], 1 / 30)
    span = KinectSystem(model=model).capture_window_s(None)
    assert span == pytest.approx((0.0, 1 / 30 + 479 * 63.5e-6))
    edges = np.linspace(*span, 41)
    w = rolling_weights(rows, edges)
    assert w.shape == (480, 40) and np.allclose(w.sum(axis=1), 1.0) and (w >= 0).all()
    # row 0 sees only the first slices, the last row only the last ones
    assert w[0, -1] == 0.0 and w[-1, 0] == 0.0
    # a linear signal's mean over a row's window (slope x its middle): each slice stands for its
    # sub-window by its middle, so a slice the window cuts is off by at most half a slice, at
    # weight <= h / T_exp - two such ends bound the error by slope h^2 / T_exp, shrinking as h^2
    slope = 3.0
    for n in (40, 400):
        edges = np.linspace(*span, n + 1)
        h = edges[1] - edges[0]
        got = rolling_weights(rows, edges) @ (slope * 0.5 * (edges[:-1] + edges[1:]))
        assert np.abs(got - slope * rows.mean(axis=1)).max() <= slope * h * h / model.exposure_s
    gs = row_windows_s(KinectModel(row_time_s=0.0))  # a global shutter: every row the same window
    assert (gs[:, 0] == 0.0).all()
    for bad in ({"exposure_s": 0.0}, {"row_time_s": -1e-6}, {"exposure_s": float("nan")}):
        with pytest.raises(ValueError, match="kinect (exposure_s|row_time_s)"):
            KinectModel(**bad)


@pytest.mark.slow
def test_the_kinect_rolling_shutter_shears_an_axially_moving_wall_by_the_closed_form(variant):
    """A wall approaching the Kinect at v: row r integrates from r t_row for T_exp, so it sees the
    wall at Z(r t_row + T_exp / 2) and the decoded depth minus the truth at mid-capture (t_m) is
    -v (r t_row + T_exp / 2 - t_m): a shear of v t_row per row (63.5 um at 1 m/s, 30 mm over the
    frame) - measured, by a line fit over the rows, within 2 % of the slope and 1 mm of the offset.
    A global shutter (row_time_s = 0) shows no shear."""
    from simbench.seeds import SeedLog
    from simbench.sim.mitsuba_dict import RenderSettings
    from simbench.systems import acquire
    from simbench.systems.kinect import KinectModel, KinectSystem

    v = 1.0
    wall = {"type": "plane", "name": "wall", "center_m": [0, 0, 1.0], "size_m": [3, 3]}
    scene = scene_from_dict({"name": "w", "object": [{**wall, "velocity_m_s": [0, 0, -v]}]})
    render = RenderSettings(spp=16, sampler="independent")
    fits = {}
    for row_time in (KinectModel().row_time_s, 0.0):
        model = KinectModel(row_time_s=row_time)
        kinect = KinectSystem(model=model)
        cal = kinect.calibrate(kinect.prepare(scene), seeds=SeedLog(), render=render)
        rec = acquire(kinect, scene, "k", seeds=SeedLog(), render=render, calibration=cal)[0]
        err = kinect.decode(rec.raw, cal, scene=rec.scene).depth_m - rec.gt.depth_m
        assert np.isfinite(err).mean() > 0.8
        per_row = np.array([np.nanmedian(r) if np.isfinite(r).sum() > 100 else np.nan for r in err])
        r = np.flatnonzero(np.isfinite(per_row))
        t0, t1 = kinect.capture_window_s(rec.scene)
        fits[row_time] = np.polyfit(r, per_row[r], 1), 0.5 * (t0 + t1), model
    (slope, offset), t_mid, model = fits[KinectModel().row_time_s]
    assert slope == pytest.approx(-v * model.row_time_s, rel=0.02)
    assert offset == pytest.approx(-v * (model.exposure_s / 2 - t_mid), abs=1e-3)
    (slope_gs, _), _, _ = fits[0.0]
    assert abs(slope_gs) < 0.05 * v * model.row_time_s


def test_the_motion_study_measures_a_capture_in_three_parts_the_slowest_ranked_first():
    """Each capture (scene/direction/speed) is three parts, in the order its rows are written
    (proposed sensor, phase shifting, competitors); phase shifting's twelve moving frames rank
    it first where it runs and last where it does not (faster than MULTI_SHOT_MAX_SPEED_M_S)."""
    from simbench.experiments.common import RunConfig
    from simbench.experiments.motion import GROUPS, MULTI_SHOT_MAX_SPEED_M_S, motion_cost, motion_parts

    parts = motion_parts(RunConfig())
    captures = sorted({p.rsplit("/", 1)[0] for p in parts})
    assert len(parts) == 3 * len(captures) and GROUPS == ("proposed", "phase_shift", "competitors")
    assert all(parts[i].endswith("/" + GROUPS[i % 3]) for i in range(len(parts)))
    fast = max(float(c.rsplit("/", 1)[1]) for c in captures)
    slowest = max(parts, key=motion_cost)
    assert slowest.endswith(f"/{MULTI_SHOT_MAX_SPEED_M_S:g}/phase_shift")
    assert motion_cost(f"bust/lateral/{fast:g}/phase_shift") == 0.0 < motion_cost(f"bust/lateral/{fast:g}/proposed")


def test_the_truth_over_a_capture_holds_every_depth_a_pixel_saw(variant):
    """capture_truths: a board sliding before a wall posed at instants <= SWEEP_STEP_PX of image
    motion apart over the exposure, first and last at the window's ends; a pixel the board's edge
    crosses sees the board at one end and the wall at the other (the mid-capture truth alone
    calls the wall's depth there wrong: the motion study's blind spot); a static scene keeps its
    one truth."""
    from types import SimpleNamespace

    from simbench.experiments.motion import SWEEP_STEP_PX, capture_states, capture_truths, motion_classes
    from simbench.metrics import wrong_pixels
    from simbench.systems import SystemOptions, get_system

    system = get_system("proposed", SystemOptions(camera_scale=0.25))
    scene = system.prepare(_board_before_wall(velocity_m_s=[0.5, 0.0, 0.0]))
    cam = scene.rig.camera
    window = (0.0, 0.02)
    travel = cam.focal_px * 0.5 * 0.02 / 1.0  # the board's edge, f v T / Z
    mid = scene_at(scene, 0.01)
    from simbench.sim.truth import ground_truth

    gt_mid = ground_truth(mid)
    rec = SimpleNamespace(scene=scene, gt=SimpleNamespace(motion_px=np.zeros(1), depth_m=gt_mid.depth_m))
    truths = capture_truths(rec, window)
    reach = image_speed_px_s(scene, cam, *window) * (window[1] - window[0])
    assert truths.shape == (math.ceil(reach / SWEEP_STEP_PX) + 1, *gt_mid.depth_m.shape)
    assert np.array_equal(truths[0], ground_truth(scene_at(scene, 0.0)).depth_m)
    assert np.array_equal(truths[-1], ground_truth(scene_at(scene, 0.02)).depth_m)
    row = cam.height_px // 2
    edge_start = cam.focal_px * -0.15 / 1.0 + cam.cx_px  # the board's left edge at t = 0 (it moves right)
    u = int(edge_start + 0.25 * travel)  # covered at the start, the wall's at mid-capture
    assert np.isclose(truths[0, row, u], 1.0) and np.isclose(gt_mid.depth_m[row, u], 1.3, atol=1e-3)
    board_depth = np.full(gt_mid.depth_m.shape, np.nan, np.float32)
    board_depth[row, u] = 1.0  # the board's depth, seen there for part of the exposure
    assert not wrong_pixels(board_depth, truths, wrong_m=0.005)[row, u]
    assert wrong_pixels(board_depth, gt_mid.depth_m, wrong_m=0.005)[row, u]
    board_depth[row, u] = 1.15  # between the two: seen at no instant
    assert wrong_pixels(board_depth, truths, wrong_m=0.005)[row, u]
    still = SimpleNamespace(scene=scene, gt=SimpleNamespace(motion_px=None, depth_m=gt_mid.depth_m, lit=gt_mid.lit))
    assert capture_truths(still, window).shape == (1, *gt_mid.depth_m.shape)
    still_depth, still_lit = capture_states(still, window)
    assert np.array_equal(still_lit, gt_mid.lit[None]) and np.array_equal(
        still_depth, gt_mid.depth_m[None], equal_nan=True
    )

    # the same instants with the projector's light: the edge's pixel moved; the board's shadow on
    # the wall slides with it, so wall pixels it crosses are lit part of the time (shadowed), and
    # every one of them sees the wall throughout
    depth_k, lit_k = capture_states(rec, window)
    assert np.array_equal(depth_k, truths) and lit_k.shape == truths.shape and lit_k.dtype == bool
    assert np.array_equal(lit_k[0], ground_truth(scene_at(scene, 0.0)).lit)
    moved, shadowed = motion_classes(depth_k, lit_k, wrong_m=0.005)
    assert moved[row, u] and not shadowed[row, u]
    assert shadowed[row].any() and np.allclose(depth_k[:, shadowed], 1.3, atol=0.01)
    # the shadow's border travels as the board's does, seen from the projector: a few pixels a row
    assert 0.75 * travel <= shadowed[row].sum() <= 1.5 * travel
    assert not (moved | shadowed)[:, : int(edge_start) - int(3 * travel)].any()  # far from both: neither


def test_motion_classes_tell_a_moved_surface_from_a_crossing_shadow():
    """motion_classes on hand-made truths: a depth range over the threshold or a surface seen part
    of the time is moved; a still surface lit part of the time is shadowed; a moved pixel is never
    also shadowed; a static capture (one instant) has neither.  The whole image's wrong shares
    split by them (_wrong_shares_image)."""
    from simbench.experiments.motion import _wrong_shares_image, motion_classes

    depth = np.full((3, 1, 8), 1.0, np.float32)
    lit = np.ones((3, 1, 8), bool)
    depth[:, 0, 1] = (1.0, 1.003, 1.004)  # within 5 mm: still
    depth[:, 0, 2] = (1.0, 1.003, 1.006)  # 6 mm: moved
    depth[0, 0, 3] = np.nan  # came into view
    lit[1, 0, 4] = False  # a shadow crossed a still surface
    depth[2, 0, 5], lit[2, 0, 5] = 1.2, False  # moved and in shadow at the end: moved only
    lit[:, 0, 6] = False  # in shadow throughout: neither
    depth[:, 0, 7], lit[:, 0, 7] = np.nan, False  # nothing seen at any instant: neither
    moved, shadowed = motion_classes(depth, lit, wrong_m=0.005)
    assert moved[0].tolist() == [False, False, True, True, False, True, False, False]
    assert shadowed[0].tolist() == [False, False, False, False, True, False, False, False]
    assert not any(a.any() for a in motion_classes(depth[:1], lit[:1], wrong_m=0.005))

    decoded = np.array([[1.0, 1.5, 1.5, 1.5, 1.5, np.nan, 1.5, np.nan]], np.float32)  # 5 wrong of 6 decoded
    shares = _wrong_shares_image(decoded, (depth, lit))
    assert shares == pytest.approx(
        {"wrong_share_image": 5 / 6, "wrong_share_image_moved": 2 / 6, "wrong_share_image_shadowed": 1 / 6}
    )
    nothing = _wrong_shares_image(np.full((1, 8), np.nan, np.float32), (depth, lit))
    assert all(math.isnan(v) for v in nothing.values()) and len(nothing) == 3


@pytest.mark.parametrize(
    ("system_name", "speed_m_s", "expected"),
    [
        ("proposed", 0.5, []),  # 4 px in the 27 ms exposure: a blur the decoders hold
        ("proposed", 40.0, ["more than 0.5 of its own", "strobed"]),  # the audit's invisible sphere
        ("phase_shift", 0.5, ["more than 0.5 of its own", "which the phase_shift decode assumes still"]),
        ("phase_shift", 0.002, []),  # 0.65 mm over the 0.32 s sequence
    ],
)
def test_a_recording_says_when_motion_makes_its_depth_untrustworthy(variant, system_name, speed_m_s, expected):
    """motion_warnings: an object smeared over more than half its own image extent, a
    multi-exposure decode whose scene moves more than STILL_TRAVEL_MM, a blur sampled more
    coarsely than MAX_SLICE_MOTION_PX a slice (the slice cap) - each warned, each from the time
    model and the truth at mid-capture; a blur the systems hold, nothing."""
    from simbench.api import motion_warnings
    from simbench.sim.timeline import motion_field_px
    from simbench.sim.truth import ground_truth
    from simbench.systems import SystemOptions, get_system

    system = get_system(system_name, SystemOptions(camera_scale=0.25))
    window = system.capture_window_s(system.prepare(_board_before_wall()))
    # the board centred in the view at mid-capture
    start_x = -0.5 * speed_m_s * (window[0] + window[1])
    scene = system.prepare(
        scene_from_dict(
            {
                "name": "board_before_wall",
                "object": [
                    {"type": "plane", "name": "wall", "center_m": [0, 0, 1.3], "size_m": [2, 2]},
                    {
                        "type": "plane",
                        "name": "board",
                        "center_m": [start_x, 0.0, 1.0],
                        "size_m": [0.2, 0.3],
                        "velocity_m_s": [speed_m_s, 0.0, 0.0],
                    },
                ],
            }
        )
    )
    gt = ground_truth(scene_at(scene, 0.5 * (window[0] + window[1])))
    motion = motion_field_px(gt.depth_m, gt.object_id, scene, scene.rig.camera, window)
    told = motion_warnings(scene, dataclasses.replace(gt, motion_px=motion), system)
    assert len(told) == len(expected) and all(e in t for e, t in zip(expected, told)), told
    assert all("'board'" in t for t in told if "object" in t)


@pytest.mark.slow
def test_a_moving_recording_states_its_window_and_slices_and_warns_of_a_smear(variant, tmp_path):
    """simbench.record of a moving scene (a quarter-resolution paper rig): meta.json's
    capture_window_s and time_slices (the blur's integration, docs/motion.md), and the smear
    warning where the object crosses more than half its own extent (a 2 cm ball at 1 m/s: 17 px
    of travel, its extent 23 px; at 0.5 m/s 8.5 px, nothing said)."""
    import simbench
    from simbench.sim.timeline import slice_count

    def scene_file(speed: float) -> str:  # the ball centred at mid-exposure
        return _ball_before_a_wall(tmp_path, speed, x_m=-0.0135 * speed)

    with warnings.catch_warnings():
        warnings.simplefilter("error", simbench.SimbenchWarning)
        rec = simbench.record(scene_file(0.5), spp=1, calibration_frames=False)
    t0, t1 = rec.meta["capture_window_s"]
    assert t0 == 0.0 and t1 == pytest.approx(rec.meta["exposure_s"])
    assert rec.meta["time_slices"] == slice_count(rec.recording.scene, rec.recording.scene.rig.camera, (t0, t1)) > 1
    with pytest.warns(simbench.SimbenchWarning, match="more than 0.5 of its own"):
        simbench.record(scene_file(1.0), spp=1, calibration_frames=False)


@pytest.mark.slow
def test_a_moving_recording_is_scored_against_one_instant_and_says_so(variant, tmp_path, capsys):
    """`simbench score` and `simbench.score` of a moving recording (a ball at 0.5 m/s before a
    wall, a quarter-resolution paper rig): the scores carry ``image_motion_px``, the fastest pixel's
    image motion (f v T / Z), and the text a note that the truth is the scene at mid-capture; a
    competitor's folder keeps gt_motion.npy too (the Kinect's); a still recording neither."""
    import json

    import simbench
    from simbench.cli import main

    def scene_file(speed: float) -> str:
        return _ball_before_a_wall(tmp_path, speed, x_m=0.0)

    rec = simbench.record(scene_file(0.5), spp=1)
    t0, t1 = rec.meta["capture_window_s"]
    want = rec.scene.rig.camera.focal_px * 0.5 * (t1 - t0) / 1.0  # the ball's nearest point, at 0.98 m
    scores = simbench.score(rec.gt.depth_m, rec)
    assert scores["image_motion_px"] == pytest.approx(want, rel=0.05) and scores["mae_mm"] == 0.0
    for system in ("proposed", "kinect"):
        out = tmp_path / system
        assert main(["render", scene_file(0.5), "--out", str(out), "--spp", "1", "--system", system]) == 0
        assert (out / "gt_motion.npy").is_file()
        capsys.readouterr()
        assert main(["score", str(out / "gt_depth.npy"), "--gt", str(out / "gt_depth.npy")]) == 0
        text = capsys.readouterr().out
        assert "note: the recording moves (" in text and "the scene at mid-capture" in text, text
        assert main(["score", str(out / "gt_depth.npy"), "--gt", str(out / "gt_depth.npy"), "--json"]) == 0
        assert json.loads(capsys.readouterr().out)["image_motion_px"] > 1.0
    still = tmp_path / "still"
    assert main(["render", scene_file(0.0), "--out", str(still), "--spp", "1"]) == 0
    capsys.readouterr()
    assert main(["score", str(still / "gt_depth.npy"), "--gt", str(still / "gt_depth.npy")]) == 0
    assert "note:" not in capsys.readouterr().out and not (still / "gt_motion.npy").exists()
    still_rec = simbench.record(scene_file(0.0), spp=1)
    assert "image_motion_px" not in simbench.score(still_rec.gt.depth_m, still_rec)


def _ball_before_a_wall(folder, speed_m_s: float, *, x_m: float) -> str:
    """A scene file in ``folder``: a 2 cm ball at (``x_m``, 0, 1 m) moving sideways at
    ``speed_m_s`` before a wall at 1.3 m, on the paper rig at a quarter of its resolution
    (``rig_q.toml`` beside it)."""
    from simbench.rig import get_rig, save_rig

    save_rig(scale_camera(get_rig("paper"), 0.25), folder / "rig_q.toml")
    path = folder / f"ball_{speed_m_s:g}.toml"
    path.write_text(
        f'name = "ball"\nrig = "rig_q.toml"\n[[object]]\ntype = "sphere"\nname = "ball"\n'
        f"center_m = [{x_m:.6f}, 0.0, 1.0]\nradius_m = 0.02\nvelocity_m_s = [{speed_m_s}, 0.0, 0.0]\n"
        '[[object]]\ntype = "plane"\nname = "wall"\ncenter_m = [0.0, 0.0, 1.3]\nsize_m = [2.0, 1.6]\n'
    )
    return str(path)
