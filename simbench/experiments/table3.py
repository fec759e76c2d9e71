"""Paper Table 3 and Fig. 10: a plaster cube next to a plaster cuboid (``scenes/discontinuity.toml``;
translucent as :mod:`simbench.sim.subsurface`'s assumed plaster, for every sensor).

Per object, over its front face (ground-truth points within 1 mm of the face plane, minus a band
at depth edges): the paper's protocol (mean absolute residual of the decoded points to their
least-squares plane - the paper's "actual depth obtained by the Least Squares Fitting method")
and the mean absolute error against ground truth.  The Kinect and ToF columns come from the
simulated competitors (:mod:`simbench.systems.kinect`, :mod:`simbench.systems.tof`) on the same
scene, scored the same way at their own resolutions (the edge band scaled to the same angle).  Writes ``table3.md``,
``table3.csv``, ``fig10.png``/``.pdf`` (cross-sections of the three sensors, as the paper's Fig. 10) and
``table3.provenance.json``.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from simbench.sim.sensor import PAPER_LATERAL_COLOUR_PX, SensorModel, with_lateral_colour
from simbench.report import figure_files, figure_formats
from simbench.experiments.common import (
    RunConfig,
    Session,
    Split,
    calibration_sentence,
    calibration_summary,
    markdown_table,
    other_rig,
    scene_errors,
    score,
    sensor_caveat,
    table_text,
)
from simbench.literature import (
    PAPER_COMPETITORS,  # system -> (the paper's name for it, its column in PAPER_TABLE3)
    PAPER_TABLE3,  # paper Table 3 (mm): object -> (proposed, Kinect, ToF)
)
from simbench.metrics import edge_band, plane_fit_error, points_from_depth
from simbench.rig import rotation_xyz_deg
from simbench.sim.scene import with_subsurface

if TYPE_CHECKING:
    from simbench.sim.scene import SceneSpec
    from simbench.sim.truth import GroundTruth

__all__ = [
    "PAPER_TABLE3",
    "SCENE",
    "SPLIT",
    "front_face_mask",
    "run_table3",
    "table3_parts",
    "measure_table3",
    "write_table3",
]

SCENE = "discontinuity"


def front_face_mask(scene: SceneSpec, gt: GroundTruth, name: str, *, tol_m: float = 1e-3) -> np.ndarray:
    """Pixels on the camera-facing (-z) face of box ``name``, from ground truth."""
    idx = [o.name for o in scene.objects].index(name)
    obj = scene.objects[idx]
    if obj.kind != "box":
        raise ValueError(f"{name!r} is a {obj.kind}, not a box")
    r = rotation_xyz_deg(obj.get("rotation_deg"))
    normal = r @ np.array([0.0, 0.0, -1.0])
    point = np.asarray(obj.get("center_m")) + r @ np.array([0.0, 0.0, -obj.get("size_m")[2] / 2])
    pts = points_from_depth(gt.depth_m, scene.rig.camera)
    with np.errstate(invalid="ignore"):
        on_face = np.abs((pts - point) @ normal) < tol_m
    return on_face & (gt.object_id == idx) & gt.lit


COMPETITORS = tuple(PAPER_COMPETITORS)
# beside the paper's columns: the multi-shot accuracy reference on the proposed projector and camera
REFERENCE_SYSTEMS = ("phase_shift",)


def _placed(session: Session):
    """The scene with its objects placed once (the same placement and seeds for every sensor)
    and its capture label."""
    label = f"table3/{SCENE}"
    return session.place(session.raw_scene(SCENE), label, PLACED), label


def _measure_competitor(session: Session, name: str) -> dict:
    """System ``name``'s recording scored per face: its label, per-face scores and its Fig. 10
    panel.  The edge band, defined on the main camera, is scaled to the system's resolution
    (the same angle, at least 1 px)."""
    raw, label = _placed(session)
    main_focal_px = session.scene(SCENE).rig.camera.focal_px
    rec, depth = session.acquire(name, raw, label)[0]
    band = edge_band(
        rec.gt.depth_m,
        object_id=rec.gt.object_id,
        band_px=max(1, int(round(session.config.edge_band_px * rec.scene.rig.camera.focal_px / main_focal_px))),
    )
    info = session.system(name).info()
    rig = other_rig(session)
    other = session.decode_recording(name, rec, rig=rig) if info.uses_scene_rig and rig else None
    faces, scores = {}, {}
    for obj in PAPER_TABLE3:
        face = front_face_mask(rec.scene, rec.gt, obj) & ~band
        faces[obj] = face
        sc = score(rec, depth, info.period_px, region=face)
        scores[obj] = {
            "plane_mae_mm": sc["plane_mae_mm"],
            "gt_mae_mm": sc["gt_mae_mm"],
            "completeness": sc["completeness"],
            "face_pixels": int(face.sum()),
            "seeds": rec.seeds,
        }
        if other is not None:
            so = score(rec, other, info.period_px, region=face)
            scores[obj]["other_rig"] = {k: so[k] for k in ("plane_mae_mm", "gt_mae_mm", "completeness")}
    label_text = info.label
    return {
        "label": label_text,
        "scores": scores,
        "panel": (label_text, rec.scene.rig.camera, rec.gt.depth_m, depth.depth_m, faces),
    }


PLACED = ("cube", "cuboid")


def what_ifs(paper: SensorModel) -> dict[str, tuple[str, SensorModel, "Callable[[SceneSpec], SceneSpec] | None"]]:
    """Physical effects not (yet) in the run's sensor model or scenes, each measured on Table 3's
    scene with the same placement and seeds: name -> (description, the sensor model to record
    with, the change to the placed scene or None)."""
    cam, prj = PAPER_LATERAL_COLOUR_PX["camera"], PAPER_LATERAL_COLOUR_PX["projector"]
    out = {
        "lateral_colour": (
            f"lateral colour of both lenses, red and blue {cam[0] - cam[2]:g} camera px and {prj[0] - prj[2]:g} DMD px "
            "apart at the corner (`simbench.sim.sensor.PAPER_LATERAL_COLOUR_PX`, an argued bound)",
            with_lateral_colour(paper, camera_px=cam, projector_px=prj),
            None,
        ),
    }
    for medium, why in SUBSURFACE_WHAT_IFS.items():
        out[f"subsurface_{medium}"] = (
            (
                f"cube and cuboid opaque ({why})"
                if medium == "opaque"
                else f"cube and cuboid translucent as {medium} ({why}; dipole diffusion, `simbench.sim.subsurface`)"
            ),
            paper,
            lambda scene, medium=medium: with_subsurface(scene, None if medium == "opaque" else medium, names=PLACED),
        )
    return out


# the plaster objects' translucency (scenes/discontinuity.toml: the assumed plaster of
# simbench.sim.subsurface) bracketed: opaque, and the least and the most translucent measured white
# media of simbench.sim.subsurface.MEDIA
SUBSURFACE_WHAT_IFS = {
    "opaque": "no subsurface scattering, as the project's tables had it before",
    "spectralon": "measured, the least translucent white diffuser",
    "marble": "measured, a translucent stone",
}


WHAT_IF_VARIANTS = (("paper", "calibrated"), ("paper", "reference"))
WHAT_IF_KEYS = ("plane_mae_mm", "gt_mae_mm", "completeness")
VARIANTS = (("paper", "calibrated"), ("paper", "reference"), ("robust", "calibrated"), ("robust", "reference"))
# beside the run's rig (RunConfig.rig), each decoder is scored with the other one too
RIG_KEYS = ("plane_mae_mm", "gt_mae_mm", "completeness")


SYSTEMS = COMPETITORS + REFERENCE_SYSTEMS
# what_ifs' effects (its keys, whatever the sensor model)
WHAT_IFS = ("lateral_colour", *(f"subsurface_{medium}" for medium in SUBSURFACE_WHAT_IFS))
PROPOSED = "proposed"


def table3_parts(config: RunConfig, *, systems: tuple[str, ...] = SYSTEMS) -> list[str]:
    """The proposed sensor's capture, each other system's recording, each what-if's capture."""
    return [PROPOSED, *systems, *WHAT_IFS]


def table3_cost(part: str) -> float:
    """A part's rank for a pool: the proposed sensor's (four decoders, the other rig's too) and
    the multi-shot reference's (12 exposures) first."""
    return 2.0 if part in (PROPOSED, *REFERENCE_SYSTEMS) else 1.0


def _proposed_capture(session: Session):
    raw, label = _placed(session)
    scene = session.prepare(raw)
    cap = session.capture(scene, label)[0]
    band = edge_band(cap.gt.depth_m, object_id=cap.gt.object_id, band_px=session.config.edge_band_px)
    faces = {name: front_face_mask(scene, cap.gt, name) & ~band for name in PAPER_TABLE3}
    return raw, label, scene, cap, faces


def _measure_proposed(session: Session) -> dict:
    """The proposed sensor's capture decoded by both decoders in both modes (and with the other
    rig), scored per face: per object its columns, the metrics, the whole scene's errors and its
    Fig. 10 panel."""
    cfg = session.config
    params = {"paper": cfg.decoder, "robust": cfg.robust()}
    _, label, scene, cap, faces = _proposed_capture(session)
    results = {(d, m): session.decode(cap, params[d], mode=m) for d, m in VARIANTS}
    other = other_rig(session)
    others = {(d, m): session.decode(cap, params[d], mode=m, rig=other) for d, m in VARIANTS} if other else {}
    columns, metrics = {}, {}
    for name, paper in PAPER_TABLE3.items():
        face = faces[name]
        row = {"face_pixels": int(face.sum())}
        for (d, m), result in results.items():
            sc = score(cap, result, cfg.decoder.period_px, region=face)
            key = f"{d}_{m}"
            row.update(
                {
                    f"{key}_plane_mae_mm": sc["plane_mae_mm"],
                    f"{key}_ratio": sc["plane_mae_mm"] / paper[0],
                    f"{key}_gt_mae_mm": sc["gt_mae_mm"],
                    f"{key}_completeness": sc["completeness"],
                    f"{key}_stripe_order_errors": sc["stripe_order_errors"],
                }
            )
            for k in ("plane_mae_mm", "gt_mae_mm", "completeness", "stripe_order_errors"):
                metrics[f"table3/{name}/{d}/{m}/{k}"] = sc[k]
            if others:
                so = score(cap, others[(d, m)], cfg.decoder.period_px, region=face)
                row.update({f"{key}_rig_{other}_{k}": so[k] for k in RIG_KEYS})
                for k in RIG_KEYS:
                    metrics[f"table3/{name}/{d}/{m}/rig_{other}/{k}"] = so[k]
        row.update({**cap.seeds, **session.seeds_used[f"{label}/placement"]})
        columns[name] = row
    result = results[("paper", "calibrated")]
    whole = scene_errors(cap, result, period_px=cfg.decoder.period_px, edge_band_px=cfg.edge_band_px)
    metrics["table3/scene/completeness"] = whole["completeness"]
    metrics["table3/scene/stripe_order_errors"] = whole["stripe_order_errors"]
    panel = ("proposed", cap.scene.rig.camera, cap.gt.depth_m, result.depth_m, faces)
    # both decoders' depth by triangulation, for the comparison on common pixels (write_table3)
    depths = {d: results[(d, "calibrated")].depth_m for d in ("paper", "robust")}
    return {"columns": columns, "metrics": metrics, "whole": whole, "panel": panel, "depths": depths}


def _measure_what_if(session: Session, effect: str) -> dict:
    """One effect of :func:`what_ifs` recorded (the same placement and seeds) and decoded by the
    paper's decoder, scored on the proposed capture's faces: per object its columns, the metrics."""
    cfg = session.config
    raw, label, _, _, faces = _proposed_capture(session)
    _, sensor, change = what_ifs(session.sensor)[effect]
    sub = (
        session
        if sensor == session.sensor
        else session.fork(dataclasses.replace(sensor, name=f"{session.sensor.name}+{effect}"))
    )
    w_scene = sub.prepare(raw if change is None else change(raw))
    w_cap = sub.capture(w_scene, label)[0]
    columns = {name: {} for name in PAPER_TABLE3}
    metrics = {}
    for d, m in WHAT_IF_VARIANTS:
        w_result = sub.decode(w_cap, cfg.decoder if d == "paper" else cfg.robust(), mode=m)
        for name in PAPER_TABLE3:
            sc = score(w_cap, w_result, cfg.decoder.period_px, region=faces[name])
            for k in WHAT_IF_KEYS:
                columns[name][f"{effect}_{d}_{m}_{k}"] = sc[k]
                metrics[f"table3/{name}/what_if/{effect}/{d}/{m}/{k}"] = sc[k]
    return {"columns": columns, "metrics": metrics}


def measure_table3(session: Session, part: str) -> dict:
    """One part of :func:`table3_parts` (plain data and its Fig. 10 panel)."""
    if part == PROPOSED:
        return _measure_proposed(session)
    if part in WHAT_IFS:
        return _measure_what_if(session, part)
    return _measure_competitor(session, part)


def write_table3(session: Session, measured: list[dict], *, systems: tuple[str, ...] = SYSTEMS) -> dict:
    """The table's files from :func:`measure_table3`'s results (in :func:`table3_parts`' order)."""
    cfg = session.config
    proposed, *rest = measured
    competitors = dict(zip(systems, rest[: len(systems)]))
    what_if = rest[len(systems) :]
    other = other_rig(session)
    metrics = dict(proposed["metrics"])
    rows = []
    for name, paper in PAPER_TABLE3.items():
        row = {"object": name, "paper_mm": paper[0], **proposed["columns"][name]}
        for d, c in competitors.items():
            if d in PAPER_COMPETITORS:
                row[f"paper_{d}_mm"] = paper[PAPER_COMPETITORS[d][1]]
            row.update(
                {
                    f"{d}_mm": c["scores"][name]["plane_mae_mm"],
                    f"{d}_gt_mae_mm": c["scores"][name]["gt_mae_mm"],
                    f"{d}_completeness": c["scores"][name]["completeness"],
                }
            )
            if "other_rig" in c["scores"][name]:
                row.update({f"{d}_rig_{other}_{k}": v for k, v in c["scores"][name]["other_rig"].items()})
            row.update({f"{d}_{k}_seed": v for k, v in c["scores"][name]["seeds"].items()})
            for k in ("plane_mae_mm", "gt_mae_mm", "completeness"):
                metrics[f"table3/{name}/{d}_{k}"] = c["scores"][name][k]
            for k, v in c["scores"][name].get("other_rig", {}).items():
                metrics[f"table3/{name}/{d}/rig_{other}/{k}"] = v
        for w in what_if:
            row.update(w["columns"][name])
        rows.append(row)
    for w in what_if:
        metrics.update(w["metrics"])
    whole = proposed["whole"]
    cols = ["object", "paper_mm", "face_pixels"]
    cols += [
        f"{d}_{m}_{k}"
        for d, m in VARIANTS
        for k in ("plane_mae_mm", "ratio", "gt_mae_mm", "completeness", "stripe_order_errors")
    ]
    cols += [f"{d}_{m}_rig_{other}_{k}" for d, m in VARIANTS for k in RIG_KEYS if other]
    cols += [
        c
        for d in competitors
        for c in ([f"paper_{d}_mm"] if d in PAPER_COMPETITORS else [])
        + [f"{d}_mm", f"{d}_gt_mae_mm", f"{d}_completeness"]
        + ([f"{d}_rig_{other}_{k}" for k in RIG_KEYS] if "other_rig" in competitors[d]["scores"][PLACED[0]] else [])
    ]
    cols += [f"{e}_{d}_{m}_{k}" for e in what_ifs(session.sensor) for d, m in WHAT_IF_VARIANTS for k in WHAT_IF_KEYS]
    cols += ["render", "noise", "placement"]
    cols += [f"{n}_{k}" for n in PLACED for k in ("depth_m", "tilt_deg")]
    cols += [f"{d}_{k}_seed" for d in competitors for k in ("render", "noise")]
    panels = [proposed["panel"], *(c["panel"] for c in competitors.values())]
    common, common_metrics = _common_pixels(proposed, competitors)
    metrics.update(common_metrics)
    files = {
        "table3.csv": table_text(rows, cols),
        "table3.md": _markdown(session, rows, whole, competitors) + common,
        **figure_files(
            "fig10",
            cross_section_figure(
                panels, title=f"Fig. 10: cross-sections of {SCENE} (the row through both objects){cfg.figure_note()}"
            ),
        ),
    }
    session.write_results(
        "table3",
        files,
        extra={
            "placement": {"depth_mm": cfg.placement_depth_mm, "tilt_deg": cfg.placement_tilt_deg},
            **({"calibration": calibration_summary(session, session.scene(SCENE))} if other else {}),
        },
    )
    return metrics


def _common_pixels(proposed: dict, competitors: dict) -> tuple[str, dict]:
    """Each structured-light method scored on the face pixels every one of them decoded - the
    paper's and the colour-robust decoder (triangulation) and the systems recorded through the
    same camera (the phase-shifting reference) - so that a method that leaves its doubtful
    pixels out is not compared on an easier set (a review of the protocols, 2026-11-30: the
    colour-robust decoder's 96 / 90 % of the faces against phase shifting's 100 %).  Markdown
    lines and metrics."""
    _, cam, gt_depth, _, faces = proposed["panel"]
    depths = {("paper", "the paper's decoder"): proposed["depths"]["paper"]}
    depths[("robust", "the colour-robust decoder")] = proposed["depths"]["robust"]
    for d, c in competitors.items():
        label, other_cam, _, depth, _ = c["panel"]
        if other_cam.size_hw == cam.size_hw and d in REFERENCE_SYSTEMS:
            depths[(d, label)] = depth
    if len(depths) < 3:
        return "", {}
    lines, metrics, parts = ["", "## On common pixels", ""], {}, []
    for name in PAPER_TABLE3:
        common = faces[name] & np.logical_and.reduce([np.isfinite(z) for z in depths.values()])
        cells = []
        for (key, label), z in depths.items():
            fit = plane_fit_error(z, cam, mask=common)
            err = np.abs(np.asarray(z, np.float64) - gt_depth)[common] * 1000.0
            mae = float(err.mean()) if err.size else float("nan")
            metrics[f"table3/{name}/common/{key}/plane_mae_mm"] = fit["mean_abs_residual_mm"]
            metrics[f"table3/{name}/common/{key}/gt_mae_mm"] = mae
            cells.append(f"{label} {fit['mean_abs_residual_mm']:.4f} / {mae:.4f}")
        share = common.sum() / max(int(faces[name].sum()), 1)
        parts.append(f"{name} ({int(common.sum())} pixels, {100 * share:.1f} % of the face): " + ", ".join(cells))
    lines.append(
        "Each method's completeness on the faces differs, and a method that leaves its doubtful pixels out is "
        "scored on an easier set; here each is scored on the face pixels all of them decoded (plane fit / GT MAE, "
        "mm, triangulation): " + "; ".join(parts) + "."
    )
    return "\n".join(lines) + "\n", metrics


# each sensor's recording and each what-if a part (the run's workers take them side by side)
SPLIT = Split("table3", table3_parts, measure_table3, write_table3, cost=table3_cost)


def run_table3(session: Session, *, systems: tuple[str, ...] = SYSTEMS) -> dict:
    """Table 3 with the proposed sensor and the other ``systems`` (registered names,
    :mod:`simbench.systems`): the paper's competitors, the Kinect and the ToF camera, and the
    multi-shot reference."""
    if systems == SYSTEMS:
        return SPLIT.run(session)
    split = dataclasses.replace(
        SPLIT,
        parts=functools.partial(table3_parts, systems=systems),
        write=functools.partial(write_table3, systems=systems),
    )
    return split.run(session)


def _what_if_section(session: Session, rows: list[dict]) -> list[str]:
    """The effects not in the run's sensor model, measured (:func:`what_if_sensors`)."""
    effects = what_ifs(session.sensor)
    lines = [
        "",
        "## What if: effects not in the sensor model, and the faces' translucency, measured",
        "",
        "The same scene, placement and seeds, recorded through the run's sensor model with one more effect (the "
        "reference plane too) or with the faces' translucency changed (the table above has them translucent as the "
        "assumed plaster), decoded by the paper's decoder; the change against the table above is what the change "
        "adds. " + " ".join(f"*{e}*: {text}." for e, (text, _, _) in effects.items()),
        "",
    ]
    hdr = [
        "effect",
        "object",
        "paper (mm)",
        "triangulation: plane fit (mm)",
        "change (mm)",
        "GT MAE (mm)",
        "change (mm)",
    ]
    hdr += ["reference: plane fit (mm)", "change (mm)"]
    body = []
    for e in effects:
        for r in rows:
            t, g, ref = (
                r[f"{e}_paper_{m}_{k}"]
                for m, k in (("calibrated", "plane_mae_mm"), ("calibrated", "gt_mae_mm"), ("reference", "plane_mae_mm"))
            )
            body.append(
                [
                    e,
                    r["object"],
                    f"{r['paper_mm']:.4f}",
                    f"{t:.4f}",
                    f"{t - r['paper_calibrated_plane_mae_mm']:+.4f}",
                    f"{g:.4f}",
                    f"{g - r['paper_calibrated_gt_mae_mm']:+.4f}",
                    f"{ref:.4f}",
                    f"{ref - r['paper_reference_plane_mae_mm']:+.4f}",
                ]
            )
    return lines + markdown_table(hdr, body)


def _exposures(n: int) -> str:
    return f"{n} exposure" + ("s" if n != 1 else "")


def _markdown(session: Session, rows: list[dict], whole: dict, competitors: dict) -> str:
    cfg = session.config
    cam = session.scene(SCENE).rig.camera
    lines = [
        "# Table 3: depth discontinuity (plaster cube next to a cuboid)",
        "",
        f"Made by `{session.command}` (scene `scenes/{SCENE}.toml`, {cam.width_px}x{cam.height_px} camera, {cfg.spp} "
        f"spp {cfg.sampler}, "
        f"sensor model `{cfg.sensor}`, base seed {cfg.seed}, variant `{session.variant}`).",
        "",
        "The paper's Table 3 is measured on its rig (Sec. 6). The cube and the cuboid are each placed with a seeded "
        "error "
        f"within +-{cfg.placement_depth_mm:g} mm in depth and +-{cfg.placement_tilt_deg:g} deg of tilt "
        f"(`simbench.sim.scene.Placement`), "
        "independently of the reference plane; offsets in `table3.csv`. Scored over each object's front face (ground "
        f"truth within 1 mm of the face plane) minus a {cfg.edge_band_px}-px band at depth edges. *Plane fit* = the "
        "paper's protocol, mean absolute residual (mm) to the least-squares plane of the decoded face; *GT MAE* = "
        "against rendered ground truth. *Triangulation* decodes with the rig (Eq. 15), *reference* matches against the "
        "separately captured reference plane (Sec. 5.4). Cross-section (paper's decoder, triangulation): `fig10.png`.",
        "",
    ]
    hdr = [
        "object",
        "paper (mm)",
        "triangulation: plane fit (mm)",
        "ratio",
        "reference: plane fit (mm)",
        "ratio",
        "robust decoder, triangulation: plane fit (mm)",
        "robust: completeness",
        "paper's decoder, triangulation: GT MAE (mm)",
        "paper's: completeness",
        "paper's: stripe-order errors",
    ]
    for d, c in competitors.items():
        hdr += (
            [f"{PAPER_COMPETITORS[d][0]}: paper / sim, plane fit (mm)", "ratio"]
            if d in PAPER_COMPETITORS
            else [f"{c['label']}: plane fit (mm)"]
        )

    def short(d: str) -> str:
        return PAPER_COMPETITORS[d][0] if d in PAPER_COMPETITORS else competitors[d]["label"]

    def competitor_cells(r: dict) -> list[str]:
        cells = []
        for d in competitors:
            if d in PAPER_COMPETITORS:
                cells += [f"{r[f'paper_{d}_mm']:.4f} / {r[f'{d}_mm']:.4f}", f"{r[f'{d}_mm'] / r[f'paper_{d}_mm']:.2f}"]
            else:
                cells.append(f"{r[f'{d}_mm']:.4f}")
        return cells

    body = [
        [
            r["object"],
            f"{r['paper_mm']:.4f}",
            f"{r['paper_calibrated_plane_mae_mm']:.4f}",
            f"{r['paper_calibrated_ratio']:.2f}",
            f"{r['paper_reference_plane_mae_mm']:.4f}",
            f"{r['paper_reference_ratio']:.2f}",
            f"{r['robust_calibrated_plane_mae_mm']:.4f}",
            f"{100 * r['robust_calibrated_completeness']:.2f} %",
            f"{r['paper_calibrated_gt_mae_mm']:.4f}",
            f"{100 * r['paper_calibrated_completeness']:.2f} %",
            str(r["paper_calibrated_stripe_order_errors"]),
        ]
        + competitor_cells(r)
        for r in rows
    ]
    lines += markdown_table(hdr, body)
    lines += _what_if_section(session, rows)
    lines += [
        "",
        "Stripe-order errors on the faces, per decoder and protocol: "
        + "; ".join(
            f"{r['object']}: " + ", ".join(f"{d} {m} {r[f'{d}_{m}_stripe_order_errors']}" for d, m in VARIANTS)
            for r in rows
        )
        + ".",
        "",
        f"Whole scene (lit pixels outside the edge band, paper's decoder, triangulation): completeness "
        f"{100 * whole['completeness']:.2f} %, "
        f"MAE {whole['mae_mm']:.3f} mm, stripe-order errors {whole['stripe_order_errors']}.",
        "",
        (
            (
                "Kinect and ToF: the simulated Kinect-v1-like speckle sensor (640x480) and SR4000-like ToF camera "
                "(176x144) of `simbench.systems.kinect` and `.tof`, on the same scene from the same camera centre, "
                "scored with the same protocol at their own resolutions (edge band scaled to the same angle, rounded "
                "to whole pixels and at least one: the ToF camera's one pixel is ~2x the angle of the main camera's "
                "band, which leaves more of its edge pixels out - in its favour). "
                if all(d in competitors for d in COMPETITORS)
                else ""
            )
            + "".join(
                f"{c['label']}: {_exposures(session.system(d).info().captures)} of the static scene per depth map "
                "(`simbench.systems`), on the same scene, scored with the same protocol at its own resolution. "
                for d, c in competitors.items()
                if d not in COMPETITORS
            )
        )
        + "Their completeness on the faces: "
        + "; ".join(
            f"{r['object']}: " + ", ".join(f"{short(d)} {100 * r[f'{d}_completeness']:.1f} %" for d in competitors)
            for r in rows
        )
        + ". Their ground-truth MAE: "
        + "; ".join(
            f"{r['object']}: " + ", ".join(f"{short(d)} {r[f'{d}_gt_mae_mm']:.3f} mm" for d in competitors)
            for r in rows
        )
        + (
            ". Left out of the competitors: multipath and wiggling (ToF), the Kinect's proprietary post-filters."
            if all(d in competitors for d in COMPETITORS)
            else "."
        ),
    ]
    if other_rig(session):
        lines += ["", *rig_section(session, rows, competitors)]
    lines += sensor_caveat(cfg)
    return "\n".join(lines) + "\n"


def rig_section(session: Session, rows: list[dict], competitors: dict) -> list[str]:
    """The Markdown section comparing the true and the calibrated rig on the faces."""
    other = other_rig(session)
    main = session.config.rig
    names = {"true": "true rig", "calibrated": "calibrated rig"}
    lines = [
        "## True rig and calibrated rig",
        "",
        calibration_sentence(session, session.scene(SCENE)),
        "",
    ]
    hdr = [
        "object",
        "decoder, protocol",
        f"{names[main]}: plane fit / GT MAE (mm)",
        f"{names[other]}: plane fit / GT MAE (mm)",
    ]
    body = []
    for r in rows:
        for d, m in VARIANTS:
            key = f"{d}_{m}"
            body.append(
                [
                    r["object"],
                    f"{d}, {'triangulation' if m == 'calibrated' else 'reference'}",
                    f"{r[f'{key}_plane_mae_mm']:.4f} / {r[f'{key}_gt_mae_mm']:.4f}",
                    f"{r[f'{key}_rig_{other}_plane_mae_mm']:.4f} / {r[f'{key}_rig_{other}_gt_mae_mm']:.4f}",
                ]
            )
        for d, c in competitors.items():
            if f"{d}_rig_{other}_plane_mae_mm" in r:
                body.append(
                    [
                        r["object"],
                        c["label"],
                        f"{r[f'{d}_mm']:.4f} / {r[f'{d}_gt_mae_mm']:.4f}",
                        f"{r[f'{d}_rig_{other}_plane_mae_mm']:.4f} / {r[f'{d}_rig_{other}_gt_mae_mm']:.4f}",
                    ]
                )
    lines += markdown_table(hdr, body)
    lines += [
        "",
        "The plane fit cannot see a calibration error that keeps a face planar (a focal length or baseline error "
        "scales depth, which bends a plane only slightly); the GT MAE sees it. In reference mode the rig enters "
        "through the focal length and baseline of Eq. 15 and the lens undistortion only; triangulation uses all of it.",
    ]
    return lines


def cross_section_figure(panels: list, *, title: str) -> dict[str, bytes]:
    """PNG and PDF (:func:`simbench.report.figure_formats`):
    one row per sensor - its depth map, and decoded and true depth along the image row
    through the middle of the faces with each face's least-squares line (the paper's red
    dotted 'actual depth').  ``panels``: (label, camera, gt_depth, depth, faces) per sensor;
    the x axis is the normalised image coordinate (x - cx) / f, the same for every camera."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import textwrap

    fig, axes = plt.subplots(
        len(panels),
        2,
        figsize=(13, 3.6 * len(panels)),
        constrained_layout=True,
        gridspec_kw={"width_ratios": [1, 1.6]},
        squeeze=False,
    )
    # one depth scale for every sensor's map, with its colour bar (a figure audit, 2026-11-30: each row
    # was scaled to itself, so one depth had other colours in other rows, and no bar said which)
    truth = np.concatenate([np.asarray(p[2], np.float64)[np.isfinite(p[2])] for p in panels])
    lo, hi = (np.percentile(truth, (0.5, 99.5)) * 1000) if truth.size else (None, None)
    fits = [("r", ":"), ("m", "--"), ("k", "-.")]  # (each face's fit its own line)
    for (label, cam, gt_depth, depth, faces), (ax0, ax) in zip(panels, axes):
        any_face = np.logical_or.reduce(list(faces.values()))
        rows = np.flatnonzero(any_face.any(axis=1))
        row = int(np.median(rows)) if rows.size else depth.shape[0] // 2
        xn = (np.arange(depth.shape[1]) - cam.cx_px) / cam.focal_px
        shown = ax0.imshow(depth * 1000, cmap="viridis", vmin=lo, vmax=hi)
        fig.colorbar(shown, ax=ax0, shrink=0.85, label="depth (mm)")
        ax0.axhline(row, color="r", lw=0.8)
        ax0.set_title(textwrap.fill(f"{label}: depth; red: the cross-section row", 55), fontsize=9)
        ax0.set_xticks([])
        ax0.set_yticks([])
        ax.plot(xn, gt_depth[row] * 1000, color="0.6", lw=2.5, label="ground truth")
        ax.plot(
            xn, depth[row] * 1000, color="C0", lw=0.8, marker="." if depth.shape[1] < 400 else None, ms=3, label=label
        )
        for (name, face), (colour, dash) in zip(faces.items(), fits * len(faces)):
            xs = np.flatnonzero(face[row] & np.isfinite(depth[row]))
            if xs.size > 2:
                coef = np.polyfit(xs, depth[row, xs] * 1000, 1)
                ax.plot(
                    xn[xs], np.polyval(coef, xs), color=colour, ls=dash, lw=1.5, label=f"least-squares fit ({name})"
                )
        ax.set_xlabel("normalised image x, (x - cx) / f")
        ax.set_ylabel("depth (mm)")
        ax.invert_yaxis()
        ax.legend(loc="best", fontsize=7)
        ax.set_title(f"{label}: row {row}", fontsize=9)
    # one x range for every cross-section (the rows' faces line up)
    spans = [a.get_xlim() for a in axes[:, 1]]
    for a in axes[:, 1]:
        a.set_xlim(min(x for x, _ in spans), max(x for _, x in spans))
    fig.suptitle(title)
    return figure_formats(fig, dpi=80)
