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

__all__ = [
    "is_moving",
    "object_at",
    "scene_at",
    "image_motion_px",
    "image_speed_px_s",
    "motion_field_px",
    "slice_count",
    "slice_spp",
]


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


def placement_warnings(scene: SceneSpec, *, window_s: tuple[float, float] = (0.0, 0.0)) -> list[str]:
    """What a scene file places where no camera view of it could mean it (a new user's audit: each
    rendered without a word): a mesh tens of metres across (in millimetres, not metres), an object
    wholly behind the camera throughout the capture window ``window_s`` (s; a moving object is
    followed over it, so one that comes into view during the capture is not reported), the camera
    inside a solid object's bounds (at time 0).  Warnings, not errors: a room around the camera,
    or an object behind it that lights the scene, may be meant."""
    out = []
    steps = np.linspace(float(window_s[0]), float(window_s[1]), 9)
    extents = [_extent_points(obj) for obj in scene.objects]
    # where each object's extent is over the window, shape (T, N, 3) (a static one: T = 1)
    tracks = [
        pts[None]
        if obj.motion is None or obj.motion.is_static
        else np.stack(
            [obj.motion.apply(pts, t, centre_m=np.asarray(dict(obj.params)[_position_key(obj)])) for t in steps]
        )
        for obj, pts in zip(scene.objects, extents)
    ]
    # (all of them behind: the render's "no object is visible" error says it)
    some_in_front = any((track[..., 2] > 0).any() for track in tracks)
    for obj, pts, track in zip(scene.objects, extents, tracks):
        span = float(np.max(pts.max(axis=0) - pts.min(axis=0)))
        if obj.kind == "mesh" and span > MESH_MAX_EXTENT_M:
            out.append(
                f"object {obj.name!r}: the mesh spans {span:.4g} m across - scene units are metres (a mesh in "
                "millimetres? `scale = 0.001` in its [[object]])"
            )
        if (track[..., 2] <= 0).all() and some_in_front:
            during = " throughout the capture" if len(track) > 1 and window_s[1] > window_s[0] else ""
            out.append(f"object {obj.name!r} lies wholly behind the camera (z <= 0 m){during}: no pixel sees it")
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


# a moving object's extent is sampled on this many points a side of each face of its bounds:
# where its bounds' corners lie behind the camera or outside the view - a floor reaching past the
# camera - the motion of the part in view is measured on the samples there (assumption: 65 a side
# resolve a bench-top object's nearest visible part to 1/64 of its size, a few % of its motion)
FACE_SAMPLES = 65


def _surface_points(obj: SceneObject) -> np.ndarray:
    """Points covering ``obj``'s bounds at time 0 - :data:`FACE_SAMPLES` a side on each face of
    its bounding box (a plane's one face), a sphere's surface - world metres, shape (N, 3)."""
    g = np.linspace(-1.0, 1.0, FACE_SAMPLES)
    u, v = (x.reshape(-1) for x in np.meshgrid(g, g, indexing="ij"))
    one = np.ones_like(u)
    faces = np.vstack(
        [np.stack(f, axis=1) for s in (-1.0, 1.0) for f in ((s * one, u, v), (u, s * one, v), (u, v, s * one))]
    )
    p = dict(obj.params)
    if obj.kind == "sphere":
        c, r = np.asarray(p["center_m"], np.float64), float(p["radius_m"])
        return c + r * faces / np.linalg.norm(faces, axis=1, keepdims=True)
    corners = _extent_points(obj)  # the 8 corners, index bits (x, y, z) of the local box
    centre = corners.mean(axis=0)
    axes = np.stack([corners[4] - corners[0], corners[2] - corners[0], corners[1] - corners[0]]) / 2.0
    return np.unique(centre + faces @ axes, axis=0)


def _in_view(p0: np.ndarray, p1: np.ndarray, camera: Intrinsics, *, near_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per straight 3-D segment ``p0 -> p1`` (shape (N, 3) each, camera frame, travelled at a
    constant velocity): the length (camera pixels) of its image inside the image, and the share
    of the segment's time spent there.  The segment is cut at the near plane ``near_m`` (what
    lies before it no pixel sees), projected (a straight segment in front of a pinhole images to
    a straight segment) and clipped to the image rectangle (Liang-Barsky); the clip's image
    parameter ``s`` maps back to the segment's own ``u = s z0 / ((1 - s) z1 + s z0)``
    (perspective-correct interpolation).  (0, 0) where no part of it is in view."""
    d = p1 - p0
    lo, hi = np.zeros(len(p0)), np.ones(len(p0))
    # z(t) = z0 + t dz >= near
    with np.errstate(divide="ignore", invalid="ignore"):
        t_near = (near_m - p0[:, 2]) / d[:, 2]
    rising, falling = d[:, 2] > 0, d[:, 2] < 0
    lo = np.where(rising, np.maximum(lo, t_near), lo)
    hi = np.where(falling, np.minimum(hi, t_near), hi)
    flat_behind = (d[:, 2] == 0) & (p0[:, 2] < near_m)
    ok = (lo < hi) & ~flat_behind
    q0, q1 = p0 + lo[:, None] * d, p0 + hi[:, None] * d
    z0, z1 = np.where(ok, q0[:, 2], 1.0), np.where(ok, q1[:, 2], 1.0)
    f = camera.focal_px
    uv0 = f * q0[:, :2] / z0[:, None] + (camera.cx_px, camera.cy_px)
    uv1 = f * q1[:, :2] / z1[:, None] + (camera.cx_px, camera.cy_px)
    e = uv1 - uv0
    s0, s1 = np.zeros(len(p0)), np.ones(len(p0))
    # the image's pixels span [-0.5, W - 0.5] x [-0.5, H - 0.5] (OpenCV centres)
    for axis, top in ((0, camera.width_px - 0.5), (1, camera.height_px - 0.5)):
        for bound, sign in ((-0.5, 1.0), (top, -1.0)):
            # inside: sign * (uv0 + s e - bound) >= 0
            g0, ge = sign * (uv0[:, axis] - bound), sign * e[:, axis]
            with np.errstate(divide="ignore", invalid="ignore"):
                s = -g0 / ge
            s0 = np.where(ge > 0, np.maximum(s0, s), s0)
            s1 = np.where(ge < 0, np.minimum(s1, s), s1)
            ok &= ~((ge == 0) & (g0 < 0))
    ok &= s0 <= s1
    length = np.where(ok, np.clip(s1 - s0, 0.0, None) * np.linalg.norm(e, axis=1), 0.0)

    def back(s: np.ndarray) -> np.ndarray:  # image parameter -> the near-cut segment's own
        return s * z0 / ((1.0 - s) * z1 + s * z0)

    share = np.where(ok, (hi - lo) * np.clip(back(np.clip(s1, 0, 1)) - back(np.clip(s0, 0, 1)), 0.0, None), 0.0)
    return length, share


# the time steps over which a window's motion is followed (a point's path between two is taken
# straight; 32 intervals keep a rotation's chord and a point's entry into the view within a few %
# of the window)
MOTION_STEPS = 33


def _image_motion(scene: SceneSpec, camera: Intrinsics, t0_s: float, t1_s: float) -> tuple[float, float]:
    """(:func:`image_motion_px`, :func:`image_speed_px_s`) of one pass over the points."""
    from simbench.sim.mitsuba_dict import CAMERA_NEAR_CLIP_M

    travel, speed = 0.0, 0.0
    steps = np.linspace(t0_s, t1_s, MOTION_STEPS)
    dt = (t1_s - t0_s) / (MOTION_STEPS - 1)
    for obj in scene.objects:
        if obj.motion is None or obj.motion.is_static:
            continue
        pts = _surface_points(obj)
        position = np.asarray(dict(obj.params)[_position_key(obj)], np.float64)
        tracks = np.stack([obj.motion.apply(pts, t, centre_m=position) for t in steps])  # (T, N, 3)
        seen = [_in_view(a, b, camera, near_m=CAMERA_NEAR_CLIP_M) for a, b in zip(tracks[:-1], tracks[1:])]
        travel = max(travel, float(np.max(sum(length for length, _ in seen))))
        if dt > 0:
            for length, share in seen:
                moving = share > 0
                if moving.any():
                    speed = max(speed, float(np.max(length[moving] / (share[moving] * dt))))
    return travel, speed


def image_motion_px(scene: SceneSpec, camera: Intrinsics, t0_s: float, t1_s: float) -> float:
    """The largest distance (camera pixels) any point of a moving object travels across the image
    between ``t0_s`` and ``t1_s``, checked along the way (a rotation can bring a point back);
    0 for a static scene.  Measured on the image: the part of a point's path behind the camera's
    near plane or outside the image is left out, so an object reaching behind the camera (a floor)
    is measured on its part in view, and one that comes into view during the window on the path
    it travels there.  The points: samples of each object's bounds (:data:`FACE_SAMPLES`)."""
    return _image_motion(scene, camera, t0_s, t1_s)[0]


def image_speed_px_s(scene: SceneSpec, camera: Intrinsics, t0_s: float, t1_s: float) -> float:
    """The fastest any point of a moving object moves across the image (camera pixels a second)
    while in view between ``t0_s`` and ``t1_s`` (over each of :data:`MOTION_STEPS` - 1 steps, the
    path it travels in view over the time it spends there); 0 for a static scene or an empty
    window.  What sets time slices and truth instants evenly spaced over a window: an object in
    view for part of the window (entering or leaving it) moves its whole image travel in that
    part, and an object approaching the camera speeds up across the image."""
    return _image_motion(scene, camera, t0_s, t1_s)[1]


def slice_count(scene: SceneSpec, camera: Intrinsics, window_s: tuple[float, float]) -> int:
    """Time slices that integrate ``window_s`` (module docstring): 1 for a static scene or an
    empty window; enough that no point in view moves more than :data:`MAX_SLICE_MOTION_PX` per
    slice (:func:`image_speed_px_s` times the slice's length), at most :data:`MAX_SLICES`."""
    t0, t1 = window_s
    if t1 <= t0 or not is_moving(scene):
        return 1
    # evenly spaced slices: the fastest in-view motion sets the count (a review: the whole travel
    # of an object in view for part of the window fell into fewer slices than it needs)
    reach = image_speed_px_s(scene, camera, t0, t1) * (t1 - t0)
    return int(min(MAX_SLICES, max(1, math.ceil(reach / MAX_SLICE_MOTION_PX))))


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
