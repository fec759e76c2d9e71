"""Running a sweep: one run (render through the cache, record, decode, score) on the experiments'
worker pool (:mod:`simbench.experiments.workers`: local processes or a Dask cluster), and the run
log that lets a restarted sweep skip finished runs."""

from __future__ import annotations

import json
import logging
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

from simbench.experiments.ablate.mapping import check_sweep, decoder_for, run_config_for, scene_for, sensor_for
from simbench.experiments.ablate.report import sweep_rows, write_sweep
from simbench.experiments.ablate.spec import EDGE_BAND_PX, MODES, Sweep, expand

log = logging.getLogger(__name__)

__all__ = ["run_one", "run_sweep", "WORKER_DIED"]


def run_one(params: dict, *, seed: int, cache_dir: str | None, label: str = "ablate") -> dict:
    """Render (through the cache), record, decode and score one parameter set.  Returns the
    metrics and timings, or ``{"error": ...}``; never raises for a bad parameter value.

    Its progress (each render cache entry made in at least
    :data:`simbench.cache.PROGRESS_MIN_S`, calibration poses), its lines starting ``[label]``,
    goes to the sweep's ``progress`` through the worker's :class:`_RunProgress` state; a run
    called otherwise is silent."""
    t0 = time.perf_counter()
    try:
        import sys

        from simbench import cache as cache_module
        from simbench.experiments.common import Session, score
        from simbench.decode.params import pattern_on_rig_warnings
        from simbench.systems.recording_checks import exposure_warnings, recording_warnings
        from simbench.experiments.workers import worker_state
        from simbench.variant import select_variant

        emit = worker_state()
        if not isinstance(emit, _RunProgress):
            emit = _RunProgress(lambda line: None)

        def say(line: str) -> None:
            emit.emit(f"[{label}] {line}")

        # a Dask worker arrives here without an entry point: choose the variant first (it must
        # steer Dr.Jit's libLLVM before Mitsuba is imported)
        if "mitsuba" not in sys.modules or sys.modules["mitsuba"].variant() is None:
            select_variant(None)
        decoder = decoder_for(params)
        sensor = sensor_for(params)
        config = run_config_for(params, seed=seed, sensor=sensor, decoder=decoder)
        session = Session(
            config, out_dir=".", cache_dir=cache_dir, progress=say, command="simbench ablate", sensor=sensor
        )

        def made(kind: str, seconds: float) -> None:
            # a cold run renders for minutes: each costly entry made says so (a new user's audit)
            if seconds >= cache_module.PROGRESS_MIN_S:
                say(f"{kind} made in {seconds:.1f} s ({time.perf_counter() - t0:.0f} s so far)")

        session.cache.on_made = made
        raw = scene_for(params)
        # every object placed by hand, each with its own seeded error (as Table 1 places its board)
        scene = session.prepare(session.place(raw, "ablate", [o.name for o in raw.objects]))
        t1 = time.perf_counter()
        cap = session.capture(scene, "ablate")[0]
        t2 = time.perf_counter()
        # what `simbench decode` says of the pattern on the rig before decoding (a fringe too fine for
        # the camera, a working range past the code's cycle): the table says it beside the numbers it
        # explains (a pattern designer's audit, 2026-11-30: a period-8 run's 112.7 mm MAE and 32 %
        # outliers came with no word of the range's ambiguity the command line names)
        told = pattern_on_rig_warnings(cap.scene.rig, decoder)
        # and what the recording shows, as `simbench.record` warns of it (a third new user's audit: a
        # board at 1.9 m, past the working range, tabled a 0.147 mm plane fit - every pixel a code
        # cycle off, 1157 mm GT MAE - with an empty warnings column)
        told = [
            *told,
            *recording_warnings(scene, cap.gt, decoder),
            *(exposure_warnings(cap.raw, cap.scene, sensor) if (np.asarray(cap.gt.object_id) >= 0).any() else []),
        ]
        for line in told:
            say(f"warning: {line}")
        row = {"warnings": told}
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
            # results depend on the variant (docs/usage.md): the sweep's provenance lists each run's
            variant=sys.modules["mitsuba"].variant(),
        )
        row["timing"] = {"setup_s": t1 - t0, "render_record_s": t2 - t1, "decode_s": t3 - t2}
        return row
    except Exception as exc:  # noqa: BLE001 - a failing run is recorded, not fatal
        from simbench import termination

        if termination.requested():  # SIGTERM, re-wrapped by a render: stop, record nothing
            raise
        msg = f"{type(exc).__name__}: {exc}".splitlines()[0]
        if "the reference capture decodes at only" in msg:
            # (a third new user's audit: a run's own reference plane was asked "is it the reference-plane
            # capture, taken with this pattern and rig?" - simbench made it)
            msg += (
                " [simbench rendered this reference plane itself, with the run's pattern, rig and sensor: its "
                "fringe did not survive them - camera noise, ambient light, a fringe too fine for the camera - "
                "so the run has no depth in either mode]"
            )
        return {
            "error": msg,
            "traceback": traceback.format_exc(limit=4),
            "timing": {"setup_s": time.perf_counter() - t0},
        }


class _RunProgress:
    """A worker's line to the sweep's ``progress`` (the worker pool's ``emit``): the pool's
    setup, so the state every worker holds, which :func:`run_one` finds there."""

    def __init__(self, emit: Callable[[str], None]) -> None:
        self.emit = emit


WORKER_DIED = "worker process died twice on this run (killed, or out of memory)"


# ------------------------------------------------------------------------------ the sweep


def _load_done(path: Path) -> dict[str, dict]:
    done = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            try:
                rec = json.loads(line)
                if rec.get("error"):  # a failed run is run again by the next start (it was done, not finished)
                    done.pop(rec["key"], None)
                    continue
                done[rec["key"]] = rec
            except (ValueError, KeyError, TypeError):
                continue  # a line cut by an interruption: that run is redone
    return done


def _named_files_digest(params: dict) -> str:
    """The first 8 hex digits of the SHA-256 of the sensor and scene files a run's values name
    (a preset's own file too) and of everything the scene file names in turn - its meshes and
    rig, by the scene's fingerprint (:func:`simbench.sim.scene.scene_fingerprint`, what a render
    is keyed by; a new user's audit, 2026-11-30: a resume after a mesh file changed kept the old
    mesh's results) - "" when they name none."""
    import hashlib

    from simbench.experiments.ablate.mapping import scene_path
    from simbench.io import json_bytes
    from simbench.sim.scene import load_scene, scene_fingerprint
    from simbench.sim.sensor import PRESETS_DIR, SENSOR_PRESETS

    files = []
    # the preset the run is made with, and the one its sensor.effects take their values from (a
    # new user's audit: a resume after the source file's noise changed kept the old results)
    for key in ("sensor.preset", "sensor.source"):
        sensor = params.get(key)
        if isinstance(sensor, str):
            files.append(PRESETS_DIR / f"{sensor}.toml" if sensor in SENSOR_PRESETS else Path(sensor))
    scene = None
    if isinstance(params.get("scene.name"), str):
        try:
            scene = scene_path(params["scene.name"])
            files.append(scene)
        except ValueError:
            pass  # (refused with its own message by the run)
    h = hashlib.sha256()
    for f in files:
        try:
            h.update(f.read_bytes())
        except OSError:
            h.update(str(f).encode())
    if scene is not None:
        try:
            h.update(json_bytes(scene_fingerprint(load_scene(scene))))
        except (ValueError, OSError):
            pass  # (the same)
    return h.hexdigest()[:8] if files else ""


def code_digest() -> str:
    """The first 16 hex digits of the SHA-256 of simbench's code - every module of the package and
    its C loops, and after a ``+`` those of the code of phase methods and object kinds registered
    from outside it (:func:`simbench.cache.foreign_code_digest`) - as a run's log records it: a
    resumed sweep reuses only runs its own code made (until 2026-11-30 a resume after a decoder
    change kept every finished run's old metrics and wrote the sweep's provenance with the new
    commit)."""
    from simbench.cache import foreign_code_digest, source_digest
    from simbench.decode.params import PHASE_METHODS
    from simbench.sim.scene import OBJECT_KIND_TABLE

    root = Path(__file__).resolve().parents[2]  # the package (not `import simbench`: its api is a layer above)
    digest = source_digest(sorted([*root.rglob("*.py"), *root.glob("*.c")]))[:16]
    # a user's own phase methods and object kinds, registered in this process, by their code (an
    # extender's audit, 2026-11-30: a resume after an edit of one kept its runs' old metrics)
    foreign = foreign_code_digest(
        *PHASE_METHODS.values(), *(f for k in OBJECT_KIND_TABLE.values() for f in (k.parse, k.to_mitsuba))
    )
    return digest if foreign is None else f"{digest}+{foreign[:16]}"


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
    parameter set (:func:`run_one`; another module-level function with its signature,
    ``(params, *, seed, cache_dir, label)``, can stand in, e.g. to test the runner).  A pool
    worker that dies costs its runs one retry; a run that kills its worker twice is recorded as
    failed (:func:`simbench.experiments.workers.run_tasks`).  ``workers`` > 1 with a
    ``scheduler`` is refused.  For :func:`run_one`, every run's values are checked first
    (:func:`~simbench.experiments.ablate.mapping.check_sweep`, which builds what it builds): a
    value that cannot run raises ``ValueError`` before anything is run or written.  A stand-in
    ``run_fn`` reads the parameters its own way, and checks them itself.
    """
    if scheduler is not None and workers > 1:
        raise ValueError("--workers and --scheduler: choose one (the cluster's workers run the sweep)")
    if run_fn is run_one:
        check_sweep(sweep)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    # a run's log key covers the files its values name, so a resumed sweep whose sensor or scene
    # file changed runs again rather than reusing their old results (a new user's audit: a sensor
    # file's read noise raised 40-fold, and the resume kept 0.2486 mm)
    runs = [{**r, "key": r["key"] + _named_files_digest(r["params"])} for r in expand(sweep)]
    log = out / f"{sweep.name}.runs.jsonl"
    code = code_digest()
    done = _load_done(log)
    # a run another version of the code made is not this code's result: it runs again
    other = {k for k, rec in done.items() if rec.get("code") != code}
    wanted = {r["key"] for r in runs}
    for k in other:
        del done[k]
    todo = [r for r in runs if r["key"] not in done]
    stale = len(other & wanted)
    progress(
        f"[ablate {sweep.name}] {len(runs)} runs, {len(runs) - len(todo)} already done, {len(todo)} to run"
        + (f" ({stale} of them finished by another version of simbench's code: run again)" if stale else "")
    )
    cache = None if cache_dir is None else str(cache_dir)
    n = 0

    def finished(run: dict, res: dict) -> None:
        nonlocal n
        n += 1
        rec = {"key": run["key"], "run": run["run"], "code": code, **res}
        _append(log, rec)
        done[run["key"]] = rec
        status = (
            f"error: {res['error']}"
            if res.get("error")
            else f"{sweep.plot_metric} {res.get(sweep.plot_metric, float('nan')):.4g}"
        )
        progress(f"[ablate {sweep.name} {n}/{len(todo)}] run {run['run']}: {status}")

    from simbench.experiments.workers import Task, run_tasks

    tasks = [
        Task(
            r["key"],
            (r["params"],),
            {"seed": r["seed"], "cache_dir": cache, "label": f"ablate {sweep.name} run {r['run']}"},
        )
        for r in todo
    ]
    by_key = {r["key"]: r for r in todo}
    run_tasks(
        tasks,
        run_fn,
        workers=workers,
        scheduler=scheduler,
        variant=variant,
        setup=_RunProgress,
        on_result=lambda task, res: finished(by_key[task.key], res),
        on_died=lambda task: finished(by_key[task.key], {"error": WORKER_DIED, "timing": {}}),
        # e.g. Dask's KilledWorker: the cluster retried the run and gave up
        on_error=lambda task, exc: finished(
            by_key[task.key], {"error": f"{type(exc).__name__}: {exc}".splitlines()[0], "timing": {}}
        ),
        progress=progress,
    )
    rows = sweep_rows(sweep, runs, done)
    write_sweep(sweep, rows, runs, done, out, command)
    return rows
