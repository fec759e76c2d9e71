"""simbench.seeds: one default, one derivation scheme, the values results depend on."""

import hashlib

import numpy as np
import pytest

from simbench.seeds import CHILD_STREAMS, DEFAULT_SEED, SeedLog, check_seed, child_seed, derive_seed, repetition_seed


def test_derivation_is_the_published_formula():
    """Result files record seeds derived this way: changing it changes every result."""
    h = int.from_bytes(hashlib.sha256(b"table1/paint/red/render").digest()[:8], "little")
    assert derive_seed(2017, "table1/paint/red/render") == int(np.random.SeedSequence([2017, h]).generate_state(1)[0])
    assert repetition_seed(2017, 3) == int(np.random.SeedSequence([2017, 3]).generate_state(1)[0])
    assert child_seed(5, "ambient_render").generate_state(1)[0] == np.random.SeedSequence([5, 3]).generate_state(1)[0]
    assert DEFAULT_SEED == 2017
    assert sorted(CHILD_STREAMS.values()) == [1, 2, 3, 5]  # numbers are part of the results


def test_labels_give_independent_stable_seeds():
    assert derive_seed(2017, "a") == derive_seed(2017, "a") != derive_seed(2018, "a")
    assert len({derive_seed(2017, f"x/{i}") for i in range(500)}) == 500


def test_seed_log_records_captures():
    log = SeedLog(7)
    render, noise = log.capture("scene", repeats=2)
    assert log.used == {
        "scene/0": {"render": render, "noise": noise[0]},
        "scene/1": {"render": render, "noise": noise[1]},
    }
    assert render == derive_seed(7, "scene/render") and noise[1] == derive_seed(7, "scene/noise/1")
    log.capture("other")
    assert "other" in log.used


@pytest.mark.parametrize("bad", [-1, 1.5, True, "3", None])
def test_bad_seeds_are_refused(bad):
    with pytest.raises(ValueError, match="non-negative integer"):
        check_seed(bad)
    with pytest.raises(ValueError):
        child_seed(1, "nope")
