"""Ablation studies: declarative sweeps over pattern, sensor, decoder and scene (``simbench ablate``).

A sweep file (TOML)::

    name = "period"                      # results/ablations/<name>.csv/.md/.png
    description = "fringe period T"
    repeats = 2                          # recordings per parameter set (own seeds each)
    seed = 2017                          # base seed (default simbench.seeds.DEFAULT_SEED): repetition r uses the same seeds in every
                                         # parameter set (common random numbers)
    plot_metric = "gt_mae_mm"            # y of the plot (default gt_mae_mm)

    [base]                               # any parameter (below) fixed for every run
    "scene.name" = "plane_white"
    "run.camera_scale" = 0.5

    [[axis]]                             # one or more axes
    name = "pattern.period_px"
    values = [11, 15, 21, 31, 41]

    [[axis]]
    name = "decoder.voting"
    values = [true, false]

    combine = "grid"                     # "grid" (every combination) or "zip" (axes in step)

Parameters (:data:`PARAMETERS`; anything else is rejected with the list):

- ``pattern.period_px``, ``pattern.order``, ``pattern.sequence`` (a 0/1 string),
  ``pattern.channels`` (which colour carries code 1, code 0 and the fringe, e.g. ``rbg``): the
  projected pattern, which the decoder is told about;
- ``decoder.<field>``: any :class:`simbench.decode.DecoderParams` field (phase method, overlay vs
  ``blue`` intensity, voting, neighbour correction, colour normalisation, ...);
- ``sensor.preset``: a sensor preset or TOML file; ``sensor.effects``: a list of
  :data:`simbench.device.EFFECTS` switched on over the ``ideal`` model, taken from
  ``sensor.source`` (default ``paper``); ``sensor.<table>.<key>``: one number of the sensor model
  (e.g. ``sensor.camera.dark_noise_e``, ``sensor.ambient.ratio``, ``sensor.projector.lumens``);
- ``scene.name`` (a file of ``scenes/``), ``scene.srgb8`` (repaint every object), ``scene.depth_m``
  (move the scene so its first object's centre is at this depth), ``scene.tilt_deg`` (the first
  object's rotation about the vertical axis);
- ``run.spp``, ``run.sampler``, ``run.camera_scale``, ``run.max_depth``.

Execution: a local process pool (``workers``) or a Dask distributed cluster (``scheduler``); each
run is a pure function of its parameters and seeds, so both give identical tables.  Renders go
through the content-hash cache, so a decoder-only axis renders each scene once.  Finished runs
are appended to ``<name>.runs.jsonl``; a restarted sweep skips them.  A failing run is recorded
with its error and the sweep goes on.
"""

from __future__ import annotations

import logging
import dataclasses
import hashlib
import itertools
import json
import math
import os
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

from simbench.seeds import DEFAULT_SEED, repetition_seed
from simbench import validate
from simbench.io import atomic_write_bytes, atomic_write_text, read_toml, save_json
from simbench.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP

log = logging.getLogger(__name__)

__all__ = ["PARAMETERS", "Sweep", "load_sweep", "sweep_from_dict", "expand", "run_one", "run_sweep", "BUILTIN_STUDIES", "STUDIES_DIR"]

STUDIES_DIR = Path(__file__).resolve().parents[1] / "studies"
# by triangulation with the rig (paper Eq. 15), then the same scores against the separately
# captured reference plane (Sec. 5.4), prefixed ``ref_``
METRICS = ("plane_mae_mm", "gt_mae_mm", "gt_rmse_mm", "gt_p95_mm", "outlier_share", "edge5_mae_mm", "completeness", "stripe_order_errors", "stripe_order_error_rate")
REF_METRICS = ("ref_plane_mae_mm", "ref_gt_mae_mm", "ref_edge5_mae_mm", "ref_completeness", "ref_stripe_order_errors")
MODES = {"calibrated": "", "reference": "ref_"}
EDGE_BAND_PX = 5  # edge5_mae_mm: the MAE outside this band at depth edges (issue 2's protocol for shapes)


def _decoder_fields() -> dict[str, str]:
    from simbench.decode import DecoderParams

    # mode: every run is scored in both modes (MODES)
    skip = {"pattern", "z0_m", "threads", "mode"}
    return {f"decoder.{f.name}": f"DecoderParams.{f.name}" for f in dataclasses.fields(DecoderParams) if f.name not in skip}


def _parameters() -> dict[str, str]:
    p = {
        "pattern.period_px": "fringe period T (projector px)",
        "pattern.order": "De Bruijn window length n of B(2, n)",
        "pattern.sequence": "explicit stripe code sequence (0/1 string)",
        "pattern.channels": "colour channels of code 1, code 0 and the fringe (paper: rgb)",
        "sensor.preset": "sensor model: a preset (ideal, minimal, paper) or a TOML file",
        "sensor.effects": "list of physical effects switched on over the ideal model",
        "sensor.source": "where sensor.effects take their values from (default paper)",
        "scene.name": "scene file of scenes/",
        "scene.srgb8": "repaint every object with this 8-bit sRGB colour",
        "scene.depth_m": "move the scene so its first object's centre is at this depth",
        "scene.tilt_deg": "rotation of the first object about the vertical axis (deg)",
        "run.spp": "samples per pixel",
        "run.sampler": "Mitsuba sample generator",
        "run.camera_scale": "camera resolution factor",
        "run.max_depth": "path length",
        "run.placement_depth_mm": "placement tolerance in depth (every object placed, seeded)",
        "run.placement_tilt_deg": "placement tolerance in tilt",
        "run.board_bow_mm_per_m": "bow of every placed board and the reference board (mm of sag per metre, seeded sign)",
        "run.board_waviness_mm": "ripple amplitude of every placed board and the reference board (mm, seeded phase)",
    }
    p.update(_decoder_fields())
    return p


PARAMETERS = _parameters()
_SENSOR_TABLES = ("camera", "camera.lens", "projector", "projector.lens", "spectral", "ambient")
DEFAULTS = {"scene.name": "plane_white", "sensor.preset": "paper", "run.spp": DEFAULT_SPP, "run.sampler": DEFAULT_SAMPLER, "run.camera_scale": 1.0, "run.max_depth": 6, "run.placement_depth_mm": 10.0, "run.placement_tilt_deg": 2.0, "run.board_bow_mm_per_m": 0.0, "run.board_waviness_mm": 0.0}


def _check_name(name: str) -> None:
    if name in PARAMETERS:
        return
    table, _, key = name.rpartition(".")
    if name.startswith("sensor.") and table[len("sensor.") :] in _SENSOR_TABLES and key:
        return
    raise ValueError(
        f"unknown sweep parameter {name!r}; valid: {sorted(PARAMETERS)} and sensor.<table>.<key> with <table> one of {list(_SENSOR_TABLES)}"
    )


@dataclasses.dataclass(frozen=True)
class Sweep:
    name: str
    description: str
    base: dict
    axes: tuple[tuple[str, tuple], ...]
    combine: str = "grid"
    repeats: int = 1
    seed: int = DEFAULT_SEED
    plot_metric: str = "gt_mae_mm"
    path: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or not all(c.isalnum() or c in "-_" for c in self.name):
            raise ValueError(f"sweep name must be letters, digits, - and _, got {self.name!r}")
        if not isinstance(self.base, dict):
            raise ValueError(f"[base] must be a table, got {self.base!r}")
        for k in self.base:
            _check_name(k)
        if not self.axes:
            raise ValueError("a sweep needs at least one [[axis]]")
        for k, values in self.axes:
            _check_name(k)
            if not values:
                raise ValueError(f"axis {k!r} has no values")
        names = [k for k, _ in self.axes]
        if len(set(names)) != len(names):
            raise ValueError(f"an axis is given twice: {names}")
        if self.combine not in ("grid", "zip"):
            raise ValueError(f"combine must be 'grid' or 'zip', got {self.combine!r}")
        if self.combine == "zip" and len({len(v) for _, v in self.axes}) != 1:
            raise ValueError("zipped axes must have the same number of values")
        object.__setattr__(self, "repeats", validate.integer(self.repeats, "repeats", lo=1, hi=10000))
        object.__setattr__(self, "seed", validate.integer(self.seed, "seed", lo=0, hi=2**63 - 1))
        if not isinstance(self.description, str):
            raise ValueError(f"description must be a string, got {self.description!r}")

        if self.plot_metric not in METRICS + REF_METRICS:
            raise ValueError(f"plot_metric must be one of {list(METRICS + REF_METRICS)}, got {self.plot_metric!r}")


def sweep_from_dict(data: dict, *, where: str = "sweep") -> Sweep:
    allowed = {"name", "description", "base", "axis", "combine", "repeats", "seed", "plot_metric"}
    bad = sorted(set(data) - allowed)
    if bad:
        raise ValueError(f"{where}: unknown key(s) {bad}; valid: {sorted(allowed)}")
    axes = []
    if not isinstance(data.get("axis", []), list):
        raise ValueError(f"{where}: axis must be an array of tables ([[axis]])")
    for i, ax in enumerate(data.get("axis", [])):
        if not isinstance(ax, dict) or set(ax) != {"name", "values"} or not isinstance(ax["values"], list):
            raise ValueError(f"{where}: axis {i + 1} needs exactly 'name' and a list 'values'")
        axes.append((ax["name"], tuple(tuple(v) if isinstance(v, list) else v for v in ax["values"])))
    try:
        return Sweep(
            name=data.get("name", ""),
            description=data.get("description", ""),
            base=data.get("base", {}),
            axes=tuple(axes),
            combine=data.get("combine", "grid"),
            repeats=data.get("repeats", 1),
            seed=data.get("seed", 2017),
            plot_metric=data.get("plot_metric", "gt_mae_mm"),
            path=where,
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


BUILTIN_STUDIES = ("design_choices", "debruijn_order", "period", "pattern_colours", "phase_method", "voting", "noise_ambient", "surface_colour")


def load_sweep(path_or_name: str | Path) -> Sweep:
    """A sweep file, or a built-in study by name (:data:`BUILTIN_STUDIES`)."""
    p = Path(path_or_name)
    where = str(p)
    if not p.suffix and str(path_or_name) in BUILTIN_STUDIES:
        p = STUDIES_DIR / f"{path_or_name}.toml"
        where = f"simbench/studies/{p.name}"  # the same on every machine
    elif not p.is_file() and not p.suffix:
        raise ValueError(f"no sweep file {p} and no built-in study of that name; built-in: {list(BUILTIN_STUDIES)}")
    data = read_toml(p, what="sweep")
    data.setdefault("name", p.stem)
    return sweep_from_dict(data, where=where)


def expand(sweep: Sweep) -> list[dict]:
    """Every run: ``{"run": index, "repeat": r, "params": {...}, "seed": s, "key": ...}``.
    Repetition ``r`` has the same seed in every parameter set (common random numbers)."""
    names = [k for k, _ in sweep.axes]
    value_lists = [v for _, v in sweep.axes]
    combos = itertools.product(*value_lists) if sweep.combine == "grid" else zip(*value_lists)
    runs = []
    for combo in combos:
        params = {**DEFAULTS, **sweep.base, **dict(zip(names, combo))}
        for r in range(sweep.repeats):
            seed = repetition_seed(sweep.seed, r)
            key = hashlib.sha256(json.dumps({"params": params, "repeat": r, "seed": seed}, sort_keys=True, default=str).encode()).hexdigest()[:16]
            runs.append({"run": len(runs), "repeat": r, "params": params, "seed": seed, "key": key})
    return runs


# ------------------------------------------------------------------------------ one run


def _sensor(params: dict):
    from simbench.device import get_sensor, sensor_from_dict, sensor_to_dict, with_effects

    if "sensor.effects" in params:
        effects = params["sensor.effects"]
        effects = [effects] if isinstance(effects, str) else list(effects)
        sensor = with_effects(get_sensor("ideal"), get_sensor(params.get("sensor.source", "paper")), effects, name="ideal+" + "+".join(effects) if effects else "ideal")
    else:
        sensor = get_sensor(params["sensor.preset"])
    overrides = {k: v for k, v in params.items() if k.startswith("sensor.") and k not in PARAMETERS}
    if overrides:
        data = sensor_to_dict(sensor)
        for k, v in overrides.items():
            *tables, key = k.split(".")[1:]
            node = data
            for t in tables:
                node = node[t]
            if key not in node:
                raise ValueError(f"unknown sensor field {k!r}; fields of [{'.'.join(tables)}]: {sorted(x for x in node if not isinstance(node[x], dict))}")
            node[key] = list(v) if isinstance(v, tuple) else v
        data["name"] = f"{sensor.name}*"
        sensor = sensor_from_dict(data, where="sweep sensor")
    return sensor


def _scene(params: dict):
    from simbench.experiments.common import SCENES_DIR
    from simbench.scene import load_scene, paint_reflectance

    scene = load_scene(SCENES_DIR / f"{params['scene.name']}.toml")
    objs = list(scene.objects)
    if "scene.srgb8" in params:
        rgb = paint_reflectance(params["scene.srgb8"])
        objs = [dataclasses.replace(o, material=dataclasses.replace(o.material, rgb=rgb)) for o in objs]
    if "scene.depth_m" in params or "scene.tilt_deg" in params:
        first = dict(objs[0].params)
        key = "center_m" if "center_m" in first else "translate_m"
        if "scene.depth_m" in params:
            dz = float(params["scene.depth_m"]) - first[key][2]
            for i, o in enumerate(objs):
                q = dict(o.params)
                k = "center_m" if "center_m" in q else "translate_m"
                q[k] = (q[k][0], q[k][1], q[k][2] + dz)
                objs[i] = dataclasses.replace(o, params=tuple(sorted(q.items())))
        if "scene.tilt_deg" in params:
            q = dict(objs[0].params)
            rx, _, rz = q.get("rotation_deg", (0.0, 0.0, 0.0))
            q["rotation_deg"] = (rx, float(params["scene.tilt_deg"]), rz)
            objs[0] = dataclasses.replace(objs[0], params=tuple(sorted(q.items())))
    return dataclasses.replace(scene, objects=tuple(objs))


def _decoder(params: dict):
    from simbench.decode import DecoderParams
    from simbench.pattern import PatternSpec, parse_sequence

    fields = {k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("decoder.")}
    for k in ("depth_range_m",):
        if k in fields and isinstance(fields[k], list):
            fields[k] = tuple(fields[k])
    kinds = {"pattern.period_px": int, "pattern.order": int, "pattern.channels": str}
    pattern = {k.split(".", 1)[1]: kinds[k](v) for k, v in params.items() if k in kinds}
    if "pattern.sequence" in params:
        pattern["sequence"] = parse_sequence(str(params["pattern.sequence"]))
    return DecoderParams(pattern=PatternSpec(**pattern), **fields)


def run_one(params: dict, *, seed: int, cache_dir: str | None) -> dict:
    """Render (through the cache), record, decode and score one parameter set.  Returns the
    metrics and timings, or ``{"error": ...}``; never raises for a bad parameter value."""
    t0 = time.perf_counter()
    try:
        from simbench.experiments.common import RunConfig, Session
        from simbench.experiments.common import score
        import sys

        from simbench.variant import select_variant

        # a Dask worker arrives here without an entry point: choose the variant first (it must
        # steer Dr.Jit's libLLVM before Mitsuba is imported)
        if "mitsuba" not in sys.modules or sys.modules["mitsuba"].variant() is None:
            select_variant(None)
        decoder = _decoder(params)
        sensor = _sensor(params)
        config = RunConfig(
            sensor=sensor.name, spp=int(params["run.spp"]), sampler=str(params["run.sampler"]), camera_scale=float(params["run.camera_scale"]), max_depth=int(params["run.max_depth"]), seed=int(seed),
            placement_depth_mm=float(params["run.placement_depth_mm"]), placement_tilt_deg=float(params["run.placement_tilt_deg"]),
            board_bow_mm_per_m=float(params["run.board_bow_mm_per_m"]), board_waviness_mm=float(params["run.board_waviness_mm"]), decoder=decoder,
        )
        session = Session(config, out_dir=".", cache_dir=cache_dir, progress=lambda s: None, command="simbench ablate", sensor=sensor)
        raw = _scene(params)
        # every object placed by hand, each with its own seeded error (as Table 1 places its board)
        scene = session.prepare(session.place(raw, "ablate", [o.name for o in raw.objects]))
        t1 = time.perf_counter()
        cap = session.capture(scene, "ablate")[0]
        t2 = time.perf_counter()
        row = {}
        for mode, prefix in MODES.items():
            result = session.decode(cap, decoder, mode=mode)
            row.update({prefix + k: float(v) for k, v in score(cap, result, decoder.period_px, edge_band_px=EDGE_BAND_PX).items()})
        t3 = time.perf_counter()
        placement = session.seeds_used["ablate/placement"]
        row.update(render_seed=cap.seeds["render"], noise_seed=cap.seeds["noise"], placement_seed=placement["placement"], error="")
        row["timing"] = {"setup_s": t1 - t0, "render_record_s": t2 - t1, "decode_s": t3 - t2}
        return row
    except Exception as exc:  # noqa: BLE001 - a failing run is recorded, not fatal
        msg = f"{type(exc).__name__}: {exc}".splitlines()[0]
        return {"error": msg, "traceback": traceback.format_exc(limit=4), "timing": {"setup_s": time.perf_counter() - t0}}


def _worker_init(variant: str | None, parent_pid: int) -> None:
    from simbench.variant import select_variant

    _die_with_parent(parent_pid)
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


def _run_pool(todo: list[dict], *, workers: int, variant: str | None, cache: str | None, finished, run_fn, marker_dir: Path, progress) -> None:
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
        with ProcessPoolExecutor(max_workers=n_workers, mp_context=ctx, initializer=_worker_init, initargs=(variant, os.getpid())) as pool:
            futs = {pool.submit(_tracked, run_fn, str(marker_dir), r["key"], r["params"], r["seed"], cache): r for r in batch}
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
        progress(f"a worker process died (runs {sorted(r['run'] for r in suspects)} were on it): retrying them one at a time")
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
    a run that kills its worker twice is recorded as failed (:func:`_run_pool`).
    """
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
        status = f"error: {res['error']}" if res.get("error") else f"{sweep.plot_metric} {res.get(sweep.plot_metric, float('nan')):.4g}"
        progress(f"[ablate {sweep.name} {n}/{len(todo)}] run {run['run']}: {status}")

    if todo:
        if scheduler is not None:
            _run_dask(todo, scheduler, cache, finished, run_fn)
        elif workers > 1:
            _run_pool(todo, workers=workers, variant=variant, cache=cache, finished=finished, run_fn=run_fn, marker_dir=out / f".{sweep.name}.running", progress=progress)
        else:
            for r in todo:
                finished(r, run_fn(r["params"], seed=r["seed"], cache_dir=cache))
    rows = _rows(sweep, runs, done)
    _write(sweep, rows, runs, done, out, command)
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


def _rows(sweep: Sweep, runs: list[dict], done: dict) -> list[dict]:
    axis_names = [k for k, _ in sweep.axes]
    rows = []
    for r in runs:
        rec = done.get(r["key"], {})
        row = {"run": r["run"], "repeat": r["repeat"], **{k: _fmt(r["params"].get(k)) for k in axis_names}}
        for k in METRICS + REF_METRICS:
            row[k] = rec.get(k, float("nan"))
        row.update(seed=r["seed"], render_seed=rec.get("render_seed", ""), noise_seed=rec.get("noise_seed", ""), placement_seed=rec.get("placement_seed", ""), error=rec.get("error", "not run"))
        rows.append(row)
    return rows


def _fmt(v) -> str:
    if isinstance(v, (list, tuple)):
        return "+".join(map(str, v)) if v else "none"
    if isinstance(v, bool):
        return "on" if v else "off"
    return str(v)


def _write(sweep: Sweep, rows: list[dict], runs: list[dict], done: dict, out: Path, command: str) -> None:
    from simbench.experiments.common import git_commit, write_table
    from simbench.simulate import versions

    axis_names = [k for k, _ in sweep.axes]
    cols = ["run", "repeat", *axis_names, *METRICS, *REF_METRICS, "seed", "render_seed", "noise_seed", "placement_seed", "error"]
    files = [write_table(out / f"{sweep.name}.csv", rows, cols)]
    timing_rows = [{"run": r["run"], **done.get(r["key"], {}).get("timing", {})} for r in runs]
    files.append(write_table(out / f"{sweep.name}.timings.csv", timing_rows, ["run", "setup_s", "render_record_s", "decode_s"]))
    files.append(atomic_write_text(out / f"{sweep.name}.md", _markdown(sweep, rows, command)))
    files.append(atomic_write_bytes(out / f"{sweep.name}.png", _plot(sweep, rows)))
    base = {k: _fmt(v) for k, v in {**DEFAULTS, **sweep.base}.items()}
    save_json(out / f"{sweep.name}.provenance.json", {
        "command": command, "sweep_file": sweep.path, "sweep": {"name": sweep.name, "base": base, "axes": [[k, [_fmt(v) for v in vs]] for k, vs in sweep.axes], "combine": sweep.combine, "repeats": sweep.repeats, "seed": sweep.seed},
        "versions": versions(), "git_commit": git_commit(),
        "files": {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in files},
    })


def _groups(sweep: Sweep, rows: list[dict]) -> list[tuple[tuple, list[dict]]]:
    axis_names = [k for k, _ in sweep.axes]
    groups: dict[tuple, list[dict]] = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in axis_names), []).append(r)
    return list(groups.items())


def _mean(rows: list[dict], key: str) -> float:
    vals = [r[key] for r in rows if not r["error"] and isinstance(r[key], float) and math.isfinite(r[key])]
    return float(np.mean(vals)) if vals else float("nan")


def _markdown(sweep: Sweep, rows: list[dict], command: str) -> str:
    from simbench.experiments.common import markdown_table

    axis_names = [k for k, _ in sweep.axes]
    base = {**DEFAULTS, **sweep.base}
    lines = [
        f"# Ablation: {sweep.name}",
        "",
        sweep.description,
        "",
        f"Made by `{command}` (sweep `{sweep.path}`; {sweep.combine} over {', '.join(axis_names)}; {sweep.repeats} repetition(s) "
        f"with the same seeds in every parameter set, base seed {sweep.seed}). Every run with its seeds: `{sweep.name}.csv`; "
        f"timings: `{sweep.name}.timings.csv`; plot: `{sweep.name}.png`.",
        "",
        "Fixed: " + ", ".join(f"`{k}` = {_fmt(v)}" for k, v in sorted(base.items()) if k not in axis_names) + ".",
        "",
        "Every object of the scene is placed with the run's placement tolerance (seeded, independent of the reference "
        "plane; `run.placement_depth_mm`, `run.placement_tilt_deg`). Decoded by triangulation with the rig (paper Eq. 15; "
        "the first columns) and against the separately captured reference plane (Sec. 5.4; `ref. plane` columns).",
        "",
        "Mean over repetitions (failed runs left out; `errors` counts them):",
        "",
    ]
    body = []
    for combo, group in _groups(sweep, rows):
        errs = sum(1 for r in group if r["error"])
        body.append([
            *combo, *(f"{_mean(group, k):.4g}" for k in ("plane_mae_mm", "gt_mae_mm", "gt_rmse_mm", "gt_p95_mm", "edge5_mae_mm")), f"{100 * _mean(group, 'outlier_share'):.3f} %",
            f"{100 * _mean(group, 'completeness'):.2f} %", f"{_mean(group, 'stripe_order_errors'):.0f}",
            *(f"{_mean(group, k):.4g}" for k in ("ref_plane_mae_mm", "ref_gt_mae_mm")), f"{100 * _mean(group, 'ref_completeness'):.2f} %", str(errs),
        ])
    header = [
        *axis_names, "plane fit (mm)", "GT MAE (mm)", "GT RMSE (mm)", "GT p95 (mm)", f"MAE off edges (mm, {EDGE_BAND_PX} px)", "outliers (> 5 mm)", "completeness", "stripe-order errors",
        "ref. plane: plane fit (mm)", "ref. plane: GT MAE (mm)", "ref. plane: completeness", "errors",
    ]
    lines += markdown_table(header, body)
    failures = sorted({r["error"] for r in rows if r["error"]})
    if failures:
        lines += ["", "Errors:", ""] + [f"- {e}" for e in failures]
    return "\n".join(lines) + "\n"


def _plot(sweep: Sweep, rows: list[dict]) -> bytes:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    axis_names = [k for k, _ in sweep.axes]
    x_name = axis_names[0]
    x_vals = list(dict.fromkeys(r[x_name] for r in rows))
    series_names = axis_names[1:] if sweep.combine == "grid" else []
    series = list(dict.fromkeys(tuple(r[k] for k in series_names) for r in rows))
    fig, ax = plt.subplots(figsize=(6.4, 4.2), constrained_layout=True)
    numeric = all(_is_number(v) for v in x_vals)
    pos = [float(v) for v in x_vals] if numeric else list(range(len(x_vals)))
    for s in series:
        means, lo, hi = [], [], []
        for xv in x_vals:
            vals = [r[sweep.plot_metric] for r in rows if r[x_name] == xv and tuple(r[k] for k in series_names) == s and not r["error"] and math.isfinite(r[sweep.plot_metric])]
            means.append(np.mean(vals) if vals else np.nan)
            lo.append(np.min(vals) if vals else np.nan)
            hi.append(np.max(vals) if vals else np.nan)
        means, lo, hi = map(np.array, (means, lo, hi))
        label = ", ".join(f"{k.split('.')[-1]}={v}" for k, v in zip(series_names, s)) or sweep.plot_metric
        ax.errorbar(pos, means, yerr=[means - lo, hi - means], fmt="o-", capsize=3, label=label)
    if not numeric:
        ax.set_xticks(pos, x_vals, rotation=20, fontsize=8)
    ax.set_xlabel(x_name)
    ax.set_ylabel(sweep.plot_metric)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    import textwrap

    ax.set_title(textwrap.fill(f"ablation {sweep.name}: {sweep.description}", 90), fontsize=8)
    from simbench.experiments.common import figure_png

    return figure_png(fig, dpi=100)


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
