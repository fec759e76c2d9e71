"""A decoded reference plane, computed once and kept: :func:`lookup_decoded_reference`.

Decoding the reference plane (and measuring its coupling matrix) is done once per calibration,
yet a command-line decode or an experiment run would redo it every time.  The decoded map is
stored in a :class:`simbench.cache.RenderCache` under a key made of everything it depends on:
the bytes of the reference and calibration captures, the rig, the decoder settings (all but the
thread count, which results do not depend on) and the decoder's own source code, so that a
changed decoder never reads a map an older one wrote.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from contextlib import nullcontext
from functools import lru_cache
from pathlib import Path

import numpy as np

from simbench import native
from simbench.cache import RenderCache, array_digest, source_digest
from simbench.decode.params import DecoderParams, phase_method_code
from simbench.decode.pipeline import ReferenceMap, decode_reference
from simbench.rig import Rig, rig_to_dict

__all__ = ["lookup_decoded_reference", "decoder_fingerprint"]


@lru_cache(maxsize=1)
def decoder_fingerprint() -> str:
    """SHA-256 over the decoder package's source files and the C loops it calls (name and
    bytes, in name order)."""
    return source_digest(sorted([*Path(__file__).parent.glob("*.py"), *native.SOURCES]))


def lookup_decoded_reference(
    reference: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams,
    primaries: Sequence[np.ndarray] | None = None,
    dark: np.ndarray | None = None,
    cache: RenderCache | None = None,
) -> tuple[ReferenceMap, Callable[[], None]]:
    """:func:`simbench.decode.decode_reference` looked up in ``cache`` (None: decoded every
    time), and a function that stores it there (nothing to do when it came from the cache): a
    command stores it only once everything else has succeeded, so a failed command leaves
    nothing behind.  Raises what ``decode_reference`` raises (a failed reference is never
    stored)."""
    parts = None
    arrays = None
    if cache is not None and cache.root is not None:
        settings = dataclasses.asdict(params)
        settings.pop("threads")
        parts = {
            "reference": array_digest(np.asarray(reference)),
            "calibration": None
            if primaries is None
            else [array_digest(np.asarray(p)) for p in primaries] + [array_digest(np.asarray(dark))],
            "rig": rig_to_dict(rig),
            "decoder": settings,
            "decoder_source": decoder_fingerprint(),
        }
        foreign = phase_method_code(params.phase_method)
        if foreign is not None:  # (only then: simbench's own methods keep their keys)
            parts["phase_method_code"] = foreign
        arrays = cache.lookup("reference_map", parts)
    fresh = arrays is None
    if fresh:
        with nullcontext() if cache is None else cache.making("reference_map"):
            ref = decode_reference(reference, rig=rig, params=params, primaries=primaries, dark=dark)
        arrays = {
            "column_px": ref.column_px,
            "expected_px": ref.expected_px,
            "inverse": ref.inverse,
            "z0_m": np.float64(ref.z0_m),
        }
        if ref.mixing is not None:
            arrays["mixing"] = ref.mixing
        if ref.registration_px is not None:
            arrays["registration_px"] = ref.registration_px

    def store() -> None:
        if fresh and parts is not None:
            cache.store("reference_map", parts, arrays)

    ref = ReferenceMap(
        column_px=arrays["column_px"],
        expected_px=arrays["expected_px"],
        inverse=arrays["inverse"],
        z0_m=float(arrays["z0_m"]),
        mixing=arrays.get("mixing"),
        registration_px=arrays.get("registration_px"),
    )
    return ref, store
