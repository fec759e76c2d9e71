"""Whether this process has been asked to stop (SIGTERM).

The command line's handler raises an exception in the main thread to unwind the command; but
an exception raised inside a Mitsuba render comes back out of Dr.Jit re-wrapped as a
``RuntimeError``, which code that records failures and goes on (an ablation run) would record as
a failed run and carry on.  Such code asks :func:`requested` and re-raises instead."""

from __future__ import annotations

import threading

__all__ = ["request", "requested"]

_REQUESTED = threading.Event()


def request() -> None:
    """Note that the process is to stop (called by the SIGTERM handler)."""
    _REQUESTED.set()


def requested() -> bool:
    """True once :func:`request` was called."""
    return _REQUESTED.is_set()
