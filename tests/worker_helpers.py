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


# A target measured in parts (simbench.experiments.common.Split) for tests/test_experiments.py:
# each part records a seed and waits a little (so that both of two workers take parts); the
# parent's write keeps the processes that measured them in WRITTEN_BY (not in its files).
WRITTEN_BY: set[int] = set()


def split_parts(config) -> list[str]:
    return [f"p{k}" for k in range(6)]


def split_measure(session, part: str) -> dict:
    import time

    seed = session.seeds.seed(f"split/{part}")
    session.seeds.record(f"split/{part}", {"render": seed})
    time.sleep(0.3)
    return {"part": part, "seed": seed, "pid": os.getpid()}


def split_write(session, results: list[dict]) -> dict:
    WRITTEN_BY.clear()
    WRITTEN_BY.update(r["pid"] for r in results)
    text = "".join(f"{r['part']} {r['seed']}\n" for r in results)
    session.write_results("split", {"split.txt": text})
    return {f"split/{r['part']}": r["seed"] for r in results}


def split_cost(part: str) -> float:
    return int(part[1:])  # the last part first


def split_measure_fails(session, part: str) -> dict:
    if part == "p3":
        raise ValueError("part p3 failed on purpose")
    return split_measure(session, part)


def threads_seen(x: int) -> tuple:
    """What a task sees of its process's thread share (tests/test_workers.py)."""
    import sys

    import cv2

    dr = sys.modules.get("drjit")
    return os.environ.get("SIMBENCH_THREADS"), cv2.getNumThreads(), None if dr is None else dr.thread_count()
