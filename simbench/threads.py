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
import sys
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = [
    "BLAS_ENVIRONMENT",
    "MALLOC_ARENAS",
    "THREADS_VARIABLE",
    "cores_shared",
    "limit_malloc_arenas",
    "process_threads",
    "apply_threads",
    "single_thread_blas",
    "usable_cpus",
]

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


# A worker process's share of the machine: the threads its own parallel work takes - Dr.Jit's
# render threads, OpenCV's and the decoder's row bands by default.  Each of these sizes itself to
# every core, so N worker processes ran N x cores threads of each.  Measured 2026-11-27: a cold
# `simbench reproduce all --workers 16` (llvm_ad_rgb) on a 16-core machine summed >= 6885
# worker-seconds where the 2-core development machine's 2 workers needed <= 5008 for the whole
# run; on 2 cores, 2 workers with 16 threads each (SIMBENCH_THREADS=16, that machine's
# oversubscription) made the cold quick run 366 s against 198-211 s with the share (1 each) and
# 202-205 s with 2 each (the share changes nothing measurable at 2 cores).  Results do not depend
# on it: those runs' files were the same bytes (a render's passes and atomic film adds,
# simbench.sim.mitsuba_dict; the decoder's exact bands; the calibration's solvers on one thread
# whatever this says, simbench.calibration.procedure).
THREADS_VARIABLE = "SIMBENCH_THREADS"


def usable_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def process_threads() -> int:
    """The threads this process's own parallel work may take: ``SIMBENCH_THREADS`` when set
    (a worker's share of its machine, set by the worker pools, or by hand on a Dask worker
    host), else every usable CPU.  A value that is not a whole number >= 1 is a ``ValueError``."""
    value = os.environ.get(THREADS_VARIABLE, "").strip()
    if not value:
        return usable_cpus()
    try:
        n = int(value)
    except ValueError:
        n = 0
    if n < 1:
        raise ValueError(f"{THREADS_VARIABLE} must be a whole number of threads >= 1, got {value[:40]!r}")
    return n


def apply_threads(n: int) -> None:
    """Size this process's thread pools to ``n``: OpenCV's and, where it is loaded, Dr.Jit's
    (its LLVM back end's render threads; call after the Mitsuba variant is chosen)."""
    import cv2

    cv2.setNumThreads(int(n))
    dr = sys.modules.get("drjit")
    if dr is not None:
        dr.set_thread_count(int(n))


@contextmanager
def cores_shared(workers: int) -> Iterator[int]:
    """This process as one of ``workers`` processes sharing the machine's cores: each takes
    ``max(1, cores // workers)`` threads (yielded), through ``SIMBENCH_THREADS`` for the
    processes it spawns meanwhile and :func:`apply_threads` here; restored after.  A
    ``SIMBENCH_THREADS`` set by the user is kept (their choice for every process)."""
    import cv2

    before_env = os.environ.get(THREADS_VARIABLE)
    user_set = bool(before_env and before_env.strip())
    n = process_threads() if user_set else max(1, usable_cpus() // max(1, int(workers)))
    before_cv = cv2.getNumThreads()
    dr = sys.modules.get("drjit")
    before_dr = dr.thread_count() if dr is not None else None
    os.environ[THREADS_VARIABLE] = str(n)
    apply_threads(n)
    try:
        yield n
    finally:
        if before_env is None:
            os.environ.pop(THREADS_VARIABLE, None)
        else:
            os.environ[THREADS_VARIABLE] = before_env
        cv2.setNumThreads(before_cv)
        if before_dr is not None:
            dr.set_thread_count(before_dr)
