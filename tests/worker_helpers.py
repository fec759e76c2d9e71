"""Module-level task functions for tests/test_workers.py (spawned workers import them)."""

from __future__ import annotations

import os
import signal
from pathlib import Path


def setup(emit, tag: str) -> dict:
    emit(f"worker {tag} ready")
    return {"tag": tag}


def square(x: int) -> tuple[int, str]:
    from simbench.experiments.workers import worker_state

    state = worker_state()
    return x * x, "parent" if state is None else state["tag"]


def fails_on(x: int, bad: int) -> int:
    if x == bad:
        raise ValueError(f"task {x} failed on purpose")
    return x


def dies_on(marker: str, *, times: int) -> str:
    """Kills its worker while ``marker``'s count of deaths is below ``times``."""
    path = Path(marker)
    died = int(path.read_text()) if path.exists() else 0
    if path.name.startswith("die") and died < times:
        path.write_text(str(died + 1))
        os.kill(os.getpid(), signal.SIGKILL)
    return path.name
