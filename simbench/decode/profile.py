"""Where a decode spends its time: per-stage wall clock, collected only when asked.

::

    with stage_times() as times:
        decode(capture, rig=rig, params=params, reference=ref)
    times.ms  # {"phase (Gabor fit)": 9.1, ...}

Each stage of :func:`simbench.decode.decode` runs inside :func:`stage`; with no collector
active that costs one context-variable look-up.  The decoder's row bands run in threads, so a
stage's time is summed over the bands that ran it in parallel: the stages add up to the
threads' work, which exceeds the decode's wall time on more than one thread.
"""

from __future__ import annotations

import contextvars
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor
from contextlib import contextmanager

__all__ = ["StageTimes", "stage", "stage_times", "run_in_context"]


class StageTimes:
    """Seconds per stage, summed over calls and threads (thread-safe), in first-seen order."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}

    def add(self, name: str, seconds: float) -> None:
        with self._lock:
            self.seconds[name] = self.seconds.get(name, 0.0) + seconds
            self.calls[name] = self.calls.get(name, 0) + 1

    @property
    def ms(self) -> dict[str, float]:
        return {k: 1000.0 * v for k, v in self.seconds.items()}


_ACTIVE: contextvars.ContextVar[StageTimes | None] = contextvars.ContextVar("simbench_stage_times", default=None)


@contextmanager
def stage(name: str) -> Iterator[None]:
    """Time the enclosed block as stage ``name`` if a collector is active."""
    times = _ACTIVE.get()
    if times is None:
        yield
        return
    t0 = time.perf_counter()
    try:
        yield
    finally:
        times.add(name, time.perf_counter() - t0)


@contextmanager
def stage_times() -> Iterator[StageTimes]:
    """Collect the stage times of everything run inside (threads started through
    :func:`run_in_context` included)."""
    times = StageTimes()
    token = _ACTIVE.set(times)
    try:
        yield times
    finally:
        _ACTIVE.reset(token)


def run_in_context(pool: Executor, fn: Callable, items: Iterable) -> list:
    """``pool.map(fn, items)`` with each call in a copy of the caller's context, so that
    worker threads report to the caller's collector (executors do not carry context over)."""
    futures = [pool.submit(contextvars.copy_context().run, fn, item) for item in items]
    return [f.result() for f in futures]
