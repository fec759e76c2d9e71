"""The paper's decoder (Sec. 5): one module per stage, chained by :func:`decode`."""

from simbench.decode.pipeline import (
    MODES,
    PHASE_METHODS,
    DecodeResult,
    DecoderParams,
    ReferenceMap,
    as_float_image,
    decode,
    REFERENCE_Z0_TOLERANCE,
    ROBUST_MIN_CONFIDENCE,
    STABILITY_KAPPA_RAD,
    STABILITY_WINDOW_SCALE,
    decode_reference,
    reference_plane_offset,
    robust_params,
)

__all__ = [
    "MODES",
    "PHASE_METHODS",
    "DecodeResult",
    "DecoderParams",
    "ReferenceMap",
    "as_float_image",
    "decode",
    "decode_reference",
    "reference_plane_offset",
    "REFERENCE_Z0_TOLERANCE",
    "robust_params",
    "ROBUST_MIN_CONFIDENCE",
    "STABILITY_KAPPA_RAD",
    "STABILITY_WINDOW_SCALE",
]
