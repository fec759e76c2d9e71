"""Ground truth at camera pixel centres, traced with Mitsuba: z-depth, the projector column
lighting each pixel, object ids and the lit mask; rays for sensors that need more than one
per pixel; depth seen from the projector.

Nothing here imports Mitsuba at module import time (:mod:`simbench.variant`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simbench.sim.mitsuba_dict import jit_arithmetic, load_scene_dict, mitsuba_scene
from simbench.rig import pixel_rays, project_to_projector
from simbench.sim.scene import SceneSpec
from simbench.variant import is_jit

__all__ = ["GroundTruth", "ground_truth", "trace_rays", "projector_distance"]


@dataclass(frozen=True)
class GroundTruth:
    """Ground truth at camera pixel centres.

    Attributes
    ----------
    depth_m : ndarray, shape (H, W), float32
        z-depth in the camera frame (not ray distance); NaN where the ray hits nothing.
    column_px : ndarray, shape (H, W), float64
        Projector column (OpenCV coordinates, sub-pixel) lighting the pixel; NaN if unlit.
    object_id : ndarray, shape (H, W), int16
        Index into ``SceneSpec.objects``; -1 where nothing is hit.
    lit : ndarray, shape (H, W), bool
        Seen by the camera and directly lit by the projector (inside its frustum, not in its
        shadow, the same side of the surface facing both).
    motion_px : ndarray, shape (H, W, 2), float32, or None
        A moving scene's: how far (du, dv camera pixels) the surface point seen at each pixel
        moves across the image during the capture (:func:`simbench.sim.timeline.motion_field_px`);
        None for a static scene.
    """

    depth_m: np.ndarray
    column_px: np.ndarray
    object_id: np.ndarray
    lit: np.ndarray
    motion_px: np.ndarray | None = None

    @property
    def seen(self) -> np.ndarray:
        return self.object_id >= 0


@jit_arithmetic()
def ground_truth(scene: SceneSpec) -> GroundTruth:
    """Cast one ray through every camera pixel centre with Mitsuba and project the hits."""
    import mitsuba as mi

    d, rig = mitsuba_scene(scene, None, spp=1, max_depth=1)
    mscene = load_scene_dict(mi, d, scene)
    rays = pixel_rays(rig.camera)
    h, w = rays.shape[:2]
    dirs = (rays / np.linalg.norm(rays, axis=-1, keepdims=True)).reshape(-1, 3).astype(np.float32)
    proj_pos = np.asarray(rig.position_m)
    key_to_index = {f"obj{i:03d}": i for i in range(len(scene.objects))}
    if is_jit(mi.variant()):
        p, n, hit, occluded, obj = _trace_vectorised(mi, mscene, dirs, proj_pos, key_to_index)
    else:
        p, n, hit, occluded, obj = _trace_scalar(mi, mscene, dirs, proj_pos, key_to_index)
    depth = np.where(hit, p[:, 2], np.nan)
    u, v, zp = project_to_projector(p, rig)
    prj = rig.projector
    in_frustum = (zp > 0) & (u >= -0.5) & (u <= prj.width_px - 0.5) & (v >= -0.5) & (v <= prj.height_px - 0.5)
    same_side = np.sign(np.sum(n * (proj_pos - p), axis=1)) == np.sign(np.sum(n * (-p), axis=1))
    lit = hit & in_frustum & ~occluded & same_side
    return GroundTruth(
        depth_m=depth.reshape(h, w).astype(np.float32),
        column_px=np.where(lit, u, np.nan).reshape(h, w),
        object_id=np.where(hit, obj, -1).reshape(h, w).astype(np.int16),
        lit=lit.reshape(h, w),
    )


@jit_arithmetic()
def trace_rays(scene: SceneSpec, dirs: np.ndarray) -> dict[str, np.ndarray]:
    """First hits of rays from the camera centre along ``dirs`` (camera frame), for sensors
    that need more than one ray per pixel (the ToF camera's supersampled footprints).

    Parameters
    ----------
    dirs : ndarray, shape (N, 3)
        Ray directions (normalised here).

    Returns
    -------
    dict of ndarray: ``p`` (N, 3) hit points (m), ``n`` (N, 3) shading normals, ``hit`` (N,)
    bool, ``occluded`` (N,) bool (the projector cannot see the hit), ``object_id`` (N,) int32
    (index into ``scene.objects``, -1 = miss).
    """
    import mitsuba as mi

    dirs = np.asarray(dirs, dtype=np.float64).reshape(-1, 3)
    if not np.all(np.isfinite(dirs)) or np.any(np.linalg.norm(dirs, axis=1) == 0):
        raise ValueError("ray directions must be finite and non-zero")
    d, rig = mitsuba_scene(scene, None, spp=1, max_depth=1)
    mscene = load_scene_dict(mi, d, scene)
    unit = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    key_to_index = {f"obj{i:03d}": i for i in range(len(scene.objects))}
    trace = _trace_vectorised if is_jit(mi.variant()) else _trace_scalar
    p, n, hit, occluded, obj = trace(mi, mscene, unit, np.asarray(rig.position_m), key_to_index)
    return {"p": p, "n": n, "hit": hit, "occluded": occluded, "object_id": obj}


def _trace_vectorised(mi, mscene, dirs, proj_pos, key_to_index):
    ray = mi.Ray3f(mi.Point3f(0.0, 0.0, 0.0), mi.Vector3f(dirs[:, 0], dirs[:, 1], dirs[:, 2]))
    si = mscene.ray_intersect(ray)
    hit = np.array(si.is_valid(), dtype=bool)
    shadow = si.spawn_ray_to(mi.Point3f(*[float(x) for x in proj_pos]))
    occluded = np.array(mscene.ray_test(shadow, si.is_valid()), dtype=bool)
    obj = np.full(hit.shape, -1, dtype=np.int32)
    for shape in mscene.shapes():
        obj[np.array(si.shape == mi.ShapePtr(shape), dtype=bool)] = key_to_index[shape.id()]
    p = np.array(si.p, dtype=np.float64).T
    n = np.array(si.n, dtype=np.float64).T
    return p, n, hit, occluded, obj


def _trace_scalar(mi, mscene, dirs, proj_pos, key_to_index):
    count = len(dirs)
    p = np.zeros((count, 3))
    n = np.zeros((count, 3))
    hit = np.zeros(count, bool)
    occluded = np.zeros(count, bool)
    obj = np.full(count, -1, np.int32)
    target = mi.Point3f(*[float(x) for x in proj_pos])
    origin = mi.Point3f(0.0, 0.0, 0.0)
    for i, dvec in enumerate(dirs.tolist()):
        si = mscene.ray_intersect(mi.Ray3f(origin, mi.Vector3f(dvec)))
        if not si.is_valid():
            continue
        hit[i] = True
        p[i] = si.p
        n[i] = si.n
        obj[i] = key_to_index[si.shape.id()]
        occluded[i] = mscene.ray_test(si.spawn_ray_to(target))
    return p, n, hit, occluded, obj


@jit_arithmetic()
def projector_distance(scene: SceneSpec, *, stride: int = 4) -> np.ndarray:
    """Depth along the projector's optical axis of the first surface each projector pixel's
    ray meets (ideal pinhole rays), for the projector's defocus.

    Rays are cast through every ``stride``-th pixel centre and the map is spread back to full
    size by nearest neighbour (defocus varies slowly with depth; ``stride`` = 1 is exact).

    Returns
    -------
    ndarray, shape (Hp, Wp), float32; NaN where the ray meets nothing.
    """
    import mitsuba as mi

    if stride < 1 or int(stride) != stride:
        raise ValueError(f"stride must be a positive integer, got {stride}")
    d, rig = mitsuba_scene(scene, None, spp=1, max_depth=1)
    mscene = load_scene_dict(mi, d, scene)
    prj = rig.projector
    hp, wp = prj.size_hw
    # one ray through the middle of each stride x stride block
    cols = np.minimum(np.arange(0, wp, stride) + stride // 2, wp - 1).astype(np.float64)
    rows = np.minimum(np.arange(0, hp, stride) + stride // 2, hp - 1).astype(np.float64)
    x = (cols[None, :] - prj.cx_px) / prj.focal_px
    y = (rows[:, None] - prj.cy_px) / prj.focal_px
    local = np.stack(np.broadcast_arrays(x, y, np.ones_like(x * y)), axis=-1).reshape(-1, 3)
    dirs = local @ rig.rotation.T
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    origin = [float(v) for v in rig.position_m]
    if is_jit(mi.variant()):
        dirs32 = dirs.astype(np.float32)
        ray = mi.Ray3f(mi.Point3f(*origin), mi.Vector3f(dirs32[:, 0], dirs32[:, 1], dirs32[:, 2]))
        si = mscene.ray_intersect(ray)
        t = np.where(np.array(si.is_valid(), dtype=bool), np.array(si.t, dtype=np.float64), np.nan)
    else:
        t = np.full(len(dirs), np.nan)
        o = mi.Point3f(*origin)
        for i, dv in enumerate(dirs.tolist()):
            si = mscene.ray_intersect(mi.Ray3f(o, mi.Vector3f(dv)))
            if si.is_valid():
                t[i] = si.t
    # distance along the axis = ray length * cos(angle to the axis) = t / |(x, y, 1)|
    z = (t / np.linalg.norm(local, axis=1)).reshape(len(rows), len(cols))
    full = np.repeat(np.repeat(z, stride, axis=0), stride, axis=1)[:hp, :wp]
    return full.astype(np.float32)
