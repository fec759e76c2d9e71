"""A moving scene over time (:mod:`simbench.sim.motion`): posed at an instant, how far its image
moves, and how many time slices integrate an exposure of it."""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from simbench.rig import angles_xyz_deg, rotation_xyz_deg
from simbench.sim.motion import MAX_SLICE_MOTION_PX, MAX_SLICES
from simbench.sim.scene import OBJECT_KIND_TABLE, SceneObject, SceneSpec, target_size_m

if TYPE_CHECKING:
    from simbench.rig import Intrinsics

__all__ = ["is_moving", "object_at", "scene_at", "image_motion_px", "motion_field_px", "slice_count", "slice_spp"]


def is_moving(scene: SceneSpec) -> bool:
    """Whether any object of ``scene`` moves."""
    return any(o.motion is not None and not o.motion.is_static for o in scene.objects)


def _position_key(obj: SceneObject) -> str:
    return OBJECT_KIND_TABLE[obj.kind].position_key


def object_at(obj: SceneObject, t_s: float) -> SceneObject:
    """``obj`` posed at time ``t_s``: its position and orientation moved, no motion left."""
    if obj.motion is None:
        return obj
    m = obj.motion
    params = dict(obj.params)
    key = _position_key(obj)
    position = np.asarray(params[key], np.float64)
    params[key] = tuple(float(x) for x in m.apply(position[None], t_s, centre_m=position)[0])
    if "rotation_deg" in params and m.angular_velocity_deg_s:
        r = m.rotation(t_s) @ rotation_xyz_deg(params["rotation_deg"])
        params["rotation_deg"] = tuple(float(a) for a in angles_xyz_deg(r))
    return dataclasses.replace(obj, params=tuple(sorted(params.items())), motion=None)


def scene_at(scene: SceneSpec, t_s: float) -> SceneSpec:
    """``scene`` at the instant ``t_s`` (s after the instant its file describes): every moving
    object posed there, as a static scene.  A static scene is returned as it is."""
    if not any(o.motion is not None for o in scene.objects):
        return scene
    return dataclasses.replace(scene, objects=tuple(object_at(o, float(t_s)) for o in scene.objects))


def _extent_points(obj: SceneObject) -> np.ndarray:
    """Points spanning ``obj`` at time 0 (its bounding box's corners, or a sphere's extremes),
    world metres, shape (N, 3): what bounds how far its image moves."""
    p = dict(obj.params)
    if obj.kind == "sphere":
        c, r = np.asarray(p["center_m"], np.float64), float(p["radius_m"])
        return np.vstack([c, c + r * np.eye(3), c - r * np.eye(3)])
    if obj.kind == "mesh":
        import trimesh

        bounds = np.asarray(trimesh.load(p["file"], force="mesh").bounds, np.float64) * float(p["scale"])
        local = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        origin = np.asarray(p["translate_m"], np.float64)
    else:
        size = np.asarray(p.get("size_m", (0.0, 0.0)), np.float64)
        if obj.kind == "target":
            size = np.asarray(target_size_m(p["squares"], p["square_m"], p["margin_squares"]), np.float64)
        half = np.append(size, 0.0)[:3] / 2.0
        local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
        origin = np.asarray(p["center_m"], np.float64)
    return origin + local @ rotation_xyz_deg(p["rotation_deg"]).T


# a mesh wider than this is taken for one in other units than metres (assumption: a bench-top
# structured-light scene spans metres, and a millimetre mesh of a 10 cm object spans 100 "m")
MESH_MAX_EXTENT_M = 20.0


def placement_warnings(scene: SceneSpec) -> list[str]:
    """What a scene file places where no camera view of it could mean it (a new user's audit: each
    rendered without a word): a mesh tens of metres across (in millimetres, not metres), an object
    wholly behind the camera, the camera inside a solid object's bounds.  Warnings, not errors:
    a room around the camera, or an object behind it that lights the scene, may be meant."""
    out = []
    extents = [_extent_points(obj) for obj in scene.objects]
    # (all of them behind: the render's "no object is visible" error says it)
    some_in_front = any((pts[:, 2] > 0).any() for pts in extents)
    for obj, pts in zip(scene.objects, extents):
        span = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
        if obj.kind == "mesh" and span > MESH_MAX_EXTENT_M:
            out.append(
                f"object {obj.name!r}: the mesh spans {span:.4g} m across - scene units are metres (a mesh in "
                "millimetres? `scale = 0.001` in its [[object]])"
            )
        if (pts[:, 2] <= 0).all() and some_in_front:
            out.append(f"object {obj.name!r} lies wholly behind the camera (z <= 0 m): no pixel sees it")
        elif _holds_the_camera(obj, pts):
            out.append(
                f"the camera (at the origin) is inside the bounds of object {obj.name!r} "
                f"({np.round(pts.min(axis=0), 3).tolist()} to {np.round(pts.max(axis=0), 3).tolist()} m): it sees "
                "the object from within"
            )
    return out


def _holds_the_camera(obj: SceneObject, pts: np.ndarray) -> bool:
    """Whether the origin (the camera) is inside a solid object: a sphere or a box exactly, a
    mesh by its bounding box."""
    p = dict(obj.params)
    if obj.kind == "sphere":
        return float(np.linalg.norm(p["center_m"])) < float(p["radius_m"])
    if obj.kind == "box":
        local = rotation_xyz_deg(p["rotation_deg"]).T @ -np.asarray(p["center_m"], np.float64)
        return bool((np.abs(local) < np.asarray(p["size_m"], np.float64) / 2.0).all())
    if obj.kind == "mesh":
        return bool(((pts.min(axis=0) < 0) & (pts.max(axis=0) > 0)).all())
    return False


def image_motion_px(scene: SceneSpec, camera: Intrinsics, t0_s: float, t1_s: float) -> float:
    """The largest distance (camera pixels) any moving object's extent points travel across the
    image between ``t0_s`` and ``t1_s``, checked along the way (a rotation can bring a point back);
    0 for a static scene.  Points behind the camera are left out."""
    worst = 0.0
    steps = np.linspace(t0_s, t1_s, 9)
    for obj in scene.objects:
        if obj.motion is None or obj.motion.is_static:
            continue
        pts = _extent_points(obj)
        position = np.asarray(dict(obj.params)[_position_key(obj)], np.float64)
        tracks = np.stack([obj.motion.apply(pts, t, centre_m=position) for t in steps])  # (T, N, 3)
        z = tracks[..., 2]
        ok = (z > 1e-3).all(axis=0)
        if not ok.any():
            continue
        uv = camera.focal_px * tracks[..., :2][:, ok] / z[:, ok][..., None]
        worst = max(worst, float(np.linalg.norm(np.diff(uv, axis=0), axis=-1).sum(axis=0).max()))
    return worst


def slice_count(scene: SceneSpec, camera: Intrinsics, window_s: tuple[float, float]) -> int:
    """Time slices that integrate ``window_s`` (module docstring): 1 for a static scene or an
    empty window; enough that no point moves more than :data:`MAX_SLICE_MOTION_PX` per slice,
    at most :data:`MAX_SLICES`."""
    t0, t1 = window_s
    if t1 <= t0 or not is_moving(scene):
        return 1
    travel = image_motion_px(scene, camera, t0, t1)
    return int(min(MAX_SLICES, max(1, math.ceil(travel / MAX_SLICE_MOTION_PX))))


def slice_spp(spp: int, n: int) -> int:
    """Samples per pixel of each of ``n`` time slices of a ``spp`` render: ``spp // n``, at least
    one (the slices are rendered with the ``independent`` sampler, which takes any count, so the
    capture keeps within ``n`` samples of ``spp`` - about a static capture's cost - until ``n``
    exceeds ``spp``: then every slice takes one sample, ``n`` in all)."""
    return max(1, int(spp) // int(n))


def motion_field_px(
    depth_m: np.ndarray, object_id: np.ndarray, scene: SceneSpec, camera: Intrinsics, window_s: tuple[float, float]
) -> np.ndarray:
    """Per pixel, how far (du, dv camera pixels) the surface point seen there at the middle of
    ``window_s`` moves across the image from the window's start to its end; 0 where nothing is
    seen or the object is static.  ``depth_m`` and ``object_id`` are the ground truth at
    mid-window (:class:`simbench.sim.truth.GroundTruth`).

    Returns
    -------
    ndarray, shape (H, W, 2), float32
    """
    from simbench.rig import pixel_rays

    t0, t1 = (float(x) for x in window_s)
    tm = 0.5 * (t0 + t1)
    out = np.zeros((*depth_m.shape, 2), np.float32)
    rays = pixel_rays(camera)
    for k, obj in enumerate(scene.objects):
        m = obj.motion
        sel = (object_id == k) & np.isfinite(depth_m)
        if m is None or m.is_static or not sel.any():
            continue
        x_mid = rays[sel] * depth_m[sel, None].astype(np.float64)  # the points at mid-window
        c = np.asarray(m.centre_m if m.centre_m is not None else dict(obj.params)[_position_key(obj)], np.float64)
        v = np.asarray(m.velocity_m_s, np.float64)
        # back to time 0: x0 = c + R(tm)^T (x - v tm - c); then forward to t0 and t1
        x0 = c + (x_mid - v * tm - c) @ m.rotation(tm)
        ends = [m.apply(x0, t, centre_m=c) for t in (t0, t1)]
        uv = [camera.focal_px * e[:, :2] / e[:, 2:3] for e in ends]
        out[sel] = (uv[1] - uv[0]).astype(np.float32)
    return out
