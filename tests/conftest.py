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
            )
        return cache[key]

    return get


@pytest.fixture(autouse=True)
def _in_a_fresh_folder(tmp_path, monkeypatch):
    """Every test runs in its own empty working folder: the CLI's relative defaults (the render
    cache ``.cache/simbench``, ``results/...``) land there, not in the checkout, so a test never
    reads a developer's warm cache (and passes for it) or leaves files behind."""
    monkeypatch.chdir(tmp_path)
