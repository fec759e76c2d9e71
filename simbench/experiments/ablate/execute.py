"""Running a sweep: one run (render through the cache, record, decode, score), local worker
processes that die with the parent and are retried once, a Dask cluster, and the run log that
lets a restarted sweep skip finished runs."""

from __future__ import annotations

import json
import logging
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path

from simbench.experiments.ablate.mapping import check_sweep, decoder_for, run_config_for, scene_for, sensor_for
from simbench.experiments.ablate.report import sweep_rows, write_sweep
from simbench.experiments.ablate.spec import EDGE_BAND_PX, MODES, Sweep, expand

log = logging.getLogger(__name__)

__all__ = ["run_one", "run_sweep", "WORKER_DIED"]


def run_one(params: dict, *, seed: int, cache_dir: str | None) -> dict:
    """Render (through the cache), record, decode and score one parameter set.  Returns the
    metrics and timings, or ``{"error": ...}``; never raises for a bad parameter value."""
    t0 = time.perf_counter()
    try:
        import sys

        from simbench.experiments.common import Session, score
        from simbench.variant import select_variant

        # a Dask worker arrives here without an entry point: choose the variant first (it must
        # steer Dr.Jit's libLLVM before Mitsuba is imported)
        if "mitsuba" not in sys.modules or sys.modules["mitsuba"].variant() is None:
            select_variant(None)
        decoder = decoder_for(params)
        sensor = sensor_for(params)
        config = run_config_for(params, seed=seed, sensor=sensor, decoder=decoder)
        session = Session(
            config, out_dir=".", cache_dir=cache_dir, progress=lambda s: None, command="simbench ablate", sensor=sensor
        )
        raw = scene_for(params)
        # every object placed by hand, each with its own seeded error (as Table 1 places its board)
        scene = session.prepare(session.place(raw, "ablate", [o.name for o in raw.objects]))
        t1 = time.perf_counter()
        cap = session.capture(scene, "ablate")[0]
        t2 = time.perf_counter()
        row = {}
        for mode, prefix in MODES.items():
            result = session.decode(cap, decoder, mode=mode)
            row.update(
                {
                    prefix + k: float(v)
                    for k, v in score(cap, result, decoder.period_px, edge_band_px=EDGE_BAND_PX).items()
                }
            )
        t3 = time.perf_counter()
        placement = session.seeds_used["ablate/placement"]
        row.update(
            render_seed=cap.seeds["render"],
            noise_seed=cap.seeds["noise"],
            placement_seed=placement["placement"],
            error="",
        )
        row["timing"] = {"setup_s": t1 - t0, "render_record_s": t2 - t1, "decode_s": t3 - t2}
        return row
    except Exception as exc:  # noqa: BLE001 - a failing run is recorded, not fatal
        from simbench import termination

        if termination.requested():  # SIGTERM, re-wrapped by a render: stop, record nothing
            raise
        msg = f"{type(exc).__name__}: {exc}".splitlines()[0]
        return {
            "error": msg,
            "traceback": traceback.format_exc(limit=4),
            "timing": {"setup_s": time.perf_counter() - t0},
        }


def _worker_init(variant: str | None, parent_pid: int) -> None:
    from simbench.threads import single_thread_blas
    from simbench.variant import select_variant

    _die_with_parent(parent_pid)
    single_thread_blas()
    select_variant(variant)


def _die_with_parent(parent_pid: int) -> None:
    """Make this worker process die when the sweep's process does (Linux ``PR_SET_PDEATHSIG``),
    so that a killed sweep leaves no workers (each holds ~0.5 GB) behind."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux: workers end when their task queue closes
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)


def _tracked(run_fn, marker_dir: str, key: str, params: dict, seed: int, cache_dir: str | None) -> dict:
    """``run_fn(params, seed=..., cache_dir=...)`` with a marker file present while it runs:
    if the worker dies, the markers left say which runs were on it."""
    marker = Path(marker_dir) / key
    marker.touch()
    try:
        return run_fn(params, seed=seed, cache_dir=cache_dir)
    finally:
        marker.unlink(missing_ok=True)


WORKER_DIED = "worker process died twice on this run (killed, or out of memory)"


def _run_pool(
    todo: list[dict],
    *,
    workers: int,
    variant: str | None,
    cache: str | None,
    finished,
    run_fn,
    marker_dir: Path,
    progress,
) -> None:
    """Run ``todo`` on a process pool.  A worker that dies (kill -9, the OOM killer) breaks the
    pool: the runs it held (their marker files are left) are retried once, each alone in a
    fresh pool; a run that kills its worker again is recorded as failed.  Runs that were only
    queued are resubmitted unpenalised."""
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    marker_dir.mkdir(parents=True, exist_ok=True)
    for m in marker_dir.iterdir():
        m.unlink()
    deaths: dict[str, int] = {}
    rounds: list[tuple[list[dict], int]] = [(list(todo), workers)]
    ctx = mp.get_context("spawn")
    while rounds:
        batch, n_workers = rounds.pop(0)
        broken: list[dict] = []
        with ProcessPoolExecutor(
            max_workers=n_workers, mp_context=ctx, initializer=_worker_init, initargs=(variant, os.getpid())
        ) as pool:
            futs = {
                pool.submit(_tracked, run_fn, str(marker_dir), r["key"], r["params"], r["seed"], cache): r
                for r in batch
            }
            for f in as_completed(futs):
                try:
                    res = f.result()
                except BrokenProcessPool:
                    broken.append(futs[f])
                    continue
                finished(futs[f], res)
        if not broken:
            continue
        on_dead = {m.name for m in marker_dir.iterdir()}
        for m in marker_dir.iterdir():
            m.unlink()
        suspects = [r for r in broken if r["key"] in on_dead]
        queued = [r for r in broken if r["key"] not in on_dead]
        retry = []
        for r in suspects:
            deaths[r["key"]] = deaths.get(r["key"], 0) + 1
            if deaths[r["key"]] >= 2:
                finished(r, {"error": WORKER_DIED, "timing": {}})
            else:
                retry.append(r)
        progress(
            f"a worker process died (runs {sorted(r['run'] for r in suspects)} were on it): retrying them one at a time"
        )
        rounds = [(rs, 1) for rs in ([r] for r in retry)] + ([(queued, workers)] if queued else []) + rounds
    marker_dir.rmdir()


# ------------------------------------------------------------------------------ the sweep


def _load_done(path: Path) -> dict[str, dict]:
    done = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                rec = json.loads(line)
                done[rec["key"]] = rec
            except (ValueError, KeyError, TypeError):
                continue  # a line cut by an interruption: that run is redone
    return done


def _append(path: Path, rec: dict) -> None:
    with open(path, "a", encoding="utf-8") as f:
        f.write(json.dumps(rec, sort_keys=True, default=str) + "\n")
        f.flush()
        os.fsync(f.fileno())


def run_sweep(
    sweep: Sweep,
    *,
    out_dir: str | Path,
    cache_dir: str | Path | None,
    workers: int = 1,
    scheduler: str | object | None = None,
    variant: str | None = None,
    progress: Callable[[str], None] = log.info,
    command: str = "",
    run_fn: Callable[..., dict] = run_one,
) -> list[dict]:
    """Run every unfinished run of ``sweep`` and write ``<name>.csv``, ``.md``, ``.png``,
    ``.timings.csv`` and ``.provenance.json`` into ``out_dir``; returns the rows.

    ``scheduler``: a Dask scheduler address (or a ``distributed.Client``); None = a local
    process pool of ``workers`` processes (1 = in this process).  ``run_fn`` runs one
    parameter set (:func:`run_one`; another module-level function with its signature can
    stand in, e.g. to test the runner).  A pool worker that dies costs its runs one retry;
    a run that kills its worker twice is recorded as failed (:func:`_run_pool`).  For
    :func:`run_one`, every run's values are checked first
    (:func:`~simbench.experiments.ablate.mapping.check_sweep`, which builds what it builds): a
    value that cannot run raises ``ValueError`` before anything is run or written.  A stand-in
    ``run_fn`` reads the parameters its own way, and checks them itself.
    """
    if run_fn is run_one:
        check_sweep(sweep)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    runs = expand(sweep)
    log = out / f"{sweep.name}.runs.jsonl"
    done = _load_done(log)
    todo = [r for r in runs if r["key"] not in done]
    progress(f"[ablate {sweep.name}] {len(runs)} runs, {len(runs) - len(todo)} already done, {len(todo)} to run")
    cache = None if cache_dir is None else str(cache_dir)
    n = 0

    def finished(run: dict, res: dict) -> None:
        nonlocal n
        n += 1
        rec = {"key": run["key"], "run": run["run"], **res}
        _append(log, rec)
        done[run["key"]] = rec
        status = (
            f"error: {res['error']}"
            if res.get("error")
            else f"{sweep.plot_metric} {res.get(sweep.plot_metric, float('nan')):.4g}"
        )
        progress(f"[ablate {sweep.name} {n}/{len(todo)}] run {run['run']}: {status}")

    if todo:
        if scheduler is not None:
            _run_dask(todo, scheduler, cache, finished, run_fn)
        elif workers > 1:
            _run_pool(
                todo,
                workers=workers,
                variant=variant,
                cache=cache,
                finished=finished,
                run_fn=run_fn,
                marker_dir=out / f".{sweep.name}.running",
                progress=progress,
            )
        else:
            for r in todo:
                finished(r, run_fn(r["params"], seed=r["seed"], cache_dir=cache))
    rows = sweep_rows(sweep, runs, done)
    write_sweep(sweep, rows, runs, done, out, command)
    return rows


def _run_dask(todo: list[dict], scheduler, cache, finished, run_fn) -> None:
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ValueError("--scheduler needs Dask distributed: pip install 'dask[distributed]'") from None
    client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
    try:
        futs = {client.submit(run_fn, r["params"], seed=r["seed"], cache_dir=cache, pure=False): r for r in todo}
        for f in as_completed(list(futs)):
            try:
                res = f.result()
            except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: Dask retried and gave up
                res = {"error": f"{type(exc).__name__}: {exc}".splitlines()[0], "timing": {}}
            finished(futs[f], res)
    finally:
        if client is not scheduler:
            client.close()
