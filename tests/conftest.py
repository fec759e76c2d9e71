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


@pytest.fixture(scope="session")
def acquisitions(variant):
    """Full-resolution, 16 spp, noisy acquisitions of the pipeline scenes (rendered once)."""
    from simbench.pattern import PatternSpec
    from simbench.scene import load_scene
    from simbench.device import get_sensor
    from simbench.simulate import acquire

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
            )
        return cache[key]

    return get


# The files holding the longest tests (`--durations` on 2 cores, 2026-11-24: the README's
# commands 220 s, the calibrations 90-110 s each, the cache's reruns 70 s, the CLI's end-to-end
# render 64 s), collected first: `make test` hands whole files to two pytest-xdist processes in
# collection order, and a long file handed out last would run alone at the end.
_LONG_FIRST = ("test_readme.py", "test_calibration.py", "test_cache.py", "test_cli.py", "test_robust_scenes.py")


def pytest_collection_modifyitems(config, items) -> None:
    rank = {name: i for i, name in enumerate(_LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: the rest keep their order
