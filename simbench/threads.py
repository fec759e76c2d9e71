"""The thread counts of the numeric libraries under simbench, set by entry points.

simbench runs its own threads and processes where they pay (the decoder's row bands, the
ablation pool) and calls BLAS only on small problems: 3x3 eigensystems, (n, 3) x (3, 3)
products, the calibration's solves.  OpenBLAS's threads cost more there than they give.  After
each call they spin waiting for the next one, taking a core from the decoder's threads.
Measured in a warm ``simbench reproduce all --quick`` on 2 cores: 37 % of the CPU samples were
in ``blas_thread_server``; with one BLAS thread the run took 16.7 s instead of 18.5 s, and
17.7 s of user time instead of 28.6 s.  A multi-threaded BLAS also sums in an order set by its
thread count, so results would depend on the machine's core count (the calibration guards
itself: :mod:`simbench.calibration.procedure`).

Like ``mi.set_variant``, this is for entry points (the CLI, the ablation workers), never done
when a library module is imported: a user's own process keeps its BLAS settings.
"""

from __future__ import annotations

import os

__all__ = ["BLAS_ENVIRONMENT", "MALLOC_ARENAS", "single_thread_blas", "limit_malloc_arenas"]

# read by OpenBLAS and MKL when they load: libraries loaded later in this process (SciPy's own
# OpenBLAS) and spawned worker processes start with one thread
BLAS_ENVIRONMENT = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def single_thread_blas() -> None:
    """Run BLAS on one thread in this process: the libraries already loaded (threadpoolctl)
    and, through the environment, those loaded later and spawned child processes."""
    from threadpoolctl import threadpool_limits

    os.environ.update(BLAS_ENVIRONMENT)
    threadpool_limits(1, user_api="blas")


# glibc's malloc arenas for the process (assumption: 2, the decoder's row-band threads on CI's 2
# cores; glibc's default is 8 per core).  The colour-robust decoder's band threads each allocate
# ~40-60 MB of images per decode; in per-thread arenas, whose heaps glibc gives back, every decode
# got fresh pages: measured 2026-11-26, `simbench bench --robust` 39.7 ms median with 319 k minor
# faults over 60 decodes, 36.6 ms and 59 k with 2 arenas (36.5 ms, 52 k with 1).
MALLOC_ARENAS = 2
_M_ARENA_MAX = -8  # glibc's malloc.h


def limit_malloc_arenas(n: int = MALLOC_ARENAS) -> None:
    """Keep glibc's malloc to ``n`` arenas in this process and, through the environment
    (``MALLOC_ARENA_MAX``), in spawned child processes; nothing where the user set
    ``MALLOC_ARENA_MAX`` already or the C library has no ``mallopt`` (not glibc).  For entry
    points, as :func:`single_thread_blas`; results do not depend on it, only the time."""
    import ctypes

    if "MALLOC_ARENA_MAX" in os.environ:
        return
    os.environ["MALLOC_ARENA_MAX"] = str(int(n))
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt(_M_ARENA_MAX, int(n))
