"""Which Mitsuba variant renders here: libLLVM discovery and the variant choice.

Nothing here imports Dr.Jit or Mitsuba at module import time: Dr.Jit binds a libLLVM when it is
first imported, so :func:`select_variant` must run first (at an entry point) to steer it.
"""

from __future__ import annotations

import glob
import logging
import os
import re
import sys
from pathlib import Path

from simbench.threads import THREADS_VARIABLE, apply_threads, process_threads

__all__ = ["MIN_LLVM_MAJOR", "find_libllvm", "choose_variant", "select_variant", "is_jit"]

log = logging.getLogger(__name__)

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
        # simbench renders three primaries as RGB channels (spectral and polarised variants
        # return other layouts); a CUDA variant needs a GPU, an LLVM one libLLVM
        usable = [
            v
            for v in available
            if v.endswith("_rgb") and (cuda or not v.startswith("cuda_")) and (llvm_ok or not v.startswith("llvm_"))
        ]
        if requested.startswith("cuda_") and not cuda:
            raise ValueError(f"variant {requested} needs a CUDA GPU, and none is usable here; usable here: {usable}")
        if not requested.endswith("_rgb"):
            raise ValueError(f"variant {requested}: simbench renders in an RGB variant; usable here: {usable}")
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
        log.warning(notice)
    try:
        mi.set_variant(variant)
    except (ImportError, RuntimeError, AttributeError) as exc:
        msg = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise ValueError(f"Mitsuba variant {variant} cannot be used here ({msg}); use --variant scalar_rgb") from None
    if os.environ.get(
        THREADS_VARIABLE, ""
    ).strip():  # a process's share of the machine (a pool's worker, or the user's)
        apply_threads(process_threads())
    return variant


def _has_cuda(dr) -> bool:
    if not os.path.exists("/dev/nvidiactl"):
        return False
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001
        return False


def is_jit(variant: str) -> bool:
    return variant.startswith(("llvm_", "cuda_"))
