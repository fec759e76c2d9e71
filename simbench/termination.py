"""Whether this process has been asked to stop (SIGTERM).

The command line's handler raises an exception in the main thread to unwind the command; but
an exception raised inside a Mitsuba render comes back out of Dr.Jit re-wrapped as a
``RuntimeError``, which code that records failures and goes on (an ablation run) would record as
a failed run and carry on.  Such code asks :func:`requested` and re-raises instead.

A few steps must not be cut in two by that exception (or by Ctrl-C's KeyboardInterrupt) -
creating a cache lock file and taking the lock, removing it and letting the lock go, renaming a
set of files into place (:func:`simbench.io.write_files`): :func:`held` defers the handler's raise
to the end of such a step (:func:`run_or_hold`)."""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

__all__ = ["request", "requested", "requested_signal", "held", "run_or_hold"]

_REQUESTED = threading.Event()
# the signal that asked (SIGTERM 15, or SIGINT 2: Ctrl-C's KeyboardInterrupt is re-wrapped by a render too)
_SIGNAL = [15]
# depth of the main thread's held steps, and what a signal handler asked to run meanwhile
# (signal handlers run in the main thread only, so only its steps can be cut)
_HELD = 0
_PENDING: list[Callable[[], None]] = []


def request(signum: int = 15) -> None:
    """Note that the process is to stop (called by the SIGTERM and SIGINT handlers)."""
    _SIGNAL[0] = int(signum)
    _REQUESTED.set()


def requested_signal() -> int:
    """The signal :func:`request` was called for (15 SIGTERM, 2 SIGINT)."""
    return _SIGNAL[0]


def requested() -> bool:
    """True once :func:`request` was called."""
    return _REQUESTED.is_set()


@contextmanager
def held() -> Iterator[None]:
    """A step the SIGTERM and SIGINT handlers' exceptions must not cut in two (main thread; elsewhere,
    where no handler runs, nothing is held): what :func:`run_or_hold` was asked to run meanwhile
    runs when the outermost held step ends."""
    global _HELD
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _HELD += 1
    try:
        yield
    finally:
        _HELD -= 1
        if _HELD == 0 and _PENDING:
            fn = _PENDING[0]
            _PENDING.clear()
            fn()


def run_or_hold(fn: Callable[[], None]) -> None:
    """Run ``fn`` (a signal handler's raise) now, or at the end of the held step the main thread
    is in (:func:`held`)."""
    if _HELD and threading.current_thread() is threading.main_thread():
        _PENDING.append(fn)
    else:
        fn()
