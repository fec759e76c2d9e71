"""Hard scenes (issue 35): what each method costs on the geometry and surfaces real users point a
sensor at - concave corners and a box interior (interreflection), objects before walls (depth
edges, projector shadows), printed charts (albedo edges), saturated paints, glossy boards
(``scenes/hard_*.toml``, written by ``scenes/make_hard_scenes.py``).

Every scene is captured once by the proposed sensor and decoded by triangulation (paper Eq. 15)
with the paper's decoder and with our colour-robust decoder, and recorded by the multi-shot
phase-shifting reference on the same projector and camera.  Scored off a band of
``RunConfig.edge_band_px`` pixels at every depth edge and object boundary of the ground truth,
over the pixels the projector lights:

- ``completeness``: decoded share of those pixels;
- ``gt_mae_mm``: mean absolute error against ground truth over the decoded ones;
- ``wrong_share``: share of those decoded pixels more than 5 mm from ground truth;
- ``wrong_share_all``: share of every decoded pixel of the image more than 5 mm from ground
  truth - the edge band, shadows and pixels the projector does not reach included, a decoded
  pixel where the truth sees nothing counted wrong: the wrong depths the output does not mark
  (the issue's goal: at most 0.1 % of the decoded pixels; until 2026-11-30 judged on
  ``wrong_share``, which a review of the protocols found blind to the band it leaves out - the
  90-degree corner's crease kept 0.51 % of its decoded pixels 5-7 mm wrong there, unseen);
- ``stripe_order_errors`` (structured light): pixels whose decoded projector column is off by
  more than half a period.

Both decoders run with no confidence threshold first; the table gives the paper's decoder so
(the paper describes no confidence) and the colour-robust decoder at its operating point
(:data:`simbench.decode.ROBUST_MIN_CONFIDENCE`).  Beside it, for both decoders: completeness
against the wrong share when only the decoded pixels whose confidence (the fringe SNR,
:func:`simbench.decode.phase.fringe_snr`, for the colour-robust decoder capped by the phase's
stability) reaches each of :data:`CONFIDENCE_THRESHOLDS` are kept -
the curves the operating point is chosen from.  What it cannot see: errors under 5 mm that are
systematic (the MAE shows them); completeness and MAE leave the edge band and the unlit pixels out
(``wrong_share_all`` does not).

What the camera and the renderer cost: the scenes of :data:`CAMERA_SCENES` are recorded again
with sets of effects of the run's sensor model taken out (:data:`CAMERA_EFFECTS`, each taken from
the ``ideal`` model: the same renders, placement and noise seeds) and decoded by the colour-robust
decoder at its operating point and the phase-shifting reference; those of :data:`RENDER_SCENES`
also rendered with more samples per pixel (:func:`more_samples`; the colour-robust decoder only):
each term's share of a shortfall, shown separately (e.g. the Bayer mosaic's on the 20:1 prints).
And on every scene, with a physical sensor model, the path tracer's noise against the camera's
(:func:`measure_render_noise`, as :mod:`simbench.experiments.render_noise` measures them on the
white board): where it is above the testbed's target, the scene's scores are pessimistic.

Writes ``hard_scenes.md``, ``hard_scenes.csv``, ``hard_scenes_camera.csv``,
``hard_scenes_render_noise.csv``, ``hard_scenes_confidence.csv``, ``hard_scenes_confidence.png``, ``.pdf`` and
``hard_scenes.provenance.json``.
"""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction
from typing import TYPE_CHECKING

import numpy as np

from simbench.decode.pipeline import apply_min_confidence
from simbench.report import figure_files, figure_formats
from simbench.experiments.common import RunConfig, Session, Split, markdown_table, score, table_text
from simbench.experiments.render_noise import REPEATS as NOISE_REPEATS
from simbench.experiments.render_noise import TARGET_RATIO, noise_captures, noise_spreads
from simbench.metrics import confidence_curve as _curve
from simbench.metrics import edge_band, every_decoded_pixel
from simbench.sim.sensor import EFFECT_TABLE, SensorModel, get_sensor, with_effects

if TYPE_CHECKING:
    from simbench.decode.params import DecoderParams
    from simbench.decode.pipeline import DecodeResult
    from simbench.systems import Recording, SystemDepth

__all__ = [
    "HARD_SCENES",
    "QUICK_SCENES",
    "CONFIDENCE_THRESHOLDS",
    "WRONG_MM",
    "run_hard_scenes",
    "measure_scene",
    "write_hard_scenes",
    "scene_names",
    "SPLIT",
    "confidence_curve",
    "operating_point",
    "GOAL_COMPLETENESS",
    "GOAL_WRONG_SHARE",
    "GOAL_MAE_MM",
    "short_of_goals",
    "object_scores",
    "scene_scores",
    "format_score",
    "CAMERA_SCENES",
    "CAMERA_EFFECTS",
    "RENDER_SCENES",
    "RENDER_SPP_FACTORS",
    "camera_sensors",
    "more_samples",
    "least_samples",
    "samples_for_target",
    "measure_render_noise",
    "NOISE_COLUMNS",
]

# scene -> its class (the list; scenes/make_hard_scenes.py writes them)
HARD_SCENES = {
    "hard_corner_045": "interreflection",
    "hard_corner_050": "interreflection",
    "hard_corner_060": "interreflection",
    "hard_corner_075": "interreflection",
    "hard_corner_090": "interreflection",
    "hard_corner_105": "interreflection",
    "hard_corner_120": "interreflection",
    "hard_corner_065_turned": "interreflection",
    "hard_corner_055_grey": "interreflection",
    "hard_vgroove_090": "interreflection",
    "hard_box_interior": "interreflection",
    "hard_box_before_wall": "depth edges, shadows",
    "hard_sphere_before_wall": "depth edges, shadows",
    "hard_stairs_deep": "depth edges, shadows",
    "hard_chart_high": "printed albedo",
    "hard_chart_mid": "printed albedo",
    "hard_chart_low": "printed albedo",
    "hard_chart_fine": "printed albedo",
    "hard_chart_fine_mid": "printed albedo",
    "hard_chart_fine_turned": "printed albedo",
    "hard_chart_fine_high_turned": "printed albedo",
    "hard_paint_red": "saturated colour",
    "hard_paint_orange": "saturated colour",
    "hard_paint_yellow_green": "saturated colour",
    "hard_paint_magenta": "saturated colour",
    "hard_glossy_005": "gloss",
    "hard_glossy_015": "gloss",
    "hard_glossy_030": "gloss",
}
# the quick (CI) run: one scene of each class
QUICK_SCENES = ("hard_corner_090", "hard_box_before_wall", "hard_chart_high", "hard_paint_orange", "hard_glossy_005")
DECODERS = ("paper", "robust")
REFERENCE_SYSTEM = "phase_shift"
WRONG_MM = 5.0  # the "wrong": more than 5 mm from ground truth
GOAL_COMPLETENESS = 0.97  # issue 35's goals per scene
GOAL_WRONG_SHARE = 0.001
GOAL_MAE_MM = 0.5
# confidence thresholds the curves are drawn at (0: every decoded pixel)
CONFIDENCE_THRESHOLDS = (0.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0, 12.0, 15.0, 20.0)
SCORE_KEYS = ("completeness", "gt_mae_mm", "wrong_share", "wrong_share_all", "stripe_order_errors")
# The scenes also rendered with at least each of RENDER_SPP_FACTORS times the run's samples per
# pixel (the colour-robust decoder only - the reference's 12 exposures would take as many renders
# again): the box interior, whose faces are lit by each other, where 36 spp leave a render noise
# above the camera's (measured 2026-12-04, 1280x960, standard deviation per channel: 1.4-1.6 DN on
# its right, top and back faces against 0.8-1.5 DN of camera noise, on a +-5 DN fringe on the right
# face; in its decoded depth 1.43x the camera's: the table's render-noise section).  4x halves that
# noise; 25x (900 spp: 30^2, rendered in passes of 4; 17.5 min on 2 cores, shared for ~7 of them
# with another run) projects it, by 1/sqrt(spp) (measured on hard_corner_045 from 36 to 144 spp:
# samples_for_target), to a fifth: under the testbed's target of a third (results/render_noise.md),
# not measured there (tests/test_hard_scenes.py checks the committed ratio still needs no more).
# The variants' calibration frames are rendered at their samples too (a session's calibration is
# its own).
RENDER_SCENES = ("hard_box_interior",)
RENDER_SPP_FACTORS = (4, 25)
# The scenes recorded again without some of the camera's effects (in HARD_SCENES' order, the order
# they are measured and written in): the printed charts (their albedo edges are where a colour
# camera's Bayer mosaic interpolates a missing colour across a 20:1 step) and RENDER_SCENES (is the
# box's few-DN fringe noise-limited?).  Measured on hard_chart_fine_high_turned before this table
# (2026-12-04, 1280x960, the colour-robust decoder at its operating point): 94.78 % complete, MAE
# 0.510 mm; without the mosaic 98.40 %, 0.360 mm; re-interpolating the mosaic in the decoder
# (gain-guided, one-sided at the edges, gradient-corrected, VNG, Gaussian) got none of it back
# (docs/decoder.md).
CAMERA_SCENES = tuple(n for n, c in HARD_SCENES.items() if c == "printed albedo" or n in RENDER_SCENES)
# the sets of effects taken out (simbench.sim.sensor.EFFECT_TABLE's names), each from the `ideal` model
CAMERA_EFFECTS = (("cfa",), ("noise",), ("cfa", "noise"))
# the scores the camera table keeps, per decoder
CAMERA_SCORE_KEYS = ("completeness", "gt_mae_mm", "wrong_share_all")
# the render-noise table's columns (measure_render_noise())
NOISE_COLUMNS = (
    "scene",
    "class",
    "render_sd_mm",
    "camera_sd_mm",
    "total_sd_mm",
    "ratio",
    "meets_target",
    "spp_for_target",
    "pixels",
    "jumps",
    "render_seeds",
    "noise_seeds",
)


def scene_scores(
    rec: Recording, depth: SystemDepth | DecodeResult, period_px: float | None, region: np.ndarray
) -> dict:
    """A recording's decoded depth scored by this target's protocol over ``region`` (the lit
    pixels off the edge band): completeness, MAE, the wrong share there and of every decoded
    pixel, and the stripe-order errors (NaN for a system without stripes)."""
    s = score(rec, depth, period_px, region=region)
    return {
        "completeness": s["completeness"],
        "gt_mae_mm": s["gt_mae_mm"],
        "wrong_share": _wrong_share(rec, depth, region),
        "wrong_share_all": wrong_share_all(depth.depth_m, rec.gt.depth_m),
        "stripe_order_errors": s.get("stripe_order_errors", float("nan")),
    }


def _wrong_share(rec, depth, region) -> float:
    err = np.abs(depth.depth_m - rec.gt.depth_m)[region & np.isfinite(depth.depth_m)]
    return float(np.mean(err > WRONG_MM / 1000.0)) if err.size else float("nan")


def wrong_share_all(depth_m: np.ndarray, gt_depth_m: np.ndarray) -> float:
    """The share of every decoded pixel (finite depth) more than :data:`WRONG_MM` from
    ``gt_depth_m``, a decoded pixel where the truth is NaN (nothing seen) counting wrong: the
    edge band, shadows and unlit pixels included (the module doc); NaN where nothing is decoded."""
    return float(
        every_decoded_pixel(depth_m, gt_depth_m, np.ones(np.shape(depth_m), bool), wrong_mm=WRONG_MM)["wrong_share_all"]
    )


def object_scores(rec: Recording, depth: "SystemDepth | DecodeResult", region: np.ndarray) -> dict:
    """Completeness over ``region``, MAE against ground truth (mm) and the share of the decoded
    pixels more than :data:`WRONG_MM` wrong: the scores of one system on one region.  NaN where
    ``region`` is empty or nothing in it is decoded."""
    if not region.any():
        return {"completeness": float("nan"), "gt_mae_mm": float("nan"), "wrong_share": float("nan")}
    s = score(rec, depth, region=region)
    return {
        "completeness": s["completeness"],
        "gt_mae_mm": s["gt_mae_mm"],
        "wrong_share": _wrong_share(rec, depth, region),
    }


def confidence_curve(
    depth_m: np.ndarray,
    confidence: np.ndarray,
    gt_depth_m: np.ndarray,
    region: np.ndarray,
    *,
    thresholds: tuple[float, ...] = CONFIDENCE_THRESHOLDS,
) -> list[dict]:
    """:func:`simbench.metrics.confidence_curve` at :data:`CONFIDENCE_THRESHOLDS` and
    :data:`WRONG_MM` (the rows the operating point is chosen from)."""
    return _curve(depth_m, confidence, gt_depth_m, region, thresholds=thresholds, wrong_mm=WRONG_MM)


def operating_point(curves: list[dict], *, decoder: str = "robust") -> float:
    """The rule :data:`simbench.decode.ROBUST_MIN_CONFIDENCE` was chosen by: the threshold of
    ``curves`` (rows of :func:`confidence_curve` with ``scene`` and ``decoder``) under which the
    most scenes meet both goals (:data:`GOAL_COMPLETENESS` of ``completeness``,
    :data:`GOAL_WRONG_SHARE` of ``wrong_share_all``, every decoded pixel's; the MAE goal is not
    judged: the curves do not hold it); of equals,
    the highest - a higher threshold keeps a subset of the pixels, so the fewest wrong ones.
    (A policy changed on 2026-11-30, after the edge term's curves were seen: until then of equals
    the lowest, the most complete, which on those curves picked 2 - 22 scenes met both goals at 2
    and at 3, and at 2 the 60-degree corner kept 0.16 % of its pixels more than 5 mm wrong;
    issue 35 puts no wrong depth unsaid before completeness.  Counting every decoded pixel, with
    the crease apex term, 3 is the pick either way: 23 scenes there, 21 at 2.)"""
    rows = [c for c in curves if c["decoder"] == decoder]
    if not rows:
        raise ValueError(f"no confidence curve of the {decoder!r} decoder")

    def meeting(t: float) -> int:
        return sum(
            c["completeness"] >= GOAL_COMPLETENESS and c["wrong_share_all"] <= GOAL_WRONG_SHARE
            for c in rows
            if c["threshold"] == t
        )

    thresholds = sorted({c["threshold"] for c in rows})
    return max(thresholds, key=lambda t: (meeting(t), t))


def _decoders(config: RunConfig) -> tuple[dict, dict]:
    """The decoders' parameters (decoded once with no threshold: the curves need every decoded
    pixel's confidence) and their operating points."""
    robust = config.robust()
    params = {"paper": config.decoder, "robust": dataclasses.replace(robust, min_confidence=0.0)}
    return params, {"paper": config.decoder.min_confidence, "robust": robust.min_confidence}


def camera_sensors(sensor: SensorModel) -> dict[str, SensorModel]:
    """``sensor`` (a physical model) with each set of :data:`CAMERA_EFFECTS` taken out - its
    fields copied from the ``ideal`` model (:func:`simbench.sim.sensor.with_effects`) - by the
    set's key (the effects' names joined by ``+``)."""
    ideal = get_sensor("ideal")
    return {
        "+".join(e): with_effects(sensor, ideal, e, name=f"{sensor.name} without {' and '.join(e)}")
        for e in CAMERA_EFFECTS
    }


def least_samples(sampler: str, spp: float) -> int:
    """The least count of samples per pixel ``sampler`` takes
    (:func:`simbench.sim.mitsuba_dict.check_sampler`) of at least ``spp`` (and 1)."""
    from simbench.sim.mitsuba_dict import check_sampler

    n = max(1, math.ceil(spp - 1e-9))  # (an exact product computed a hair above its integer)
    while True:
        try:
            check_sampler(sampler, n)
            return n
        except ValueError:
            n += 1


def more_samples(sampler: str, spp: int, *, factor: int) -> int:
    """The samples per pixel of a variant of :data:`RENDER_SCENES` (``factor``: one of
    :data:`RENDER_SPP_FACTORS`): the least count the sampler takes of at least ``factor`` x
    ``spp`` (:func:`least_samples`; a square times a square is a square; the orthogonal sampler
    needs a prime squared)."""
    return least_samples(sampler, factor * int(spp))


def samples_for_target(sampler: str, spp: int, *, ratio: float) -> int | None:
    """The samples per pixel at which a render noise of ``ratio`` x the camera's at ``spp`` would
    be :data:`simbench.experiments.render_noise.TARGET_RATIO` of it, were it to fall as
    1/sqrt(spp) (:func:`least_samples` of the sampler); None where ``ratio`` is not finite.
    (Measured on ``hard_corner_045``, 2026-12-04, 1280x960: the colour-robust decoder's render
    spread 0.242 mm at 36 spp multijitter, 0.121 mm at 144 spp - 1/sqrt(spp) predicts 0.121 -,
    0.185 mm at 64 spp ldsampler (0.182 predicted), 0.306 mm at 36 spp independent: the
    stratified generators buy ~1.25x at a count, no more, on interreflected light; render time
    ~0.8 s per spp there, on 2 cores.  The renders' own noise falls as fast or a little faster -
    the stratified pixel footprint on the direct light: tests/test_physics_renders.py -, so the
    count is no underestimate.)"""
    if not np.isfinite(ratio):
        return None
    return least_samples(sampler, spp * (ratio / TARGET_RATIO) ** 2)


def _camera_variants(session: Session, name: str) -> list[tuple[str, str, Session]]:
    """The variants of the camera table for scene ``name``: (key, description, the session that
    records it) - the sets of :data:`CAMERA_EFFECTS` taken out (``without_EFFECTS``) and, for
    :data:`RENDER_SCENES`, more samples per pixel (``spp_N``).  A run with ``rig = "calibrated"``
    calibrates each camera's rig through that camera, as a lab would."""
    out = [
        (
            f"without_{key}",
            f"without {' and '.join(EFFECT_TABLE[e].description for e in key.split('+'))}",
            session.fork(s),
        )
        for key, s in camera_sensors(session.sensor).items()
    ]
    if name in RENDER_SCENES:
        cfg = session.config
        for factor in RENDER_SPP_FACTORS:
            spp = more_samples(cfg.sampler, cfg.spp, factor=factor)
            more = session.fork(session.sensor, config=dataclasses.replace(cfg, spp=spp))
            out.append((f"spp_{spp}", f"rendered with {spp} spp, not {cfg.spp}", more))
    return out


def _capture(session: Session, name: str, label: str) -> tuple[Recording, np.ndarray]:
    """Scene ``name`` captured by the proposed sensor (``label``'s seeds) and the pixels it is
    scored over: the lit ones off the edge band."""
    cap = session.capture(session.prepare(session.raw_scene(name)), label)[0]
    band = edge_band(cap.gt.depth_m, object_id=cap.gt.object_id, band_px=session.config.edge_band_px)
    return cap, cap.gt.lit & ~band


def _decoded(session: Session, cap: Recording, region: np.ndarray, params, min_confidence: float):
    """``cap`` decoded with ``params`` by triangulation (no threshold) and its scores
    (:func:`scene_scores`) with ``min_confidence`` applied."""
    full = session.decode(cap, params, mode="calibrated")
    result = apply_min_confidence(full, min_confidence)
    return full, scene_scores(cap, result, session.config.decoder.period_px, region)


def _reference_scored(session: Session, name: str, label: str) -> tuple[Recording, dict]:
    """Scene ``name`` recorded by the multi-shot reference (``label``'s seeds) and scored."""
    rec, depth = session.acquire(REFERENCE_SYSTEM, session.raw_scene(name), label)[0]
    band = edge_band(rec.gt.depth_m, object_id=rec.gt.object_id, band_px=session.config.edge_band_px)
    info = session.system(REFERENCE_SYSTEM).info()
    return rec, scene_scores(rec, depth, info.period_px, rec.gt.lit & ~band)


def _camera_rows(session: Session, name: str, row: dict, robust, operating: float) -> tuple[list[dict], dict]:
    """The rows of the camera table for scene ``name`` (its row of the main table first, then one
    per variant of :func:`_camera_variants`; ``description`` for the Markdown) and their metrics
    (``hard_scenes/SCENE/DECODER/VARIANT/METRIC``); the reference is not recorded at more samples
    per pixel (NaN)."""
    label = f"hard_scenes/{name}"
    first = {"scene": name, "camera": "", "description": "as modelled"}
    rows = [{**first, **{f"{d}_{k}": row[f"{d}_{k}"] for d in ("robust", REFERENCE_SYSTEM) for k in CAMERA_SCORE_KEYS}}]
    metrics = {}
    for variant, description, sub in _camera_variants(session, name):
        scores = {"robust": _decoded(sub, *_capture(sub, name, label), robust, operating)[1]}
        if not variant.startswith("spp_"):
            scores[REFERENCE_SYSTEM] = _reference_scored(sub, name, label)[1]
        out = {"scene": name, "camera": variant, "description": description}
        for d in ("robust", REFERENCE_SYSTEM):
            for k in CAMERA_SCORE_KEYS:
                out[f"{d}_{k}"] = scores[d][k] if d in scores else float("nan")
                if d in scores:
                    metrics[f"hard_scenes/{name}/{d}/{variant}/{k}"] = scores[d][k]
        rows.append(out)
    return rows, metrics


def measure_render_noise(
    session: Session,
    name: str,
    *,
    label: str,
    region: np.ndarray,
    robust: DecoderParams,
    min_confidence: float,
) -> dict:
    """Scene ``name``'s render noise against its camera noise, in the colour-robust decoder's
    depth (``robust`` by triangulation, at ``min_confidence``), by the protocol of
    :func:`simbench.experiments.render_noise.noise_spreads`: :data:`NOISE_REPEATS` recordings of
    the scene's render under ``label`` with noise seeds of their own (the first is
    :func:`measure_scene`'s capture) - the camera's noise - and :data:`NOISE_REPEATS` captures each
    rendered and recorded with seeds of their own (the first the same capture) - the camera's and
    the renderer's together - all recorded by the run's camera with its noise on (it dithers the
    8-bit quantisation) and decoded by ``session`` with one calibration, over the pixels of
    ``region`` every map decodes less stripe-order jumps (more than :data:`WRONG_MM` from the
    pixel's median).  Returns the spreads, their ratio, whether it meets
    :data:`simbench.experiments.render_noise.TARGET_RATIO`, :func:`samples_for_target`, the pixels,
    the jumps' share and the captures' seeds."""
    cfg = session.config
    scene = session.prepare(session.raw_scene(name))
    caps, recordings, seeds = noise_captures(session, scene, first=label, others=f"{label}/render")
    depths = np.stack(
        [apply_min_confidence(session.decode(c, robust, mode="calibrated"), min_confidence).depth_m for c in caps]
    )
    spreads = noise_spreads(depths, recordings=recordings, region=region, jump_mm=WRONG_MM)
    return {
        "scene": name,
        "class": HARD_SCENES[name],
        **spreads,
        "meets_target": bool(spreads["ratio"] <= TARGET_RATIO),
        "spp_for_target": samples_for_target(cfg.sampler, cfg.spp, ratio=spreads["ratio"]),
        **seeds,
    }


def scene_names(config: RunConfig) -> tuple[str, ...]:
    """The scenes a run measures: every hard scene, or one of each class when quick."""
    return QUICK_SCENES if config.quick else tuple(HARD_SCENES)


def measure_scene(session: Session, name: str) -> dict:
    """One hard scene: its table row, its confidence curves and its metrics (plain data)."""
    cfg = session.config
    params, operating = _decoders(cfg)
    curves, metrics = [], {}
    label = f"hard_scenes/{name}"
    cap, region = _capture(session, name, label)
    row = {"scene": name, "class": HARD_SCENES[name], "scored_pixels": int(region.sum()), **cap.seeds}
    for d in DECODERS:
        full, scores = _decoded(session, cap, region, params[d], operating[d])
        for k, v in scores.items():
            row[f"{d}_{k}"] = v
            metrics[f"hard_scenes/{name}/{d}/{k}"] = v
        for c in confidence_curve(full.depth_m, full.confidence, cap.gt.depth_m, region):
            curves.append({"scene": name, "decoder": d, **c})
    rec, ref_scores = _reference_scored(session, name, label)
    for k, v in ref_scores.items():
        row[f"{REFERENCE_SYSTEM}_{k}"] = v
        metrics[f"hard_scenes/{name}/{REFERENCE_SYSTEM}/{k}"] = v
    row.update({f"{REFERENCE_SYSTEM}_{k}_seed": v for k, v in rec.seeds.items()})
    camera = []
    if name in CAMERA_SCENES:
        camera, more = _camera_rows(session, name, row, params["robust"], operating["robust"])
        metrics.update(more)
    noise = None
    # (a sensor model with no physical camera has no camera noise to weigh the renderer's against)
    if session.sensor.is_physical:
        noise = measure_render_noise(
            session, name, label=label, region=region, robust=params["robust"], min_confidence=operating["robust"]
        )
        for k in ("render_sd_mm", "camera_sd_mm", "ratio"):
            metrics[f"hard_scenes/{name}/render_noise/{k}"] = noise[k]
    return {"row": row, "curves": curves, "metrics": metrics, "camera": camera, "render_noise": noise}


def write_hard_scenes(session: Session, measured: list[dict]) -> dict:
    """The target's files from :func:`measure_scene`'s results (in :func:`scene_names`' order)."""
    names = [m["row"]["scene"] for m in measured]
    _, operating = _decoders(session.config)
    rows = [m["row"] for m in measured]
    curves = [c for m in measured for c in m["curves"]]
    camera = [c for m in measured for c in m["camera"]]
    noise = [m["render_noise"] for m in measured if m["render_noise"] is not None]
    metrics = {k: v for m in measured for k, v in m["metrics"].items()}
    cols = ["scene", "class", "scored_pixels"]
    cols += [f"{d}_{k}" for d in (*DECODERS, REFERENCE_SYSTEM) for k in SCORE_KEYS]
    cols += ["render", "noise", f"{REFERENCE_SYSTEM}_render_seed", f"{REFERENCE_SYSTEM}_noise_seed"]
    files = {
        "hard_scenes.csv": table_text(rows, cols),
        "hard_scenes_camera.csv": table_text(
            camera, ["scene", "camera", *(f"{d}_{k}" for d in ("robust", REFERENCE_SYSTEM) for k in CAMERA_SCORE_KEYS)]
        ),
        "hard_scenes_confidence.csv": table_text(
            curves, ["scene", "decoder", "threshold", "completeness", "wrong_share", "wrong_share_all"]
        ),
        **figure_files("hard_scenes_confidence", _curve_plot(curves, operating, note=session.config.figure_note())),
        "hard_scenes.md": _markdown(session, rows, curves, operating, camera=camera, noise=noise),
    }
    if noise:
        files["hard_scenes_render_noise.csv"] = table_text(noise, NOISE_COLUMNS)
    session.write_results(
        "hard_scenes",
        files,
        extra={
            "scenes": names,
            "wrong_mm": WRONG_MM,
            "confidence_thresholds": list(CONFIDENCE_THRESHOLDS),
            "operating_points": operating,
            "camera_effects_taken_out": {
                "+".join(e): {x: list(EFFECT_TABLE[x].fields) for x in e} for e in CAMERA_EFFECTS
            },
            "render_scenes": {
                "scenes": list(RENDER_SCENES),
                "spp": [more_samples(session.config.sampler, session.config.spp, factor=f) for f in RENDER_SPP_FACTORS],
            },
            "render_noise": {"repeats": NOISE_REPEATS, "target_ratio": TARGET_RATIO, "measured": bool(noise)},
        },
    )
    return metrics


# the scenes are measured one by one (the run's workers take them side by side)
SPLIT = Split("hard_scenes", scene_names, measure_scene, write_hard_scenes)


def run_hard_scenes(session: Session) -> dict:
    """Every scene of :func:`scene_names` measured, then the files written (:class:`Split`)."""
    return SPLIT.run(session)


_MARKERS = "os^vD<>pPXh*"
# where a share of exactly 0 is drawn on the curves' log axes: under half of one pixel of the paper's
# 1280x960 (8.1e-7 a pixel)
_NONE_AT = 4e-7


def _scene_style(k: int) -> tuple[tuple[float, float, float], str]:
    """The colour and marker of the ``k``-th scene of a panel: tab20's strong colours, then its
    light ones, each with the next marker (distinct for 20 scenes; a class has at most 11)."""
    from matplotlib import colormaps

    colours = colormaps["tab20"].colors
    return tuple(colours[(2 * k) % 20 + (2 * k) // 20 % 2]), _MARKERS[k % len(_MARKERS)]


def _curve_plot(curves: list[dict], operating: dict, *, note: str = "") -> dict[str, bytes]:
    """PNG and PDF: each scene's completeness-vs-wrong-pixel curve, a row per decoder and a column per
    scene class (:data:`HARD_SCENES`; a scene outside it in a column of its own), each scene of a
    class in its own colour and marker (one panel held all 25 until 2026-11-30, and its colour
    cycle of 10 gave three scenes each colour); both axes logarithmic (the pixels lost, not those
    kept)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(c["scene"] for c in curves))
    classes = list(dict.fromkeys(HARD_SCENES.get(n, n) for n in names))
    fig, axes = plt.subplots(
        len(DECODERS),
        len(classes),
        figsize=(3.3 * len(classes) + 0.6, 3.0 * len(DECODERS) + 1.4),
        sharex=True,
        sharey=True,
        squeeze=False,
        constrained_layout=True,
    )
    titles = {"paper": "paper's decoder", "robust": "colour-robust decoder"}
    for row, d in enumerate(DECODERS):
        for col, cls in enumerate(classes):
            ax = axes[row, col]
            members = [n for n in names if HARD_SCENES.get(n, n) == cls]
            nothing = []
            for k, name in enumerate(members):
                cs = [c for c in curves if c["scene"] == name and c["decoder"] == d]
                # both axes logarithmic, as a detection-error trade-off: the pixels lost, not those kept,
                # so that the near-complete end, where the operating points and the goals lie, is
                # not a line at the right edge (nothing lost, or nothing wrong, drawn at _NONE_AT: under
                # one pixel of a full-resolution image, so that every share measured shows as it is - a
                # figure audit found 24 points of 0.001-0.01 % drawn at a floor of 0.01 % called "none")
                xs = [
                    100 * max(1.0 - c["completeness"], _NONE_AT) if np.isfinite(c["completeness"]) else np.nan
                    for c in cs
                ]
                ys = [
                    100 * max(c["wrong_share_all"], _NONE_AT) if np.isfinite(c["wrong_share_all"]) else np.nan
                    for c in cs
                ]
                colour, marker = _scene_style(k)
                label = name.removeprefix("hard_")
                if not any(c["completeness"] > 0 for c in cs):
                    nothing.append(label)  # (no point to draw: no wrong share)
                ax.plot(xs, ys, "-", marker=marker, ms=3, lw=1, color=colour, label=label)
                at = [i for i, c in enumerate(cs) if c["threshold"] == operating[d]]
                if at:
                    ax.plot(xs[at[0]], ys[at[0]], "s", ms=8, mfc="none", mew=1.2, color=colour)
            if nothing:
                ax.text(
                    0.97,
                    0.96,
                    "nothing decoded: " + ", ".join(nothing),
                    transform=ax.transAxes,
                    ha="right",
                    va="top",
                    fontsize=7,
                )
            ax.axhline(0.1, color="k", ls=":", lw=1)
            ax.axvline(100 * (1 - GOAL_COMPLETENESS), color="k", ls="--", lw=1)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.grid(alpha=0.3, which="both")
            if row == 0:
                ax.set_title(cls, fontsize=9)
            if row == len(DECODERS) - 1:
                ax.set_xlabel(
                    "pixels lost: not decoded or under the threshold\n(% of lit pixels off the edge band)", fontsize=8
                )
                ax.legend(fontsize=6.5, loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=2, frameon=False)
            if col == 0:
                ax.set_ylabel(f"{titles[d]}\nof every decoded pixel, > 5 mm wrong (%)", fontsize=8)
    fig.suptitle(
        "Hard scenes: pixels lost against pixels > 5 mm wrong as the confidence threshold rises (square: the "
        f"operating point, paper's decoder {operating['paper']:g}, colour-robust {operating['robust']:g}; the "
        f"goals: left of dashed, 97 % complete; below dotted, 0.1 % wrong; none lost or wrong drawn at "
        f"{100 * _NONE_AT:.5f} %){note}",
        fontsize=9,
    )
    return figure_formats(fig, dpi=110)


def _held_out(curves: list[dict]) -> str:
    """How the rule's pick moves when each scene in turn is left out of the curves it reads: the
    operating point is chosen on the scenes it is reported on (in sample), and so were several of
    the colour-robust decoder's terms; this shows how much the pick rests on any one scene."""
    names = list(dict.fromkeys(c["scene"] for c in curves if c["decoder"] == "robust"))
    if len(names) < 2:
        return "Held out: one scene only, nothing to leave out."
    picks = {n: operating_point([c for c in curves if c["scene"] != n]) for n in names}
    full = operating_point(curves)
    moved = {n: t for n, t in picks.items() if t != full}
    told = (
        "the same threshold every time"
        if not moved
        else ", ".join(f"without `{n}` {t:g}" for n, t in moved.items()) + f"; {full:g} otherwise"
    )
    return (
        f"Held out: the rule applied to the curves with each of the {len(names)} scenes left out in turn picks "
        f"{told}. (The operating point is chosen on the scenes it is reported on, and several of the colour-robust "
        "decoder's confidence terms were designed on them - in sample; this shows only how much the pick rests on any "
        "one scene. The phase-shifting reference's threshold comes from its Gray code's error rate, not from these "
        "curves.)"
    )


def _reference_min_snr() -> float:
    from simbench.systems.phase_shift import reference_spec

    return reference_spec().min_snr


def short_of_goals(row: dict, system: str) -> list[str]:
    """Which of issue 35's three goals a scene's results row (:func:`measure_scene`'s) misses
    for ``system`` (a decoder or the reference): ``"complete"``, ``"MAE"``, ``"wrong"`` (a
    decoder that decodes nothing misses all three; an empty list: it meets them)."""
    c, mae, wrong = (row[f"{system}_{k}"] for k in ("completeness", "gt_mae_mm", "wrong_share_all"))
    misses = []
    if not c >= GOAL_COMPLETENESS:
        misses.append("complete")
    if not mae <= GOAL_MAE_MM:
        misses.append("MAE")
    if not wrong <= GOAL_WRONG_SHARE:
        misses.append("wrong")
    return misses


def _shortfalls(rows: list[dict], system: str) -> str:
    short = [(r["scene"], short_of_goals(r, system)) for r in rows]
    short = [f"`{n}` ({', '.join(m)})" for n, m in short if m]
    return f"{len(short)} of {len(rows)}" + (": " + ", ".join(short) if short else "")


def format_score(v: float, pct: bool = False) -> str:
    """A score for a Markdown cell: a share as a percentage (``pct``), else 3 decimals; ``-`` if not finite."""
    if not np.isfinite(v):
        return "-"
    return f"{100 * v:.2f} %" if pct else f"{v:.3f}"


def _noise_section(noise: list[dict], operating: dict, cfg: RunConfig) -> list[str]:
    """The markdown section of the render-noise table (none without rows)."""
    if not noise:
        return []
    table = [
        [
            f"`{r['scene']}`",
            r["class"],
            f"{r['render_sd_mm']:.4f}",
            f"{r['camera_sd_mm']:.4f}",
            f"{r['ratio']:.2f}",
            "yes" if r["meets_target"] else "no",
            "-" if r["spp_for_target"] is None else str(r["spp_for_target"]),
        ]
        for r in noise
    ]
    over = [r for r in noise if not r["meets_target"]]
    by_class = {}
    for r in over:
        by_class.setdefault(r["class"], []).append(r["ratio"])
    spans = [
        f"{c}: {len(v)} ({min(v):.2f}-{max(v):.2f} of the camera's)" if len(v) > 1 else f"{c}: 1 ({v[0]:.2f})"
        for c, v in by_class.items()
    ]
    summary = f"{len(noise) - len(over)} of {len(noise)} scenes meet the target" + (
        "; above it, by class - " + "; ".join(spans) + "." if over else "."
    )
    target = str(Fraction(TARGET_RATIO).limit_denominator(100))
    return [
        "## What the renderer's noise is, scene by scene",
        "",
        "The path tracer's noise against the camera's on each scene, in the colour-robust decoder's depth at its "
        f"operating point (confidence >= {operating['robust']:g}), by triangulation "
        "(`simbench.experiments.hard_scenes.measure_render_noise`): the depth spread (root mean per-pixel variance, "
        f"mm) over {NOISE_REPEATS} recordings of the table's capture's render with noise seeds of their own - *camera "
        f"noise*, what a real camera adds frame to frame - and over {NOISE_REPEATS} captures each rendered and "
        "recorded with seeds of their own - both noises together; *render noise* is the root of the difference of "
        "the two variances. Both arms are recorded with the camera's noise on, which dithers the 8-bit quantisation "
        "(recorded noise-free, as `render_noise.md` did on the white board until 2026-12-05, a render noise of a "
        "fraction of a DN reads too large), and taken over the same pixels: those every map decodes, less those "
        "where a map is "
        f"more than {WRONG_MM:g} mm from the pixel's median (a stripe-order jump; their share is `jumps` in "
        "`hard_scenes_render_noise.csv`, with the seeds). The testbed's target is render noise at most "
        f"{target} of camera noise (`render_noise.md`). A scene above it is scored here under more noise than a "
        "camera alone gives it - sqrt(1 + r^2) of the camera's, for a ratio r. *spp for the target*: the samples per "
        f"pixel of the run's sampler (`{cfg.sampler}`, {cfg.spp} spp here) that would meet it, were render noise to "
        "fall as 1/sqrt(spp) (`simbench.experiments.hard_scenes.samples_for_target`; render time grows about in "
        "proportion). " + summary,
        "",
        *markdown_table(
            [
                "scene",
                "class",
                "render noise (mm)",
                "camera noise (mm)",
                "render / camera",
                f"<= {target}",
                "spp for the target",
            ],
            table,
        ),
        "",
    ]


def _camera_section(camera: list[dict], operating: dict, cfg: RunConfig, noise: list[dict]) -> list[str]:
    """The markdown section of the camera table (none without rows); ``noise``: the render-noise
    rows, whose ratios say where the most samples rendered put each re-rendered scene."""
    if not camera:
        return []
    rendered = [n for n in RENDER_SCENES if any(c["scene"] == n for c in camera)]
    most = more_samples(cfg.sampler, cfg.spp, factor=max(RENDER_SPP_FACTORS))
    ratios = {r["scene"]: r["ratio"] for r in noise}
    where = [
        f"`{n}` {ratios[n]:.2f} of the camera's at {cfg.spp} spp, projected to "
        f"{ratios[n] * math.sqrt(cfg.spp / most):.2f} at {most} by 1/sqrt(spp), not measured"
        for n in rendered
        if n in ratios
    ]
    more = (
        f"{', '.join(f'`{n}`' for n in rendered)} also rendered with more samples per pixel (the colour-robust "
        "decoder only; their calibration frames too, at the same samples): on faces lit by each other the path "
        "tracer's noise at the run's samples is above a camera's "
        f"(the next section{': ' + '; '.join(where) if where else ''}; the target: at most "
        f"{Fraction(TARGET_RATIO).limit_denominator(100)}). "
        if rendered
        else ""
    )
    header = ["scene", "camera"]
    for title in ("colour-robust", "phase shifting"):
        header += [f"{title}: complete", "MAE mm", "> 5 mm, all decoded"]
    table = []
    for c in camera:
        cells = [f"`{c['scene']}`", c["description"]]
        for d in ("robust", REFERENCE_SYSTEM):
            cells += [
                format_score(c[f"{d}_completeness"], True),
                format_score(c[f"{d}_gt_mae_mm"]),
                format_score(c[f"{d}_wrong_share_all"], True),
            ]
        table.append(cells)
    return [
        "## What the camera and the renderer cost",
        "",
        f"{', '.join(f'`{n}`' for n in dict.fromkeys(c['scene'] for c in camera))} recorded again with effects of "
        f"the sensor model `{cfg.sensor}` taken out - their parameters taken from the `ideal` model "
        "(`simbench/presets/ideal.toml`; the Bayer mosaic out: all three colours at every pixel, as a three-chip "
        "camera has them; the noise out: no shot, dark or fixed-pattern noise) - from the same renders with the same "
        f"seeds, decoded by the colour-robust decoder at its operating point (confidence >= {operating['robust']:g}) "
        "and by the phase-shifting reference, scored as above (`hard_scenes_camera.csv`). "
        f"{more}"
        "Each row shows one term's share of a shortfall on its own.",
        "",
        *markdown_table(header, table),
        "",
    ]


def _markdown(
    session: Session,
    rows: list[dict],
    curves: list[dict],
    operating: dict,
    *,
    camera: list[dict] | None = None,
    noise: list[dict] | None = None,
) -> str:
    cfg = session.config
    cam = session.scene(rows[0]["scene"]).rig.camera if rows else None
    size = f"{cam.width_px}x{cam.height_px} camera, " if cam else ""
    header = ["scene", "class"]
    for d, title in (("paper", "paper's decoder"), ("robust", "colour-robust"), (REFERENCE_SYSTEM, "phase shifting")):
        header += [f"{title}: complete", "MAE mm", "> 5 mm", "> 5 mm, all decoded"]
    table = []
    for r in rows:
        cells = [f"`{r['scene']}`", r["class"]]
        for d in ("paper", "robust", REFERENCE_SYSTEM):
            cells += [
                format_score(r[f"{d}_completeness"], True),
                format_score(r[f"{d}_gt_mae_mm"]),
                format_score(r[f"{d}_wrong_share"], True),
            ]
            cells.append(format_score(r[f"{d}_wrong_share_all"], True))
        table.append(cells)
    # per threshold, over the scenes: the worst completeness and wrong share, and how many scenes meet both goals
    sweep = []
    for d in DECODERS:
        for t in CONFIDENCE_THRESHOLDS:
            cs = [c for c in curves if c["decoder"] == d and c["threshold"] == t]
            wrong = [c["wrong_share_all"] for c in cs if np.isfinite(c["wrong_share_all"])]
            meet = sum(c["completeness"] >= GOAL_COMPLETENESS and c["wrong_share_all"] <= GOAL_WRONG_SHARE for c in cs)
            mark = " (operating point)" if t == operating[d] else ""
            sweep.append(
                [
                    d,
                    f"{t:g}{mark}",
                    format_score(min(c["completeness"] for c in cs), True),
                    format_score(float(np.median([c["completeness"] for c in cs])), True),
                    format_score(max(wrong) if wrong else float("nan"), True),
                    f"{sum(w <= 0.001 for w in wrong)} of {len(cs)}",
                    f"{meet} of {len(cs)}",
                ]
            )
    lines = [
        "# Hard scenes: what each method costs where flat boards do not go",
        "",
        f"Made by `{session.command}` ({size}{cfg.spp} spp {cfg.sampler}, sensor model `{cfg.sensor}`, base seed "
        f"{cfg.seed}, variant `{session.variant}`). Scenes: `scenes/hard_*.toml` (`scenes/make_hard_scenes.py`). "
        "Plot: `hard_scenes_confidence.png`; every number: `hard_scenes.csv`, `hard_scenes_confidence.csv`, "
        "`hard_scenes_camera.csv`.",
        "",
        "The proposed sensor's capture decoded by triangulation with the paper's decoder (no confidence threshold: "
        "the paper describes none) and with our colour-robust decoder at its operating point (confidence >= "
        f"{operating['robust']:g}: pixels below are holes), beside the multi-shot phase-shifting reference (12 "
        "exposures on the same projector and camera; pixels whose modulation SNR is below what its Gray code needs, "
        f"{_reference_min_snr():.3g}, are holes: `docs/competitors.md`). "
        f"Scored over the lit pixels off a {cfg.edge_band_px}-px band at every depth edge and object boundary: "
        "*complete* = decoded share, *MAE* against ground truth, *> 5 mm* = share of those decoded pixels more than "
        "5 mm wrong; *> 5 mm, all decoded* = share of every decoded pixel of the image more than 5 mm wrong - the "
        "edge band, shadows and unlit pixels included, a depth where the truth sees nothing counted wrong: the wrong "
        "depths the output does not mark, which the goals count (until 2026-11-30 they counted the band-free share, "
        "blind to the band: a review of the protocols). Issue 35's goal for the colour-robust decoder: >= 97 % "
        "complete, MAE <= 0.5 mm, <= 0.1 % of the decoded pixels wrong, on every scene.",
        "",
        *markdown_table(header, table),
        "",
        f"Scenes short of the goals (>= {100 * GOAL_COMPLETENESS:g} % complete, MAE <= {GOAL_MAE_MM:g} mm, <= "
        f"{100 * GOAL_WRONG_SHARE:g} % wrong; which missed in brackets): the colour-robust decoder "
        f"{_shortfalls(rows, 'robust')}; the phase-shifting reference (12 exposures) "
        f"{_shortfalls(rows, REFERENCE_SYSTEM)}; the paper's decoder {_shortfalls(rows, 'paper')}.",
        "",
        "## Confidence: the operating point",
        "",
        "Every decoded pixel carries a confidence, the fringe SNR: the RMS of the fitted fringe over the RMS of what "
        "the local cosine fit leaves in its window (`simbench.decode.phase.fringe_snr`). Noise, a depth edge or an "
        "albedo step inside the window, and a second fringe added by a highlight all lower it. The colour-robust "
        "decoder caps it by the phase's stability, 0.4 rad over the phase's change when the window is halved "
        "(`DecoderParams.phase_stability`): a window straddling an edge or a crease is biased, less so when narrower; "
        "and by 0.4 rad over the phase bias predicted at concave creases from the decoded column map's concave second "
        "difference over a period (`DecoderParams.crease_doubt`: the faces' light on each other shifts the fringe "
        "itself there, which no window sees); and by 0.4 rad over the bend of the decoded column map within two "
        "window sigmas of a depth edge or hole, along the rows and down the columns, measured against the line "
        "through the next period of it (`DecoderParams.edge_doubt`: the window there holds both sides' fringes, and "
        "the halved one still reaches across); and it is 0 on a stripe whose De Bruijn position the stripes on both "
        "of its sides contest (`DecoderParams.position_doubt`: a run of misread codes that reads like another "
        "stretch of the sequence decodes coherently, while the stripes beyond it agree through it) or that the "
        "windows of its well-read codes do not give (`DecoderParams.code_doubt`: pieces of stripes on a dark print, "
        "their codes read from a couple of pixels, read like some stretch of the sequence one time in four), and 0 "
        "within 1.25 "
        "window sigmas of a shadow (`DecoderParams.shadow_doubt`: the window there fits a fringe the shadow's penumbra "
        "cuts off at any phase); and it is capped, "
        "over the whole capture, by 0.4 rad over the phase of the shift between its code channels' fringe and its "
        "fringe channel's beyond 0.15 px (`DecoderParams.registration_doubt`: misregistered colour channels bias "
        "every depth at full fringe SNR; no scene here is misregistered). "
        "Keeping only the pixels at or above a threshold, over the scenes above (the rule that chose the "
        "colour-robust decoder's operating point, `simbench.experiments.hard_scenes.operating_point`: the threshold "
        "under which the most scenes meet both of its goals - >= 97 % complete and <= 0.1 % of every decoded pixel "
        "wrong; the MAE goal, which a threshold barely moves, is not judged here -, of equals the highest (the fewest "
        "wrong pixels; until 2026-11-30 the lowest); it was applied to the full-resolution "
        f"run of all {len(HARD_SCENES)} scenes; on this run's scenes it picks {operating_point(curves):g}):",
        "",
        _held_out(curves),
        "",
        *markdown_table(
            [
                "decoder",
                "confidence >=",
                "worst completeness",
                "median completeness",
                "worst > 5 mm (all decoded)",
                "scenes <= 0.1 % wrong",
                "scenes meeting both (complete, wrong; MAE not judged)",
            ],
            sweep,
        ),
        "",
        "What it cannot see: systematic errors under 5 mm are in the MAE only, which leaves the edge band and the "
        "shadowed pixels (unlit in the ground truth) out; the confidence is the phase fit's, so a wrong stripe order "
        "(a whole period off) on a clean fringe keeps a high confidence - the stripe-order column of "
        "`hard_scenes.csv` counts those.",
        "",
        *_camera_section(camera or [], operating, cfg, noise or []),
        *_noise_section(noise or [], operating, cfg),
    ]
    return "\n".join(lines)
