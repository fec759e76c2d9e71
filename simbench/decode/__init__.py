"""The paper's decoder (Sec. 5) and our colour-robust one: one module per stage, chained by
:func:`decode`.

- :mod:`~simbench.decode.color`: channel overlay weights, colour code, voting, unmixing (Sec. 5.1-5.2)
- :mod:`~simbench.decode.phase`: the Gabor phase and the fringe SNR (Sec. 5.3);
  :mod:`~simbench.decode.fourier`: FTP and windowed Fourier ridges, interchangeable with it
- :mod:`~simbench.decode.debruijn`: De Bruijn unwrapping with neighbour correction (Sec. 5.2)
- :mod:`~simbench.decode.depth`: reference-plane matching and depth (Sec. 5.4); the crease and edge
  terms of the colour-robust decoder's confidence
- :mod:`~simbench.decode.params`: the parameters (:class:`DecoderParams`, :func:`robust_params`)
- :mod:`~simbench.decode.pipeline`: the chain; :mod:`~simbench.decode.bands`: its row bands in
  threads; :mod:`~simbench.decode.persist`: decoded reference planes cached
- :mod:`~simbench.decode.temporal`: the multi-shot reference's phase shifting and Gray code
"""

from simbench.decode.params import (
    MODES,
    PAPER_ADDED_CHECKS,
    AddedCheck,
    CREASE_APEX_MIN_PX,
    CREASE_APEX_PERIODS,
    CREASE_APEX_SHARE,
    CREASE_BIAS_RATIO,
    CREASE_LOBE_SHARE,
    CREASE_MAX_STEP_SLOPES,
    CREASE_PEAK_PERIODS,
    CREASE_SCALE_PERIODS,
    EDGE_BEND_FIT_PERIODS,
    EDGE_BEND_REACH_SIGMAS,
    with_assignments,
    with_changes,
    without_checks,
    PHASE_METHODS,
    DecoderParams,
    ROBUST_MIN_AMPLITUDE,
    ROBUST_MIN_CONFIDENCE,
    STABILITY_KAPPA_RAD,
    STABILITY_WINDOW_SCALE,
    robust_params,
)
from simbench.decode.pipeline import (
    DecodeResult,
    ReferenceMap,
    as_float_image,
    decode,
    REFERENCE_Z0_TOLERANCE,
    REFERENCE_Z0_WARNING,
    REFERENCE_EXTENT_PERCENTILES,
    decode_reference,
    reference_plane_extent,
    reference_plane_offset,
)

__all__ = [
    "MODES",
    "PAPER_ADDED_CHECKS",
    "AddedCheck",
    "CREASE_APEX_MIN_PX",
    "CREASE_APEX_PERIODS",
    "CREASE_APEX_SHARE",
    "CREASE_BIAS_RATIO",
    "CREASE_LOBE_SHARE",
    "CREASE_MAX_STEP_SLOPES",
    "CREASE_PEAK_PERIODS",
    "CREASE_SCALE_PERIODS",
    "EDGE_BEND_FIT_PERIODS",
    "EDGE_BEND_REACH_SIGMAS",
    "with_assignments",
    "with_changes",
    "without_checks",
    "PHASE_METHODS",
    "DecodeResult",
    "DecoderParams",
    "ReferenceMap",
    "as_float_image",
    "decode",
    "decode_reference",
    "reference_plane_offset",
    "reference_plane_extent",
    "REFERENCE_Z0_TOLERANCE",
    "REFERENCE_Z0_WARNING",
    "REFERENCE_EXTENT_PERCENTILES",
    "robust_params",
    "ROBUST_MIN_AMPLITUDE",
    "ROBUST_MIN_CONFIDENCE",
    "STABILITY_KAPPA_RAD",
    "STABILITY_WINDOW_SCALE",
]
