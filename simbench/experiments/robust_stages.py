"""What each of the colour-robust decoder's stages buys (ours; issue 35): the hard scenes decoded
with the whole decoder and with one stage at a time turned back to the paper decoder's setting.

The colour-robust decoder (:func:`simbench.decode.robust_params`) is the paper's with some twenty
additions, and its speed goal (within 1.5x of the paper decoder's, ``simbench bench --robust``)
is not met: this study says which additions earn their time.  Each variant of :data:`VARIANTS`
sets its fields - and the fields that cannot stand without them or mean something else without
them (:class:`DecoderParams` refuses some such pairs; the others are named in :data:`VARIANTS`) -
to the run's paper decoder's values; everything else stays the colour-robust
decoder's, its operating point (confidence >= :data:`simbench.decode.ROBUST_MIN_CONFIDENCE`)
included, fixed: a stage that feeds the confidence changes what the threshold keeps, and that is
part of what it buys.  Every hard scene (:mod:`simbench.experiments.hard_scenes`, the same
captures: their renders come from the cache) is scored by that target's protocol: lit pixels off
a band at depth edges, completeness, MAE, and the share of every decoded pixel more than 5 mm
wrong; a variant's row says how many scenes meet issue 35's three goals and what it loses
against the whole decoder.  What each stage costs in time is machine-dependent and not in these
files: ``simbench bench --robust --stages`` times the same variants (docs/results.md).

Writes ``robust_stages.md``, ``robust_stages.csv``, ``robust_stages.png``, ``.pdf`` and
``robust_stages.provenance.json``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from simbench.decode import DecoderParams
from simbench.decode.pipeline import apply_min_confidence
from simbench.experiments import hard_scenes
from simbench.experiments.common import RunConfig, Session, Split, markdown_table, table_text
from simbench.metrics import edge_band
from simbench.report import figure_files, figure_formats

__all__ = [
    "VARIANTS",
    "Variant",
    "variant_params",
    "without_stage",
    "measure_scene",
    "write_robust_stages",
    "SPLIT",
    "FULL",
]


@dataclass(frozen=True)
class Variant:
    """One stage of the colour-robust decoder turned off: the :class:`DecoderParams` fields set
    back to the paper decoder's values (the stage's own first, then those that need it), and
    what the stage does."""

    fields: tuple[str, ...]
    does: str


# The colour-robust decoder's additions (simbench.decode.robust_params), one variant each; the
# order is the pipeline's.  min_confidence (the operating point) is not a stage: it stays.
VARIANTS: dict[str, Variant] = {
    "unmix": Variant(("unmix",), "the primaries unmixed by the coupling matrix measured on the reference plane"),
    "color_normalize": Variant(
        (
            "color_normalize",
            "albedo_flatten",
            "albedo_edge_skip",
            "albedo_columns",
            "intensity_mode",
            "weights_down_columns",
            "shadow_doubt",
            "min_amplitude",
        ),
        "each channel normalised by its local range (with it the albedo flattening, the weighted overlay and the "
        "shadow term, which need it, and the amplitude floor, a share of the local range: on raw channels the "
        "same number would be a floor in full-scale units, a test the paper's decoder does not make)",
    ),
    "albedo_flatten": Variant(
        ("albedo_flatten", "albedo_edge_skip", "albedo_columns"),
        "printed steps flattened along the rows (with the column flattening and the skipped step pixels, which "
        "need it)",
    ),
    "albedo_columns": Variant(("albedo_columns",), "printed steps flattened down the columns"),
    "albedo_edge_skip": Variant(("albedo_edge_skip",), "the pixels straddling a flattened step carry no sample"),
    "intensity_mode": Variant(
        ("intensity_mode", "weights_down_columns"),
        "the overlay (Eq. 9) weighted by each channel's noise (with the weights' means down the columns, which "
        "need it)",
    ),
    "weights_down_columns": Variant(("weights_down_columns",), "the overlay's noise weights averaged down the columns"),
    "min_amplitude": Variant(("min_amplitude",), "a fringe under 2 % of the local range taken for none"),
    "carrier_bank": Variant(("carrier_bank",), "other carriers tried where the nominal phase fit fails"),
    "centroid_correction": Variant(("centroid_correction",), "the phase of a cut window moved to its pixel"),
    "phase_stability": Variant(
        ("phase_stability", "narrow_snr"),
        "the confidence capped by the phase's change at half the window (with the narrow window's SNR, which needs it)",
    ),
    "narrow_snr": Variant(("narrow_snr",), "the better of the two windows' fringe SNRs"),
    "pool_code": Variant(("pool_code",), "a stripe's code voted down the stripe"),
    "bridge_gap_periods": Variant(("bridge_gap_periods",), "short invalid gaps in a row bridged by the phase"),
    "link_keep_certain": Variant(
        ("link_keep_certain", "link_split"),
        "of a broken link, the stripe the edge is not in kept (with the straddler's parts, which need it)",
    ),
    "link_split": Variant(("link_split",), "of a broken link's dropped stripe, the part on its own side kept"),
    "crease_doubt": Variant(("crease_doubt",), "doubt beside concave creases"),
    "edge_doubt": Variant(("edge_doubt",), "doubt where the decoded map bends beside a depth edge"),
    "position_doubt": Variant(("position_doubt",), "doubt on a stripe whose De Bruijn position is contested"),
    "code_doubt": Variant(("code_doubt",), "doubt on a stripe whose position rests on codes read from few pixels"),
    "shadow_doubt": Variant(("shadow_doubt",), "doubt within reach of a shadow"),
    "registration_doubt": Variant(("registration_doubt",), "doubt on a capture whose channels are misregistered"),
}

FULL = "none (the whole decoder)"
SCORE_KEYS = ("completeness", "gt_mae_mm", "wrong_share_all")


def without_stage(robust: DecoderParams, paper: DecoderParams, name: str) -> DecoderParams:
    """``robust`` with :data:`VARIANTS` ``[name]``'s fields at ``paper``'s values (``FULL``:
    ``robust`` itself)."""
    if name == FULL:
        return robust
    if name not in VARIANTS:
        raise ValueError(f"unknown stage {name!r}; valid: {list(VARIANTS)}")
    return dataclasses.replace(robust, **{f: getattr(paper, f) for f in VARIANTS[name].fields})


def variant_params(config: RunConfig, name: str) -> DecoderParams:
    """The colour-robust decoder of ``config`` without stage ``name`` (:func:`without_stage`),
    decoded with no threshold (the operating point is applied after: :func:`measure_scene`)."""
    return dataclasses.replace(without_stage(config.robust(), config.decoder, name), min_confidence=0.0)


def _names() -> tuple[str, ...]:
    return (FULL, *VARIANTS)


def measure_scene(session: Session, name: str) -> dict:
    """One hard scene decoded by every variant: rows of scores at the operating point."""
    cfg = session.config
    operating = cfg.robust().min_confidence
    cap = session.capture(session.prepare(session.raw_scene(name)), f"hard_scenes/{name}")[0]
    band = edge_band(cap.gt.depth_m, object_id=cap.gt.object_id, band_px=cfg.edge_band_px)
    region = cap.gt.lit & ~band
    rows, metrics = [], {}
    for v in _names():
        full = session.decode(cap, variant_params(cfg, v), mode="calibrated")
        scores = hard_scenes.scene_scores(cap, apply_min_confidence(full, operating), cfg.decoder.period_px, region)
        rows.append({"stage_off": v, "scene": name, **{k: scores[k] for k in SCORE_KEYS}})
        tag = "none" if v == FULL else v
        metrics.update({f"robust_stages/{tag}/{name}/{k}": scores[k] for k in SCORE_KEYS})
    return {"rows": rows, "metrics": metrics}


def _assignment(field: str, value: object) -> str:
    """``NAME=VALUE`` as ``--decoder`` reads it (:func:`simbench.decode.with_assignments`)."""
    text = str(value).lower() if isinstance(value, bool) else f"{value:g}" if isinstance(value, float) else str(value)
    return f"{field}={text}"


def _meets(r: dict) -> bool:
    return not hard_scenes.short_of_goals({f"x_{k}": r[k] for k in SCORE_KEYS}, "x")


def _largest(delta: np.ndarray, scenes: list[str], *, sign: float, scale: float, digits: int, floor: float) -> str:
    """The largest change of ``delta`` (per scene; NaN: not measured there) in the direction
    ``sign`` (-1: the largest fall), times ``scale``, with its scene; ``-`` under ``floor``."""
    d = sign * delta
    if not np.isfinite(d).any() or np.nanmax(d) < floor:
        return "-"
    k = int(np.nanargmax(d))
    return f"{scale * delta[k]:+.{digits}f} (`{scenes[k]}`)"


def _summary(rows: list[dict], scenes: list[str]) -> list[list[str]]:
    """Per variant: scenes meeting the goals, the ones it loses and gains against the whole
    decoder, the largest fall in completeness and rises in wrong share and MAE (each with its
    scene: a maximum over scenes would show the hardest scene's level, not the stage's effect),
    the median completeness, and the scenes where nothing decodes (no wrong share or MAE)."""
    cell = {(r["stage_off"], r["scene"]): r for r in rows}
    base = {s: cell[FULL, s] for s in scenes}
    out = []
    for v in _names():
        mine = [cell[v, s] for s in scenes]
        lost = [r["scene"] for r in mine if _meets(base[r["scene"]]) and not _meets(r)]
        gained = [r["scene"] for r in mine if _meets(r) and not _meets(base[r["scene"]])]

        def delta(key: str) -> np.ndarray:
            return np.array([r[key] - base[s][key] for r, s in zip(mine, scenes)], dtype=float)

        c = np.array([r["completeness"] for r in mine], dtype=float)
        none = sum(1 for r in mine if not r["completeness"] > 0)
        whole = v == FULL
        out.append(
            [
                "none (the whole decoder)" if whole else f"`{v}`",
                f"{sum(map(_meets, mine))} of {len(scenes)}",
                ", ".join(f"`{s}`" for s in lost) or "-",
                ", ".join(f"`{s}`" for s in gained) or "-",
                "-" if whole else _largest(delta("completeness"), scenes, sign=-1, scale=100, digits=2, floor=5e-5),
                "-" if whole else _largest(delta("wrong_share_all"), scenes, sign=1, scale=100, digits=3, floor=5e-6),
                "-" if whole else _largest(delta("gt_mae_mm"), scenes, sign=1, scale=1, digits=3, floor=5e-4),
                hard_scenes.format_score(float(np.nanmedian(c)) if np.isfinite(c).any() else float("nan"), True),
                str(none),
            ]
        )
    return out


def _plot(rows: list[dict], scenes: list[str], *, note: str = "") -> dict[str, bytes]:
    """PNG and PDF: each stage's absence by scene - beside the whole decoder, the change in
    completeness and in the share of every decoded pixel more than 5 mm wrong (points; symmetric
    logarithmic colour scales, so that a hundredth of a point and sixty points both show: a
    confidence term buys fewer wrong pixels, a flattening more complete ones); a cross where the
    scene then misses issue 35's goals that it met, a ring where it meets them and did not."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import SymLogNorm

    base = {r["scene"]: r for r in rows if r["stage_off"] == FULL}
    stages = list(VARIANTS)
    cell = {(r["stage_off"], r["scene"]): r for r in rows}

    def change(key: str) -> np.ndarray:
        # a scene with nothing decoded has no wrong share: no change drawn
        return np.array([[100 * (cell[v, s][key] - base[s][key]) for s in scenes] for v in stages], dtype=float)

    panels = (
        ("completeness", "completeness change (points)", "RdBu", 0.1),
        ("wrong_share_all", "change in the share > 5 mm wrong,\nof every decoded pixel (points)", "RdBu_r", 0.01),
    )
    fig, axes = plt.subplots(
        1, 2, figsize=(0.68 * len(scenes) + 5.0, 0.3 * len(stages) + 2.8), sharey=True, constrained_layout=True
    )
    for ax, (key, label, cmap, linthresh) in zip(axes, panels):
        values = change(key)
        finite = values[np.isfinite(values)]
        span = max(10 * linthresh, float(np.abs(finite).max()) if finite.size else 0.0)
        image = ax.imshow(
            np.ma.masked_invalid(values),
            cmap=plt.get_cmap(cmap).with_extremes(bad="0.6"),
            norm=SymLogNorm(linthresh=linthresh, vmin=-span, vmax=span),
            aspect="auto",
        )
        for i, v in enumerate(stages):
            for j, s in enumerate(scenes):
                was, now = _meets(base[s]), _meets(cell[v, s])
                if was and not now:
                    ax.plot(j, i, "x", color="k", ms=6, mew=1.5)
                elif now and not was:
                    ax.plot(j, i, "o", mfc="none", color="k", ms=6, mew=1.2)
        ax.set_xticks(range(len(scenes)), [s.removeprefix("hard_") for s in scenes], rotation=90, fontsize=7)
        ax.set_xlabel("scene")
        fig.colorbar(image, ax=ax, shrink=0.8).set_label(label, fontsize=8)
    axes[0].set_yticks(range(len(stages)), stages, fontsize=7)
    axes[0].set_ylabel("stage off (set to the paper decoder's setting)")
    fig.suptitle(
        "The colour-robust decoder without one stage, at its operating point, against the whole decoder\n"
        f"x: the scene no longer meets issue 35's goals; o: it now does; grey: nothing decoded{note}",
        fontsize=9,
    )
    return figure_formats(fig, dpi=110)


def write_robust_stages(session: Session, measured: list[dict]) -> dict:
    """The target's files from :func:`measure_scene`'s results (scenes in run order)."""
    cfg = session.config
    rows = [r for m in measured for r in m["rows"]]
    metrics = {k: v for m in measured for k, v in m["metrics"].items()}
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    operating = cfg.robust().min_confidence
    cam = session.scene(scenes[0]).rig.camera if scenes else None
    size = f"{cam.width_px}x{cam.height_px} camera, " if cam else ""
    stages = [
        [f"`{n}`", " ".join(f"`{_assignment(f, getattr(cfg.decoder, f))}`" for f in v.fields), v.does]
        for n, v in VARIANTS.items()
    ]
    quick = (
        f" - this run's {len(scenes)} of the {len(hard_scenes.HARD_SCENES)}, one of each class, at the quick run's "
        "resolution and samples (the goals were set for the full-resolution run; a scene's margin to them is not "
        "the same here) -"
        if cfg.quick
        else ""
    )
    lines = [
        "# What each stage of the colour-robust decoder buys",
        "",
        f"Made by `{session.command}` ({size}{cfg.spp} spp {cfg.sampler}, sensor model `{cfg.sensor}`, base seed "
        f"{cfg.seed}, variant `{session.variant}`). Every number: `robust_stages.csv`; by scene: "
        "`robust_stages.png`.",
        "",
        f"The hard scenes{quick} (`hard_scenes.md`: the same captures, the same protocol) decoded by the "
        "colour-robust decoder by triangulation, whole and with one stage at a time set back to the paper decoder's "
        "setting (with the fields that need it: the last table gives each variant as `--decoder` assignments on top "
        f"of the colour-robust decoder), at its operating point (confidence >= {operating:g}) throughout. *Meet the "
        "goals*: the three the project set the colour-robust decoder on these scenes (issue 35), >= 97 % complete, "
        "MAE <= 0.5 mm, <= 0.1 % of every decoded pixel more than 5 mm wrong; *lost* / *gained*: the scenes that "
        "meet them with the whole decoder and not without the stage, and the reverse; *largest fall* / *rise*: the "
        "scene where turning the stage off costs most, and by how much, in percentage points of the share or in mm "
        "(none under 0.005 points of completeness, 0.0005 points of wrong share, 0.0005 mm of MAE; a scene where "
        "nothing decodes has no wrong share or MAE, and is counted in the last column). A stage whose absence helps "
        "a scene shows here only when the scene then meets the goals (*gained*): the plot shows every change both "
        "ways, and `robust_stages.csv` every value (shares as fractions, MAE in mm). The time each stage costs is "
        "not here (it is the machine's, not the run's): `simbench bench --robust --stages` times the same variants "
        "(measured in `docs/results.md`).",
        "",
        *markdown_table(
            [
                "stage off",
                "meet the goals",
                "lost",
                "gained",
                "largest fall in completeness (points)",
                "largest rise in > 5 mm wrong, all decoded (points)",
                "largest rise in MAE (mm)",
                "median completeness",
                "scenes with nothing decoded",
            ],
            _summary(rows, scenes),
        ),
        "",
        "What it cannot see: two stages that each cover for the other (turning either off alone costs nothing, "
        "both would) - one at a time shows what each adds to the rest, not what it does alone; the scenes are "
        "the ones several stages were designed on (in sample); stages made for captures these scenes do not "
        "hold show nothing here - `registration_doubt` (colour channels misregistered), `position_doubt` and "
        "`pool_code` (a dark board's noisy or compressed codes: tests/test_decode.py, tests/test_robust_decoder.py, "
        "tests/test_registration.py) - and "
        "`registration_doubt`'s reference-plane path is not scored (triangulation only); the operating point "
        "stays where the whole decoder's curves put it, so a scene lost mixes the stage's value with a "
        "threshold chosen without it.",
        "",
        "## The stages",
        "",
        *markdown_table(["stage", "set to the paper decoder's (`--decoder` assignments)", "what it does"], stages),
        "",
    ]
    session.write_results(
        "robust_stages",
        {
            "robust_stages.csv": table_text(rows, ["stage_off", "scene", *SCORE_KEYS]),
            "robust_stages.md": "\n".join(lines),
            **figure_files("robust_stages", _plot(rows, scenes, note=cfg.figure_note())),
        },
        extra={
            "scenes": scenes,
            "operating_point": operating,
            "variants": {n: list(v.fields) for n, v in VARIANTS.items()},
        },
    )
    return metrics


# the scenes are measured one by one, as hard_scenes' (the run's workers take them side by side)
SPLIT = Split("robust_stages", hard_scenes.scene_names, measure_scene, write_robust_stages)
