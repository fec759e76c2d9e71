"""``simbench reproduce``: regenerate the paper's tables and figures, and check regressions.

Targets: ``table1``, ``table3``, ``fig9``, ``figures``, ``budget`` (the sensor error budget),
``render_noise`` (render against camera noise), ``flatness`` (error against board flatness),
``hard_scenes`` (interreflection, depth edges, printed albedo, saturated paint, gloss: issue 35;
not part of ``all``: :data:`ALL_TARGETS`) or ``all``.  The full run (``make
reproduce``) writes into ``results/``; ``--quick`` (640x480, 4 spp, 3 recordings per Fig. 9
depth) is the CI benchmark, whose key errors are compared with the thresholds in
``results/quick/thresholds.toml`` (:func:`check_thresholds`).
"""

from __future__ import annotations

import dataclasses
import heapq
import logging
import json
import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from simbench import validate
from simbench.experiments import (
    budget,
    fig9,
    figures,
    flatness,
    hard_scenes,
    motion,
    render_noise,
    robust_stages,
    table1,
    table3,
)
from simbench.experiments.common import RunConfig, Session, Split
from simbench.io import atomic_write_text, read_toml, save_json

log = logging.getLogger(__name__)

__all__ = [
    "TARGETS",
    "Target",
    "ALL_TARGETS",
    "check_targets",
    "reproduce",
    "load_thresholds",
    "check_thresholds",
    "same_values",
    "check_run_settings",
    "THRESHOLD_RUN_SETTINGS",
    "earlier_run",
    "thresholds_from",
    "task_summary",
    "list_schedule_s",
    "task_profile",
    "task_seconds",
    "record_task_seconds",
    "write_thresholds",
    "kept_thresholds",
]


@dataclass(frozen=True)
class Target:
    """One target of ``simbench reproduce``: the function that makes its files, whether ``all``
    runs it, and its place in the order the workers take targets in (``rank``: the longest
    first - warm quick run on 2 cores: fig9 7.0 s, table1 3.2 s, table3 2.1 s, figures 1.7 s,
    budget 1.0 s, the others 0.5 s; hard_scenes by its renders - so that no long target starts
    last)."""

    run: Callable[[Session], dict]
    in_all: bool
    rank: int
    # measured in parts that a pool runs side by side (``run`` is then ``split.run``)
    split: Split | None = None


def _split(split: Split, in_all: bool, rank: int) -> Target:
    return Target(split.run, in_all, rank, split=split)


# hard_scenes is not in ``all``: at full resolution its 26 scenes, each with the 12-exposure
# phase-shifting reference, take ~2-3 h of rendering on 2 cores from an empty cache (measured:
# 7-16 min a scene), more than the rest together; its quick form runs in CI (`make quick`:
# `reproduce all hard_scenes robust_stages --quick`; robust_stages decodes hard_scenes' captures
# again, without their reference, and is not in ``all`` either).  Every target is measured in
# parts (Split: its scenes, depths, boards, captures), so that workers take them side by side.
TARGETS: dict[str, Target] = {
    "table1": _split(table1.SPLIT, True, 1),
    "table3": _split(table3.SPLIT, True, 3),
    "fig9": _split(fig9.SPLIT, True, 0),
    "figures": _split(figures.SPLIT, True, 4),
    "budget": _split(budget.SPLIT, True, 5),
    "render_noise": _split(render_noise.SPLIT, True, 6),
    "flatness": _split(flatness.SPLIT, True, 7),
    "hard_scenes": _split(hard_scenes.SPLIT, False, 2),
    "robust_stages": _split(robust_stages.SPLIT, False, 2),
    "motion": _split(motion.SPLIT, True, 1),
}

# what ``all`` runs: the paper's tables and figures and the studies beside them
ALL_TARGETS = tuple(name for name, target in TARGETS.items() if target.in_all)


def _resolve(targets: list[str]) -> list[str]:
    named = set(targets or ["all"])
    if "all" in named:
        named = (named - {"all"}) | set(ALL_TARGETS)
    bad = sorted(t for t in named if t not in TARGETS)
    if bad:
        raise ValueError(f"unknown target(s) {bad}; valid: {list(TARGETS) + ['all']}")
    return [t for t in TARGETS if t in named]


def check_targets(targets: list[str]) -> list[str]:
    """The target names to run (``all`` = every one), or a ValueError listing the valid ones."""
    return _resolve(targets)


def reproduce(
    targets: list[str],
    *,
    config: RunConfig,
    out_dir: str | Path,
    cache_dir: str | Path | None,
    progress: Callable[[str], None] = log.info,
    command: str = "",
    workers: int = 1,
    scheduler: str | object | None = None,
) -> dict:
    """Run the targets; returns ``{metric path: value}`` of all of them (also written to
    ``<out_dir>/metrics.json`` merged with earlier runs' metrics of other targets).

    Each target runs with a seed log of its own (:meth:`Session.for_target`), so its outputs,
    provenance included, do not depend on which targets ran before it; ``workers`` > 1 runs the
    targets on that many workers (this process and spawned ones), each target's parts side by
    side, the costliest first (:class:`simbench.experiments.common.Split`: Table 1's boards,
    Fig. 9's depths, the hard scenes, ...), with the same outputs as one process.  It pays
    on a warm cache, where every target is decoding and scoring, and on a cold one too, where
    the targets' single-threaded work overlaps the other worker's renders (an entry two workers
    need is made once: :meth:`simbench.cache.RenderCache.get_or_make`).

    ``scheduler``: a Dask scheduler address (or a ``distributed.Client``) to run the targets on
    instead (:func:`simbench.experiments.workers.run_tasks`; ``workers`` is then the cluster's
    business): each worker runs this run's Mitsuba variant, reads and fills the render cache at
    ``cache_dir`` (give a path every worker sees: a shared filesystem), writes a target's files
    to a folder of its own and sends them back, and this process writes them into ``out_dir``
    (atomically) - so the outputs are those of a local run."""
    names = _resolve(targets)
    workers = validate.integer(workers, "workers", lo=1)
    if scheduler is not None and workers > 1:
        raise ValueError("--workers and --scheduler: choose one (the cluster's workers run the targets)")
    session = Session(config, out_dir=out_dir, cache_dir=cache_dir, progress=progress, command=command)
    metrics: dict = {}
    if scheduler is not None:
        metrics = _run_in_workers(names, session=session, workers=workers, progress=progress, scheduler=scheduler)
    elif workers == 1 or len(_tasks(names, config)) == 1:
        for name in names:
            metrics.update(_run_target(session, name))
    else:
        metrics = _run_in_workers(names, session=session, workers=workers, progress=progress)
    hits, misses = session.cache.hits, session.cache.misses
    path = Path(out_dir) / "metrics.json"
    merged = {}
    if path.is_file():
        try:
            merged = {k: v for k, v in json.loads(path.read_text()).items() if k.split("/")[0] not in names}
        except (ValueError, AttributeError):
            merged = {}
    save_json(path, dict(sorted({**merged, **metrics}.items())))
    progress(f"cache: {hits} hits, {misses} made; results in {out_dir}")
    if session.cache.made:
        # summed over the workers: on a cold cache, where the run's time went
        progress(f"made: {session.cache.made_summary()}")
    return metrics


def _run_target(session: Session, name: str) -> dict:
    with session.timed(f"{name} done"):
        return TARGETS[name].run(session.for_target())


def _worker_start(
    emit: Callable[[str], None], config: RunConfig, out_dir: str | None, cache_dir: str | None, command: str
):
    """A worker's session, made once (systems and calibrations are then shared by the targets it
    runs, as in one process); its progress goes to the parent through ``emit``.  ``out_dir``
    None (a cluster worker): each task writes into a temporary folder of its own, whose files
    :func:`_worker_task` sends back and then removes."""
    return Session(config, out_dir=out_dir or ".", cache_dir=cache_dir, progress=emit, command=command)


def _worker_run(name: str, ship: bool = False, part: tuple | None = None) -> tuple:
    """:func:`_worker_task` and the seconds it took (the run's task-time summary)."""
    t0 = time.perf_counter()
    result = _worker_task(name, ship, part)
    return (*result, time.perf_counter() - t0)


def _worker_task(name: str, ship: bool = False, part: tuple | None = None) -> tuple:
    """One task on a worker: the target ``name`` whole, or one ``part`` of it, ``(split, index,
    total, part name)`` (:class:`Split`).  Returns its metrics (a part: its result and seeds, see
    :meth:`Split.measure_part`), the cache hits, misses and entries made
    (:attr:`simbench.cache.RenderCache.made`) it counted (the counts start at zero per task)
    and, when ``ship`` (a cluster worker), the files it wrote ({path under the output folder:
    bytes}; removed here; a part writes none)."""
    from simbench.experiments.workers import worker_state

    import shutil
    import tempfile

    session = worker_state()
    cache = session.cache
    cache.hits, cache.misses, cache.made = 0, 0, {}
    if part is not None:
        split, index, total, part_name = part
        measured = split.measure_part(session, part_name, index=index, total=total)
        return measured, cache.hits, cache.misses, cache.made, {}
    if ship:
        # the task's own folder, removed whatever happens (a worker's one folder, kept for its
        # life, was left in /tmp when the worker ended: 82 after a day of tests here)
        session.out = Path(tempfile.mkdtemp(prefix="simbench-reproduce-"))
    try:
        metrics = _run_target(session, name)
        files = (
            {
                p.relative_to(session.out).as_posix(): p.read_bytes()
                for p in sorted(session.out.rglob("*"))
                if p.is_file()
            }
            if ship
            else {}
        )
    finally:
        if ship:
            shutil.rmtree(session.out, ignore_errors=True)
    return metrics, cache.hits, cache.misses, cache.made, files


def _tasks(names: list[str], config: RunConfig, seconds: dict[str, float] | None = None) -> list:
    """The pool's tasks, longest first: each target whole, a split target's parts one by one.

    With ``seconds`` (task -> seconds a run took, :func:`task_seconds`): the tasks it knows by
    their seconds, the longest first across every target, after those it does not know (which
    might be long).  Without, or among the unknown: by target rank, then within a target its
    costliest first (:class:`Split`).  The order decides only when a task starts: every file is
    written from the parts in their own order, the same whatever ran where."""
    from simbench.experiments.workers import Task

    tasks = []
    for name in sorted(names, key=lambda n: TARGETS[n].rank):
        split = TARGETS[name].split
        if split is None:
            tasks.append(Task(name, (name,)))
            continue
        total = len(split.parts(config))
        for index, part in split.ranked(config):
            tasks.append(Task(f"{name}/{part}", (name,), {"part": (split, index, total, part)}))
    if seconds:
        known = sorted((t for t in tasks if t.key in seconds), key=lambda t: -seconds[t.key])  # stable
        tasks = [t for t in tasks if t.key not in seconds] + known
    return tasks


# The seconds each task of a pooled run took, kept in the render cache's folder (one file; a run
# merges its own in, keeping each task's longest): a cold run's renders make a task long, a warm
# run's reuse short, and the order wants the long case.  Absent there, the seconds shipped in
# simbench/experiments/task_seconds.toml (a measured cold run).  Keyed by the run's profile.
TASK_SECONDS_NAME = "task_seconds.json"
_SHIPPED_TASK_SECONDS = Path(__file__).resolve().parent / "task_seconds.toml"


def task_profile(config: RunConfig, variant: str) -> str:
    """What a task's seconds are measured under: quick or full, and the Mitsuba variant."""
    return f"{'quick' if config.quick else 'full'} {variant}"


def task_seconds(cache_root: str | Path | None, profile: str) -> dict[str, float]:
    """Task -> seconds for ``profile``: the cache folder's record, else the shipped one's (the
    same quick/full profile of any variant), else {}.  An unreadable record counts as none."""
    if cache_root is not None:
        try:
            recorded = json.loads((Path(cache_root) / TASK_SECONDS_NAME).read_text()).get(profile)
        except (OSError, ValueError, AttributeError):
            recorded = None
        recorded = _seconds_table(recorded)
        if recorded:
            return recorded
    try:
        shipped = read_toml(_SHIPPED_TASK_SECONDS, what="task seconds")
    except (OSError, ValueError):
        return {}
    return _seconds_table(shipped.get(profile.split(" ")[0]))


def _seconds_table(table: object) -> dict[str, float]:
    """The finite, non-negative numbers of a task-seconds table (a record edited by hand keeps
    what it still holds of them: the order is a schedule, never worth failing a run for)."""
    if not isinstance(table, dict):
        return {}
    out = {}
    for key, value in table.items():
        if isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value) and value >= 0:
            out[str(key)] = float(value)
    return out


def record_task_seconds(cache_root: str | Path | None, profile: str, durations: dict[str, float]) -> None:
    """Merge a pooled run's task seconds into the cache folder's record (each task's longest;
    written atomically; two runs finishing together may lose one's update - the order is a
    schedule, not a result)."""
    if cache_root is None or not durations or not Path(cache_root).is_dir():
        return
    path = Path(cache_root) / TASK_SECONDS_NAME
    try:
        record = json.loads(path.read_text())
        if not isinstance(record, dict):
            record = {}
    except (OSError, ValueError):
        record = {}
    mine = _seconds_table(record.get(profile))
    for key, value in durations.items():
        mine[key] = round(max(float(value), mine.get(key, 0.0)), 1)
    record[profile] = dict(sorted(mine.items()))
    try:
        atomic_write_text(path, json.dumps(record, indent=1, sort_keys=True) + "\n")
    except OSError as exc:  # a read-only shared cache: the run's results stand
        log.warning("task seconds not recorded in %s (%s)", path, exc)


def list_schedule_s(seconds: Sequence[float], workers: int) -> float:
    """When the last of tasks lasting ``seconds`` ends if each, in the order given, starts on the
    first of ``workers`` workers to be free (list scheduling: a pool's behaviour with no task
    waiting for another's renders, and no start-up or writing time)."""
    if workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    free = [0.0] * min(workers, max(len(seconds), 1))
    for s in seconds:
        heapq.heappush(free, heapq.heappop(free) + float(s))
    return max(free)


def task_summary(durations: dict[str, float], *, workers: int | None) -> str:
    """One line on where a pooled run's time went: its tasks' seconds summed over the workers,
    the longest task, and what they bound a run on W workers to, ``max(longest, sum / W)`` -
    a lower bound (renders a task waits for on another worker, the writing after the pool and
    starting the workers come on top), for this run's workers and for 16; then what the pool's
    order makes of these seconds (:func:`list_schedule_s` with the tasks longest first, as a
    run that finds them recorded takes them, :func:`_tasks`)."""
    if not durations:
        return "tasks: none"
    total = sum(durations.values())
    key, longest = max(durations.items(), key=lambda kv: kv[1])
    bounds = list(dict.fromkeys(w for w in (workers, 16) if w))
    bound = ", ".join(f"{max(longest, total / w):.0f} s on {w}" for w in bounds)
    ordered = sorted(durations.values(), reverse=True)
    scheduled = ", ".join(f"{list_schedule_s(ordered, w):.0f} s on {w}" for w in bounds)
    return (
        f"tasks: {len(durations)}, {total:.0f} worker-s in all, the longest {longest:.0f} s ({key}); "
        f"a run takes at least {bound} workers; longest first, {scheduled}"
    )


def _died(task) -> None:
    raise RuntimeError(f"a reproduce worker process died twice on task {task.key} (killed, or out of memory)")


def _run_in_workers(
    names: list[str],
    *,
    session: Session,
    workers: int,
    progress: Callable[[str], None],
    scheduler: str | object | None = None,
) -> dict:
    """The targets on ``workers`` workers of :mod:`simbench.experiments.workers`: this process
    (it has its imports and its session already) and ``workers - 1`` spawned processes, each
    taking the next task (:func:`_tasks`), longest first, when it is free; or on the Dask
    cluster ``scheduler`` (every task there, a whole target's files sent back and written here).
    A split target's parts are measured on the workers and its files written here once all are
    in.  The cache's counts of the other workers are added to ``session``'s."""
    from simbench.experiments.workers import run_tasks
    from simbench.io import write_files

    done: dict[str, dict] = {}
    durations: dict[str, float] = {}  # task -> seconds on its worker
    parts: dict[str, dict[int, tuple]] = {}  # split target -> part index -> (result, seeds)
    counts: list[tuple] = []  # the other workers' cache hits, misses and entries made, per task
    ship = scheduler is not None

    def on_result(task, result) -> None:
        value, *count, files, seconds = result
        durations[task.key] = seconds
        part = task.kwargs.get("part")
        if part is None:
            done[task.key] = value
        else:
            parts.setdefault(task.args[0], {})[part[1]] = value
        counts.append(tuple(count))
        # a target's files and its provenance as one set, as a local run writes them (Session.write_results)
        write_files({session.out / rel: data for rel, data in files.items()})

    def here(task):
        t0 = time.perf_counter()
        part = task.kwargs.get("part")
        if part is None:
            return _run_target(session, task.key), 0, 0, {}, {}, time.perf_counter() - t0
        split, index, total, name = part
        return split.measure_part(session, name, index=index, total=total), 0, 0, {}, {}, time.perf_counter() - t0

    cache_root = None if session.cache.root is None else str(session.cache.root)
    profile = task_profile(session.config, session.variant)
    tasks = _tasks(names, session.config, task_seconds(cache_root, profile))

    def collect(name: str) -> None:
        split = TARGETS[name].split
        measured = parts.get(name, {})
        total = len(split.parts(session.config))
        if name in done or len(measured) < total:
            return
        # its parts' time on the workers, and the writing here (alone, "budget done (0.0 s)" read
        # as the target's time: a third audit)
        worker_s = sum(s for k, s in durations.items() if k.startswith(f"{name}/"))
        t0 = time.perf_counter()
        done[name] = split.collect(session.for_target(), [measured[i] for i in range(total)])
        progress(f"{name} done ({total} parts, {worker_s:.1f} worker-s; written in {time.perf_counter() - t0:.1f} s)")

    split_names = [name for name in names if TARGETS[name].split is not None]
    try:
        run_tasks(
            [dataclasses.replace(t, kwargs={**t.kwargs, "ship": ship}) for t in tasks],
            _worker_run,
            workers=min(workers, len(tasks)),
            scheduler=scheduler,
            variant=session.variant,
            setup=_worker_start,
            setup_args=(session.config, None if ship else str(session.out), cache_root, session.command),
            in_parent=None if ship else here,
            on_result=on_result,
            on_died=_died,
            progress=progress,
        )
    except BaseException:
        # a part failed (or the run was stopped): the targets whose parts are all in are still
        # written, so that a long run keeps what it finished; then the error goes on
        for name in split_names:
            collect(name)
        raise
    progress(task_summary(durations, workers=min(workers, len(tasks)) if scheduler is None else None))
    record_task_seconds(cache_root, profile, durations)
    session.cache.hits += sum(c[0] for c in counts)  # in the parent's counts already: its own tasks'
    session.cache.misses += sum(c[1] for c in counts)
    for c in counts:
        session.cache.add_made(c[2])
    for name in split_names:
        collect(name)
    return {k: v for name in names for k, v in done[name].items()}


# ---------------------------------------------------------------------------------------
# Regression thresholds.  A rule per kind of metric, applied to the measured quick values:
#   errors (``*_mm``)         max = measured * (1 + margin) + 0.02 mm
#   completeness              min = measured - 0.01 (one percentage point), floor 0
#   stripe-order errors       max = measured * (1 + margin) + 20 pixels
#   stripe-order error rate   max = measured * (1 + margin) + 0.0005
#   the noise studies' spreads (NOISE_SPREADS) also min = measured * (1 - margin) - 0.02 mm, floor 0
# The margin (default 0.25) covers run-to-run differences between machines (the llvm and
# scalar variants sample differently); a change to the decoder that makes a key error 25 %
# worse fails CI.
#   A row that decodes under MIN_SCORED_COMPLETENESS of its region gets no error threshold: its
# errors are the mean of a few hundred stray pixels (mostly in the wrong stripe order), which
# render noise alone moves by tens of mm - measured: the paper decoder on the quick run's paint
# blue board (0.46 % decoded, 73 % of those in the wrong order) went from 55.8 to 78.5 mm when
# the ambient render's 1 % noise was taken out (675e7f2).  Such a row is held by its stripe-order
# errors (count and rate) alone: its completeness threshold is 0 by the rule above.  A row that
# decodes when the thresholds are written keeps every threshold (a run in which it decodes under
# 1 % fails its completeness).
MIN_SCORED_COMPLETENESS = 0.01

# The depth spreads the noise studies measure (render_noise, hard_scenes' render_noise parts): a
# spread is the simulator's noise carried through the decoder, so a smaller one is not a better
# decoder but, as likely, a study that no longer sees its noise - e.g. the "own renders" taking
# the main render's seed, which makes the render noise 0 and every scene's ratio "met".  They are
# held from below too (the max alone let such a collapse pass CI).
NOISE_SPREADS = ("render_sd_mm", "camera_sd_mm")


def _rules(name: str, value: float, margin: float) -> list[tuple[str, float]]:
    """The bounds (``("max" | "min", value)``) a metric of this name measured at ``value`` gets."""
    leaf = name.rsplit("/", 1)[-1]
    if leaf in NOISE_SPREADS and value is not None and not math.isnan(value):
        return [*_rule(name, value, margin), ("min", round(max(0.0, value * (1 - margin) - 0.02), 4))]
    return _rule(name, value, margin)


def _rule(name: str, value: float, margin: float) -> list[tuple[str, float]]:
    leaf = name.rsplit("/", 1)[-1]
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return []
    if leaf == "bias_mm":
        return []  # signed: a "max" would not bound its size
    if leaf.endswith("_mm"):
        return [("max", round(value * (1 + margin) + 0.02, 4))]
    if leaf == "completeness":
        return [("min", round(max(0.0, value - 0.01), 4))]
    if leaf == "stripe_order_errors":
        return [("max", int(math.ceil(value * (1 + margin) + 20)))]
    # shares of pixels (the wrong shares of a region, of every decoded pixel, of the whole image)
    if leaf == "stripe_order_error_rate" or leaf.startswith("wrong_share"):
        return [("max", round(value * (1 + margin) + 0.0005, 6))]
    return []


def _too_sparse(name: str, metrics: dict) -> bool:
    """An error metric of a row whose own completeness is under MIN_SCORED_COMPLETENESS."""
    prefix, leaf = name.rsplit("/", 1) if "/" in name else ("", name)
    done = metrics.get(f"{prefix}/completeness")
    return leaf.endswith("_mm") and done is not None and not done >= MIN_SCORED_COMPLETENESS


def thresholds_from(metrics: dict, *, margin: float) -> dict:
    out = {}
    for name, value in sorted(metrics.items()):
        if _too_sparse(name, metrics):
            continue
        bounds = _rules(name, value, margin)
        if bounds:
            out[name] = {"measured": value, **dict(bounds)}
    return out


def write_thresholds(
    path: str | Path,
    metrics: dict,
    *,
    margin: float,
    command: str,
    targets: list[str] | None = None,
    quick: bool | None = None,
    settings: dict | None = None,
) -> Path:
    """A thresholds TOML from measured metrics (the header states the rules and the margin).

    ``targets``: the targets the metrics come from, where ``path`` holds thresholds of others
    too - its entries of other targets are kept (as ``metrics.json`` keeps their metrics), so that
    an intended change to one target re-derives that target's thresholds only; the header keeps
    the command that wrote the file and adds this one.  The file's margin must be ``margin``.  A
    run of every target writes it anew.  ``quick``: whether the run was ``--quick`` (the header's
    first line names the runs the file is for; a file of the other resolution that would keep
    entries is refused: :func:`kept_thresholds`).  ``settings``: the run's
    :data:`THRESHOLD_RUN_SETTINGS`, stated in the header (a check of a run at other settings is
    refused: :func:`check_run_settings`)."""
    from simbench import validate

    path = Path(path)
    kept = kept_thresholds(path, targets, margin=margin, quick=quick) if targets is not None else {}
    written_by = f"# Written by: {command}"
    if kept:  # else the run covers every target of the file: written anew
        text = path.read_text(encoding="utf-8").splitlines()
        header = [line for line in text if line.startswith("# Written by: ")][:1] or ["# Written by: (not recorded)"]
        this = f"# Then for {' '.join(_resolve(targets))}: "
        updates = [line for line in text if line.startswith("# Then for ") and not line.startswith(this)]
        written_by = "\n".join([*header, *updates, this + command])
    runs = {True: "quick runs (`--quick`)", False: "full-resolution runs", None: "runs"}[quick]
    lines = [
        f"# Regression thresholds for {runs}: `simbench reproduce TARGETS --check FILE` fails a run outside them.",
        written_by,
        f"# Margin {margin!r}: errors (mm) max = measured*(1+margin)+0.02; completeness min = measured-0.01;",
        "# stripe-order errors max = measured*(1+margin)+20; their rate and the shares of pixels > 5 mm wrong",
        "# (wrong_share, wrong_share_all, wrong_share_image) max = measured*(1+margin)+0.0005; the noise studies'",
        f"# spreads ({', '.join(NOISE_SPREADS)}) also min = measured*(1-margin)-0.02 (a collapsed spread is a study"
        " that no longer sees its noise). No error",
        f"# threshold for a row that decodes under {MIN_SCORED_COMPLETENESS:.0%} of its region (the errors of a few"
        " stray pixels): its stripe-order errors hold it.",
        "# Regenerate only for an intended change, and say why in the commit.",
        *([_settings_line(settings)] if settings else []),
        "",
    ]
    table = {**kept, **thresholds_from(metrics, margin=validate.number(margin, "margin", lo=0.0))}
    for name, t in sorted(table.items()):
        lines.append(f'["{name}"]')
        for k, v in t.items():
            lines.append(f"{k} = {v!r}" if not isinstance(v, float) else f"{k} = {v:.6g}")
        lines.append("")
    return atomic_write_text(path, "\n".join(lines))


# the run settings a thresholds file states and a check must share (the measured values depend on
# each; a decoder developer's audit, 2026-11-30: a quick run at --spp 16 was checked against 4-spp
# thresholds without a word).  The decoder is not among them: its changes are what a check measures.
THRESHOLD_RUN_SETTINGS = ("sensor", "spp", "sampler", "max_depth", "seed", "camera_scale")
_SETTINGS_PREFIX = "# Run settings: "


def _settings_line(settings: dict) -> str:
    return _SETTINGS_PREFIX + ", ".join(f"{k}={settings[k]!r}" for k in THRESHOLD_RUN_SETTINGS if k in settings)


def check_run_settings(path: str | Path, settings: dict) -> None:
    """A ValueError when thresholds file ``path`` states run settings
    (:data:`THRESHOLD_RUN_SETTINGS`, its header's ``# Run settings:`` line) that ``settings`` (this
    run's) differ from; a file that states none (written before the line was) is taken as it is."""
    import ast

    text = Path(path).read_text(encoding="utf-8") if Path(path).is_file() else ""
    line = next((ln for ln in text.splitlines() if ln.startswith(_SETTINGS_PREFIX)), None)
    if line is None:
        return
    theirs = {}
    for item in line[len(_SETTINGS_PREFIX) :].split(", "):
        key, _, value = item.partition("=")
        try:
            theirs[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            raise ValueError(f"{path}: unreadable run settings line {line!r}") from None
    differ = [k for k in THRESHOLD_RUN_SETTINGS if k in theirs and k in settings and theirs[k] != settings[k]]
    if differ:
        them = ", ".join(f"{k}={theirs[k]!r}" for k in differ)
        mine = ", ".join(f"{k}={settings[k]!r}" for k in differ)
        raise ValueError(
            f"{path} holds thresholds of runs at {them}; this run is at {mine}: a check compares like runs only "
            "(write thresholds for these settings with --write-thresholds FILE)"
        )


def kept_thresholds(path: str | Path, targets: list[str], *, margin: float, quick: bool | None = None) -> dict:
    """The entries of thresholds file ``path`` that a run of ``targets`` leaves as they are
    (:func:`write_thresholds`): none if the file does not exist or the run makes every target
    (the file is then written anew, unread - a broken file is mended so); entries of a target
    simbench no longer has are dropped (a check would refuse them).  A ValueError if entries
    are kept and the file's margin is not ``margin`` or (``quick`` given) it was written by a run
    of the other resolution (its header states one margin and one command)."""
    path = Path(path)
    names = set(_resolve(targets))
    if not path.is_file() or names == set(TARGETS):
        return {}
    table = load_thresholds(path)
    gone = sorted({k.split("/")[0] for k in table} - set(TARGETS))
    if gone:
        log.warning("%s: dropping the thresholds of %s, no longer a target", path, ", ".join(gone))
    others = set(TARGETS) - names
    kept = {k: v for k, v in table.items() if k.split("/")[0] in others}
    if not kept:
        return {}
    held = ", ".join(sorted({k.split("/")[0] for k in kept}))
    text = path.read_text(encoding="utf-8")
    found = re.search(r"^# Margin (\S+):", text, flags=re.M)
    if found is None:
        raise ValueError(f"{path}: states no margin; write it anew with a run of every target it holds ({held})")
    if float(found.group(1)) != margin:
        raise ValueError(
            f"{path}: its margin is {found.group(1)}, not {margin!r}; to change the margin write the whole file "
            f"anew (a run that also makes {held})"
        )
    _check_resolution(path, quick)
    return kept


def _check_resolution(path: Path, quick: bool | None) -> None:
    """A ValueError when thresholds file ``path`` was written by a run of the other resolution
    than ``quick`` (its header says which; a file that does not is taken as it is)."""
    if quick is None:
        return
    text = Path(path).read_text(encoding="utf-8")
    # the header's first line names the runs (:func:`write_thresholds`); a file written before it
    # did, by the command that wrote it
    header = re.search(r"^# Regression thresholds for (quick|full-resolution) runs", text, flags=re.M)
    written = re.search(r"^# Written by: (.*)$", text, flags=re.M)
    if header is not None:
        theirs, what = header.group(1) == "quick", f"its header: {header.group(1)} runs"
    elif written is not None and written.group(1) != "(not recorded)":
        theirs, what = "--quick" in written.group(1).split(), written.group(1)
    else:
        return
    if theirs != quick:
        raise ValueError(
            f"{path} holds thresholds of a {'quick' if theirs else 'full'} run ({what}); "
            f"this run is {'quick' if quick else 'full'}"
        )


def load_thresholds(path: str | Path) -> dict:
    """A thresholds file, checked: every entry a table with a finite ``max`` and/or ``min``."""
    from simbench import validate

    table = read_toml(path, what="thresholds")
    for name, t in table.items():
        if not isinstance(t, dict) or not ({"max", "min"} & set(t)):
            raise ValueError(f"{path}: [{name!r}] needs max or min")
        for k in ("max", "min"):
            if k in t:
                validate.number(t[k], f"{path}: [{name!r}] {k}")
        # the bound that holds a regression back (a decoder developer's audit, 2026-11-30: `min = 0`
        # written in place of an error's `max` passed every run)
        for side, _ in _rules(str(name), 1.0, 0.0):
            if side not in t:
                leaf = str(name).rsplit("/", 1)[-1]
                worse = (
                    f"a {'higher' if side == 'max' else 'lower'} {leaf} is worse"
                    if leaf not in NOISE_SPREADS
                    else f"{leaf} is a noise study's spread, held from both sides"
                )
                raise ValueError(
                    f"{path}: [{name!r}] has no {side}, and {worse}: give {side} (the bound that fails a regression)"
                )
    return table


def check_threshold_names(
    table: dict, targets: list[str], *, path: str | Path = "thresholds", quick: bool | None = None
) -> None:
    """Before a run: every metric a thresholds file names must come from one of the targets the
    run makes (``TARGET/.../METRIC``), so a misnamed or unselected metric fails at once rather
    than as "not measured" after the run.  (The parts between the target and the metric depend
    on what the run makes; they are checked after it, as ``not measured``.)  ``quick`` given:
    the file must have been written by a run of that resolution (a quick run checked against
    full-resolution thresholds fails them, or passes them, for the resolution alone)."""
    if quick is not None and Path(path).is_file():
        _check_resolution(Path(path), quick)
    names = set(check_targets(targets))
    for name in table:
        parts = str(name).split("/")
        if len(parts) < 2 or parts[0] not in TARGETS:
            raise ValueError(
                f"{path}: metric {name!r} is not made by the targets of this run ({sorted(names)}) nor by any other; "
                "metric names are TARGET/.../METRIC as in results/quick/thresholds.toml"
            )
    # a file of several targets' entries checks a run of some of them on theirs (a new user's audit:
    # `reproduce budget --check results/quick/thresholds.toml` was refused); one with none of this
    # run's would check nothing - nor would an empty one (a decoder developer's audit, 2026-11-30:
    # an empty or comment-only file printed "all metrics within" and exited 0)
    if not table:
        raise ValueError(f"{path}: holds no thresholds (an empty table checks nothing)")
    if not any(str(name).split("/")[0] in names for name in table):
        held = sorted({str(name).split("/")[0] for name in table})
        raise ValueError(
            f"{path}: its metrics are not made by the targets of this run ({sorted(names)}): it holds {held}'s only"
        )


def check_thresholds(metrics: dict, thresholds_path: str | Path, *, targets: list[str] | None = None) -> list[str]:
    """Failures (one line each) of ``metrics`` against a thresholds file; empty = pass.

    A metric named in the file but NaN in ``metrics`` fails too; one the run did not make at all
    is a ``ValueError`` naming it (a misspelt name is the file's fault, not a regression: it exited
    1 as one, a decoder developer's audit, 2026-11-30).  ``targets``: only the entries of these
    targets are checked (a run of some of the file's targets).
    """
    table = load_thresholds(thresholds_path)
    if targets is not None:
        run = set(check_targets(targets))
        table = {k: v for k, v in table.items() if str(k).split("/")[0] in run}
    unknown = sorted(name for name in table if name not in metrics)
    if unknown:
        import difflib

        near = {n: difflib.get_close_matches(n, list(metrics), n=1, cutoff=0.9) for n in unknown[:5]}
        shown = "; ".join(f"{n}{f' (did you mean {m[0]}?)' if m else ''}" for n, m in near.items())
        more = f" and {len(unknown) - 5} more" if len(unknown) > 5 else ""
        raise ValueError(f"{thresholds_path}: {len(unknown)} metric(s) this run does not make: {shown}{more}")
    failures = []
    for name, t in sorted(table.items()):
        v = metrics.get(name)
        if v is None or (isinstance(v, float) and math.isnan(v)):
            failures.append(f"{name}: not measured")
            continue
        if "max" in t and v > t["max"]:
            failures.append(f"{name} = {v:.6g} > max {t['max']} (measured when set: {t.get('measured')})")
        if "min" in t and v < t["min"]:
            failures.append(f"{name} = {v:.6g} < min {t['min']} (measured when set: {t.get('measured')})")
    return failures


def earlier_run(reference_path: str | Path) -> dict | str:
    """What :func:`same_values` compares with, read now: an earlier run's ``metrics.json`` and
    the CPU its targets' provenance files record ({"path", "metrics", "cpu_of"}), or why not (a
    string).  Read before a run that may write over it (a decoder developer's audit, 2026-11-30:
    `reproduce --quick --check results/quick/thresholds.toml`, writing into results/quick, compared
    its metrics with themselves: "288 of 288 the same bits")."""
    path = Path(reference_path)
    try:
        reference = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        return f"no comparison with {path} ({type(exc).__name__})"
    cpu_of: dict[str, str] = {}  # target -> the CPU its provenance records
    for prov in sorted(path.parent.rglob("*.provenance.json")):
        try:
            cpu = json.loads(prov.read_text()).get("versions", {}).get("cpu")
        except (OSError, ValueError):
            continue
        if cpu:
            cpu_of[prov.name.split(".")[0]] = cpu
    return {"path": path, "metrics": reference, "cpu_of": cpu_of}


def same_values(metrics: dict, reference: str | Path | dict) -> str:
    """One line on how many of ``metrics`` equal, bit for bit, those of an earlier run's
    ``metrics.json`` (the committed one beside a thresholds file: its path, or
    :func:`earlier_run`'s reading of it), with the CPU each run was made on and the metric
    farthest apart - what a check on another machine tells about reproducibility across CPUs
    (docs/rendering.md), which thresholds cannot."""
    from simbench.sim.keys import cpu_model

    earlier = reference if isinstance(reference, dict) else earlier_run(reference)
    if isinstance(earlier, str):
        return earlier
    path, reference, cpu_of = earlier["path"], earlier["metrics"], earlier["cpu_of"]
    cpus = sorted(set(cpu_of.values()))
    if len(cpus) <= 1:
        made_on = cpus[0] if cpus else "a CPU not recorded"
    else:  # a file remade in part elsewhere: which targets each CPU made
        made_on = "; ".join(f"{c}: {', '.join(sorted(t for t, v in cpu_of.items() if v == c))}" for c in cpus)

    def equal(a: object, b: object) -> bool:
        both_nan = isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)
        return both_nan or a == b

    here = cpu_model()
    shared = sorted(set(metrics) & set(reference))
    differ = [k for k in shared if not equal(metrics[k], reference[k])]
    line = (
        f"{len(shared) - len(differ)} of {len(shared)} metrics the same bits as {path} "
        f"(made on {made_on}; this run on {here})"
    )
    if len(cpus) > 1 and here in cpus:
        mine = [k for k in shared if cpu_of.get(k.split("/")[0]) == here]
        apart = set(differ)
        same = sum(1 for k in mine if k not in apart)
        line += f"; of the {len(mine)} made on this run's CPU, {same} the same bits"
    numeric = [
        (abs(metrics[k] - reference[k]) / max(abs(reference[k]), 1e-12), k)
        for k in differ
        if isinstance(metrics[k], float | int)
        and isinstance(reference[k], float | int)
        and math.isfinite(metrics[k])
        and math.isfinite(reference[k])
    ]
    if numeric:
        rel, key = max(numeric)
        line += f"; the farthest apart: {key}, {rel:.2g} of its value"
    return line
