"""The experiments' worker pool (simbench.experiments.workers): every task's result exactly
once, in this process and spawned workers; failures raised or handed on; dead workers retried."""

from __future__ import annotations

import pytest

from simbench.experiments.workers import Task, run_tasks
from tests import worker_helpers


def _collect(tasks, fn, **kw) -> tuple[dict, list, list]:
    results, died, lines = {}, [], []

    def on_result(task, result):
        assert task.key not in results, "a result delivered twice"
        results[task.key] = result

    run_tasks(tasks, fn, on_result=on_result, on_died=died.append, progress=lines.append, **kw)
    return results, died, lines


def test_every_task_runs_once_in_this_process_and_the_workers():
    tasks = [Task(str(i), (i,)) for i in range(8)]
    kw = {"workers": 2, "variant": "scalar_rgb", "setup": worker_helpers.setup, "setup_args": ("w",)}
    # the spawned workers alone: each made its state with the setup, whose line came back
    results, died, lines = _collect(tasks, worker_helpers.square, **kw)
    assert {k: v for k, v in results.items()} == {str(i): (i * i, "w") for i in range(8)}
    assert not died and "worker w ready" in lines
    # this process takes tasks too
    results, _, _ = _collect(tasks, worker_helpers.square, in_parent=lambda task: (task.args[0] ** 2, "parent"), **kw)
    assert {k: v[0] for k, v in results.items()} == {str(i): i * i for i in range(8)}
    assert {v[1] for v in results.values()} <= {"parent", "w"} and results["0"][1] == "parent"  # the first task here


def test_each_worker_process_takes_its_share_of_the_cores(monkeypatch):
    """With N processes on C cores each sizes its thread pools (Dr.Jit's render threads, OpenCV's,
    the decoder's row bands by default) to C // N, this process too while the run lasts; then
    they are restored.  A share the user set (SIMBENCH_THREADS) is every process's."""
    import cv2
    import drjit as dr

    from simbench.threads import THREADS_VARIABLE, usable_cpus

    monkeypatch.delenv(THREADS_VARIABLE, raising=False)
    share = max(1, usable_cpus() // 2)
    before = (cv2.getNumThreads(), dr.thread_count())
    here = []

    def in_parent(task):
        here.append(worker_helpers.threads_seen(0))
        return here[-1]

    tasks = [Task(str(i), (i,)) for i in range(4)]
    results, _, _ = _collect(tasks, worker_helpers.threads_seen, workers=2, variant="scalar_rgb", in_parent=in_parent)
    assert set(results.values()) == {(str(share), share, share)}, results
    assert here and THREADS_VARIABLE not in __import__("os").environ
    assert (cv2.getNumThreads(), dr.thread_count()) == before
    monkeypatch.setenv(THREADS_VARIABLE, "3")
    results, _, _ = _collect(tasks, worker_helpers.threads_seen, workers=2, variant="scalar_rgb")
    assert set(results.values()) == {("3", 3, 3)}, results


def test_one_worker_runs_everything_here_in_order():
    order = []
    tasks = [Task(str(i), (i,)) for i in range(4)]
    run_tasks(tasks, worker_helpers.square, on_result=lambda t, r: order.append(t.key), on_died=None, workers=1)
    assert order == ["0", "1", "2", "3"]


def test_an_exception_stops_the_run_or_goes_to_on_error():
    tasks = [Task(str(i), (i, 2)) for i in range(5)]
    with pytest.raises(ValueError, match="task 2 failed on purpose"):
        _collect(tasks, worker_helpers.fails_on, workers=2, variant="scalar_rgb")
    errors = {}
    results, _, _ = _collect(
        tasks,
        worker_helpers.fails_on,
        workers=2,
        variant="scalar_rgb",
        on_error=lambda task, exc: errors.setdefault(task.key, str(exc)),
    )
    assert set(results) == {"0", "1", "3", "4"} and errors == {"2": "task 2 failed on purpose"}


def test_a_dead_worker_costs_its_task_one_retry_and_a_second_death_goes_to_on_died(tmp_path):
    names = ["ok1", "die1", "ok2", "ok3"]
    once = [Task(n, (str(tmp_path / "once" / n),), {"times": 1}) for n in names]
    (tmp_path / "once").mkdir()
    results, died, lines = _collect(once, worker_helpers.dies_on, workers=2, variant="scalar_rgb")
    assert sorted(results) == sorted(names) and not died
    assert any("a worker process died" in line for line in lines)
    (tmp_path / "twice").mkdir()
    always = [Task(n, (str(tmp_path / "twice" / n),), {"times": 5}) for n in names]
    results, died, _ = _collect(always, worker_helpers.dies_on, workers=2, variant="scalar_rgb")
    assert sorted(results) == ["ok1", "ok2", "ok3"] and [t.key for t in died] == ["die1"]
    assert (tmp_path / "twice" / "die1").read_text() == "2"  # killed twice, not more
