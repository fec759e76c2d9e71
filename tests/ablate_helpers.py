"""Stand-in run functions for the sweep runner's tests (module level, so that spawned pool
workers can import them).  They read ``scene.name`` as a marker path instead of a scene."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path


def _row(seed: int) -> dict:
    return {
        "plane_mae_mm": 0.1,
        "gt_mae_mm": float(seed % 97) / 97.0,
        "gt_rmse_mm": 0.2,
        "gt_p95_mm": 0.3,
        "outlier_share": 0.0,
        "edge5_mae_mm": 0.1,
        "completeness": 1.0,
        "stripe_order_errors": 0.0,
        "stripe_order_error_rate": 0.0,
        "render_seed": seed,
        "noise_seed": seed,
        "error": "",
        "timing": {},
    }


def quick_run(params: dict, *, seed: int, cache_dir, label: str = "") -> dict:
    return _row(seed)


def dies_once(params: dict, *, seed: int, cache_dir, label: str = "") -> dict:
    """Kills its worker the first time it sees its marker path, succeeds after."""
    marker = Path(params["scene.name"])
    if marker.name.startswith("die") and not marker.exists():
        marker.touch()
        os.kill(os.getpid(), signal.SIGKILL)
    return _row(seed)


def always_dies(params: dict, *, seed: int, cache_dir, label: str = "") -> dict:
    if Path(params["scene.name"]).name.startswith("die"):
        os.kill(os.getpid(), signal.SIGKILL)
    return _row(seed)


def slow_run(params: dict, *, seed: int, cache_dir, label: str = "") -> dict:
    """Says it has started (touches its marker path), then takes ten minutes."""
    Path(params["scene.name"]).touch()
    time.sleep(600)
    return _row(seed)


def fails_on_marker(params: dict, *, seed: int, cache_dir, label: str = "") -> dict:
    """Fails as run_one records a failure when ``scene.name`` is ``fail``."""
    if params["scene.name"] == "fail":
        return {"error": "RuntimeError: failed on purpose", "traceback": "", "timing": {}}
    return _row(seed)


def talking_run(params: dict, *, seed: int, cache_dir, label: str = "") -> dict:
    """Says a line inside the run as run_one does (through the worker's state), then succeeds."""
    from simbench.experiments.workers import worker_state

    worker_state().emit(f"[{label}] inside, pid {os.getpid()}")
    return _row(seed)
