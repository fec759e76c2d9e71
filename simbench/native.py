"""simbench's compiled loops (``simbench/_ckernels.c``, ``simbench/_lens.c``): loading, argument
checks, provenance.

The C files are built into the package when it is installed (``pip install -e .``, which
``make setup`` runs; a C compiler is needed) and loaded here with :mod:`ctypes`, which releases
the GIL around every call, so threads run the loops in parallel.  It is compiled without fused
multiply-add or reassociation (``pyproject.toml``), so every loop gives the bits of the numpy
expression it replaces, on any machine.  Loading costs about a millisecond.

The modules that call a loop (:mod:`simbench.decode._kernels`, :mod:`simbench.optics`) declare
its C signature with :func:`bind` and pass arrays through :func:`ptr`, which checks dtype, shape,
C-contiguity and writability first: a mismatch raises instead of reading stray memory.  This
module is the lowest layer: it imports nothing of simbench.
"""

from __future__ import annotations

import ctypes
import importlib.util
import re
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = ["SOURCE", "LENS_SOURCE", "SOURCES", "bind", "ptr", "f32", "compiler", "stale_sources"]

# the decoder's loops, the triangulation and the plane fit
SOURCE = Path(__file__).with_name("_ckernels.c")
# the lens model's remap grids: the only loops between a scene and a recording
LENS_SOURCE = Path(__file__).with_name("_lens.c")
# every C source of the one library, in name order
SOURCES = (SOURCE, LENS_SOURCE)

P = ctypes.c_void_p
I64 = ctypes.c_int64
F32 = ctypes.c_float
F64 = ctypes.c_double


def _built_file() -> str:
    spec = importlib.util.find_spec("simbench._ckernels")
    if spec is None or spec.origin is None:
        raise ImportError(
            "simbench's compiled loops (simbench/_ckernels.c, _lens.c) are not built: "
            "run `make setup` (or `pip install -e .`; it needs a C compiler)"
        )
    stale = stale_sources(Path(spec.origin))
    if stale:
        # a loop whose C signature changed would read its arguments from the old one's places
        raise ImportError(
            f"simbench's compiled loops ({Path(spec.origin).name}) are older than {', '.join(stale)}: "
            "rebuild them with `make setup` (or `pip install -e .`)"
        )
    return spec.origin


def stale_sources(built: Path, sources: tuple[Path, ...] = SOURCES) -> list[str]:
    """The names of ``sources`` changed after ``built`` was made (by modification time), where
    they are at hand (an installed package may not ship them)."""
    made = built.stat().st_mtime
    return [s.name for s in sources if s.is_file() and s.stat().st_mtime > made]


@lru_cache(maxsize=1)
def _cdll() -> ctypes.CDLL:
    return ctypes.CDLL(_built_file())


def bind(signatures: dict[str, tuple]) -> ctypes.CDLL:
    """The library with the C signatures ``{name: (restype, [argtypes])}`` declared."""
    lib = _cdll()
    for name, (restype, argtypes) in signatures.items():
        fn = getattr(lib, name)
        fn.restype = restype
        fn.argtypes = argtypes
    return lib


def ptr(a: np.ndarray, name: str, dtype: np.dtype | type, shape: tuple | None = None, *, writable: bool = False) -> int:
    """The data address of ``a`` after checking what the C function assumes of it."""
    if not isinstance(a, np.ndarray):
        raise TypeError(f"{name}: expected an ndarray, got {type(a).__name__}")
    if a.dtype != dtype:
        raise TypeError(f"{name}: expected dtype {np.dtype(dtype)}, got {a.dtype}")
    if not a.flags.c_contiguous:
        raise ValueError(f"{name}: must be C-contiguous")
    if shape is not None and a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")
    if writable and not a.flags.writeable:
        raise ValueError(f"{name}: must be writable")
    return a.ctypes.data


def f32(x: float) -> float:
    """``x`` rounded to float32 (as numpy rounds a Python float compared with a float32 image),
    for a C ``float`` argument."""
    return float(np.float32(x))


def compiler() -> str:
    """The compiler that built the loops, as it signed the shared library (``.comment``
    section, e.g. ``GCC: (Debian 12.2.0-14) 12.2.0``), for provenance; "unknown" if unsigned."""
    data = Path(_built_file()).read_bytes()
    found = re.findall(rb"(GCC: \([^\x00]*\) [^\x00]+|clang version [^\x00]+)", data)
    return found[0].decode(errors="replace").strip() if found else "unknown"
