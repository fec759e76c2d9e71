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

__all__ = ["BLAS_ENVIRONMENT", "single_thread_blas"]

# read by OpenBLAS and MKL when they load: libraries loaded later in this process (SciPy's own
# OpenBLAS) and spawned worker processes start with one thread
BLAS_ENVIRONMENT = {"OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def single_thread_blas() -> None:
    """Run BLAS on one thread in this process: the libraries already loaded (threadpoolctl)
    and, through the environment, those loaded later and spawned child processes."""
    from threadpoolctl import threadpool_limits

    os.environ.update(BLAS_ENVIRONMENT)
    threadpool_limits(1, user_api="blas")
