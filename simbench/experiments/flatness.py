"""Error against board flatness: the white board of Table 1 (and the reference board) given a
form error - a bow, then a ripple - at growing levels, decoded by the run's (paper's) decoder
by triangulation (paper Eq. 15) and against the reference plane (Sec. 5.4).  Writes
``flatness.md``, ``flatness.csv``, ``flatness.png``, ``.pdf`` and ``flatness.provenance.json``.

What each score sees:

- *plane fit* (the paper's Table 1 protocol): the residual of the decoded points to their
  least-squares plane.  A perfect sensor reports a bowed board's own form here, so this score
  rises with the bow even where the sensor is exact: Table 1's numbers mix sensor error with
  board flatness, and the paper's simulated boards (Sec. 5.5) were perfectly flat.
- *against ground truth*: the rendered surface, form included; a bowed test board costs
  nothing here, a bowed *reference* board does in reference mode, which takes the reference
  for a plane at Z0 (every depth decoded against it inherits the reference's form, scaled).
- *the board itself*: the plane-fit RMS and peak-to-valley of the rendered surface where the
  camera sees it - what a perfect sensor would report.

Every level uses the same placement, render and noise seeds (common random numbers); the bow's
sign and the ripple's phase are drawn per board (:func:`simbench.sim.scene.board_form`), the test
board's and the reference board's independently.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from simbench.report import figure_files, figure_formats
from simbench.experiments.common import (
    RunConfig,
    Session,
    Split,
    markdown_table,
    score,
    table_text,
)
from simbench.metrics import plane_fit_error, points_from_depth

if TYPE_CHECKING:
    from simbench.experiments.common import Capture

__all__ = [
    "SPLIT",
    "flatness_parts",
    "measure_board",
    "write_flatness",
    "BOW_LEVELS_MM",
    "WAVINESS_LEVELS_MM",
    "QUICK_BOW_LEVELS_MM",
    "QUICK_WAVINESS_LEVELS_MM",
    "run_flatness",
    "surface_form",
]

SCENE = "plane_white"
MODES = ("calibrated", "reference")
# levels (assumption: a bow of 0 to 2 mm per metre spans a precision plate to a board one would
# not use as a target; ripples of 20-200 um, laminated panels' surface waviness)
BOW_LEVELS_MM = (0.0, 0.25, 0.5, 1.0, 2.0)
WAVINESS_LEVELS_MM = (0.02, 0.05, 0.1, 0.2)
QUICK_BOW_LEVELS_MM = (0.0, 1.0)
QUICK_WAVINESS_LEVELS_MM = (0.1,)

# the scores of each board, by both protocols (reference-plane ones prefixed ref_)
SCORE_KEYS = ("plane_mae_mm", "plane_rms_mm", "gt_mae_mm", "gt_rmse_mm", "completeness", "stripe_order_errors")


def surface_form(cap: Capture) -> dict:
    """Plane-fit RMS and peak-to-valley (mm) of the rendered surface over the lit pixels: the
    form a perfect sensor would report."""
    gt = cap.gt
    mask = gt.lit & np.isfinite(gt.depth_m)
    fit = plane_fit_error(gt.depth_m, cap.scene.rig.camera, mask=mask)
    pts = points_from_depth(gt.depth_m, cap.scene.rig.camera)[mask]
    if len(pts) < 3 or not np.all(np.isfinite(fit["normal"])):
        return {"form_rms_mm": float("nan"), "form_pv_mm": float("nan")}
    r = (pts - pts.mean(axis=0)) @ np.asarray(fit["normal"]) * 1000.0
    return {"form_rms_mm": fit["rms_residual_mm"], "form_pv_mm": float(r.max() - r.min())}


def _levels(quick: bool) -> list[tuple[str, float, float]]:
    bows = QUICK_BOW_LEVELS_MM if quick else BOW_LEVELS_MM
    waves = QUICK_WAVINESS_LEVELS_MM if quick else WAVINESS_LEVELS_MM
    return [("bow", b, 0.0) for b in bows] + [("waviness", 0.0, w) for w in waves]


def flatness_parts(config: RunConfig) -> list[str]:
    """The boards, ``bow 0.5`` ...: every bow level, then every waviness level."""
    return [f"{kind} {bow_mm if kind == 'bow' else wave_mm:g}" for kind, bow_mm, wave_mm in _levels(config.quick)]


def measure_board(session: Session, part: str) -> dict:
    """One board form (``bow 0.5``: its kind and level in mm), placed, recorded and decoded both
    ways: its row and metrics (plain data)."""
    cfg = session.config
    kind, level, bow_mm, wave_mm = next(
        (k, b if k == "bow" else w, b, w) for k, b, w in _levels(cfg.quick) if f"{k} {b if k == 'bow' else w:g}" == part
    )
    metrics = {}
    sub = session.fork(
        session.sensor, config=dataclasses.replace(cfg, board_bow_mm_per_m=bow_mm, board_waviness_mm=wave_mm)
    )
    scene = sub.prepare(sub.place(sub.raw_scene(SCENE), "flatness/white", ["board"]))
    cap = sub.capture(scene, "flatness/white")[0]
    row = {"form": kind, "level_mm": level, **surface_form(cap)}
    for mode in MODES:
        s = score(cap, sub.decode(cap, cfg.decoder, mode=mode), cfg.decoder.period_px)
        prefix = "" if mode == "calibrated" else "ref_"
        for k in SCORE_KEYS:
            row[prefix + k] = s[k]
            metrics[f"flatness/{kind}_{level:g}/{mode}/{k}"] = s[k]
    placed = sub.seeds_used["flatness/white/placement"]
    row["board_bow_mm_per_m"] = 1000.0 * placed.get("board_bow_m_per_m", 0.0)
    row["board_waviness_phase_rad"] = placed.get("board_waviness_phase_rad", "")
    ref_form = sub.config.reference_form()
    row["reference_bow_mm_per_m"] = 1000.0 * ref_form.get("bow_m_per_m", 0.0)
    row["reference_waviness_phase_rad"] = ref_form.get("waviness_phase_rad", "")
    return {"row": row, "metrics": metrics}


def write_flatness(session: Session, measured: list[dict]) -> dict:
    """The study's files from :func:`measure_board`'s results (in :func:`flatness_parts`' order)."""
    cfg = session.config
    rows = [m["row"] for m in measured]
    metrics = {k: v for m in measured for k, v in m["metrics"].items()}
    cols = [
        "form",
        "level_mm",
        "form_rms_mm",
        "form_pv_mm",
        *SCORE_KEYS,
        *(f"ref_{k}" for k in SCORE_KEYS),
        "board_bow_mm_per_m",
        "board_waviness_phase_rad",
        "reference_bow_mm_per_m",
        "reference_waviness_phase_rad",
    ]
    files = {
        "flatness.csv": table_text(rows, cols),
        **figure_files(
            "flatness",
            flatness_plot(rows, title=f"{SCENE}, sensor {cfg.sensor}: error against board flatness{cfg.figure_note()}"),
        ),
        "flatness.md": _markdown(session, rows),
    }
    session.write_results(
        "flatness",
        files,
        extra={
            "bow_levels_mm": list(BOW_LEVELS_MM),
            "waviness_levels_mm": list(WAVINESS_LEVELS_MM),
            "quick": cfg.quick,
        },
    )
    return metrics


# each board form a part (the run's workers take them side by side)
SPLIT = Split("flatness", flatness_parts, measure_board, write_flatness)


def run_flatness(session: Session) -> dict:
    """Every board of :func:`flatness_parts` measured, then the files written (:class:`Split`)."""
    return SPLIT.run(session)


def flatness_plot(rows: list[dict], *, title: str) -> dict[str, bytes]:
    """PNG and PDF (:func:`simbench.report.figure_formats`): the scores
    against the bow (left) and the ripple amplitude (right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), constrained_layout=True)
    for ax, kind, xlabel in (
        (axes[0], "bow", "bow: sag over a 1 m chord (mm per metre)"),
        (axes[1], "waviness", "ripple amplitude (mm)"),
    ):
        rs = [r for r in rows if r["form"] == kind]
        if not rs:
            ax.set_visible(False)
            continue
        x = [r["level_mm"] for r in rs]
        for key, style, label in (
            ("plane_rms_mm", "o-", "triangulation: RMS residual to fitted plane (Table 1 protocol)"),
            ("gt_rmse_mm", "s-", "triangulation: RMSE against ground truth"),
            ("ref_plane_rms_mm", "o--", "reference plane: RMS residual to fitted plane"),
            ("ref_gt_rmse_mm", "s--", "reference plane: RMSE against ground truth"),
            ("form_rms_mm", "k:", "the board's own form (plane-fit RMS of the rendered surface)"),
        ):
            ax.plot(x, [r[key] for r in rs], style, label=label)
        ax.set_xlabel(xlabel)
        ax.set_ylabel("mm")
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    return figure_formats(fig, dpi=110)


def _markdown(session: Session, rows: list[dict]) -> str:
    cfg = session.config
    scene = session.scene(SCENE)
    cam = scene.rig.camera
    sx, sy = dict(scene.objects[0].params)["size_m"]  # the scene's one board
    lines = [
        "# Error against board flatness",
        "",
        f"Made by `{session.command}` (scene `scenes/{SCENE}.toml`, {cam.width_px}x{cam.height_px} camera, {cfg.spp} "
        f"spp {cfg.sampler}, "
        f"sensor model `{cfg.sensor}`, the paper's decoder, base seed {cfg.seed}, variant `{session.variant}`). Plot: "
        f"`flatness.png`.",
        "",
        "The white board, placed as in Table 1, and the reference board get a form error "
        "(`simbench.sim.scene.board_form_m`): a bow "
        f"(paraboloid, the level its sag over a 1 m chord: mm per metre; the board is {sx:g} x {sy:g} m, the camera "
        f"sees its middle), then a "
        "ripple across the stripes (50 mm period, the level its amplitude). The bow's sign and the ripple's phase are "
        "seeded per "
        "board, test and reference independently (`board_bow_mm_per_m`, `reference_bow_mm_per_m` in `flatness.csv`). "
        "*Form* is the "
        "rendered surface's own plane-fit RMS where the camera sees it: what a perfect sensor reports under the "
        "paper's Table 1 "
        "protocol. *Plane fit* cannot tell the board's form from sensor error; *GT* (ground truth, the formed surface) "
        "can, and "
        "shows what the reference protocol inherits from a bowed reference board.",
        "",
    ]
    hdr = [
        "form",
        "level (mm, bow: mm per m)",
        "board form RMS (mm)",
        "triangulation: plane-fit RMS",
        "triangulation: GT RMSE",
        "reference: plane-fit RMS",
        "reference: GT RMSE",
        "completeness",
        "stripe-order errors",
    ]
    body = [
        [
            r["form"],
            f"{r['level_mm']:g}",
            f"{r['form_rms_mm']:.3f}",
            f"{r['plane_rms_mm']:.3f}",
            f"{r['gt_rmse_mm']:.3f}",
            f"{r['ref_plane_rms_mm']:.3f}",
            f"{r['ref_gt_rmse_mm']:.3f}",
            f"{100 * r['completeness']:.2f} %",
            f"{r['stripe_order_errors']:.0f}",
        ]
        for r in rows
    ]
    lines += markdown_table(hdr, body)
    bowed = [r for r in rows if r["form"] == "bow" and r["level_mm"] > 0]
    if bowed:
        same = bowed[0]["board_bow_mm_per_m"] * bowed[0]["reference_bow_mm_per_m"] > 0
        lines += [
            "",
            f"In this run the test board and the reference board bow {'the same way' if same else 'opposite ways'} "
            f"(seeded signs): the "
            "reference protocol subtracts the reference's form from the test board's, so its plane fit "
            + (
                "hides the bow (the two cancel) while its error against ground truth grows with it"
                if same
                else "sees about twice the bow"
            )
            + " - a protocol that can cancel the error it measures. Triangulation does not use the reference board.",
        ]
    return "\n".join(lines) + "\n"
