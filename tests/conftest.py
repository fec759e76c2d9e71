"""Shared fixtures: the Mitsuba variant (chosen once, as an entry point would) and cached renders."""

from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


@pytest.fixture(scope="session")
def variant() -> str:
    from simbench.variant import select_variant

    return select_variant()


def run_folder(config, tmp_path_factory) -> Path:
    """A folder of this test run's, shared by its pytest-xdist worker processes (the parent of
    each worker's own base folder; the base folder itself without workers): new each run."""
    base = tmp_path_factory.getbasetemp()
    return base.parent if hasattr(config, "workerinput") else base


@pytest.fixture(scope="session")
def shared_render_cache(request, tmp_path_factory):
    """A render cache shared by this run's test processes, for fixtures whose renders several
    test files read (each file runs whole in one worker, so a per-process fixture rendered them
    once per worker: the white board's 16-spp renders four times, ~30 s).  The cache makes an
    entry once under its key's lock and the others read it (:meth:`simbench.cache.RenderCache.get_or_make`);
    that a cached recording is the bits of a fresh one is tests/test_cache.py's claim."""
    from simbench.cache import RenderCache

    return RenderCache(run_folder(request.config, tmp_path_factory) / "shared-render-cache")


@pytest.fixture(scope="session")
def acquisitions(variant, shared_render_cache):
    """Full-resolution, 16 spp, noisy acquisitions of the pipeline scenes (rendered once per
    test run, :func:`shared_render_cache`)."""
    from simbench.pattern import PatternSpec
    from simbench.sim.scene import load_scene
    from simbench.sim.sensor import get_sensor
    from simbench.systems.proposed import acquire

    cache: dict = {}

    def get(name: str, seed: int = 7):
        key = (name, seed)
        if key not in cache:
            cache[key] = acquire(
                load_scene(SCENES / f"{name}.toml"),
                pattern=PatternSpec(),
                sensor=get_sensor("minimal"),
                spp=16,
                seed=seed,
                cache=shared_render_cache,
            )
        return cache[key]

    return get


def bare_files(folder: Path, capture, reference, rig) -> list[str]:
    """``capture.png``, ``reference.png`` and ``rig.toml`` written to ``folder`` (no recording
    manifest: bare files, as a user's own), and the ``simbench decode`` arguments naming them."""
    from simbench.io import save_png
    from simbench.rig import save_rig

    save_png(folder / "capture.png", capture)
    save_png(folder / "reference.png", reference)
    save_rig(rig, folder / "rig.toml")
    return [
        str(folder / "capture.png"),
        "--reference",
        str(folder / "reference.png"),
        "--rig",
        str(folder / "rig.toml"),
    ]


@pytest.fixture(autouse=True)
def _in_a_fresh_folder(tmp_path, monkeypatch):
    """Every test runs in its own empty working folder: the CLI's relative defaults (the render
    cache ``.cache/simbench``, ``results/...``) land there, not in the checkout, so a test never
    reads a developer's warm cache (and passes for it) or leaves files behind."""
    monkeypatch.chdir(tmp_path)


# Each test file's work (s), measured at 48850dc with `make test` (`--durations=0`, summed per file,
# 2 workers on this 2-core machine): files run whole in one worker (`--dist loadfile`), in this order
# (`--no-loadscope-reorder`), heaviest first, so that the last file to start is a short one.  By
# pytest-xdist's default order (most tests first) the README file (1 test of 281 s, 6 tests) started
# last and the run took 826 s of wall time for 1410 s of work on 2 workers.  A file not listed
# comes after these, in collection order (so a new file of more than ~20 s belongs here: the
# `--durations=10` list `make test` prints shows it); the figures need only rank the files.
FILE_SECONDS = {
    "test_readme.py": 283,
    "test_calibration.py": 193,
    "test_decode.py": 105,
    "test_robust_scenes.py": 98,
    "test_cli.py": 94,
    "test_experiments.py": 86,
    "test_motion.py": 59,
    "test_render.py": 58,
    "test_bench.py": 53,
    "test_phase_shift.py": 50,
    "test_files.py": 34,
    "test_ablate.py": 31,
    "test_optics.py": 29,
    "test_physics_renders.py": 26,
    "test_cache.py": 26,
    "test_systems.py": 25,
    "test_decode_fourier.py": 24,
}


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(sorted(FILE_SECONDS, key=FILE_SECONDS.get, reverse=True))}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: collection order within
