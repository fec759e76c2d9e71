"""One worker pool for every experiment runner - ``simbench reproduce``'s targets and ``simbench
ablate``'s runs: tasks run in this process, on local worker processes, or on a Dask cluster.

Local workers are spawned processes (a forked Mitsuba/Dr.Jit process is not safe to use) with
single-threaded numeric libraries (:func:`simbench.threads.single_thread_blas`: their threads
inside our processes oversubscribe the cores) and the run's Mitsuba variant; they die with the
process that started them (Linux ``PR_SET_PDEATHSIG``), so a killed run leaves none behind, and
their messages reach the caller's ``progress``.  Each worker holds one task at a time, taken in
the order given (callers give the longest first), so a free worker always takes the next one.

A worker that dies (kill -9, the out-of-memory killer) breaks the pool: the tasks that were
running on it and beside it are retried once, each alone in a fresh worker, and a task whose
worker dies again is handed to ``on_died``; the other tasks go on in a fresh pool.
"""

from __future__ import annotations

import logging
import os
import threading
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)

__all__ = ["Task", "run_tasks"]


@dataclass(frozen=True)
class Task:
    """One unit of work: ``fn(*args, **kwargs)`` of the pool's function, named by ``key``."""

    key: str
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)


# the worker process's own state: what the caller's setup made (e.g. an experiment session)
_worker_state: Any = None
# on a Dask worker, whose threads may run tasks side by side: each thread's own state
_thread = threading.local()
_dask_lock = threading.Lock()
# the Dask event topic workers' progress lines travel on to the client
PROGRESS_TOPIC = "simbench-progress"


def worker_state() -> Any:
    """In a worker process: what the pool's ``setup`` returned (None without one); on a Dask
    worker, the state this thread's ``setup`` made."""
    return getattr(_thread, "state", _worker_state)


def _start(variant: str | None, parent_pid: int, messages, setup, setup_args: tuple) -> None:
    global _worker_state
    from simbench.threads import limit_malloc_arenas, single_thread_blas
    from simbench.variant import select_variant

    _die_with_parent(parent_pid)
    single_thread_blas()
    limit_malloc_arenas()
    select_variant(variant)  # with the share of the cores cores_shared set (SIMBENCH_THREADS)
    if setup is not None:
        _worker_state = setup(messages.put, *setup_args)


def _die_with_parent(parent_pid: int) -> None:
    """Make this worker process die when the process that started it does."""
    import ctypes
    import signal

    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # not Linux: workers end when their task queue closes
    if os.getppid() != parent_pid:  # the parent died before the signal was armed
        os._exit(1)


def _call(fn: Callable, task: Task) -> Any:
    return fn(*task.args, **task.kwargs)


def run_tasks(
    tasks: Sequence[Task],
    fn: Callable[..., Any],
    *,
    on_result: Callable[[Task, Any], None],
    on_died: Callable[[Task], None],
    workers: int = 1,
    scheduler: str | object | None = None,
    variant: str | None = None,
    setup: Callable[..., Any] | None = None,
    setup_args: tuple = (),
    in_parent: Callable[[Task], Any] | None = None,
    on_error: Callable[[Task, Exception], None] | None = None,
    progress: Callable[[str], None] = log.info,
) -> None:
    """Run every task and hand each result to ``on_result(task, result)`` as it comes (called
    from one thread at a time).

    fn : a module-level function (spawned workers and Dask import it), run as
        ``fn(*task.args, **task.kwargs)``.  An exception it raises goes to ``on_error(task,
        exc)`` when given (the run goes on); without it, it stops the run: the tasks running
        finish, no other starts, and the exception is raised here.
    workers : local processes; 1 = every task in this process, in order.
    scheduler : a Dask scheduler address or ``distributed.Client`` instead of local workers
        (``fn`` then runs on the cluster's workers, with ``variant``, or each picking its own
        when None; the tasks are submitted in the order given, Dask's priority falling with it,
        so the longest given first start first).
    setup : run once in each local worker as ``setup(emit, *setup_args)`` (``emit(str)`` sends a
        line to ``progress``); what it returns is :func:`worker_state` there (with one worker and
        no ``in_parent``: made in this process for the run, ``emit`` being ``progress``).  On Dask, once per
        worker thread (a worker's threads may run tasks side by side), its lines sent as Dask
        events (:data:`PROGRESS_TOPIC`) that this process passes to ``progress``.
    in_parent : this process takes tasks too, as one of the ``workers``, running
        ``in_parent(task)`` (it has its imports and state already); None = it only waits.
    on_died : a task whose worker died twice (raise from it to stop the run).
    """
    tasks = list(tasks)
    if not tasks:
        return
    run_here = in_parent if in_parent is not None else (lambda task: _call(fn, task))
    if on_error is not None:
        on_result = _or_error(on_result, on_error)
        run_here = _caught(run_here)
        fn = _Caught(fn)
    if scheduler is not None:
        _run_dask(
            tasks, fn, scheduler, on_result, variant=variant, setup=setup, setup_args=setup_args, progress=progress
        )
    elif workers <= 1:
        with _parent_as_worker(None if in_parent is not None else setup, setup_args, progress):
            for task in tasks:
                on_result(task, run_here(task))
    else:
        _run_local(
            tasks,
            fn,
            workers=workers,
            variant=variant,
            on_result=on_result,
            on_died=on_died,
            setup=setup,
            setup_args=setup_args,
            in_parent=None if in_parent is None else run_here,
            progress=progress,
        )


@contextmanager
def _parent_as_worker(setup, setup_args: tuple, progress: Callable[[str], None]) -> Iterator[None]:
    """This process as the one worker: ``setup(progress, *setup_args)`` made its
    :func:`worker_state` (its lines go straight to ``progress``) while the tasks run here."""
    if setup is None:
        yield
        return
    had, before = hasattr(_thread, "state"), getattr(_thread, "state", None)
    _thread.state = setup(progress, *setup_args)
    try:
        yield
    finally:
        if had:
            _thread.state = before
        else:
            del _thread.state


class _Failed:
    """A task's exception, carried back as its result (picklable: the message and type name)."""

    def __init__(self, exc: Exception) -> None:
        self.exc = exc if _picklable(exc) else RuntimeError(f"{type(exc).__name__}: {exc}")


def _picklable(exc: Exception) -> bool:
    import pickle

    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:  # noqa: BLE001 - any failure to round-trip
        return False
    return True


class _Caught:
    """``fn`` with its exceptions returned as :class:`_Failed` (picklable for the workers)."""

    def __init__(self, fn: Callable) -> None:
        self.fn = fn

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return self.fn(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - handed to on_error
            _reraise_if_stopping()
            return _Failed(exc)


def _caught(run: Callable[[Task], Any]) -> Callable[[Task], Any]:
    def wrapped(task: Task) -> Any:
        try:
            return run(task)
        except Exception as exc:  # noqa: BLE001 - handed to on_error
            _reraise_if_stopping()
            return _Failed(exc)

    return wrapped


def _reraise_if_stopping() -> None:
    """Inside an ``except``: re-raise when the process was asked to stop (SIGTERM or Ctrl-C
    re-wrapped as a RuntimeError by a render), which is no failure of the task to record (a new
    user's audit: `ablate` recorded each Ctrl-C as a failed run and went on)."""
    from simbench import termination

    if termination.requested():
        raise


def _or_error(on_result: Callable, on_error: Callable) -> Callable:
    def deliver(task: Task, result: Any) -> None:
        if isinstance(result, _Failed):
            on_error(task, result.exc)
        else:
            on_result(task, result)

    return deliver


def _run_local(tasks, fn, *, workers, variant, on_result, on_died, setup, setup_args, in_parent, progress) -> None:
    import multiprocessing as mp

    import queue

    from simbench.threads import cores_shared, process_threads

    process_threads()  # a SIMBENCH_THREADS simbench refuses fails here, before any thread starts
    ctx = mp.get_context("spawn")
    messages = ctx.Queue()
    stop = threading.Event()

    def relay() -> None:
        # this process only reads the queue: it never takes the queue's shared write lock, which a
        # worker that exits (or dies) while sending can leave held (a run finished its targets and
        # then hung here, waiting to put its own end-of-messages marker behind that lock)
        while True:
            try:
                message = messages.get(timeout=0.1)
            except queue.Empty:
                if stop.is_set():
                    return
                continue
            progress(message)

    relay_thread = threading.Thread(target=relay, daemon=True)
    relay_thread.start()
    lock = threading.Lock()

    def deliver(task: Task, result: Any) -> None:
        with lock:
            on_result(task, result)

    todo = deque(tasks)
    deaths: dict[str, int] = {}
    init = (variant, os.getpid(), messages, setup, setup_args)
    # each process (this one among them when it takes tasks) takes its share of the cores; the
    # workers read it from the environment they are spawned with (simbench.variant.select_variant)
    with cores_shared(workers):
        try:
            while todo:
                broken = _pool_round(
                    todo, fn, ctx=ctx, init=init, workers=workers, in_parent=in_parent, deliver=deliver, lock=lock
                )
                if not broken:
                    continue
                progress(
                    f"a worker process died (tasks {sorted(t.key for t in broken)} were running): retrying them one "
                    "at a time"
                )
                for task in broken:
                    deaths[task.key] = deaths.get(task.key, 0) + 1
                    while deaths[task.key] < 2:
                        if _alone(task, fn, ctx=ctx, init=init, deliver=deliver):
                            break
                        deaths[task.key] += 1
                    if deaths[task.key] >= 2:
                        with lock:
                            on_died(task)
        finally:
            stop.set()  # the relay drains what the workers sent, then ends
            relay_thread.join()


def _pool_round(todo: deque, fn, *, ctx, init, workers: int, in_parent, deliver, lock) -> list[Task]:
    """Tasks from ``todo`` on one pool until it is empty, a task raises (re-raised here) or a
    worker dies; returns the tasks that were running on the pool when it broke.

    Only this (the calling) thread submits, so only it starts worker processes: a worker dies
    with the thread that started it (``PR_SET_PDEATHSIG`` follows the creating thread, not the
    process), and workers started by short-lived threads were killed when those ended - holding
    a queue's lock, which hung the run.  This process's own tasks (``in_parent``) run in a thread
    beside it."""
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    broken: list[Task] = []
    failed: list[BaseException] = []

    def take() -> Task | None:
        with lock:
            return todo.popleft() if todo and not failed and not broken else None

    def run_here(first: Task | None) -> None:
        task = first
        try:
            while task is not None:
                deliver(task, in_parent(task))
                task = take()
        except BaseException as exc:  # noqa: BLE001 - re-raised in the caller's thread
            with lock:
                failed.append(exc)
                todo.clear()  # the workers finish the task they hold, then stop

    spawned = workers - 1 if in_parent is not None else workers
    with ProcessPoolExecutor(max_workers=spawned, mp_context=ctx, initializer=_start, initargs=init) as pool:
        # this process takes the first task before the workers start: it has its imports and
        # state, while a spawned worker first imports (so the longest task starts at once here)
        here = None
        if in_parent is not None:
            here = threading.Thread(target=run_here, args=(take(),), daemon=True)
            here.start()
        running: dict = {}

        def fill() -> None:
            while len(running) < spawned and (task := take()) is not None:
                try:
                    running[pool.submit(_call, fn, task)] = task
                except BrokenProcessPool:
                    # a worker died since the last result came in: this task never ran; it goes
                    # back first in line for the next pool, and the running ones report the break
                    with lock:
                        todo.appendleft(task)
                    return

        try:
            fill()
            while running:
                done, _ = wait(list(running), return_when=FIRST_COMPLETED)
                for future in done:
                    task = running.pop(future)
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        with lock:
                            broken.append(task)
                        continue
                    except BaseException as exc:  # noqa: BLE001 - raised below, once the others are in
                        with lock:
                            failed.append(exc)
                        continue
                    deliver(task, result)
                fill()
        except BaseException:
            with lock:
                todo.clear()
            raise
        finally:
            if here is not None:
                here.join()
    if failed:
        raise failed[0]
    return broken


def _alone(task: Task, fn, *, ctx, init, deliver) -> bool:
    """``task`` on a fresh worker of its own: False when that worker dies too."""
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    with ProcessPoolExecutor(max_workers=1, mp_context=ctx, initializer=_start, initargs=init) as pool:
        try:
            result = pool.submit(_call, fn, task).result()
        except BrokenProcessPool:
            return False
    deliver(task, result)
    return True


def _dask_emit(line: str) -> None:
    """A progress line from a Dask worker to the client (:data:`PROGRESS_TOPIC`)."""
    from distributed import get_worker

    get_worker().log_event(PROGRESS_TOPIC, str(line))


def _dask_call(fn, task: Task, variant: str | None, setup, setup_args: tuple) -> Any:
    """``fn(task)`` on a Dask worker: the variant chosen (a worker arrives without an entry
    point; Dr.Jit's libLLVM must be steered before Mitsuba is imported) and this thread's
    ``setup`` state made once per run: a worker's threads outlive a run, so the state is kept
    with the setup and arguments that made it and made anew for a run that brings others
    (another config, cache or command on the same cluster)."""
    made_by = (setup, setup_args)
    with _dask_lock:  # one variant choice and setup at a time in a worker process
        _dask_variant(variant)
        if setup is not None and getattr(_thread, "made_by", None) != made_by:
            from simbench.threads import limit_malloc_arenas, single_thread_blas

            single_thread_blas()
            limit_malloc_arenas()
            _thread.state = setup(_dask_emit, *setup_args)
            _thread.made_by = made_by
    return _call(fn, task)


def _dask_variant(variant: str | None) -> None:
    import sys

    from simbench.variant import select_variant

    mi = sys.modules.get("mitsuba")
    current = None if mi is None else mi.variant()
    if current is None:
        select_variant(variant)
    elif variant is not None and current != variant:
        raise RuntimeError(
            f"this Dask worker runs Mitsuba variant {current!r} already; the run asks for {variant!r} "
            "(one variant per worker process: give the run its own workers)"
        )


def _run_dask(
    tasks: list[Task], fn, scheduler, on_result, *, variant=None, setup=None, setup_args=(), progress=log.info
) -> None:
    """The tasks on a Dask cluster (Dask retries a task whose worker dies, then raises
    ``KilledWorker``, handed on as the task's exception)."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise ValueError("--scheduler needs Dask distributed: pip install 'dask[distributed]'") from None
    client = scheduler if isinstance(scheduler, Client) else Client(scheduler)
    client.subscribe_topic(PROGRESS_TOPIC, lambda event: progress(event[1]))
    try:
        # priority falls with the order given: the longest tasks (given first) start first
        run_id = uuid.uuid4().hex[:12]  # task keys unique on a cluster that runs several runs
        futures = {
            client.submit(
                _dask_call,
                fn,
                task,
                variant,
                setup,
                setup_args,
                pure=False,
                key=f"simbench-{run_id}-{i}-{task.key}",
                priority=len(tasks) - i,
            ): task
            for i, task in enumerate(tasks)
        }
        for future in as_completed(list(futures)):
            try:
                result = future.result()
            except Exception as exc:  # noqa: BLE001 - e.g. KilledWorker: Dask retried and gave up
                result = _Failed(exc)
            if isinstance(result, _Failed) and not isinstance(fn, _Caught):
                raise result.exc
            on_result(futures[future], result)
    finally:
        client.unsubscribe_topic(PROGRESS_TOPIC)
        if client is not scheduler:
            client.close()
