"""Paper Fig. 9: RMSE of a white board at 0.9 ... 1.4 m, repeated measurements.

Each depth is rendered once and recorded ``fig9_repeats`` times: a static board measured
again differs by camera noise only (render noise is a simulation artefact, not a physical
repetition).  Per recording: RMSE against ground truth and the RMS residual to the
least-squares plane of the decoded points (the plane-fit form of the paper's protocol);
the figure shows the mean over recordings with the min-max spread.  The paper prints Fig. 9 as
a chart without numbers; its text states only that the RMSE grows with depth and stays below
the Kinect's and the ToF camera's, so no paper values stand beside ours.  The Kinect and
ToF curves come with the competitor-sensors issue.  Writes ``fig9.png``, ``.pdf``, ``fig9.csv``,
``fig9.md`` and ``fig9.provenance.json``.
"""

from __future__ import annotations

import warnings

import numpy as np

from simbench.report import figure_files, figure_formats
from simbench.experiments.common import (
    RunConfig,
    Session,
    Split,
    calibration_sentence,
    calibration_summary,
    made_by,
    markdown_table,
    other_rig,
    score,
    sensor_caveat,
    table_text,
)
from simbench.literature import CHIABRANDO_TOF, PAPER_COMPETITORS, nguyen_kinect_sigma_mm

__all__ = ["DEPTHS_M", "SPLIT", "run_fig9", "measure_depth", "write_fig9", "fig9_parts", "fig9_plot"]

DEPTHS_M = (0.9, 1.0, 1.1, 1.2, 1.3, 1.4)
SENSORS = ("proposed", "kinect", "tof", "phase_shift")


def sensor_label(name: str) -> str:
    """A system's label for the plot and the text (:meth:`simbench.systems.DepthSystem.info`)."""
    from simbench.systems import get_system

    return get_system(name).info().label


def _scene_name(z: float) -> str:
    return f"plane_depth_{int(round(z * 100)):03d}cm"


def fig9_parts(config: RunConfig) -> list[str]:
    """The depths, as the boards' scene names (``plane_depth_090cm`` ...)."""
    return [_scene_name(z) for z in DEPTHS_M]


def measure_depth(session: Session, name: str) -> dict:
    """One depth: the board placed once, recorded ``fig9_repeats`` times by every sensor and
    scored; its rows and metrics (plain data)."""
    cfg = session.config
    z = DEPTHS_M[fig9_parts(cfg).index(name)]
    rows, metrics = [], {}
    other = other_rig(session)
    # one placement of the board per depth, seen by every sensor
    raw = session.place(session.raw_scene(name), f"fig9/{name}", ["board"])
    placement = session.seeds_used[f"fig9/{name}/placement"]
    scene = session.prepare(raw)
    for k, cap in enumerate(session.capture(scene, f"fig9/{name}", repeats=cfg.fig9_repeats)):
        tri = score(cap, session.decode(cap, cfg.decoder, mode="calibrated"), cfg.decoder.period_px)
        ref = score(cap, session.decode(cap, cfg.decoder, mode="reference"), cfg.decoder.period_px)
        extra = {}
        if other:
            tri_o = score(cap, session.decode(cap, cfg.decoder, mode="calibrated", rig=other), cfg.decoder.period_px)
            ref_o = score(cap, session.decode(cap, cfg.decoder, mode="reference", rig=other), cfg.decoder.period_px)
            extra = {
                "other_rig_rmse_mm": tri_o["gt_rmse_mm"],
                "other_rig_plane_rms_mm": tri_o["plane_rms_mm"],
                "other_rig_ref_rmse_mm": ref_o["gt_rmse_mm"],
            }
        rows.append(
            {
                "sensor": "proposed",
                "depth_m": z,
                "repeat": k,
                "rmse_mm": tri["gt_rmse_mm"],
                "plane_rms_mm": tri["plane_rms_mm"],
                "mae_mm": tri["gt_mae_mm"],
                "bias_mm": tri["bias_mm"],
                "completeness": tri["completeness"],
                "stripe_order_errors": tri["stripe_order_errors"],
                "ref_rmse_mm": ref["gt_rmse_mm"],
                "ref_plane_rms_mm": ref["plane_rms_mm"],
                "ref_stripe_order_errors": ref["stripe_order_errors"],
                **extra,
                **cap.seeds,
                **placement,
            }
        )
    for device in SENSORS[1:]:
        recs = session.acquire(device, raw, f"fig9/{name}", repeats=cfg.fig9_repeats)
        # per-pixel temporal sigma over the recordings (how Chiabrando et al. measure a ToF camera)
        with np.errstate(invalid="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            stack = np.stack([depth.depth_m for _, depth in recs])
            sigma = np.nanstd(stack, axis=0, ddof=1) if len(recs) > 1 else np.full(stack.shape[1:], np.nan)
        lit = recs[0][0].gt.lit
        temporal_mm = float(np.nanmean(sigma[lit])) * 1000 if np.isfinite(sigma[lit]).any() else float("nan")
        info = session.system(device).info()
        for k, (rec, depth) in enumerate(recs):
            sc = score(rec, depth, info.period_px)
            extra = {}
            if info.uses_scene_rig and other:
                so = score(rec, session.decode_recording(device, rec, rig=other), info.period_px)
                extra = {"other_rig_rmse_mm": so["gt_rmse_mm"], "other_rig_plane_rms_mm": so["plane_rms_mm"]}
            rows.append(
                {
                    "sensor": device,
                    "depth_m": z,
                    "repeat": k,
                    "rmse_mm": sc["gt_rmse_mm"],
                    "plane_rms_mm": sc["plane_rms_mm"],
                    "mae_mm": sc["gt_mae_mm"],
                    "bias_mm": sc["bias_mm"],
                    "completeness": sc["completeness"],
                    "stripe_order_errors": sc.get("stripe_order_errors", ""),
                    "temporal_sigma_mm": temporal_mm,
                    **extra,
                    **rec.seeds,
                }
            )
    for sensor in SENSORS:
        sel = [r for r in rows if r["depth_m"] == z and r["sensor"] == sensor]
        prefix = f"fig9/{z:.1f}m" if sensor == "proposed" else f"fig9/{sensor}/{z:.1f}m"
        keys = ("rmse_mm", "plane_rms_mm", "completeness") + (
            ("stripe_order_errors", "ref_rmse_mm", "ref_plane_rms_mm")
            if sensor == "proposed"
            else ("temporal_sigma_mm",)
        )
        keys += tuple(k for k in ("other_rig_rmse_mm", "other_rig_ref_rmse_mm") if k in sel[0])
        for key in keys:
            metrics[f"{prefix}/{key}"] = (
                float(np.mean([r[key] for r in sel])) if key != "stripe_order_errors" else int(max(r[key] for r in sel))
            )
    return {"rows": rows, "metrics": metrics}


def write_fig9(session: Session, measured: list[dict]) -> dict:
    """The figure's files from :func:`measure_depth`'s results (in :func:`fig9_parts`' order)."""
    cfg = session.config
    rows = [r for m in measured for r in m["rows"]]
    metrics = {k: v for m in measured for k, v in m["metrics"].items()}
    cols = [
        "sensor",
        "depth_m",
        "repeat",
        "rmse_mm",
        "plane_rms_mm",
        "mae_mm",
        "bias_mm",
        "completeness",
        "stripe_order_errors",
        "ref_rmse_mm",
        "ref_plane_rms_mm",
        "ref_stripe_order_errors",
        "temporal_sigma_mm",
        "other_rig_rmse_mm",
        "other_rig_plane_rms_mm",
        "other_rig_ref_rmse_mm",
        "render",
        "noise",
        "placement",
        "board_depth_m",
        "board_tilt_deg",
    ]
    files = {
        "fig9.csv": table_text(rows, cols),
        **figure_files(
            "fig9",
            fig9_plot(
                rows,
                title=f"Fig. 9: RMSE of a white board against depth ({cfg.fig9_repeats} recordings per depth)"
                + cfg.figure_note(),
                other_rig_name=other_rig(session),
            ),
        ),
        "fig9.md": _markdown(session, rows),
    }
    other = other_rig(session)
    scene = session.scene(fig9_parts(cfg)[-1])  # the rig every depth shares
    session.write_results("fig9", files, extra={"calibration": calibration_summary(session, scene)} if other else None)
    return metrics


# each depth a part (the run's workers take them side by side)
SPLIT = Split("fig9", fig9_parts, measure_depth, write_fig9)


def run_fig9(session: Session) -> dict:
    """Every depth of :func:`fig9_parts` measured, then the files written (:class:`Split`)."""
    return SPLIT.run(session)


def _summary(
    rows: list[dict], key: str, sensor: str = "proposed"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rows = [r for r in rows if r.get("sensor", "proposed") == sensor]
    zs = np.array(sorted({r["depth_m"] for r in rows}))
    vals = [np.array([r[key] for r in rows if r["depth_m"] == z]) for z in zs]
    return zs, np.array([v.mean() for v in vals]), np.array([v.min() for v in vals]), np.array([v.max() for v in vals])


def _has_other_rig(rows: list[dict], sensor: str) -> bool:
    """Whether every row of ``sensor`` carries its other-rig RMSE (rows of a run that compared rigs)."""
    own = [r for r in rows if r.get("sensor", "proposed") == sensor]
    return bool(own) and all(isinstance(r.get("other_rig_rmse_mm"), float) for r in own)


def _errorbar(axis, rows: list[dict], key: str, sensor: str, **style) -> None:
    """Mean of ``key`` per depth with min-max bars."""
    zs, mean, lo, hi = _summary(rows, key, sensor)
    axis.errorbar(zs, mean, yerr=[mean - lo, hi - mean], capsize=3, **style)


def fig9_plot(rows: list[dict], *, title: str, other_rig_name: str | None = "calibrated") -> dict[str, bytes]:
    """PNG and PDF (:func:`simbench.report.figure_formats`):
    mean RMSE per depth with min-max bars (from the rows of ``fig9.csv``); dashed: the
    same recordings decoded with the other rig (``other_rig_name``, the calibrated one in a run
    on the true rig)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 5.4), constrained_layout=True)
    # each system its own colour and marker (not colour alone); dashed lines are the other rig's only
    # (a figure audit, 2026-11-30: the plane residual was dashed too, and drawn under the RMSE it equals)
    markers = dict(zip(SENSORS, "osD^"))
    for axis, sensors in ((ax, SENSORS), (ax2, ("proposed",))):
        for i, sensor in enumerate(sensors):
            if not any(r.get("sensor", "proposed") == sensor for r in rows):
                continue
            label = f"{sensor_label(sensor)}: RMSE vs ground truth"
            color = f"C{SENSORS.index(sensor)}"
            _errorbar(axis, rows, "rmse_mm", sensor, fmt=f"{markers[sensor]}-", color=color, label=label)
            if _has_other_rig(rows, sensor):
                label = f"{sensor_label(sensor)}: with the {other_rig_name} rig"
                _errorbar(axis, rows, "other_rig_rmse_mm", sensor, fmt="x--", color=color, alpha=0.7, label=label)
            if sensor == "proposed":
                label = "proposed: RMS residual to fitted plane (open squares)"
                _errorbar(
                    axis, rows, "plane_rms_mm", sensor, fmt="s", ms=9, mfc="none", mew=1.2, color="C0", label=label
                )
                if axis is ax2 and all("ref_rmse_mm" in r for r in rows if r.get("sensor", "proposed") == "proposed"):
                    # (black: C3 is phase shifting's colour in the left panel)
                    label = "proposed, reference-plane protocol: RMSE vs ground truth"
                    _errorbar(axis, rows, "ref_rmse_mm", sensor, fmt="^:", color="k", alpha=0.8, label=label)
    zz = np.linspace(min(DEPTHS_M), max(DEPTHS_M), 50)
    if any(r.get("sensor") == "kinect" for r in rows):
        label = "real Kinect v1, Nguyen et al. 2012 model: sigma_z"
        ax.plot(zz, nguyen_kinect_sigma_mm(zz), ":", color="C1", label=label)
    if any(r.get("sensor") == "tof" for r in rows):
        label = "real SR4000, Chiabrando et al. 2009: temporal sigma"
        ax.plot(*CHIABRANDO_TOF, "*", ms=12, color="C2", label=label)
    for axis in (ax, ax2):
        axis.set_xlabel("board depth (m)")
        axis.set_ylabel("RMSE (mm); real devices: sigma (mm)" if axis is ax else "RMSE (mm)")
        axis.set_ylim(bottom=0)
        axis.grid(alpha=0.3)
    # below the axes: inside, the full panel's nine entries covered the ToF and Kinect curves at 1.1-1.3 m
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False, handlelength=1.4)
    ax2.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=1, frameon=False)
    ax2.set_title("proposed method alone (zoomed)", fontsize=9)
    fig.suptitle(f"{title} (bars: min to max over the repetitions)", fontsize=10)
    return figure_formats(fig, dpi=110)


def _markdown(session: Session, rows: list[dict]) -> str:
    cfg = session.config
    cam = session.scene("plane_depth_100cm").rig.camera
    lines = [
        "# Fig. 9: RMSE against depth",
        "",
        made_by(session, cam)
        + f"base seed {cfg.seed}, {cfg.fig9_repeats} recordings per depth, variant `{session.variant}`). Plot: "
        f"`fig9.png`; "
        "every recording with its seeds: `fig9.csv`.",
        "",
        "The paper gives Fig. 9 as a chart only, without numbers: what its text says is below the table. Fig. 9 is "
        "measured on the paper's rig (Sec. 6). Each board is placed with a seeded error within "
        f"+-{cfg.placement_depth_mm:g} mm and +-{cfg.placement_tilt_deg:g} deg "
        "(`simbench.sim.scene.Placement`), the same "
        "placement for every sensor. The proposed method is decoded by triangulation with the rig (Eq. 15; RMSE "
        "against "
        "ground truth, and RMS residual to the fitted plane); the reference-plane protocol (Sec. 5.4, reference at 1.0 "
        "m) "
        "is the extra column.",
        "",
    ]
    zs, mean, lo, hi = _summary(rows, "rmse_mm")
    _, pmean, _, _ = _summary(rows, "plane_rms_mm")
    _, comp, _, _ = _summary(rows, "completeness")
    _, rmean, _, _ = _summary(rows, "ref_rmse_mm")
    comp_rows = {d: _summary(rows, "rmse_mm", d) for d in SENSORS[1:] if any(r.get("sensor") == d for r in rows)}
    has_other = {d: _has_other_rig(rows, d) for d in SENSORS}
    om = _summary(rows, "other_rig_rmse_mm")[1] if has_other.get("proposed") else None
    orf = _summary(rows, "other_rig_ref_rmse_mm")[1] if has_other.get("proposed") else None
    other = {d: _summary(rows, "other_rig_rmse_mm", d) for d in SENSORS[1:] if has_other.get(d)}
    rig_name = other_rig(session)
    body = []
    for i, (z, m, a, b, p, c, rm) in enumerate(zip(zs, mean, lo, hi, pmean, comp, rmean)):
        row = [f"{z:.1f}", f"{m:.3f}", f"{a:.3f} - {b:.3f}", f"{p:.3f}", f"{rm:.3f}", f"{100 * c:.2f} %"]
        k = comp_rows.get("kinect")
        row.append(f"{k[1][i]:.2f}" if k is not None else "-")
        row.append(f"{float(nguyen_kinect_sigma_mm(z)):.2f}")
        row.append(f"{k[1][i] / float(nguyen_kinect_sigma_mm(z)):.2f}" if k is not None else "-")
        t = comp_rows.get("tof")
        row.append(f"{t[1][i]:.2f}" if t is not None else "-")
        tz = [r["temporal_sigma_mm"] for r in rows if r.get("sensor") == "tof" and r["depth_m"] == z]
        row.append(f"{tz[0]:.2f}" if tz else "-")
        row.append(f"{CHIABRANDO_TOF[1]:.1f}" if abs(z - CHIABRANDO_TOF[0]) < 1e-9 else "-")
        ps = comp_rows.get("phase_shift")
        row.append(f"{ps[1][i]:.3f}" if ps is not None else "-")
        if rig_name:
            row.append(f"{om[i]:.3f}" if om is not None else "-")
            row.append(f"{orf[i]:.3f}" if orf is not None else "-")
            ops = other.get("phase_shift")
            row.append(f"{ops[1][i]:.3f}" if ops is not None else "-")
        body.append(row)
    lines += markdown_table(
        [
            "depth (m)",
            "proposed RMSE (mm), triangulation, mean",
            "min - max",
            "plane-fit RMS (mm)",
            "reference-plane protocol RMSE (mm)",
            "completeness",
            "Kinect sim RMSE (mm)",
            "real Kinect sigma_z (Nguyen 2012)",
            "ratio (sim RMSE / real sigma_z)",
            "ToF sim RMSE (mm)",
            "ToF sim per-pixel temporal sigma (mm)",
            "real SR4000 sigma (Chiabrando 2009)",
            "phase shifting RMSE (mm)",
        ]
        + (
            [
                f"proposed, {rig_name} rig: RMSE (mm)",
                f"proposed, {rig_name} rig, reference protocol (mm)",
                f"phase shifting, {rig_name} rig (mm)",
            ]
            if rig_name
            else []
        ),
        body,
    )
    lines += [
        "",
        "The paper's text: the proposed method's RMSE grows with depth and stays below the Kinect's and the ToF "
        "camera's. "
        "Real-device columns are published measurements, not the paper's: the Kinect's axial-noise model "
        "sigma_z = 1.2 mm + 1.9 mm (z - 0.4)^2 (Nguyen, Izadi & Lovell 2012) and the SR4000's per-pixel sigma on a "
        "white wall "
        "at 1.3 m (Chiabrando et al. 2009). The Kinect's ratio sets our RMSE against ground truth, bias included, "
        "beside the real device's axial noise, a standard deviation without its bias: not one quantity, so a ratio "
        "above 1 may be bias alone. The ToF check of the competitor issue (temporal per-pixel sigma at 1.3 m) "
        "is "
        "in `tests/test_baselines.py`.",
    ]
    if rig_name:
        lines += [
            "",
            f"Every depth-system column above decodes with the {session.config.rig} rig; the last three decode the "
            f"same recordings with the {rig_name} one (dashed in the plot). "
            + calibration_sentence(session, session.scene("plane_depth_100cm")),
        ]
    trend = "grows" if np.all(np.diff(mean) > 0) else "does not grow monotonically"
    lines += ["", f"Our RMSE {trend} with depth over 0.9-1.4 m."]
    for d, (_, cm, _, _) in comp_rows.items():
        below = np.all(mean < cm)
        if d not in PAPER_COMPETITORS:
            n = session.system(d).info().captures
            lines.append(
                f"The multi-shot reference ({sensor_label(d)}, {n} exposures per depth map) has "
                f"RMSE {cm.min():.3f}-{cm.max():.3f} mm, {'above' if below else 'below'} the proposed method's at "
                f"{'every' if below or np.all(mean > cm) else 'some'} depth."
            )
            continue
        lines.append(
            f"Proposed RMSE {'below' if below else 'NOT below'} the {sensor_label(d)}'s at "
            f"{'every' if below else 'some'} depth"
            + (" (as the paper states)." if below else " (the paper states it is below).")
        )
    lines += sensor_caveat(cfg)
    return "\n".join(lines) + "\n"
