"""Mitsuba variant choice, capture and reference renders, and ground truth at pixel centres.

Nothing here imports Dr.Jit or Mitsuba at module import time: Dr.Jit binds a libLLVM when it is
first imported, so :func:`select_variant` must run first (at an entry point) to steer it.
"""

from __future__ import annotations

import glob
import math
import os
import re
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from simbench.rig import Intrinsics, Rig, pixel_rays, project_to_projector
from simbench.scene import SceneSpec, object_to_mitsuba

__all__ = [
    "MIN_LLVM_MAJOR",
    "find_libllvm",
    "choose_variant",
    "select_variant",
    "projector_texture",
    "realised_rig",
    "SAMPLERS",
    "DEFAULT_SAMPLER",
    "DEFAULT_SPP",
    "check_sampler",
    "mitsuba_scene",
    "render_radiance",
    "GroundTruth",
    "ground_truth",
    "trace_rays",
]

# Mitsuba 3.6+ kernels use llvm.minimum/maximum intrinsics; LLVM <= 15 cannot select them and
# aborts the whole process ("LLVM ERROR: Cannot select ... fminimum"), which no try can catch.
MIN_LLVM_MAJOR = 16

_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
    "/usr/local/opt/llvm/lib/libLLVM*.dylib",
)


def _llvm_major_from_path(path: Path) -> int | None:
    for name in (path.name, Path(os.path.realpath(path)).name):
        m = re.match(r"libLLVM[-.]?(?:so\.)?(\d+)", name)
        if m:
            return int(m.group(1))
    m = re.search(r"llvm-(\d+)", str(path))
    return int(m.group(1)) if m else None


def find_libllvm() -> list[tuple[int, Path]]:
    """Shared libLLVM files on this machine with their major versions, newest first."""
    found: dict[Path, int] = {}
    for pattern in _LLVM_GLOBS:
        for p in glob.glob(pattern):
            path = Path(p)
            major = _llvm_major_from_path(path)
            if major is not None and path.is_file():
                found.setdefault(path, major)
    return sorted(((v, p) for p, v in found.items()), key=lambda x: (-x[0], str(x[1])))


def _notice(msg: str) -> None:
    print(f"simbench: {msg}", file=sys.stderr)


def choose_variant(
    requested: str | None,
    *,
    available: list[str],
    llvm_version: tuple[int, ...] | None,
    cuda: bool,
) -> tuple[str, str | None]:
    """The Mitsuba variant to use, and a notice for the user (or None).

    Order: ``requested`` if given; else ``cuda_ad_rgb`` with a CUDA GPU; else ``llvm_ad_rgb``
    when Dr.Jit runs on libLLVM >= 16; else ``scalar_rgb`` (about 5x slower) with a notice.

    Raises
    ------
    ValueError
        Unknown variant, or an LLVM variant requested where it would abort the process.
    """
    llvm_ok = llvm_version is not None and llvm_version[0] >= MIN_LLVM_MAJOR
    llvm_text = "none found" if llvm_version is None else ".".join(map(str, llvm_version))
    if requested:
        if requested not in available:
            raise ValueError(f"unknown Mitsuba variant {requested!r}; available: {available}")
        if requested.startswith("llvm_") and not llvm_ok:
            raise ValueError(
                f"variant {requested} needs libLLVM >= {MIN_LLVM_MAJOR} (found: {llvm_text}); "
                "install it (Debian: apt-get install libllvm19) or use --variant scalar_rgb"
            )
        return requested, None
    if cuda and "cuda_ad_rgb" in available:
        return "cuda_ad_rgb", None
    if llvm_ok and "llvm_ad_rgb" in available:
        return "llvm_ad_rgb", None
    return "scalar_rgb", (
        f"libLLVM >= {MIN_LLVM_MAJOR} not available (found: {llvm_text}); rendering with "
        "scalar_rgb, about 5x slower. Fix: apt-get install libllvm19 (done by `make setup` as root)."
    )


def select_variant(requested: str | None = None) -> str:
    """Choose (:func:`choose_variant`) and set the Mitsuba variant; call once at an entry
    point, before other Mitsuba use.  Points Dr.Jit at a libLLVM >= 16 if one exists, then
    checks the version Dr.Jit actually loaded."""
    if "drjit" not in sys.modules and "DRJIT_LIBLLVM_PATH" not in os.environ:
        good = [p for v, p in find_libllvm() if v >= MIN_LLVM_MAJOR]
        if good:
            os.environ["DRJIT_LIBLLVM_PATH"] = str(good[0])
    import drjit as dr
    import mitsuba as mi

    try:
        llvm = tuple(dr.detail.llvm_version()) if dr.has_backend(dr.JitBackend.LLVM) else None
    except Exception:  # noqa: BLE001 - no usable LLVM backend at all
        llvm = None
    variant, notice = choose_variant(requested, available=list(mi.variants()), llvm_version=llvm, cuda=_has_cuda(dr))
    if notice:
        _notice(notice)
    mi.set_variant(variant)
    return variant


def _has_cuda(dr) -> bool:
    if not os.path.exists("/dev/nvidiactl"):
        return False
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001
        return False


def _is_jit(variant: str) -> bool:
    return variant.startswith(("llvm_", "cuda_"))


def _pad_factor(c_px: float, size: int, scale: int) -> tuple[int, int, float]:
    """Fine-pixel padding (left, total) that centres principal point ``c_px`` at upsampling
    ``scale``, and the principal point actually realised (OpenCV px of the original grid)."""
    a = round(2 * scale * (c_px + 0.5)) - 1  # 2 * realised centre, in fine pixels
    half = max((a + 1) / 2, (2 * scale * size - 1 - a) / 2)
    total = int(round(2 * half))
    left = int(round(half - (a + 1) / 2))
    realised = ((a / 2) + 0.5) / scale - 0.5
    return left, total, realised


def projector_texture(drive: np.ndarray, projector: Intrinsics) -> tuple[np.ndarray, float, Intrinsics]:
    """Texture and field of view for Mitsuba's ``projector`` emitter.

    Mitsuba's projector is a centred frustum; an off-centre principal point is modelled by
    padding the pattern with black (and, if the offset is not on the half-pixel grid, by
    nearest-neighbour upsampling by 2 first, which keeps DMD pixels sharp).

    Parameters
    ----------
    drive : ndarray, shape (H, W, 3), float32
        Linear projector drive in [0, 1] (what the DMD emits per channel).
    projector : Intrinsics

    Returns
    -------
    texture : ndarray, shape (H', W', 3), float32
    fov_x_deg : float
    realised : Intrinsics
        The projector as rendered (principal point snapped to the 1/4-px grid at worst).
    """
    h, w = projector.size_hw
    if drive.shape != (h, w, 3):
        raise ValueError(f"pattern shape {drive.shape} does not match the projector {(h, w, 3)}")
    scale, (lx, tx), (ly, ty), realised = _padding(projector)
    tex = drive
    if scale > 1:
        tex = np.repeat(np.repeat(tex, scale, axis=0), scale, axis=1)
    if (tx, ty) != (w * scale, h * scale):
        out = np.zeros((ty, tx, 3), dtype=np.float32)
        out[ly : ly + h * scale, lx : lx + w * scale] = tex
        tex = out
    fov = float(np.degrees(2 * np.arctan(tx / (2.0 * scale * projector.focal_px))))
    return np.ascontiguousarray(tex, dtype=np.float32), fov, realised


def _padding(projector: Intrinsics) -> tuple[int, tuple[int, int], tuple[int, int], Intrinsics]:
    """Upsampling factor, (left, total) padding along x and y, and the realised projector."""
    h, w = projector.size_hw
    best = None
    for scale in (1, 2):
        lx, tx, cx = _pad_factor(projector.cx_px, w, scale)
        ly, ty, cy = _pad_factor(projector.cy_px, h, scale)
        err = max(abs(cx - projector.cx_px), abs(cy - projector.cy_px))
        if best is None or err < best[0] - 1e-9:
            best = (err, scale, (lx, tx), (ly, ty), cx, cy)
    _, scale, pad_x, pad_y, cx, cy = best
    return scale, pad_x, pad_y, Intrinsics(projector.width_px, projector.height_px, projector.focal_px, cx, cy, projector.distortion)


def realised_rig(rig: Rig) -> Rig:
    """The rig as Mitsuba renders it (projector principal point on the padding grid)."""
    realised = _padding(rig.projector)[3]
    if realised == rig.projector:
        return rig
    return Rig(rig.camera, realised, rig.position_m, rig.rotation_deg, rig.name)


def _look_at_z(mi, position) -> object:
    pos = [float(x) for x in position]
    return mi.ScalarTransform4f().look_at(origin=pos, target=[pos[0], pos[1], pos[2] + 1.0], up=[0, -1, 0])


def _pose(mi, rig: Rig) -> object:
    m = np.eye(4)
    # Mitsuba's camera frame with look_at(up=-y) is OpenCV's (x right, y down, z forward).
    m[:3, :3] = rig.rotation
    m[:3, 3] = rig.position_m
    return mi.ScalarTransform4f(m.tolist()) @ _look_at_z(mi, (0, 0, 0))


# Mitsuba 3's sample generators (plugin reference, "Samplers"): independent = uniform random;
# stratified = jittered strata (sample count rounded to a square per dimension); multijitter =
# correlated multi-jittered (Kensler 2013); orthogonal = orthogonal array-based Latin
# hypercube (sample count a prime squared); ldsampler = low-discrepancy (0,2)-sequence
# (a square power of two: 4, 16, 64 ...).  We accept a count only where Mitsuba would not silently change it.
SAMPLERS = ("independent", "stratified", "multijitter", "orthogonal", "ldsampler")
# The run default, from measurement (results/render_noise.md, `simbench reproduce render_noise`):
# on the white board under the `paper` sensor, the cheapest setting whose render-noise depth
# spread stays at most 1/3 of the camera-noise one with a 10 % margin (0.28 measured).
# Independent sampling would need ~150-190 spp for it (1.02 at 16 spp, falling as 1/sqrt(spp)).
DEFAULT_SAMPLER = "multijitter"
DEFAULT_SPP = 36


def check_sampler(sampler: str, spp: int) -> None:
    """ValueError unless Mitsuba renders exactly ``spp`` samples per pixel with ``sampler``."""
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; valid: {list(SAMPLERS)}")
    root = math.isqrt(int(spp))
    if sampler in ("stratified", "multijitter") and root * root != spp:
        raise ValueError(f"the {sampler} sampler needs a square sample count (4, 9, 16, 25 ...), got {spp}")
    if sampler == "orthogonal" and not (root * root == spp and _is_prime(root)):
        raise ValueError(f"the orthogonal sampler needs a sample count that is a prime squared (4, 9, 25, 49 ...), got {spp}")
    if sampler == "ldsampler" and (spp & (spp - 1) or root * root != spp):
        raise ValueError(f"the ldsampler needs a sample count that is a square power of two (4, 16, 64, 256 ...), got {spp}")


def _is_prime(n: int) -> bool:
    return n >= 2 and all(n % k for k in range(2, math.isqrt(n) + 1))


def mitsuba_scene(scene: SceneSpec, drive: np.ndarray | None, *, spp: int, max_depth: int, sampler: str = "independent") -> tuple[dict, Rig]:
    """Mitsuba scene dictionary: camera, projector emitter with the pattern, objects, ambient.

    ``drive=None`` leaves out the projector (the ambient light alone, or geometry only).
    ``sampler`` is one of :data:`SAMPLERS` (Mitsuba's sample generators).
    Returns the dictionary and the rig as rendered (see :func:`projector_texture`).
    """
    import mitsuba as mi

    if spp < 1 or int(spp) != spp:
        raise ValueError(f"spp must be a positive integer, got {spp}")
    check_sampler(sampler, spp)
    rig = scene.rig
    cam = rig.camera
    d: dict = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth)},
        "sensor": {
            "type": "perspective",
            "fov": cam.fov_x_deg,
            "fov_axis": "x",
            # Mitsuba measures the offset in image widths/heights, positive moving the
            # principal point towards -x/-y (checked by tests/test_render.py).
            "principal_point_offset_x": ((cam.width_px - 1) / 2.0 - cam.cx_px) / cam.width_px,
            "principal_point_offset_y": ((cam.height_px - 1) / 2.0 - cam.cy_px) / cam.height_px,
            "near_clip": 1e-3,
            "far_clip": 1e3,
            "to_world": _look_at_z(mi, (0, 0, 0)),
            "film": {
                "type": "hdrfilm",
                "width": cam.width_px,
                "height": cam.height_px,
                "rfilter": {"type": "box"},
                "pixel_format": "rgb",
                "component_format": "float32",
            },
            "sampler": {"type": sampler, "sample_count": int(spp)},
        },
    }
    if scene.camera_lens is not None and drive is not None:
        # Mitsuba's thin lens has no principal-point offset
        if d["sensor"]["principal_point_offset_x"] or d["sensor"]["principal_point_offset_y"]:
            raise ValueError(f"scene {scene.name!r}: camera defocus (thin lens) needs a centred camera principal point, got ({cam.cx_px}, {cam.cy_px})")
        aperture_radius_m, focus_m = scene.camera_lens
        s = d["sensor"]
        del s["principal_point_offset_x"], s["principal_point_offset_y"]
        s.update(type="thinlens", aperture_radius=float(aperture_radius_m), focus_distance=float(focus_m))
    if drive is not None:
        tex, fov_p, _ = projector_texture(drive, rig.projector)
        d["projector"] = {
            "type": "projector",
            "fov": fov_p,
            "scale": float(scene.projector_scale),
            "to_world": _pose(mi, rig),
            "irradiance": {
                "type": "bitmap",
                "bitmap": mi.Bitmap(tex),
                "raw": True,
                "filter_type": "nearest",
                "wrap_mode": "clamp",
            },
        }
    if max(scene.ambient_rgb) > 0:
        d["ambient"] = {"type": "constant", "radiance": {"type": "rgb", "value": list(scene.ambient_rgb)}}
    for i, obj in enumerate(scene.objects):
        d[f"obj{i:03d}"] = object_to_mitsuba(obj, key=f"obj{i:03d}")
    return d, realised_rig(rig)


def render_radiance(scene: SceneSpec, drive: np.ndarray | None, *, spp: int, seed: int, max_depth: int = 6, sampler: str = "independent") -> np.ndarray:
    """Path-traced radiance reaching the camera, lit by the projector showing ``drive`` and by
    the scene's ambient light.

    Light adds linearly, and a path tracer choosing between two emitters per sample spends
    half its samples on each: render the projector and the ambient light separately (a scene
    with no ambient light, and ``drive=None``) and add the images, as
    :func:`simbench.simulate.render_channels` does.

    Parameters
    ----------
    drive : ndarray, shape (Hp, Wp, 3), float32 in [0, 1], or None
        Linear projector output per channel (after the projector's transfer curve); None =
        projector off.
    spp, seed : int
        Samples per pixel and the sampler seed (same seed, same image: bit-identical in llvm).
    max_depth : int
        Path length limit (>= 3 gives one interreflection bounce).
    sampler : str
        One of :data:`SAMPLERS`.

    Returns
    -------
    ndarray, shape (H, W, 3), float32, linear radiance (pattern value 1 on a white
    Lambertian plane facing the projector at 1 m gives radiance ``scale``).
    """
    import mitsuba as mi

    d, _ = mitsuba_scene(scene, drive, spp=spp, max_depth=max_depth, sampler=sampler)
    img = mi.render(_load(mi, d, scene), seed=int(seed), spp=int(spp))
    return np.array(img, dtype=np.float32)


def _load(mi, d: dict, scene: SceneSpec):
    """``mi.load_dict`` with Mitsuba's loader errors (a malformed mesh file, say) turned into
    a one-line ``ValueError`` naming the scene object."""
    # optimize=False: Mitsuba's optimiser merges meshes sharing a material into one shape,
    # which loses per-object ids and fails outright for meshes with different attributes
    # (a cube next to a PLY mesh).
    try:
        return mi.load_dict(d, optimize=False)
    except RuntimeError as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        for i, obj in enumerate(scene.objects):
            msg = msg.replace(f'"obj{i:03d}"', f"object {obj.name!r}")
        raise ValueError(f"scene {scene.name!r}: Mitsuba could not load it: {msg}") from None


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
    """

    depth_m: np.ndarray
    column_px: np.ndarray
    object_id: np.ndarray
    lit: np.ndarray

    @property
    def seen(self) -> np.ndarray:
        return self.object_id >= 0


def ground_truth(scene: SceneSpec) -> GroundTruth:
    """Cast one ray through every camera pixel centre with Mitsuba and project the hits."""
    import mitsuba as mi

    d, rig = mitsuba_scene(scene, None, spp=1, max_depth=1)
    mscene = _load(mi, d, scene)
    rays = pixel_rays(rig.camera)
    h, w = rays.shape[:2]
    dirs = (rays / np.linalg.norm(rays, axis=-1, keepdims=True)).reshape(-1, 3).astype(np.float32)
    proj_pos = np.asarray(rig.position_m)
    key_to_index = {f"obj{i:03d}": i for i in range(len(scene.objects))}
    if _is_jit(mi.variant()):
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
    mscene = _load(mi, d, scene)
    unit = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    key_to_index = {f"obj{i:03d}": i for i in range(len(scene.objects))}
    trace = _trace_vectorised if _is_jit(mi.variant()) else _trace_scalar
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
    mscene = _load(mi, d, scene)
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
    if _is_jit(mi.variant()):
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
