"""BLAS thread counts set by the entry points (simbench.threads), in fresh interpreters: an
in-process test would see whatever BLAS settings earlier tests left."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

_REPORT = textwrap.dedent(
    """
    import json, os
    from threadpoolctl import threadpool_info
    def blas():
        return [i for i in threadpool_info() if i["user_api"] == "blas"]
    def report():
        return {
            "threads": sorted({(i["filepath"], i["num_threads"]) for i in blas()}),
            "env": os.environ.get("OPENBLAS_NUM_THREADS"),
        }
    """
)


def _run(code: str) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    out = subprocess.run(
        [sys.executable, "-c", _REPORT + textwrap.dedent(code)], capture_output=True, text=True, timeout=300, env=env
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_cli_runs_blas_on_one_thread_also_in_libraries_loaded_later():
    """After ``simbench`` starts, numpy's BLAS and a BLAS loaded afterwards (SciPy's own) run on
    one thread, and spawned children inherit it through the environment; a process that only
    imports simbench keeps its BLAS settings."""
    untouched = _run(
        """
        import numpy, simbench.cli, simbench.experiments.reproduce
        print(json.dumps(report()))
        """
    )
    assert untouched["env"] is None
    cli = _run(
        """
        import contextlib, io
        import numpy
        from simbench.cli import main
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["--help"]) == 0
        import scipy.linalg
        scipy.linalg.eigh([[2.0, 1.0], [1.0, 2.0]])
        print(json.dumps(report()))
        """
    )
    assert cli["env"] == "1"
    assert len(cli["threads"]) >= 2, cli  # numpy's BLAS and SciPy's
    assert all(n == 1 for _, n in cli["threads"]), cli


def test_the_cli_keeps_malloc_to_few_arenas_and_respects_the_users_setting():
    """After ``simbench`` starts, glibc's MALLOC_ARENA_MAX is set for spawned children (and mallopt
    called for this process); a value the user set stays; importing simbench alone sets nothing."""
    code = """
        import contextlib, io
        from simbench.cli import main
        with contextlib.redirect_stdout(io.StringIO()):
            assert main(["--help"]) == 0
        print(json.dumps({"arenas": os.environ.get("MALLOC_ARENA_MAX")}))
        """
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_ARENA_MAX"}

    def run(code: str, extra: dict) -> dict:
        out = subprocess.run(
            [sys.executable, "-c", "import json, os\n" + textwrap.dedent(code)],
            capture_output=True,
            text=True,
            timeout=300,
            env={**env, **extra},
        )
        assert out.returncode == 0, out.stderr
        return json.loads(out.stdout.strip().splitlines()[-1])

    from simbench.threads import MALLOC_ARENAS

    assert run(code, {})["arenas"] == str(MALLOC_ARENAS)
    assert run(code, {"MALLOC_ARENA_MAX": "7"})["arenas"] == "7"
    imported = 'import simbench.cli\nprint(json.dumps({"arenas": os.environ.get("MALLOC_ARENA_MAX")}))'
    assert run(imported, {})["arenas"] is None


def test_a_process_share_of_the_cores_is_read_from_simbench_threads(monkeypatch):
    """SIMBENCH_THREADS: a whole number >= 1, else every usable CPU; anything else named."""
    import pytest

    from simbench.threads import THREADS_VARIABLE, process_threads, usable_cpus

    monkeypatch.delenv(THREADS_VARIABLE, raising=False)
    assert process_threads() == usable_cpus() >= 1
    monkeypatch.setenv(THREADS_VARIABLE, " 5 ")
    assert process_threads() == 5
    for bad in ("0", "-2", "1.5", "many"):
        monkeypatch.setenv(THREADS_VARIABLE, bad)
        with pytest.raises(ValueError, match=f"SIMBENCH_THREADS must be a whole number of threads >= 1, got '{bad}'"):
            process_threads()


def test_cores_shared_divides_the_cores_and_restores_the_pools(monkeypatch):
    import cv2

    import simbench.threads as threads
    from simbench.decode.bands import row_bands
    from simbench.decode.params import DecoderParams
    from simbench.rig import paper_rig

    monkeypatch.delenv(threads.THREADS_VARIABLE, raising=False)
    monkeypatch.setattr(threads, "usable_cpus", lambda: 16)
    before = cv2.getNumThreads()
    with threads.cores_shared(5) as n:
        assert n == 3 and os.environ[threads.THREADS_VARIABLE] == "3" and cv2.getNumThreads() == 3
        # the decoder's default row bands follow the share (an explicit count does not)
        assert row_bands(960, 1280, DecoderParams(), paper_rig())[2] == 3
        assert row_bands(960, 1280, DecoderParams(threads=6), paper_rig())[2] == 6
    assert threads.THREADS_VARIABLE not in os.environ and cv2.getNumThreads() == before
    with threads.cores_shared(64) as n:
        assert n == 1
    monkeypatch.setenv(threads.THREADS_VARIABLE, "2")  # the user's choice is kept
    with threads.cores_shared(5) as n:
        assert n == 2 and cv2.getNumThreads() == 2
    assert os.environ[threads.THREADS_VARIABLE] == "2" and cv2.getNumThreads() == before


def test_a_share_set_by_hand_holds_in_any_entry_point_and_a_bad_one_is_one_line(tmp_path):
    """SIMBENCH_THREADS set by the user (a Dask worker host, a shared machine): choosing the
    Mitsuba variant (every entry point that renders: CLI, API, pool workers) sizes Dr.Jit's and
    OpenCV's threads to it; a value simbench refuses is one line and exit 2 before any work."""
    code = """
        import json, cv2
        from simbench.variant import select_variant
        select_variant(None)
        import drjit as dr
        print(json.dumps([dr.thread_count(), cv2.getNumThreads()]))
        """
    env = {**os.environ, "SIMBENCH_THREADS": "1"}
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300, env=env
    )
    assert out.returncode == 0, out.stderr
    assert json.loads(out.stdout.strip().splitlines()[-1]) == [1, 1]
    env["SIMBENCH_THREADS"] = "-2"
    out = subprocess.run(
        [sys.executable, "-m", "simbench", "pattern", "--out", str(tmp_path / "p.png")],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert out.returncode == 2 and not (tmp_path / "p.png").exists()
    assert out.stderr.strip() == "simbench: error: SIMBENCH_THREADS must be a whole number of threads >= 1, got '-2'"
