"""Path-traced renders of a scene lit by the projector (Mitsuba 3).

Nothing here imports Dr.Jit or Mitsuba at module import time: select the variant first
(:func:`simbench.variant.select_variant`, at an entry point).
"""

from __future__ import annotations

import numpy as np

from simbench.sim.mitsuba_dict import atomic_film_adds, jit_arithmetic, load_scene_dict, mitsuba_scene
from simbench.sim.scene import SceneSpec

__all__ = ["render_radiance"]


def render_radiance(
    scene: SceneSpec, drive: np.ndarray | None, *, spp: int, seed: int, max_depth: int = 6, sampler: str = "independent"
) -> np.ndarray:
    """Path-traced radiance reaching the camera, lit by the projector showing ``drive`` and by
    the scene's ambient light.

    Light adds linearly, and a path tracer choosing between two emitters per sample spends
    half its samples on each: render the projector and the ambient light separately (a scene
    with no ambient light, and ``drive=None``) and add the images, as
    :func:`simbench.sim.capture.render_channels` does.

    Parameters
    ----------
    drive : ndarray, shape (Hp, Wp, 3), float32 in [0, 1], or None
        Linear projector output per channel (after the projector's transfer curve); None =
        projector off.
    spp, seed : int
        Samples per pixel and the sampler seed (same seed, same image: bit-identical in llvm,
        where a count other than a power of two is rendered in passes,
        :func:`simbench.sim.mitsuba_dict.samples_per_pass`, and the film takes atomic adds,
        :func:`simbench.sim.mitsuba_dict.atomic_film_adds`).
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
    level = mi.log_level()
    if "samples_per_pass" in d["integrator"]:
        # Mitsuba warns that the setting is deprecated (passes cost time; here they are what
        # makes the image repeatable) and that a multi-pass render is evaluated at once
        mi.set_log_level(mi.LogLevel.Error)
    try:
        with atomic_film_adds(), jit_arithmetic():
            img = mi.render(load_scene_dict(mi, d, scene), seed=int(seed), spp=int(spp))
        return np.array(img, dtype=np.float32)
    finally:
        mi.set_log_level(level)
