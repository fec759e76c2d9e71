"""The paper's decoder (Sec. 5) as one function chaining the stages, each stage's output kept."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Iterator, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from typing import TypeVar

import numpy as np

from simbench import validate
from simbench.decode import _kernels
from simbench.decode.color import (
    color_code,
    mixing_matrix,
    albedo_gain,
    normalize_channels,
    normalized_color_code,
    overlay_weights,
    segment_stripes,
    unmix,
    vote_codes,
)
from simbench.decode.debruijn import (
    drop_broken_links,
    keep_certain_sides,
    neighbour_correct,
    stripe_floor,
    window_positions_of_stripes,
)
from simbench.decode.depth import (
    absolute_column,
    inverse_column_table,
    match_reference,
)
from simbench.decode.fourier import ftp_phase, wfr_phase
from simbench.decode.phase import (
    INTENSITY_MODES,
    certainty_map,
    MAX_FRINGE_SNR,
    certainty_window_px,
    fringe_snr,
    gabor_phase,
    overlay_intensity,
)
from simbench.decode.profile import run_in_context, stage
from simbench.optics import undistort_image
from simbench.pattern import (
    PatternSpec,
    check_channels,
    code_sequence,
    window_positions,
)
from simbench.rig import Rig, projector_column_at_depth, triangulation_steps, triangulation_values

__all__ = [
    "DecoderParams",
    "AddedCheck",
    "PAPER_ADDED_CHECKS",
    "without_checks",
    "with_changes",
    "robust_params",
    "ROBUST_MIN_CONFIDENCE",
    "ROBUST_MIN_AMPLITUDE",
    "STABILITY_KAPPA_RAD",
    "STABILITY_WINDOW_SCALE",
    "phase_change",
    "apply_min_confidence",
    "PHASE_METHODS",
    "MODES",
    "ReferenceMap",
    "DecodeResult",
    "LazyStages",
    "as_float_image",
    "decode_reference",
    "reference_plane_offset",
    "REFERENCE_Z0_TOLERANCE",
    "decode",
]

# each: (intensity, *, certainty, period_px, sigma_x_px, sigma_y_px, offset=True) -> PhaseResult
PHASE_METHODS = {"gabor": gabor_phase, "ftp": ftp_phase, "wfr": wfr_phase}
MODES = ("reference", "calibrated")
# Gaps the colour-robust decoder bridges, in camera periods (assumption: just under one period,
# so that at the nominal period at most one wrap hides in a gap - where the local period is
# shorter the slope predicts more and the bridge is refused.  Measured on
# scenes/robust_printed.toml: the phase fit fails for 6-11 px beside most printed edges and for
# 20-26 px beside the saturated red and orange tiles, whose fits are poor anyway)
ROBUST_BRIDGE_GAP_PERIODS = 0.95
# The colour-robust decoder's floor on the fitted amplitude of its normalised fringe (units of the
# local range, so relative: a fringe with 2 % of the local range is none; assumption, the value
# the paper's decoder once used in full-scale units, kept so that the robust decoder's results
# did not move when the paper's decoder dropped it)
ROBUST_MIN_AMPLITUDE = 0.02
# The colour-robust decoder's operating point: the confidence (fringe SNR, capped by the phase's
# stability) below which a decoded pixel is a hole.  Chosen by the rule of
# simbench.experiments.hard_scenes.operating_point (the threshold under which the most scenes meet
# issue 35's goals, >= 97 % complete and <= 0.1 % of the decoded pixels > 5 mm wrong; of equals,
# the lowest) on the 19 hard scenes at full resolution (1280x960, 36 spp, sensor `paper`, seed
# 2017; results/hard_scenes_confidence.csv, `simbench reproduce hard_scenes`, from which
# tests/test_hard_scenes.py checks the rule still picks it).  Re-derived for each deliberate change
# of the decoder: with the albedo flattening (DecoderParams.albedo_flatten) 14 scenes met both
# goals at 2 and at 3, so 2; with the flattening's shadow guard (ALBEDO_MIN_VISIBILITY: a
# projector shadow is no longer brightened like dark ink) 14 meet them at 3 and 13 at 2 (12 at 4
# and 5, 11 with no threshold), so 3; with link_keep_certain (at this same level) 15 at 3.  At 3:
# box before wall 98.8 % complete / 0.00 % wrong, sphere before wall 97.4 % / 0.03 %, deep
# stairs 97.4 % / 0.00 %, printed charts of 3:1 and 1.6:1 97.1 % and 100 % / 0 %, glossy boards
# 98.0-99.6 % / 0 %.  Short of the goals there: the 20:1 chart (80.4 %, 0 % wrong; 91.5 % at 2),
# the fine chart (squares under a period: nothing), the box interior (77 %) and the 60-degree
# corner (0.42 % wrong, -5 to -12 mm beside the crease, stable across window widths:
# interreflection, none with direct light only).  Not tuned on any table of the paper; a white
# board scores ~30.
ROBUST_MIN_CONFIDENCE = 3.0
# The phase-stability term of the confidence (DecoderParams.phase_stability): the phase is fitted
# again with a window half as wide along x, and a pixel whose phase moves by |dpsi| between the two
# scores STABILITY_KAPPA_RAD / |dpsi|.  A window that straddles a depth edge, a printed albedo step
# or a crease is biased by what lies on the far side, and by less when it is narrower; a clean
# fringe gives the same phase at both widths up to noise.  kappa = 0.4 rad (assumption, set before
# the operating point was chosen: a pixel scoring 4 has moved 0.1 rad, 0.33 projector px or
# ~1.6 mm at 1 m, a third of the 5 mm that counts as wrong).  At a threshold of 3 the phase
# may move by 0.13 rad (~2.2 mm); noise alone moves it by ~0.04 rad (1 sigma) at SNR 3 (the
# narrow window's phase variance less the wide one's: 1/(SNR^2 N_eff) with N_eff = 4 pi sigma_x
# sigma_y, ~72 and ~36 samples), so noise trips it at ~3 sigma.
STABILITY_WINDOW_SCALE = 0.5
STABILITY_KAPPA_RAD = 0.4


@dataclass(frozen=True)
class DecoderParams:
    """Decoder settings (defaults: the paper's pattern, our choices where the paper is silent).

    The defaults are the paper's decoder as we read it: its stages (Eq. 9 overlay, Gabor phase
    Eq. 10-11, Eq. 13 colour code, voting Sec. 5.2, De Bruijn windows with the neighbour
    correction Sec. 5.3, Eq. 14 cycle number, Eq. 15 depth) with the checks it needs and does not
    describe, each ours, named in :data:`PAPER_ADDED_CHECKS` with its reason and switchable by
    :func:`without_checks`: ``lit_test`` (``dark_level``), ``max_residual``,
    ``window_support``, ``stripe_step``, ``min_support``, ``link_check``; the built-in study
    ``paper_checks`` measures what each buys on the seven colour boards.  All are relative to the
    local fringe, the window or the period but the lit test, an absolute floor on any light in a
    period of the row (it buys 17 points of completeness on the high-contrast printed chart,
    ``hard_chart_high``, and nothing on the boards).  The fitted-amplitude floor
    (``min_amplitude``, absolute) bought nothing on the boards, the 19 hard scenes, Table 3 or
    Fig. 9 (on the pink/cyan clutter of Fig. 13a it traded 3 points of completeness for 16 %
    fewer stripe-order errors) and is 0 for the paper's decoder; the colour-robust decoder keeps
    it on its normalised fringe (:data:`ROBUST_MIN_AMPLITUDE`, relative to the local range).

    Attributes
    ----------
    pattern : :class:`simbench.pattern.PatternSpec`
        The projected pattern (default: the paper's); the decoder reads its fringe period T
        (projector px), window length, stripe codes and channel assignment (code 1, code 0,
        fringe), also as ``period_px``, ``order``, ``sequence`` and ``channels``; it reorders the
        capture's channels so that every stage sees the paper's layout (R = code 1, G = code 0,
        B = fringe).  A table of PatternSpec's fields (TOML, JSON) is accepted.
    intensity_mode : str
        ``overlay`` (paper Eq. 9), ``blue`` (the fringe channel alone: blue in the paper's
        pattern) or ``weighted`` (normalised channels weighted by their noise,
        :func:`simbench.decode.color.overlay_weights`; needs ``color_normalize``).
    phase_method : str
        Key of :data:`PHASE_METHODS`: ``gabor`` (paper Eq. 10-11), ``ftp`` (Fourier transform
        profilometry, row by row) or ``wfr`` (windowed Fourier ridges); see
        :mod:`simbench.decode.fourier`.  All three use the same window for their quality maps.
    sigma_periods : float
        Gabor envelope sigma along x in fringe periods (camera px = ``sigma_periods * T_cam``).
        The paper gives no value; 0.25 (with ``sigma_y_ratio`` 0.6) trades noise against the
        band lost where the window straddles a depth edge (measured on scenes/sphere.toml).
    sigma_y_ratio : float
        Envelope sigma along y relative to x.
    camera_period_px : float or None
        Fringe period in camera px; ``None`` = ``T * f_cam / f_proj`` (exact for fronto-parallel
        surfaces with a rectified rig).
    unmix : bool
        Separate the projector's primaries before every stage with the inverse of the coupling
        matrix measured on the reference plane (:func:`simbench.decode.color.mixing_matrix`,
        Caspi et al. 1998): the reference must come with its calibration captures under each
        primary.  Off = the paper's decoder (raw channels).
    color_normalize : bool
        Normalise each channel by its local range across neighbouring stripes before the
        overlay (Eq. 9) and the code (Eq. 13) (:func:`simbench.decode.color.normalize_channels`);
        off = the paper's decoder.
    albedo_flatten : bool
        Before the normalisation, divide out printed albedo steps found along the rows
        (:func:`simbench.decode.color.albedo_gain`; ours, needs ``color_normalize``): each
        segment between two steps brought to its brighter neighbour's level, so that a window
        over the step sees one fringe.  Off = the paper's decoder.
    voting : bool
        Majority vote of codes per stripe (paper Sec. 5.2); off = the stripe's middle pixel.
    neighbour_reach : int
        Neighbours per side in the W check and correction (paper Sec. 5.3); 0 = off.
    min_support : int
        Votes a stripe's W needs to be kept.
    bridge_gap_periods : float
        Bridge gaps of invalid pixels up to this share of the camera period within a row when
        the phase on both sides agrees (:func:`simbench.decode.color.segment_stripes`); 0 (the
        paper's decoder: not described) never bridges.  At most 1, so that a gap holds at most
        one wrap.
    link_check : bool
        After the correction, drop both stripes of any link whose W do not follow each other
        (a depth edge hidden in a smooth phase; :func:`simbench.decode.debruijn.drop_broken_links`).
    link_keep_certain : float
        A confidence level: of a broken link's two stripes, keep the one the edge is not in
        (ours, needs ``link_check``; :func:`simbench.decode.debruijn.keep_certain_sides`): where
        every pixel of one stripe is at or above this level, a pixel of the other below it (the
        phase windows over the edge), and the first's link on its other side holds.  A level of
        its own, not ``min_confidence``, so that a decode with no operating point (to score a
        range of thresholds) keeps the same stripes.  0 = both dropped (the paper's decoder: not
        described); the colour-robust decoder's: :data:`ROBUST_MIN_CONFIDENCE`.
    stripe_step_ratio : tuple of float
        (low, high): a step of the wrapped phase between neighbouring pixels of a row, after a
        wrap is unwrapped, outside ``[low, high] * 2 pi / T_cam`` ends a run of stripes without a
        link (:func:`simbench.decode.color.segment_stripes`; the high end never exceeds 0.9 pi,
        so that a wrap stays a wrap).  ``(0, inf)`` keeps only that cap.
    dark_level, saturation_level : float
        In [0, 1] of full scale: a period-wide row maximum below ``dark_level`` is unlit;
        any channel at or above ``saturation_level`` is clipped.
    min_amplitude : float
        Minimum fitted fringe amplitude for a valid pixel: full-scale units, or units of the local
        range with ``color_normalize``.  0 for the paper's decoder (see above).
    max_residual : float
        Maximum fit residual relative to the fringe RMS (rejects windows over depth edges; it
        also grows with shading gradients and fringe chirp, so it cannot be tight).
    min_window_support : float
        Minimum share of the Gabor window's weight on certain (lit, unclipped) samples.
    phase_stability : bool
        Fold the phase's stability into the confidence: the phase is fitted again with a window
        :data:`STABILITY_WINDOW_SCALE` as wide along x, and the confidence is the lower of the
        fringe SNR and :data:`STABILITY_KAPPA_RAD` over the phase's change (the colour-robust
        decoder; off = the fringe SNR alone, and no second fit).
    min_confidence : float
        The operating point: decoded pixels whose confidence (:attr:`DecodeResult.confidence`)
        is below it become holes (NaN depth, not valid);
        their confidence stays in :attr:`DecodeResult.confidence`, so a user can see why and
        choose another.  0 (the paper's decoder: the paper describes no confidence) keeps every
        decoded pixel; :func:`robust_params` sets :data:`ROBUST_MIN_CONFIDENCE`.
    min_reference_coverage : float
        Share of the reference capture's pixels that must decode: a reference plane at Z0
        fills the view, so a black, unlit or unrelated reference is an error, not a silent
        fall-back to triangulation (assumption: half the view, leaving room for a reference
        board smaller than the view).
    mode : str
        ``reference`` (paper Sec. 5.4) or ``calibrated`` (triangulate with the rig).
    z0_m : float
        Reference-plane depth Z0.
    depth_range_m : tuple of float
        Working range; depths outside are invalid.  In calibrated mode the cycle number is
        chosen for the middle of this range (in inverse depth).
    threads : int or None
        Worker threads (row bands); None = one per CPU.  Results do not depend on it.
    """

    pattern: PatternSpec = PatternSpec()
    intensity_mode: str = "overlay"
    phase_method: str = "gabor"
    sigma_periods: float = 0.25
    sigma_y_ratio: float = 0.6
    camera_period_px: float | None = None
    unmix: bool = False
    color_normalize: bool = False
    albedo_flatten: bool = False
    voting: bool = True
    neighbour_reach: int = 3
    min_support: int = 3
    bridge_gap_periods: float = 0.0
    link_check: bool = True
    link_keep_certain: float = 0.0
    stripe_step_ratio: tuple[float, float] = (0.3, 3.0)
    dark_level: float = 0.04
    saturation_level: float = 1.0
    min_amplitude: float = 0.0
    max_residual: float = 0.6
    min_window_support: float = 0.5
    phase_stability: bool = False
    min_confidence: float = 0.0
    min_reference_coverage: float = 0.5
    mode: str = "reference"
    z0_m: float = 1.0
    depth_range_m: tuple[float, float] = (0.75, 1.75)
    threads: int | None = None

    def __post_init__(self) -> None:
        v = validate
        fixed = {
            "pattern": _pattern_of(self.pattern),
            "intensity_mode": v.choice(self.intensity_mode, "intensity_mode", INTENSITY_MODES),
            "phase_method": v.choice(self.phase_method, "phase_method", PHASE_METHODS),
            "sigma_periods": v.number(self.sigma_periods, "sigma_periods", lo=0.0, hi=10.0, lo_open=True),
            "sigma_y_ratio": v.number(self.sigma_y_ratio, "sigma_y_ratio", lo=0.0, hi=10.0, lo_open=True),
            "camera_period_px": v.optional(
                v.number, self.camera_period_px, "camera_period_px", lo=2.0, hi=float(v.MAX_SIDE_PX), lo_open=True
            ),
            "unmix": v.boolean(self.unmix, "unmix"),
            "color_normalize": v.boolean(self.color_normalize, "color_normalize"),
            "albedo_flatten": v.boolean(self.albedo_flatten, "albedo_flatten"),
            "voting": v.boolean(self.voting, "voting"),
            "neighbour_reach": v.integer(self.neighbour_reach, "neighbour_reach", lo=0, hi=64),
            "min_support": v.integer(self.min_support, "min_support", lo=1, hi=129),
            "bridge_gap_periods": v.number(self.bridge_gap_periods, "bridge_gap_periods", lo=0.0, hi=1.0),
            "link_check": v.boolean(self.link_check, "link_check"),
            "link_keep_certain": v.number(self.link_keep_certain, "link_keep_certain", lo=0.0, hi=MAX_FRINGE_SNR),
            "stripe_step_ratio": v.numbers(
                list(self.stripe_step_ratio) if isinstance(self.stripe_step_ratio, tuple) else self.stripe_step_ratio,
                "stripe_step_ratio",
                2,
                lo=0.0,
                allow_inf=True,
            ),
            "dark_level": v.number(self.dark_level, "dark_level", lo=0.0, hi=1.0),
            "saturation_level": v.number(self.saturation_level, "saturation_level", lo=0.0, hi=1.0, lo_open=True),
            "min_amplitude": v.number(self.min_amplitude, "min_amplitude", lo=0.0, hi=1.0),
            "max_residual": v.number(self.max_residual, "max_residual", lo=0.0, lo_open=True, allow_inf=True),
            "min_window_support": v.number(self.min_window_support, "min_window_support", lo=0.0, hi=1.0),
            "phase_stability": v.boolean(self.phase_stability, "phase_stability"),
            "min_confidence": v.number(self.min_confidence, "min_confidence", lo=0.0, hi=MAX_FRINGE_SNR),
            "min_reference_coverage": v.number(self.min_reference_coverage, "min_reference_coverage", lo=0.0, hi=1.0),
            "mode": v.choice(self.mode, "mode", MODES),
            "z0_m": v.number(self.z0_m, "z0_m", lo=0.0, lo_open=True),
            "depth_range_m": v.numbers(self.depth_range_m, "depth_range_m", 2, lo=0.0, lo_open=True),
            "threads": v.optional(v.integer, self.threads, "threads", lo=1, hi=1024),
        }
        lo, hi = fixed["depth_range_m"]
        if not lo < hi:
            raise ValueError(f"depth_range_m must satisfy 0 < near < far, got {self.depth_range_m}")
        if not fixed["stripe_step_ratio"][0] < fixed["stripe_step_ratio"][1]:
            raise ValueError(f"stripe_step_ratio must satisfy low < high, got {self.stripe_step_ratio}")
        if fixed["intensity_mode"] == "weighted" and not fixed["color_normalize"]:
            raise ValueError("intensity_mode 'weighted' needs color_normalize = true (it weights normalised channels)")
        if fixed["albedo_flatten"] and not fixed["color_normalize"]:
            raise ValueError("albedo_flatten needs color_normalize = true (it flattens before the normalisation)")
        for name, value in fixed.items():
            object.__setattr__(self, name, value)

    @property
    def period_px(self) -> int:
        return self.pattern.period_px

    @property
    def order(self) -> int:
        return self.pattern.order

    @property
    def sequence(self) -> tuple[int, ...] | None:
        return self.pattern.sequence

    @property
    def channels(self) -> str:
        return self.pattern.channels

    @property
    def cycle(self) -> int:
        return 2**self.order if self.sequence is None else len(self.sequence)

    def camera_period(self, rig: Rig) -> float:
        if self.camera_period_px is not None:
            return float(self.camera_period_px)
        return self.period_px * rig.camera.focal_px / rig.projector.focal_px


def _pattern_of(value) -> PatternSpec:
    """``value`` as a PatternSpec: one already, or a table of its fields (lists as tuples)."""
    if isinstance(value, PatternSpec):
        return value
    if isinstance(value, Mapping):
        fields = {f.name for f in dataclasses.fields(PatternSpec)}
        unknown = sorted(set(value) - fields)
        if unknown:
            raise ValueError(f"pattern: unknown field(s) {unknown}; valid: {sorted(fields)}")
        return PatternSpec(**{k: tuple(x) if isinstance(x, list) else x for k, x in value.items()})
    raise ValueError(f"pattern must be a PatternSpec or a table of its fields, got {value!r}")


def robust_params(params: DecoderParams = DecoderParams()) -> DecoderParams:
    """Our colour-robust decoder (not the paper's): ``params`` with the primaries unmixed by
    the coupling matrix measured on the reference plane (Caspi et al. 1998) and each channel
    normalised by its local range across neighbouring stripes, so that the code (Eq. 13) and
    the fringe (Eq. 9) no longer depend on the surface colour or on a stripe's colour; its
    validity tests then act on signal relative to the local range (``min_amplitude``,
    :data:`ROBUST_MIN_AMPLITUDE`, on the normalised fringe, ``max_residual`` relative to it;
    the lit test looks across a whole code window).  Its confidence folds in the phase's
    stability against the window's width (``phase_stability``) and its operating point makes the pixels below
    :data:`ROBUST_MIN_CONFIDENCE` holes.  Everything else as ``params``."""
    return dataclasses.replace(
        params,
        unmix=True,
        color_normalize=True,
        albedo_flatten=True,
        link_keep_certain=ROBUST_MIN_CONFIDENCE,
        intensity_mode="weighted",
        bridge_gap_periods=ROBUST_BRIDGE_GAP_PERIODS,
        min_amplitude=ROBUST_MIN_AMPLITUDE,
        phase_stability=True,
        min_confidence=ROBUST_MIN_CONFIDENCE,
    )


@dataclass(frozen=True)
class AddedCheck:
    """A check in the paper's decoder that the paper does not describe (ours): the
    :class:`DecoderParams` values that switch it off, and why it is there."""

    off: dict
    reason: str


# The checks our reading of the paper's decoder adds to its stages (Eq. 9, Gabor Eq. 10-11,
# Eq. 13, voting, De Bruijn windows with the neighbour correction, Eq. 14-15), each switchable
# (without_checks) and measured by the built-in study simbench/studies/paper_checks.toml
# (results/ablations/paper_checks.md).  Kept beside them, as the paper's stages need them: the
# clipped-sample test (a sample at full scale has lost its fringe value) and the working depth
# range (Eq. 14's cycle number k is chosen for it).
PAPER_ADDED_CHECKS = {
    "lit_test": AddedCheck(
        {"dark_level": 0.0},
        "a pixel whose row holds nothing above dark_level (full scale) within a period is unlit "
        "(projector shadow, black surface) and takes no part in any phase fit, so that windows "
        "beside a shadow fit the lit samples alone; an absolute level (dark_level also floors the "
        "colour-robust decoder's normalisation and noise weights, which switching it off changes too)",
    ),
    "max_residual": AddedCheck(
        {"max_residual": math.inf},
        "a fit whose residual exceeds max_residual of the fitted fringe's RMS (a fringe SNR below "
        "1/max_residual) is no phase: windows over depth edges, shadows and stripe-by-stripe "
        "amplitude changes; relative to the local fringe",
    ),
    "window_support": AddedCheck(
        {"min_window_support": 0.0},
        "a phase fitted on less than min_window_support of its window's weight (the rest unlit or "
        "clipped) is no phase; relative to the window",
    ),
    "stripe_step": AddedCheck(
        {"stripe_step_ratio": (0.0, math.inf)},
        "a phase step between neighbouring pixels outside stripe_step_ratio of the nominal slope "
        "ends a run of stripes (a depth edge); relative to the fringe period",
    ),
    "min_support": AddedCheck(
        {"min_support": 1},
        "a stripe's De Bruijn position needs min_support agreeing windows among its neighbours "
        "(Sec. 5.3 says one error 'can be checked by its neighborhoods', not how many agree)",
    ),
    "link_check": AddedCheck(
        {"link_check": False},
        "both stripes of a link whose positions do not follow each other after the correction "
        "are dropped (a depth edge hidden in a smooth phase)",
    ),
}


def without_checks(params: DecoderParams, names: str | Sequence[str]) -> DecoderParams:
    """``params`` with the added checks ``names`` (keys of :data:`PAPER_ADDED_CHECKS`, a name or
    a list; ``"none"`` for none, ``"all"`` for all) switched off."""
    names = [names] if isinstance(names, str) else list(names)
    if names == ["none"]:
        return params
    if names == ["all"]:
        names = list(PAPER_ADDED_CHECKS)
    unknown = sorted(set(names) - set(PAPER_ADDED_CHECKS))
    if unknown:
        raise ValueError(f"unknown decoder check(s) {unknown}; valid: {sorted(PAPER_ADDED_CHECKS)}, 'none' or 'all'")
    changes: dict = {}
    for n in names:
        changes.update(PAPER_ADDED_CHECKS[n].off)
    return dataclasses.replace(params, **changes)


def with_changes(params: DecoderParams, changes: Mapping[str, object]) -> DecoderParams:
    """``params`` with the fields ``changes`` names replaced (a list for a tuple field becomes a
    tuple, as TOML and JSON give them) and, under the key ``without``, the paper decoder's added
    checks switched off (:func:`without_checks`): the one place where the command line's
    ``--decoder name=value`` and an ablation's ``decoder.*`` axes become decoder settings.  An
    unknown name is a ``ValueError`` listing the valid ones.

    Examples
    --------
    >>> p = with_changes(DecoderParams(), {"depth_range_m": [0.5, 2.0], "phase_method": "ftp"})
    >>> p.depth_range_m, p.phase_method
    ((0.5, 2.0), 'ftp')
    """
    names = {f.name for f in dataclasses.fields(params)}
    unknown = sorted(set(changes) - names - {"without"})
    if unknown:
        raise ValueError(f"unknown decoder setting(s) {unknown}; valid: {sorted(names | {'without'})}")
    fields = {
        k: tuple(v) if isinstance(v, list) and isinstance(getattr(params, k), tuple) else v
        for k, v in changes.items()
        if k != "without"
    }
    return without_checks(dataclasses.replace(params, **fields), changes.get("without", "none"))


def with_assignments(params: DecoderParams, items: Sequence[str]) -> DecoderParams:
    """``params`` with ``name=value`` items applied (:func:`with_changes`): each value parsed as
    a TOML scalar or array (``voting=false``, ``depth_range_m=[0.5, 2.0]``), a bare word as a
    string (``phase_method=ftp``); ``without=NAME`` switches an added check off.  The command
    line's ``--decoder`` items.

    Examples
    --------
    >>> with_assignments(DecoderParams(), ["phase_method=ftp", "voting=false"]).voting
    False
    """
    import tomllib

    names = {f.name for f in dataclasses.fields(params)} | {"without"}
    changes = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or key not in names:
            raise ValueError(f"--decoder takes name=value with name one of {sorted(names)}; got {item!r}")
        try:
            changes[key] = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            changes[key] = text  # a bare word: phase_method=ftp
    try:
        return with_changes(params, changes)
    except ValueError as exc:
        raise ValueError(f"--decoder: {exc}") from None


@dataclass(frozen=True)
class ReferenceMap:
    """A decoded reference-plane capture.

    column_px : ndarray, shape (H, W), float32; projector column per camera pixel, NaN unknown
    expected_px : ndarray, shape (H, W), float32; ``column_px`` with the gaps filled from the
        rig's prediction for a plane at Z0 (what the cycle number is chosen against)
    inverse : ndarray, shape (H, Wp + 1), float32; x showing each integer column per row
    z0_m : float
    mixing : ndarray, shape (3, 3), float64, or None; the projector-to-camera coupling matrix
        K (:func:`simbench.decode.color.mixing_matrix`), when calibration captures under each
        primary came with the reference
    """

    column_px: np.ndarray
    expected_px: np.ndarray
    inverse: np.ndarray
    z0_m: float
    mixing: np.ndarray | None = None


@dataclass(frozen=True)
class DecodeResult:
    """Decoder output, on the camera's ideal pinhole pixel grid (a capture from a camera with
    lens distortion in the rig is undistorted first).

    depth_m : ndarray, shape (H, W), float32; NaN where invalid
    valid : ndarray, shape (H, W), bool
    confidence : ndarray, shape (H, W), float32; the fringe SNR
        (:func:`simbench.decode.phase.fringe_snr`; with ``params.phase_stability`` capped at
        :data:`STABILITY_KAPPA_RAD` over the phase's change) of every pixel the decoder found a depth for,
        those below ``params.min_confidence`` (now holes) included; 0 where it found none
    column_px : ndarray, shape (H, W), float32; decoded projector column, NaN if invalid
    stripe_index : ndarray, shape (H, W), int32; n of Eq. 14, -1 if invalid
    stages : Mapping of str -> ndarray; intermediate images (paper Fig. 6), made on first access
    """

    depth_m: np.ndarray
    valid: np.ndarray
    confidence: np.ndarray
    column_px: np.ndarray
    stripe_index: np.ndarray
    stages: Mapping = field(default_factory=dict)


class LazyStages(Mapping):
    """Stage images computed on first access, so a decode only pays for the ones it needs.

    A stage made from another stage takes the mapping as its argument (``put(..., derived=True)``)
    instead of closing over it: a closure over the mapping that holds it is a reference cycle,
    which kept every band's intermediate images (~40 MB a decode) alive until Python's cyclic
    collector ran, so each decode wrote into freshly faulted memory and a process grew to ~1 GB.
    """

    def __init__(self) -> None:
        self._make: dict[str, tuple[Callable, bool]] = {}
        self._done: dict[str, np.ndarray] = {}

    def put(self, name: str, value, *, derived: bool = False) -> None:
        """``value``: an image, a function of no arguments making it, or with ``derived`` a
        function of this mapping making it."""
        if derived and not callable(value):
            raise TypeError(f"stage {name!r}: a derived stage needs a function of the stages")
        if callable(value):
            self._make[name] = (value, derived)
        else:
            self._make[name] = (lambda v=value: v, False)

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._done:
            make, derived = self._make[name]
            self._done[name] = make(self) if derived else make()
        return self._done[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._make)

    def __len__(self) -> int:
        return len(self._make)


def _check_capture(image: np.ndarray, expected_size_hw: tuple[int, int] | None) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"capture must have shape (H, W, 3), got {img.shape}")
    if expected_size_hw is not None and img.shape[:2] != tuple(expected_size_hw):
        raise ValueError(
            f"capture is {img.shape[1]}x{img.shape[0]} (WxH); the rig's camera is "
            f"{expected_size_hw[1]}x{expected_size_hw[0]}"
        )
    if img.dtype in (np.uint8, np.uint16):
        return img
    if np.issubdtype(img.dtype, np.floating):
        if not np.isfinite(img.sum(dtype=np.float64)):
            raise ValueError("capture contains NaN or inf")
        return img
    raise ValueError(f"unsupported capture dtype {img.dtype}; use uint8, uint16 or float")


def _ideal_image(image: np.ndarray, rig: Rig) -> np.ndarray:
    """The capture resampled onto the ideal pinhole grid when the rig's camera has lens
    distortion (every later stage, and the output, live on that grid)."""
    return undistort_image(image, rig.camera) if rig.camera.has_distortion else image


def _to_float(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.uint8:
        return np.multiply(img, np.float32(1 / 255), dtype=np.float32)
    if img.dtype == np.uint16:
        return np.multiply(img, np.float32(1 / 65535), dtype=np.float32)
    return img.astype(np.float32)


def as_float_image(image: np.ndarray, *, expected_size_hw: tuple[int, int] | None = None) -> np.ndarray:
    """A capture as float32 RGB in [0, 1]: uint8 / 255, uint16 / 65535, floats as they are.

    Raises
    ------
    ValueError
        Wrong shape or size, unsupported dtype, or non-finite float values.
    """
    return _to_float(_check_capture(image, expected_size_hw))


def _per_pixel(per_stripe: np.ndarray, labels: np.ndarray, fill) -> np.ndarray:
    """Spread one value per stripe over its pixels; ``fill`` where the label is -1."""
    out = np.empty(labels.shape, per_stripe.dtype)
    _kernels.gather(np.ascontiguousarray(per_stripe), np.ascontiguousarray(labels), per_stripe.dtype.type(fill), out)
    return out


def _fused_front_end(params: DecoderParams, unmixing: np.ndarray | None, image: np.ndarray) -> bool:
    """Whether a band takes the one-pass front end (:func:`simbench.decode._kernels.front_end`):
    the paper's channels as they are (no unmixing or normalisation), intensity by Eq. 9 or the
    fringe channel, a contiguous uint8/uint16/float32 capture."""
    return (
        unmixing is None
        and not params.color_normalize
        and params.intensity_mode in _FUSED_INTENSITY
        and image.dtype in (np.uint8, np.uint16, np.float32)
        and image.flags.c_contiguous
    )


_FUSED_INTENSITY = {"overlay": 0, "blue": 1}


@dataclass(frozen=True)
class BandStripes:
    """What the stripe stages leave for the absolute column (paper Eq. 14) of a band's rows.

    labels : ndarray, shape (h, W), int32; stripe of each pixel, -1 none
    position : ndarray, shape (n_stripes,), int32; W of each stripe after the neighbour
        correction, -1 unknown
    wrapped, expected, confidence : ndarray, shape (h, W), float32; the wrapped phase, the
        column the cycle number is chosen against, the fringe SNR (:func:`fringe_snr`)
    """

    labels: np.ndarray
    position: np.ndarray
    wrapped: np.ndarray
    expected: np.ndarray
    confidence: np.ndarray
    period_px: int
    cycle: int

    def position_map(self) -> np.ndarray:
        """W per pixel, -1 unknown."""
        return _per_pixel(self.position, self.labels, -1)

    @cached_property
    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(column_px, stripe_index) per pixel, before the depth range is applied
        (:func:`simbench.decode.depth.absolute_column`)."""
        return absolute_column(
            self.position_map(), self.wrapped, self.expected, period_px=self.period_px, cycle=self.cycle
        )


def _columns(
    image: np.ndarray,
    order: list[int],
    expected_column: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams,
    crop: slice,
    unmixing: np.ndarray | None = None,
) -> tuple[BandStripes, LazyStages]:
    """Stages 1-3 for one band of rows.

    ``image`` is the band of the checked capture (any dtype :func:`as_float_image` takes,
    channels in the capture's order; ``order`` lists the indices of code 1, code 0 and the
    fringe) plus a halo of rows above and below for the phase fit; ``crop`` selects the band's
    own rows, to which everything after the fit is restricted.
    Returns (:class:`BandStripes`, stages) for the cropped rows; the stage images of the
    absolute column (``position``, ``column``, ``unwrapped_phase``) are made on access.
    """
    t_cam = params.camera_period(rig)
    # with normalised channels a stripe whose colour the surface absorbs is still usable, so
    # "lit" looks across the neighbouring stripes: twice the normalisation window, so that
    # at the image border, where only one side is in view, both stripe colours still are
    window = 2 * (params.order + 1) if params.color_normalize else 1
    if _fused_front_end(params, unmixing, image):
        # the same bits as the general path below, in one pass over the capture
        with stage("front end (float, lit/clipped, Eq. 9, Eq. 13)"):
            hb, wb = image.shape[:2]
            intensity = np.empty((hb, wb), np.float32)
            certainty = np.empty((hb, wb), np.float32)
            lit = np.empty((hb, wb), bool)
            code_full = np.empty((hb, wb), bool)
            _kernels.front_end(
                image,
                order,
                _FUSED_INTENSITY[params.intensity_mode],
                certainty_window_px(t_cam, window),
                params.dark_level,
                params.saturation_level,
                intensity,
                certainty,
                lit,
                code_full,
            )
            code = code_full[crop]
    else:
        with stage("to float"):
            rgb = _to_float(image if order == [0, 1, 2] else image[..., order])
        with stage("lit and clipped pixels"):
            certainty, lit = certainty_map(
                rgb,
                period_px=t_cam,
                dark_level=params.dark_level,
                saturation_level=params.saturation_level,
                window_periods=window,
            )
        raw = rgb
        weights = span = None
        with stage("colour unmixing and normalisation"):
            if unmixing is not None:
                rgb = unmix(rgb, unmixing)
            if params.color_normalize:
                norm = dict(period_px=t_cam, order=params.order, min_span=0.25 * params.dark_level, return_span=True)
                normed, span = normalize_channels(rgb, **norm)
                if params.albedo_flatten:
                    gain = albedo_gain(rgb, span, period_px=t_cam, order=params.order)
                    # with no step anywhere the gain is exactly 1 and the normalisation stands
                    if not (gain == 1.0).all():
                        normed, span = normalize_channels(rgb * gain[..., None], **norm)
                rgb = normed
                if params.intensity_mode == "weighted":
                    weights = overlay_weights(
                        raw, span, unmixing=unmixing, period_px=t_cam, order=params.order, floor=params.dark_level
                    )
        with stage("intensity overlay (Eq. 9)"):
            intensity = overlay_intensity(rgb, mode=params.intensity_mode, weights=weights)
        with stage("colour code (Eq. 13)"):
            code = color_code(rgb[crop]) if span is None else normalized_color_code(rgb[crop], span[crop])
    sx = params.sigma_periods * t_cam
    with stage(f"phase ({params.phase_method}, Eq. 10-11)"):
        # no offset: no stage reads it, and not writing it saves a fifth of the Gabor kernel's output
        phase = PHASE_METHODS[params.phase_method](
            intensity,
            certainty=certainty,
            period_px=t_cam,
            sigma_x_px=sx,
            sigma_y_px=sx * params.sigma_y_ratio,
            offset=False,
        )
    narrow = None
    if params.phase_stability:
        with stage(f"phase stability ({params.phase_method} at {STABILITY_WINDOW_SCALE:g} x the window)"):
            narrow = PHASE_METHODS[params.phase_method](
                intensity,
                certainty=certainty,
                period_px=t_cam,
                sigma_x_px=sx * STABILITY_WINDOW_SCALE,
                sigma_y_px=sx * params.sigma_y_ratio,
                offset=False,
            ).wrapped[crop]
    with stage("validity"):
        intensity, certainty, lit = intensity[crop], certainty[crop], lit[crop]
        wrapped, amplitude, residual, support_w = (
            phase.wrapped[crop],
            phase.amplitude[crop],
            phase.residual[crop],
            phase.support[crop],
        )
        valid = np.empty(lit.shape, bool)
        _kernels.validity(
            lit,
            support_w,
            amplitude,
            residual,
            params.min_window_support,
            params.min_amplitude,
            params.max_residual,
            valid,
        )
    with stage("stripe segmentation and voting"):
        stripes = segment_stripes(
            wrapped,
            valid,
            period_px=t_cam,
            min_step_ratio=params.stripe_step_ratio[0],
            max_step_ratio=params.stripe_step_ratio[1],
            max_gap_px=int(params.bridge_gap_periods * t_cam),
        )
        stripe_code, agreement = vote_codes(code, stripes, voting=params.voting)
    lab = stripes.labels
    with stage("confidence"):
        confidence = fringe_snr(residual)
        shift = None
        if narrow is not None:
            shift = phase_change(wrapped, narrow)
            with np.errstate(divide="ignore", invalid="ignore"):
                # fmin: where the narrow fit has no phase the fringe SNR stands
                np.fmin(confidence, np.float32(STABILITY_KAPPA_RAD) / shift, out=confidence)
    with stage("De Bruijn windows and neighbour correction"):
        table = _window_table(params.order, params.sequence)
        raw_w = window_positions_of_stripes(
            stripe_code, stripes.linked_prev, order=params.order, table=table, cycle=params.cycle
        )
        w_fixed, support = neighbour_correct(
            raw_w, stripes.linked_prev, cycle=params.cycle, reach=params.neighbour_reach, min_support=params.min_support
        )
        if params.link_check:
            dropped = drop_broken_links(w_fixed, stripes.linked_prev, cycle=params.cycle)
            # the stripe floors only where a link broke (most bands of a smooth scene have none)
            if params.link_keep_certain > 0.0 and not np.array_equal(dropped, w_fixed):
                dropped = keep_certain_sides(
                    w_fixed,
                    dropped,
                    stripes.linked_prev,
                    stripe_floor(confidence, stripes),
                    cycle=params.cycle,
                    min_confidence=params.link_keep_certain,
                )
            w_fixed = dropped
            support = np.where(w_fixed >= 0, support, 0)
    band = BandStripes(
        labels=lab,
        position=w_fixed.astype(np.int32, copy=False),
        wrapped=wrapped,
        expected=np.ascontiguousarray(expected_column, dtype=np.float32),
        confidence=confidence,
        period_px=params.period_px,
        cycle=params.cycle,
    )
    st = LazyStages()
    st.put("intensity", intensity)
    st.put("certainty", certainty)
    st.put("lit", lit)
    st.put("window_support", support_w)
    st.put("wrapped_phase", wrapped)
    st.put("amplitude", amplitude)
    st.put("fit_residual", residual)
    st.put("confidence", confidence)
    if shift is not None:
        st.put("phase_change", shift)
    st.put("phase_valid", valid)
    st.put("code", code)
    st.put("stripe_label", lab)
    st.put("stripe_code", lambda: _per_pixel(stripe_code.astype(np.int8), lab, -1))
    st.put("stripe_agreement", lambda: _per_pixel(agreement, lab, 0.0))
    st.put("position_raw", lambda: _per_pixel(raw_w, lab, -1))
    st.put("position", band.position_map)
    st.put("support", lambda: _per_pixel(support, lab, 0))
    st.put("column", lambda: band.columns[0])

    def unwrapped():
        index = band.columns[1]
        return np.where(index >= 0, wrapped + np.float32(2 * np.pi) * index, np.float32(np.nan))

    st.put("unwrapped_phase", unwrapped)
    return band, st


_R = TypeVar("_R")


def apply_min_confidence(result: _R, min_confidence: float) -> _R:
    """``result`` - a :class:`DecodeResult` decoded with no threshold, or any depth result with
    ``depth_m``, ``valid`` and ``confidence`` (and optionally ``column_px``, ``stripe_index``),
    e.g. :class:`simbench.systems.SystemDepth` - with the valid pixels whose confidence is not
    at least ``min_confidence`` made holes, their confidence kept: for a DecodeResult the same
    bits :func:`decode` gives with that ``min_confidence`` (tests/test_decode.py), without
    decoding again."""
    conf = np.asarray(result.confidence, np.float32)
    with np.errstate(invalid="ignore"):
        doubtful = result.valid & ~(conf >= np.float32(min_confidence))
    changes = {
        "depth_m": np.where(doubtful, np.float32(np.nan), result.depth_m).astype(np.float32, copy=False),
        "valid": result.valid & ~doubtful,
        "confidence": conf,
    }
    if getattr(result, "column_px", None) is not None:
        changes["column_px"] = np.where(doubtful, np.float32(np.nan), result.column_px)
    if getattr(result, "stripe_index", None) is not None:
        changes["stripe_index"] = np.where(doubtful, np.int32(-1), result.stripe_index)
    return dataclasses.replace(result, **changes)


def phase_change(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """|a - b| of two wrapped phases, wrapped to [0, pi] (float32, rad; NaN where either is)."""
    d = np.abs(np.asarray(a, np.float32) - np.asarray(b, np.float32))
    return np.minimum(d, np.float32(2 * np.pi) - d)


@lru_cache(maxsize=16)
def _window_table(order: int, sequence: tuple[int, ...] | None) -> np.ndarray:
    t = window_positions(code_sequence(sequence, order=order), order=order)
    t.setflags(write=False)
    return t


@lru_cache(maxsize=16)
def _plane_columns(rig: Rig, z_m: float) -> np.ndarray:
    col = projector_column_at_depth(z_m, rig).astype(np.float32)
    col.setflags(write=False)
    return col


def _bands(height: int, width: int, params: DecoderParams, rig: Rig) -> tuple[list[tuple[int, int]], int, int]:
    """Row bands, the halo (rows) each needs for the phase fit, and the worker threads: one
    band per thread, never thinner than 4 halos (or 32 rows).

    (Bands were once also kept under 4 MiB of float32 image each, because first-touching fresh
    huge pages made single-thread decodes slow; the fresh pages came from a reference cycle that
    kept each decode's images alive, and since that is gone one band per thread is the faster
    plan: single-thread 1280x960 decode 15.8 -> 15.2 ms median, 2 threads unchanged.)"""
    sy = params.sigma_periods * params.camera_period(rig) * params.sigma_y_ratio
    halo = int(np.ceil(3.0 * sy))
    most = max(1, height // max(4 * halo, 32))
    threads = max(1, params.threads or os.cpu_count() or 1)
    n = min(threads, most)
    edges = np.linspace(0, height, n + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])], halo, n


def _run_bands(fn, image: np.ndarray, params: DecoderParams, rig: Rig) -> list:
    """Apply ``fn(band_with_halo, order, rows, crop)`` to each band, in parallel threads
    (``image`` is a checked capture, each band a view of its rows; ``order``: the channel
    indices of code 1, code 0 and the fringe)."""
    h = image.shape[0]
    bands, halo, workers = _bands(h, image.shape[1], params, rig)
    order = list(check_channels(params.channels))

    def work(band):
        r0, r1 = band
        a0, a1 = max(0, r0 - halo), min(h, r1 + halo)
        return fn(image[a0:a1], order, slice(r0, r1), slice(r0 - a0, r1 - a0))

    if workers == 1:
        return [work(b) for b in bands]
    return run_in_context(_band_pool(os.getpid(), workers), work, bands)


@lru_cache(maxsize=8)
def _band_pool(pid: int, workers: int) -> ThreadPoolExecutor:
    """The row bands' worker threads, kept for the process (``pid``: a forked child makes its
    own; it does not inherit the threads): a pool per decode started two threads each time,
    ~1.3 s of a warm quick run's 252 decodes.  Bands hold no state between decodes."""
    return ThreadPoolExecutor(max_workers=workers, thread_name_prefix="simbench-band")


def _merge_stages(parts: list[LazyStages]) -> LazyStages:
    """Stack the bands' stage images; stripe labels are renumbered to stay unique."""
    if len(parts) == 1:
        return parts[0]
    merged = LazyStages()

    def stack(name):
        arrays = [p[name] for p in parts]
        if name == "stripe_label":
            out, offset = [], 0
            for a in arrays:
                out.append(np.where(a >= 0, a + offset, -1))
                offset += int(a.max()) + 1 if a.size and a.max() >= 0 else 0
            arrays = out
        return np.concatenate(arrays, axis=0)

    for name in parts[0]:
        merged.put(name, lambda name=name: stack(name))
    return merged


def _unmixing(mixing: np.ndarray | None, params: DecoderParams) -> np.ndarray | None:
    """The inverse coupling matrix in the stages' channel order (R = code 1, G = code 0,
    B = fringe), or None when ``params.unmix`` is off."""
    if not params.unmix:
        return None
    if mixing is None:
        raise ValueError(
            "unmix=True needs the reference plane's calibration captures under each primary (decode_reference(..., "
            "primaries=, dark=))"
        )
    order = list(check_channels(params.channels))
    inv = np.linalg.inv(np.asarray(mixing, np.float64))
    return inv[np.ix_(order, order)]


def _calibration_region(primaries, dark: np.ndarray) -> np.ndarray:
    """Pixels where every primary lifts its own channel to at least a quarter of its 95th
    percentile over the dark frame: the lit reference plane, away from shadows and borders."""
    d = np.asarray(dark, np.float32)
    region = np.ones(d.shape[:2], bool)
    for p, img in enumerate(primaries):
        lift = np.asarray(img, np.float32)[..., p] - d[..., p]
        region &= lift >= 0.25 * np.percentile(lift, 95)
    return region


def decode_reference(
    reference: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams,
    primaries: Sequence[np.ndarray] | None = None,
    dark: np.ndarray | None = None,
) -> ReferenceMap:
    """Decode a reference-plane capture (a plane at ``params.z0_m``) into its column map.

    Done once per calibration; :func:`decode` then matches captures against it.  With
    ``primaries`` (the plane under the projector's red, green and blue primary at full drive)
    and ``dark`` (under a black frame) the coupling matrix is measured too
    (:func:`simbench.decode.color.mixing_matrix`), which ``params.unmix`` needs.

    Raises
    ------
    ValueError
        When less than ``params.min_reference_coverage`` of the pixels decode (a black,
        saturated or unrelated image is not a reference), or calibration captures are
        missing, mis-sized or unusable.
    """
    image = _ideal_image(_check_capture(reference, rig.camera.size_hw), rig)
    mixing = None
    if primaries is not None or dark is not None:
        if primaries is None or dark is None or len(primaries) != 3:
            raise ValueError("the coupling-matrix calibration needs three primary captures and a dark frame")
        cal = [_to_float(_ideal_image(_check_capture(c, rig.camera.size_hw), rig)) for c in (*primaries, dark)]
        mixing = mixing_matrix(cal[:3], cal[3], region=_calibration_region(cal[:3], cal[3]))
    unmixing = _unmixing(mixing, params)
    predicted = _plane_columns(rig, float(params.z0_m))
    parts = _run_bands(
        lambda img, order, rows, crop: _columns(
            img, order, predicted[rows], rig=rig, params=params, crop=crop, unmixing=unmixing
        )[0].columns[0],
        image,
        params,
        rig,
    )
    column = np.concatenate(parts, axis=0)
    coverage = float(np.isfinite(column).mean())
    if coverage < params.min_reference_coverage:
        raise ValueError(
            f"the reference capture decodes at only {100 * coverage:.1f} % of its pixels (at least "
            f"{100 * params.min_reference_coverage:.0f} % expected of a lit plane at Z0 = {params.z0_m:g} m): "
            "is it the reference-plane capture, taken with this pattern and rig?"
        )
    expected = np.where(np.isfinite(column), column, predicted)
    inverse = inverse_column_table(column, projector_width=rig.projector.width_px)
    return ReferenceMap(column_px=column, expected_px=expected, inverse=inverse, z0_m=params.z0_m, mixing=mixing)


# How far a decoded reference plane may lie from Z0, relative (assumption: a lab places its
# reference board within 1 % of Z0 - simbench.sim.scene.Placement's +-10 mm at 1 m - and a
# calibrated rig adds well under 0.5 %; a reference of another rig lies far outside: a 0.120 m
# baseline read as 0.093 m puts the plane ~29 % off).
REFERENCE_Z0_TOLERANCE = 0.03


def reference_plane_offset(reference: ReferenceMap, rig: Rig) -> float:
    """Where a decoded reference plane lies relative to Z0 by triangulation with ``rig``:
    the median over its decoded pixels of ``(Z - Z0) / Z0`` (to first order in the column's
    change with depth); NaN when nothing decoded.

    Reference mode matches captures against the reference and so cannot itself tell a
    reference of another rig, or a wrong Z0: depths then come out wrong everywhere, without a
    word.  Triangulating the reference with the rig can (:data:`REFERENCE_Z0_TOLERANCE`).
    """
    z0 = float(reference.z0_m)
    dz = 0.01 * z0
    c0 = projector_column_at_depth(z0, rig)
    slope = (projector_column_at_depth(z0 + dz, rig) - c0) / dz  # columns per metre
    col = reference.column_px
    ok = np.isfinite(col) & np.isfinite(slope) & (np.abs(slope) > 1e-6)
    if not ok.any():
        return float("nan")
    return float(np.median((col[ok] - c0[ok]) / slope[ok])) / z0


def decode(
    capture: np.ndarray,
    *,
    rig: Rig,
    params: DecoderParams = DecoderParams(),
    reference: ReferenceMap | np.ndarray | None = None,
) -> DecodeResult:
    """Decode one capture into depth (paper Sec. 5).

    Rows are processed in bands on ``params.threads`` threads (each with a halo of rows for
    the phase fit); the result does not depend on the number of threads.

    Parameters
    ----------
    capture : ndarray, shape (H, W, 3), uint8/uint16/float
        RGB capture of the scene under the pattern; (H, W) must match ``rig.camera``.
    rig : Rig
    params : DecoderParams
    reference : ReferenceMap or ndarray, optional
        The reference-plane capture (or its decoded map, to decode many captures against one
        reference); required in ``reference`` mode, and with ``params.unmix`` (for its
        coupling matrix) in either mode.

    Returns
    -------
    DecodeResult
        Never raises on a legal image: what cannot be decoded is NaN in ``depth_m`` and False
        in ``valid``.
    """
    with stage("input check and undistortion"):
        image = _ideal_image(_check_capture(capture, rig.camera.size_hw), rig)
    h, w = image.shape[:2]
    zmin, zmax = params.depth_range_m
    ref = None
    if params.mode == "reference" and reference is None:
        raise ValueError("reference mode needs the reference-plane capture (or use mode='calibrated')")
    if params.unmix and not isinstance(reference, ReferenceMap):
        raise ValueError(
            "unmix=True needs the decoded reference (decode_reference with its calibration captures under each primary)"
        )
    if reference is not None and (params.mode == "reference" or params.unmix):
        ref = reference if isinstance(reference, ReferenceMap) else decode_reference(reference, rig=rig, params=params)
        if ref.column_px.shape != (h, w):
            raise ValueError(f"reference map shape {ref.column_px.shape} does not match the capture {(h, w)}")
    unmixing = _unmixing(ref.mixing if ref is not None else None, params)
    if params.mode == "reference":
        expected = ref.expected_px
    else:
        ref = None  # calibrated mode uses the reference for its coupling matrix only
        expected = _plane_columns(rig, 2.0 / (1.0 / zmin + 1.0 / zmax))
    rig_values = triangulation_values(rig)
    distorted, newton_steps, refine_steps = triangulation_steps(rig)
    depth_out = np.empty((h, w), np.float32)
    valid_out = np.empty((h, w), bool)
    conf_out = np.empty((h, w), np.float32)
    col_out = np.empty((h, w), np.float32)
    index_out = np.empty((h, w), np.int32)
    inv_fb = 1.0 / (rig.camera.focal_px * rig.baseline_m)

    def band(img, order, rows, crop):
        stripes, stages = _columns(img, order, expected[rows], rig=rig, params=params, crop=crop, unmixing=unmixing)
        # paper Eq. 14-15: a column the reference row never shows (near the image's ends, for
        # surfaces off the reference depth) cannot be matched: it is triangulated with the rig
        how = "reference matching" if ref is not None else "triangulation"
        with stage(f"column, depth, output (Eq. 14-15, {how})"):
            _kernels.decode_tail(
                stripes.labels,
                stripes.position,
                stripes.wrapped,
                stripes.expected,
                stripes.confidence,
                t=params.period_px,
                cycle=params.cycle,
                row0=rows.start,
                table=ref.inverse[rows] if ref is not None else None,
                inv_z0=1.0 / ref.z0_m if ref is not None else 0.0,
                inv_fb=inv_fb,
                rig_values=rig_values,
                distorted=distorted,
                newton_steps=newton_steps,
                refine_steps=refine_steps,
                zmin=zmin,
                zmax=zmax,
                depth_out=depth_out[rows],
                valid_out=valid_out[rows],
                conf_out=conf_out[rows],
                col_out=col_out[rows],
                index_out=index_out[rows],
            )
        if ref is not None:
            stages.put("reference_x", lambda: match_reference(stripes.columns[0], ref.inverse[rows]))
            stages.put(
                "triangulated",
                lambda st: np.isnan(st["reference_x"]) & np.isfinite(stripes.columns[0]),
                derived=True,
            )
        return stages

    parts = _run_bands(band, image, params, rig)
    if params.min_confidence > 0.0:
        with stage("operating point (min_confidence)"):
            doubtful = valid_out & (conf_out < np.float32(params.min_confidence))
            depth_out[doubtful] = np.nan
            col_out[doubtful] = np.nan
            index_out[doubtful] = -1
            valid_out &= ~doubtful
    return DecodeResult(
        depth_m=depth_out,
        valid=valid_out,
        confidence=conf_out,
        column_px=col_out,
        stripe_index=index_out,
        stages=_merge_stages(parts),
    )
