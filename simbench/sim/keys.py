"""Cache keys of the simulator's results: the renderer's identity, the code a recording or
projector drive is made by, the library versions its bits depend on, and provenance versions.

Everything the simulator caches is keyed by a SHA-256 of the values it is made from
(:class:`simbench.cache.RenderCache`) plus what is here, so a changed model, renderer or library
never reuses an older entry.
"""

from __future__ import annotations

import platform
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import numpy as np

from simbench.cache import RenderCache, source_digest

__all__ = [
    "versions",
    "renderer_id",
    "cached_arrays",
    "cpu_model",
    "sim_code_digest",
    "recording_libraries",
    "seed_key",
]


# distribution names of what provenance records (read from the installed metadata: no import,
# so nothing another package put into sys.modules, such as colour-science's stand-in for a
# missing SciPy, can break or fool the lookup)
VERSIONED_DISTRIBUTIONS = {
    "simbench": "simbench",
    "mitsuba": "mitsuba",
    "drjit": "drjit",
    "numpy": "numpy",
    # OpenCV (remaps, filters); simbench's own C loops (simbench/_lens.c, compiled at
    # install: the C compiler is recorded too)
    "opencv": "opencv-python-headless",
    "colour": "colour-science",
    "scipy": "scipy",
}


def versions() -> dict:
    """Versions of the installed packages that affect results, and of Python."""
    from importlib import metadata

    out = {}
    for key, dist in VERSIONED_DISTRIBUTIONS.items():
        try:
            out[key] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[key] = "not installed"
    out["python"] = platform.python_version()
    from simbench.native import compiler

    out["c_compiler"] = compiler()
    out["cpu"] = cpu_model()
    return out


def cpu_model(cpuinfo: str | None = None) -> str:
    """The processor's model name and, on Linux x86, its widest vector instructions (from
    ``cpuinfo``, the text of /proc/cpuinfo, read when None; elsewhere the platform's word), e.g.
    ``"AMD EPYC (AVX2)"``.  Part of provenance because results depend on it in their last digits:
    OpenCV's and numpy's SIMD code and Dr.Jit's packet width follow the instruction sets the CPU
    has, and two "AMD EPYC" models, one with AVX-512 and one without, gave 765 of the quick run's
    1830 metrics the same bits (docs/rendering.md, "Across CPUs")."""
    if cpuinfo is None:
        try:
            with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
                cpuinfo = f.read()
        except OSError:
            cpuinfo = ""
    name, flags = "", set()
    for line in cpuinfo.splitlines():
        key, _, value = line.partition(":")
        if key.strip() == "model name" and not name:
            name = value.strip()
        elif key.strip() == "flags" and not flags:
            flags = set(value.split())
        if name and flags:
            break
    name = name or platform.processor() or platform.machine() or "unknown"
    isa = next((label for flag, label in (("avx512f", "AVX-512"), ("avx2", "AVX2")) if flag in flags), None)
    if isa is None and flags:
        isa = "no AVX2"
    return f"{name} ({isa})" if isa else name


def renderer_id() -> dict:
    """The variant, the Mitsuba version and whether Dr.Jit's fast math is used for it
    (:func:`simbench.sim.mitsuba_dict.jit_arithmetic`: every render, scene load and ray cast of
    simbench runs inside it, on whatever thread) - part of every render key."""
    import mitsuba as mi

    from simbench.sim.mitsuba_dict import fast_math

    return {"variant": mi.variant(), "mitsuba": mi.__version__, "fast_math": fast_math(mi.variant())}


def cached_arrays(
    kind: str,
    parts: dict,
    make: Callable[[], dict[str, np.ndarray]],
    *,
    cache: RenderCache | None = None,
    wait: bool = True,
) -> dict[str, np.ndarray] | None:
    """``make()``'s arrays, looked up in / stored to ``cache`` under ``kind`` and ``parts``
    plus the renderer's identity (variant, Mitsuba version); ``wait=False``: None when another
    process is making them (:meth:`simbench.cache.RenderCache.get_or_make`)."""
    return make() if cache is None else cache.get_or_make(kind, {**parts, **renderer_id()}, make, wait=wait)


@lru_cache(maxsize=1)
def sim_code_digest() -> str:
    """SHA-256 of the simulator's code: every module of :mod:`simbench.sim`, the lens model
    (:mod:`simbench.optics`) and its compiled loops (``simbench/_lens.c``).  Part of the keys
    of what is derived from renders by code - recordings and projector drives - so that an edit
    anywhere in the simulator never reuses an older result (renders themselves are keyed by
    their inputs and ``RENDER_VERSION``)."""
    import simbench.native
    import simbench.optics

    here = Path(__file__).parent
    return source_digest([*sorted(here.glob("*.py")), simbench.optics.__file__, simbench.native.LENS_SOURCE])


def seed_key(rng: object) -> "int | dict | None":
    """A noise seed as cache-key data: an integer, or a SeedSequence by what its streams are
    drawn from (entropy, spawn key, pool size); None for anything else (a Generator's state
    moves on as it draws)."""
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool):
        return int(rng)
    if isinstance(rng, np.random.SeedSequence):
        entropy = rng.entropy
        return {
            "entropy": [int(e) for e in entropy] if isinstance(entropy, (list, tuple, np.ndarray)) else int(entropy),
            "spawn_key": [int(k) for k in rng.spawn_key],
            "pool_size": int(rng.pool_size),
        }
    return None


@lru_cache(maxsize=1)
def recording_libraries() -> dict:
    """The libraries whose algorithms or data a recording's bits depend on: numpy (the noise
    draws), OpenCV (demosaicing, remapping), colour-science (the crosstalk of the primaries'
    renders; its version read without importing it)."""
    from importlib import metadata

    import cv2

    try:
        colour = metadata.version("colour-science")
    except metadata.PackageNotFoundError:
        colour = "not installed"
    return {"numpy": np.__version__, "opencv": cv2.__version__, "colour-science": colour}
