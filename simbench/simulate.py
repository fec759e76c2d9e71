"""One simulated acquisition: pattern -> scene render -> camera, for a scene and its reference.

Seeds: one base seed is split with ``numpy.random.SeedSequence`` into the capture's render seed,
the reference's render seed and the two camera-noise seeds; all four are recorded.
"""

from __future__ import annotations

import dataclasses
import platform
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from simbench.cache import RenderCache, array_digest, scene_fingerprint
from simbench.io import save_exr, save_json, save_npy, save_png
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.render import GroundTruth, ground_truth, realised_rig, render_radiance
from simbench.rig import save_rig
from simbench.scene import SceneSpec, reference_scene
from simbench.sensor import SimpleCamera, project_drive, simple_camera

__all__ = ["Acquisition", "split_seed", "cached_radiance", "cached_ground_truth", "acquire", "write_acquisition", "versions"]

REFERENCE_ALBEDO = 0.8  # assumption: a matte white board as the reference plane


def split_seed(seed: int) -> dict[str, int]:
    """Four independent 32-bit seeds from one base seed."""
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    kids = np.random.SeedSequence(int(seed)).spawn(4)
    names = ("render_capture", "render_reference", "noise_capture", "noise_reference")
    return {n: int(k.generate_state(1)[0]) for n, k in zip(names, kids)}


@dataclass(frozen=True)
class Acquisition:
    """A capture, its reference-plane capture, ground truth and everything to reproduce them."""

    scene: SceneSpec
    pattern: np.ndarray  # (Hp, Wp, 3) uint8, what the projector is sent
    capture: np.ndarray  # (H, W, 3) recorded image
    reference: np.ndarray  # (H, W, 3) recorded image of the reference plane
    gt: GroundTruth
    meta: dict = field(default_factory=dict)


def versions() -> dict:
    import drjit
    import mitsuba

    import simbench

    return {
        "simbench": simbench.__version__,
        "mitsuba": mitsuba.__version__,
        "drjit": drjit.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def _renderer_id() -> dict:
    import mitsuba as mi

    return {"variant": mi.variant(), "mitsuba": mi.__version__}


def cached_radiance(scene: SceneSpec, drive: np.ndarray, *, spp: int, seed: int, max_depth: int, cache: RenderCache | None = None) -> np.ndarray:
    """:func:`simbench.render.render_radiance`, looked up in / stored to ``cache``."""
    if cache is None:
        return render_radiance(scene, drive, spp=spp, seed=seed, max_depth=max_depth)
    parts = {"scene": scene_fingerprint(scene), "drive": array_digest(drive), "spp": int(spp), "seed": int(seed), "max_depth": int(max_depth), **_renderer_id()}
    return cache.get_or_make("radiance", parts, lambda: {"radiance": render_radiance(scene, drive, spp=spp, seed=seed, max_depth=max_depth)})["radiance"]


def cached_ground_truth(scene: SceneSpec, *, cache: RenderCache | None = None) -> GroundTruth:
    """:func:`simbench.render.ground_truth`, looked up in / stored to ``cache``."""
    if cache is None:
        return ground_truth(scene)

    def make() -> dict:
        gt = ground_truth(scene)
        return {"depth_m": gt.depth_m, "column_px": gt.column_px, "object_id": gt.object_id, "lit": gt.lit}

    arrays = cache.get_or_make("truth", {"scene": scene_fingerprint(scene), **_renderer_id()}, make)
    return GroundTruth(**arrays)


def acquire(
    scene: SceneSpec,
    *,
    pattern: PatternSpec,
    camera: SimpleCamera,
    spp: int,
    seed: int,
    max_depth: int = 6,
    with_reference: bool = True,
    cache: RenderCache | None = None,
) -> Acquisition:
    """Render and record a scene (and its reference plane) lit by the pattern.

    A Mitsuba variant must already be selected (:func:`simbench.render.select_variant`).
    Renders and ground truth come from ``cache`` when it holds them.
    """
    import mitsuba as mi

    rig = realised_rig(scene.rig)
    if rig != scene.rig:
        print(
            f"simbench: projector principal point rendered at ({rig.projector.cx_px}, {rig.projector.cy_px}) "
            f"instead of ({scene.rig.projector.cx_px}, {scene.rig.projector.cy_px}); rig.toml records the rendered one",
            file=sys.stderr,
        )
        scene = dataclasses.replace(scene, rig=rig)
    if tuple(pattern.size_hw) != scene.rig.projector.size_hw:
        raise ValueError(f"pattern size {pattern.size_hw} differs from the projector's {scene.rig.projector.size_hw}")
    seeds = split_seed(seed)
    pat = quantize(fringe_pattern(pattern))
    drive = project_drive(pat)
    rad = cached_radiance(scene, drive, spp=spp, seed=seeds["render_capture"], max_depth=max_depth, cache=cache)
    capture = simple_camera(rad, camera=camera, rng=seeds["noise_capture"])
    reference = np.zeros_like(capture)
    if with_reference:
        ref_scene = reference_scene(scene, albedo=REFERENCE_ALBEDO)
        ref_rad = cached_radiance(ref_scene, drive, spp=spp, seed=seeds["render_reference"], max_depth=max_depth, cache=cache)
        reference = simple_camera(ref_rad, camera=camera, rng=seeds["noise_reference"])
    gt = cached_ground_truth(scene, cache=cache)
    meta = {
        "scene": scene.name,
        "pattern": {"size_hw": list(pattern.size_hw), "period_px": pattern.period_px, "order": pattern.order, "sequence": pattern.codes().tolist(), "dc": pattern.dc, "amplitude": pattern.amplitude},
        "camera": {k: getattr(camera, k) for k in ("exposure", "full_well_e", "read_noise_e", "bits", "noise")},
        "spp": int(spp),
        "max_depth": int(max_depth),
        "seed": int(seed),
        "seeds": seeds,
        "reference_depth_m": scene.reference_depth_m,
        "reference_albedo": REFERENCE_ALBEDO,
        "variant": mi.variant(),
        "versions": versions(),
    }
    return Acquisition(scene=scene, pattern=pat, capture=capture, reference=reference, gt=gt, meta=meta)


def write_acquisition(acq: Acquisition, out_dir: str | Path) -> dict[str, Path]:
    """Write an acquisition as the files of ``simbench render`` (all writes atomic)."""
    out = Path(out_dir)
    files = {
        "capture": save_png(out / "capture.png", acq.capture),
        "reference": save_png(out / "reference.png", acq.reference),
        "gt_depth": save_npy(out / "gt_depth.npy", acq.gt.depth_m),
        "gt_depth_exr": save_exr(out / "gt_depth.exr", acq.gt.depth_m),
        "gt_column": save_npy(out / "gt_column.npy", acq.gt.column_px),
        "gt_lit": save_npy(out / "gt_lit.npy", acq.gt.lit),
        "gt_object_id": save_npy(out / "gt_object_id.npy", acq.gt.object_id),
        "rig": save_rig(acq.scene.rig, out / "rig.toml"),
    }
    files["meta"] = save_json(out / "meta.json", {**acq.meta, "files": {k: v.name for k, v in files.items()}})
    return files
