"""Scene specs as Mitsuba scene dictionaries: the projector emitter's texture and padding, the
camera and projector poses, the sampler settings, and loading.

Nothing here imports Mitsuba at module import time (:mod:`simbench.variant`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from types import ModuleType

import numpy as np

from simbench.cache import RenderCache
from simbench.rig import Intrinsics, Rig
from simbench.sim.scene import SceneSpec, object_to_mitsuba

# the camera's near clipping distance (Mitsuba's default is 0.01 m; a millimetre lets a scene put
# a surface close to the lens): nearer points are not seen
CAMERA_NEAR_CLIP_M = 1e-3

__all__ = [
    "projector_texture",
    "realised_rig",
    "SAMPLERS",
    "DEFAULT_SAMPLER",
    "DEFAULT_SPP",
    "check_sampler",
    "AMBIENT_SPP_DIVISOR",
    "ambient_spp",
    "samples_per_pass",
    "pass_settings",
    "film_settings",
    "atomic_film_adds",
    "FILM_CHANNELS",
    "RenderSettings",
    "mitsuba_scene",
    "load_scene_dict",
]


def _pad_factor(c_px: float, size: int, scale: int) -> tuple[int, int, float]:
    """Fine-pixel padding (left, total) that centres principal point ``c_px`` at upsampling
    ``scale``, and the principal point actually realised (OpenCV px of the original grid)."""
    a = round(2 * scale * (c_px + 0.5)) - 1  # 2 * realised centre, in fine pixels
    half = max((a + 1) / 2, (2 * scale * size - 1 - a) / 2)
    total = int(round(2 * half))
    left = int(round(half - (a + 1) / 2))
    realised = ((a / 2) + 0.5) / scale - 0.5
    return left, total, realised


# the last texture made from a read-only drive: (drive, projector, result).  A moving capture
# renders the same drive in every time slice (the Kinect's dot pattern); the upsampling and padding
# were ~25 ms a slice.  Only a read-only drive is reused, by identity (held here, so that its id
# cannot pass to another array), since a writable one could change under the same object.
_LAST_TEXTURE: tuple = ()
# ... and the mi.Bitmap made of that texture: (texture, bitmap).  mi.Bitmap copies its array (the
# Kinect's 1980x2532 dot texture: 35-45 ms a time slice); Mitsuba's loader only reads it.
_LAST_BITMAP: tuple = ()


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
    global _LAST_TEXTURE
    if drive.flags.writeable:
        return _texture(drive, projector)
    last = _LAST_TEXTURE  # one read: another thread may replace it
    if last and last[0] is drive and last[1] == projector:
        return last[2]
    result = _texture(drive, projector)
    _LAST_TEXTURE = (drive, projector, result)
    return result


def _texture(drive: np.ndarray, projector: Intrinsics) -> tuple[np.ndarray, float, Intrinsics]:
    h, w = projector.size_hw
    scale, (lx, tx), (ly, ty), realised = _padding(projector)
    tex = drive
    if scale > 1:
        tex = np.repeat(np.repeat(tex, scale, axis=0), scale, axis=1)
    if (tx, ty) != (w * scale, h * scale):
        out = np.zeros((ty, tx, 3), dtype=np.float32)
        out[ly : ly + h * scale, lx : lx + w * scale] = tex
        tex = out
    fov = float(np.degrees(2 * np.arctan(tx / (2.0 * scale * projector.focal_px))))
    tex = np.ascontiguousarray(tex, dtype=np.float32)
    # mi.Bitmap takes writable arrays only (a read-only drive passes through unpadded)
    return (tex if tex.flags.writeable else tex.copy()), fov, realised


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
    return (
        scale,
        pad_x,
        pad_y,
        Intrinsics(projector.width_px, projector.height_px, projector.focal_px, cx, cy, projector.distortion),
    )


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
# spread stayed at most 1/3 of the camera-noise one with a 10 % margin (0.28 measured on
# 2026-11-23, the renders recorded noise-free, which reads a sub-DN render noise too large).
# Recorded with the camera's noise on (2026-12-05) it is 0.22, and `orthogonal` at 25 spp (0.24)
# meets the margin too; the default stays: the binding scenes are those lit by each other, up
# to 1.6x the camera's noise at 36 spp (results/hard_scenes.md), and a change re-renders all.
# Independent sampling would need ~150-190 spp for it (1.01 at 16 spp, falling as 1/sqrt(spp)).
DEFAULT_SAMPLER = "multijitter"
DEFAULT_SPP = 36
# The ambient light's renders take a quarter of the projector renders' samples.  The ambient light
# is 2 % of the projector's white (assumption: paper.toml [ambient]) and smooth, so its sampling
# noise is small beside the camera's: measured on scenes/sphere.toml under the `paper` sensor
# (tests/test_physics_renders.py), its render at 9 spp adds 0.7-1.5 % to the lit pixels' noise
# variance (36 spp: a quarter of that), and a full-resolution ambient render takes 2.2-3.4 s
# instead of 9.2-10.0 s (2 cores) in every scene that is not one diffuse object filling the view
# (there the ambient light is a constant and is not rendered: simbench.sim.capture.uniform_ambient).
AMBIENT_SPP_DIVISOR = 4


@dataclass(frozen=True)
class RenderSettings:
    """How a scene is rendered: samples per pixel, Mitsuba sampler, path length, and the render
    cache renders are looked up in and stored to (None: none)."""

    spp: int
    sampler: str
    max_depth: int = 6
    cache: RenderCache | None = None


def check_sampler(sampler: str, spp: int) -> None:
    """ValueError unless Mitsuba renders exactly ``spp`` samples per pixel with ``sampler``."""
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r}; valid: {list(SAMPLERS)}")
    root = math.isqrt(int(spp))
    if sampler in ("stratified", "multijitter") and root * root != spp:
        raise ValueError(f"the {sampler} sampler needs a square sample count (4, 9, 16, 25 ...), got {spp}")
    if sampler == "orthogonal" and not (root * root == spp and _is_prime(root)):
        raise ValueError(
            f"the orthogonal sampler needs a sample count that is a prime squared (4, 9, 25, 49 ...), got {spp}"
        )
    if sampler == "ldsampler" and (spp & (spp - 1) or root * root != spp):
        raise ValueError(
            f"the ldsampler needs a sample count that is a square power of two (4, 16, 64, 256 ...), got {spp}"
        )


def ambient_spp(spp: int, sampler: str) -> int:
    """Samples per pixel of an ambient-light render made beside projector renders of ``spp``:
    the largest count ``sampler`` accepts (:func:`check_sampler`) that is at most
    ``spp // AMBIENT_SPP_DIVISOR`` and at least 1; ``spp`` itself where the sampler accepts none
    (the orthogonal sampler at 4 and 9 spp)."""
    for n in range(max(1, int(spp) // AMBIENT_SPP_DIVISOR), 0, -1):
        try:
            check_sampler(sampler, n)
        except ValueError:
            continue
        return n
    return int(spp)


# Dr.Jit's LLVM backend runs a kernel over the sample wavefront (pixels x samples per pass, a
# pixel's samples adjacent) in work units of 16384 lanes, or, for a wavefront of at most
# 16384 x 2 x threads lanes, in units of a multiple of the SIMD packet (>= 4 lanes on every
# LLVM target).  A pixel whose samples straddle two units gets them added into the film by two
# threads in either order: a different last bit from run to run (measured here: 18-81 values of
# a 1280x960 plane at 36 spp differ between two renders with the same seed; none at 16 or 64).
# Passes whose sample count divides every unit keep each pixel in one unit; Mitsuba adds the
# passes in order, and the sampler's stratification spans all passes (its sample index is
# pass x samples per pass + lane).
_LLVM_BLOCK_LANES = 16384
_MIN_PACKET_LANES = 4
_MAX_THREADS = 128  # the one-unit-size bound below holds up to this many render threads


def samples_per_pass(spp: int, *, pixels: int) -> int:
    """Samples per pixel per wavefront pass that give the same image on every run of a JIT
    (``llvm_*``) variant: all ``spp`` at once when a power of two on a wavefront large enough
    for 16384-lane work units; otherwise the largest power of two dividing ``spp``, at most 4
    (36 -> 4, 9 passes; 25 -> 1; small test renders at 16 -> 4).  Costs ~20 % of a 36-spp
    render (a plane 2.25 -> 2.77 s, the bust 5.1 -> 6.05 s, measured on 2 cores)."""
    spp, pixels = int(spp), int(pixels)
    pow2 = spp & -spp  # the largest power of two dividing spp
    if pow2 == spp and pixels * spp > _LLVM_BLOCK_LANES * 2 * _MAX_THREADS:
        return spp
    return min(pow2, _MIN_PACKET_LANES)


def _is_prime(n: int) -> bool:
    return n >= 2 and all(n % k for k in range(2, math.isqrt(n) + 1))


def pass_settings(spp: int, *, pixels: int) -> dict:
    """The path integrator's ``samples_per_pass`` where :func:`samples_per_pass` needs more
    than one pass, else nothing (JIT variants only: the scalar variant renders each pixel on one
    thread, and there passes would be added by the threads in either order).  Part of a render's
    cache key: the passes change the image's last bits."""
    import mitsuba as mi

    per_pass = samples_per_pass(spp, pixels=pixels)
    return {} if per_pass == spp or mi.variant().startswith("scalar") else {"samples_per_pass": per_pass}


# Dr.Jit's LLVM backend adds into a small array (at most dr.expand_threshold() entries, 2^20 by
# default) through one copy per thread, the copies summed at the end ("expand" mode): a pixel's
# value then depends on which threads took its samples.  The film of a small render (H x W x
# FILM_CHANNELS entries) is such an array: a 176x144 render (the ToF camera's) in passes of 4
# samples differed in 32000-76000 of its 76032 values between renders with one seed.  Renders
# run with the threshold at 0 (:func:`atomic_film_adds`): atomic adds, in sample order within
# a work unit, as on a large film.
FILM_CHANNELS = 4  # R, G, B and the filter weight: Mitsuba's hdrfilm, pixel_format "rgb"
_DRJIT_EXPAND_THRESHOLD = 1 << 20  # Dr.Jit's default, under which its renders expanded


@contextmanager
def atomic_film_adds() -> Iterator[None]:
    """Dr.Jit's scatter-adds into the film as atomic adds whatever the film's size (the block
    above), restored after."""
    import drjit as dr

    before = dr.expand_threshold()
    dr.set_expand_threshold(0)
    try:
        yield
    finally:
        dr.set_expand_threshold(before)


def fast_math(variant: str) -> bool:
    """Whether simbench lets Dr.Jit use fast math for ``variant``: on the GPU (``cuda_*``), not on
    the CPU (:func:`jit_arithmetic`)."""
    return variant.startswith("cuda_")


@contextmanager
def jit_arithmetic() -> Iterator[None]:
    """Dr.Jit's arithmetic for the Mitsuba work inside (scene loading, rendering, ray casting),
    on this thread, restored after: on the CPU without fast math (:func:`fast_math`), so that a
    render's bits do not depend on which x86 CPU runs it.

    With ``JitFlag.FastMath`` (Dr.Jit's default) a reciprocal square root - every vector
    normalisation: the glossy BSDFs' half vectors, shading frames - is the CPU's estimate
    instruction (``vrsqrt14`` on AVX-512) refined by one Newton step, and the estimate's bits are
    the vendor's: the same quick run gave the glossy scenes (specular, clutter,
    hard_glossy_005) up to 6e-4 of their MAE apart on an Intel Xeon and an AMD EPYC, the diffuse
    scenes the same bytes (2026-11-27).  Without it the kernels hold IEEE operations only and a
    render compiled for AVX2 alone gives the host's AVX-512 bits at the same vector width
    (``tests/test_render.py``); a 640x480 16-spp glossy scene took 0.216-0.218 s either way.  The
    packet width (16 lanes on AVX-512, 8 on AVX2) still orders the film's per-packet sums
    (``JitFlag.ScatterReduceLocal``; off, it costs ~14 % a render), so a CPU without AVX-512
    renders other last bits.  Dr.Jit keeps its flags per thread (a pool's parent runs tasks on
    a thread of its own), hence a context around the work, not a setting at start-up; the
    render keys hold the policy (:func:`simbench.sim.keys.renderer_id`)."""
    import drjit as dr
    import mitsuba as mi

    before = dr.flag(dr.JitFlag.FastMath)
    dr.set_flag(dr.JitFlag.FastMath, fast_math(mi.variant()))
    try:
        yield
    finally:
        dr.set_flag(dr.JitFlag.FastMath, before)


def film_settings(*, pixels: int) -> dict:
    """``{"film_adds": "atomic"}`` for a JIT render whose film Dr.Jit's default would have
    added into by expansion (:func:`atomic_film_adds` changed its last bits), else nothing:
    part of a render's cache key, so that such renders cached before are not reused."""
    import mitsuba as mi

    small = int(pixels) * FILM_CHANNELS <= _DRJIT_EXPAND_THRESHOLD
    return {"film_adds": "atomic"} if small and not mi.variant().startswith("scalar") else {}


def mitsuba_scene(
    scene: SceneSpec, drive: np.ndarray | None, *, spp: int, max_depth: int, sampler: str = "independent"
) -> tuple[dict, Rig]:
    """Mitsuba scene dictionary: camera, projector emitter with the pattern, objects, ambient.

    ``drive=None`` leaves out the projector (the ambient light alone, or geometry only).
    ``sampler`` is one of :data:`SAMPLERS` (Mitsuba's sample generators).
    Returns the dictionary and the rig as rendered (see :func:`projector_texture`).
    """
    import mitsuba as mi

    if spp < 1 or int(spp) != spp:
        raise ValueError(f"spp must be a positive integer, got {spp}")
    moving = [o.name for o in scene.objects if o.motion is not None]
    if moving:  # a render is one instant: the caller poses the scene (simbench.sim.timeline.scene_at)
        raise ValueError(
            f"scene {scene.name!r}: objects {moving} move; render it posed at an instant or through an exposure "
            "window (simbench.sim.capture.render_channels)"
        )
    check_sampler(sampler, spp)
    rig = scene.rig
    cam = rig.camera
    d: dict = {
        "type": "scene",
        "integrator": {
            "type": "path",
            "max_depth": int(max_depth),
            **pass_settings(spp, pixels=cam.width_px * cam.height_px),
        },
        "sensor": {
            "type": "perspective",
            "fov": cam.fov_x_deg,
            "fov_axis": "x",
            # Mitsuba measures the offset in image widths/heights, positive moving the
            # principal point towards -x/-y (checked by tests/test_render.py).
            "principal_point_offset_x": ((cam.width_px - 1) / 2.0 - cam.cx_px) / cam.width_px,
            "principal_point_offset_y": ((cam.height_px - 1) / 2.0 - cam.cy_px) / cam.height_px,
            "near_clip": CAMERA_NEAR_CLIP_M,
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
            raise ValueError(
                f"scene {scene.name!r}: camera defocus (thin lens) needs a centred camera principal point, got "
                f"({cam.cx_px}, {cam.cy_px})"
            )
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
                "bitmap": _bitmap(mi, tex),
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


def _bitmap(mi: ModuleType, tex: np.ndarray) -> object:
    """``mi.Bitmap(tex)``, the last one reused when ``tex`` is :func:`projector_texture`'s kept
    texture (made of a read-only drive, handed out as the same array for the same drive and read
    by nothing but this)."""
    global _LAST_BITMAP
    last = _LAST_BITMAP  # one read each: another thread may replace them
    if last and last[0] is tex:
        return last[1]
    bitmap = mi.Bitmap(tex)
    kept = _LAST_TEXTURE
    if kept and kept[2][0] is tex:
        _LAST_BITMAP = (tex, bitmap)
    return bitmap


def load_scene_dict(mi: ModuleType, d: dict, scene: SceneSpec) -> object:
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
