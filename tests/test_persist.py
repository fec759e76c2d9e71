"""Decoded reference planes kept in the render cache (simbench.decode.persist): stored only when
the caller commits, read back bit for bit, keyed by everything the map depends on."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from simbench.cache import RenderCache
from simbench.decode import DecoderParams, decode_reference
from simbench.decode.persist import lookup_decoded_reference
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.rig import paper_rig
from simbench.sim.projector import transfer_curve
from simbench.sim.synthetic import synthetic_plane_capture

RIG = paper_rig()


@pytest.fixture(scope="module")
def reference_image() -> np.ndarray:
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec())), transfer="linear")
    return synthetic_plane_capture(drive, RIG, point_m=(0, 0, 1.0))[0]


def _entries(root) -> int:
    return len(list(root.glob("reference_map-*.npz")))


def test_a_reference_is_stored_on_commit_and_read_back_bit_for_bit(tmp_path, reference_image):
    cache = RenderCache(tmp_path / "c")
    params = DecoderParams()
    ref, store = lookup_decoded_reference(reference_image, rig=RIG, params=params, cache=cache)
    assert _entries(tmp_path / "c") == 0  # nothing before the caller says its command succeeded
    store()
    assert _entries(tmp_path / "c") == 1
    direct = decode_reference(reference_image, rig=RIG, params=params)
    again, store_again = lookup_decoded_reference(reference_image, rig=RIG, params=params, cache=cache)
    store_again()
    assert cache.hits == 1 and _entries(tmp_path / "c") == 1
    for field in ("column_px", "expected_px", "inverse", "registration_px"):
        assert np.array_equal(getattr(again, field), getattr(direct, field), equal_nan=True)
        assert np.array_equal(getattr(ref, field), getattr(direct, field), equal_nan=True)
    assert direct.registration_px.shape == (3, 4) and np.abs(direct.registration_px).max() < 0.02
    assert again.z0_m == direct.z0_m and again.mixing is None


def test_the_key_holds_the_image_the_rig_and_the_settings_but_not_the_thread_count(tmp_path, reference_image):
    cache = RenderCache(tmp_path / "c")
    lookup_decoded_reference(reference_image, rig=RIG, params=DecoderParams(), cache=cache)[1]()
    lookup_decoded_reference(reference_image, rig=RIG, params=DecoderParams(threads=1), cache=cache)[1]()
    assert _entries(tmp_path / "c") == 1 and cache.hits == 1  # threads change no bit of the map
    brighter = np.clip(reference_image * 1.01, 0, 1).astype(reference_image.dtype)
    lookup_decoded_reference(brighter, rig=RIG, params=DecoderParams(), cache=cache)[1]()
    lookup_decoded_reference(reference_image, rig=RIG, params=DecoderParams(z0_m=1.0001), cache=cache)[1]()
    moved = dataclasses.replace(RIG, position_m=(RIG.position_m[0] + 1e-4, *RIG.position_m[1:]))
    lookup_decoded_reference(reference_image, rig=moved, params=DecoderParams(), cache=cache)[1]()
    assert _entries(tmp_path / "c") == 4


def test_without_a_cache_the_reference_is_decoded_each_time(reference_image):
    ref, store = lookup_decoded_reference(reference_image, rig=RIG, params=DecoderParams(), cache=None)
    store()  # nothing to store
    assert np.isfinite(ref.column_px).mean() > 0.95
