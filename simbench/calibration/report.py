"""What ``simbench calibrate`` writes: the estimated rig (``rig.toml``, the format every
``--rig`` option reads), ``calibration.json`` (settings, seeds, poses, reprojection RMS, the
per-parameter error against the true rig), ``report.md`` and ``calibration.png``/``.pdf`` (the
poses and the residuals).
"""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np

from simbench.calibration.procedure import CalibrationResult, rig_errors
from simbench.calibration.target import CalibrationTarget
from simbench.rig import Rig

__all__ = ["write_calibration", "calibration_figure", "calibration_markdown", "PUBLISHED_RMS_PX"]

# Reprojection RMS that published projector-camera calibrations report (pixels): the band a
# simulated calibration through a realistic sensor model should land in.  Assumption from the
# literature as we know it, not yet checked against the papers' tables (the stored copies we
# could search hold no numbers): plane-based camera calibrations with sub-pixel corners reach
# about 0.05-0.3 px (Zhang 2000 reports 0.3 px with a 1990s camera), projector calibrations
# by local homographies about 0.1-0.5 px (Moreno and Taubin 2012).
PUBLISHED_RMS_PX = (0.05, 0.5)

_MODEL_TERMS = {"radial": "k1, k2", "radial_tangential": "k1, k2, p1, p2, the Bouguet toolbox's default"}

_PARAMETERS = (
    ("camera focal (px)", lambda r: r.camera.focal_px, "camera_focal_pct", "{:+.3f} %"),
    ("camera cx (px)", lambda r: r.camera.cx_px, "camera_cx_px", "{:+.3f} px"),
    ("camera cy (px)", lambda r: r.camera.cy_px, "camera_cy_px", "{:+.3f} px"),
    ("camera k1", lambda r: r.camera.distortion[0], "camera_k1", "{:+.4f}"),
    ("camera k2", lambda r: r.camera.distortion[1], "camera_k2", "{:+.4f}"),
    ("camera p1", lambda r: r.camera.distortion[2], "camera_p1", "{:+.5f}"),
    ("camera p2", lambda r: r.camera.distortion[3], "camera_p2", "{:+.5f}"),
    ("projector focal (px)", lambda r: r.projector.focal_px, "projector_focal_pct", "{:+.3f} %"),
    ("projector cx (px)", lambda r: r.projector.cx_px, "projector_cx_px", "{:+.3f} px"),
    ("projector cy (px)", lambda r: r.projector.cy_px, "projector_cy_px", "{:+.3f} px"),
    ("projector k1", lambda r: r.projector.distortion[0], "projector_k1", "{:+.4f}"),
    ("projector k2", lambda r: r.projector.distortion[1], "projector_k2", "{:+.4f}"),
    ("projector p1", lambda r: r.projector.distortion[2], "projector_p1", "{:+.5f}"),
    ("projector p2", lambda r: r.projector.distortion[3], "projector_p2", "{:+.5f}"),
    ("baseline (mm)", lambda r: 1000.0 * r.baseline_m, "baseline_mm", "{:+.3f} mm"),
    ("projector position (mm)", None, "position_mm", "{:.3f} mm"),
    ("projector rotation (deg)", None, "rotation_deg", "{:.4f} deg"),
)


def calibration_figure(result: CalibrationResult, *, target: CalibrationTarget, truth: Rig) -> dict[str, bytes]:
    """PNG and PDF (:func:`simbench.report.figure_formats`):
    (a) the corners of every view in the camera image, (b) the poses seen from above
    with the camera and projector, (c) the stereo residuals of camera and projector."""
    from simbench.report import figure_formats, panel_row

    plt, fig, ax = panel_row(3, width=4.4)
    cam = truth.camera
    colours = plt.get_cmap("tab20")(np.linspace(0, 1, max(len(result.views), 2)))
    for k, v in enumerate(result.views):
        if v.camera_px is not None:
            ax[0].plot(v.camera_px[:, 0], v.camera_px[:, 1], ".", ms=2, color=colours[k], label=f"{k}")
    ax[0].set_xlim(-0.5, cam.width_px - 0.5)
    ax[0].set_ylim(cam.height_px - 0.5, -0.5)
    ax[0].set_aspect("equal")
    ax[0].set_xlabel("camera image x (px)")
    ax[0].set_ylabel("camera image y (px)")
    ax[0].set_title("(a) corners found, a colour per pose")
    sx, sy = target.size_m
    outline = np.array([[-sx / 2, 0, 0], [sx / 2, 0, 0]])
    for k, v in enumerate(result.views):
        ends = outline @ v.pose.rotation.T + np.asarray(v.pose.center_m)
        style = "-" if v.camera_px is not None else ":"
        ax[1].plot(ends[:, 0], ends[:, 2], style, color=colours[k], lw=2)
        # the number beyond the target's right end (at its centre, near poses' numbers overlapped:
        # a figure audit, 2026-11-30)
        ax[1].annotate(str(k), (ends[1, 0], ends[1, 2]), xytext=(3, 0), textcoords="offset points", fontsize=7)
    ax[1].plot([0], [0], "ks", label="camera")
    ax[1].plot([truth.position_m[0]], [truth.position_m[2]], "r^", label="projector")
    ax[1].set_xlabel("x (m)")
    ax[1].set_ylabel("z (m)")
    ax[1].set_title("(b) target poses from above (dotted: not found)")
    ax[1].legend(fontsize=7, loc="lower right")
    for name, marker in (("camera", "."), ("projector", "x")):
        r = result.residuals_px[name]
        ax[2].plot(r[:, 0], r[:, 1], marker, ms=3, alpha=0.5, label=f"{name} ({_rms(r):.3f} px RMS)")
    lim = max(0.05, float(np.max(np.abs(np.concatenate(list(result.residuals_px.values()))))) * 1.1)
    ax[2].set_xlim(-lim, lim)
    ax[2].set_ylim(lim, -lim)
    ax[2].set_aspect("equal")
    ax[2].axhline(0, color="0.7", lw=0.5)
    ax[2].axvline(0, color="0.7", lw=0.5)
    ax[2].set_xlabel("residual x (px)")
    ax[2].set_ylabel("residual y (px)")
    ax[2].set_title("(c) reprojection residuals")
    ax[2].legend(fontsize=7)
    return figure_formats(fig, dpi=110)


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(np.asarray(r) ** 2, axis=1)))) if len(r) else math.nan


def calibration_markdown(
    result: CalibrationResult, *, target: CalibrationTarget, truth: Rig, settings: dict, command: str
) -> str:
    """The report: procedure, settings, reprojection RMS, per-parameter error, per-view table."""
    from simbench.report import markdown_table

    err = rig_errors(result.rig, truth)
    lo, hi = PUBLISHED_RMS_PX
    rms = result.rms_px
    inside = all(lo <= rms[k] <= hi for k in ("camera", "projector"))
    lines = [
        "# Calibration of the rig",
        "",
        f"Made by `{command}`; sensor model `{settings['sensor']}`, target `{target.name}` "
        f"({target.squares[0]} x {target.squares[1]} squares of {1000 * target.square_m:g} mm, bow "
        f"{1000 * target.bow_m_per_m:g} mm/m, waviness {1000 * target.waviness_m:g} mm), {settings['poses']} poses, "
        f"seed {settings['seed']}, {settings['spp']} spp {settings['sampler']} for the sequences and "
        f"{settings['corner_spp']} for the white frames.",
        "",
        "Procedure (simbench.calibration): at every pose the projector shows a white frame, then 4-step phase "
        "shifting + complementary Gray code in columns and in rows; the camera records each through the sensor model. "
        "Corners: `cv2.findChessboardCornersSB` + `cv2.cornerSubPix`; camera: `cv2.calibrateCamera` (Zhang 2000); "
        "projector as an inverse camera (Zhang and Huang 2006) with each corner's projector coordinates from a local "
        "homography of the decoded pixels around it (Moreno and Taubin 2012); then `cv2.stereoCalibrate`. Model: one "
        f"focal length, principal point and the `{settings['distortion']}` distortion terms "
        f"({_MODEL_TERMS.get(settings['distortion'], '?')}; k3 = 0).",
        "",
        "## Reprojection RMS",
        "",
        *markdown_table(
            ["solve", "RMS (px)"],
            [[k, f"{v:.4f}"] for k, v in rms.items()],
        ),
        "",
        f"Published projector-camera calibrations report about {lo}-{hi} px (simbench.calibration.report."
        f"PUBLISHED_RMS_PX says where from): camera and projector here are {'inside' if inside else 'OUTSIDE'} that "
        f"range. A simulated lab has no printing error, no board flex (unless the target file gives it) and the lens "
        f"model it fits, so it sits at the band's low end.",
        "",
        "## Estimated rig against the true rig",
        "",
        "The true rig is the one the renders realise (the preset with the sensor model's lens distortion); the error "
        "is estimated minus true.",
        "",
    ]
    rows = []
    for label, get, key, fmt in _PARAMETERS:
        true = "" if get is None else f"{get(truth):.6g}"
        est = "" if get is None else f"{get(result.rig):.6g}"
        rows.append([label, true, est, fmt.format(err[key])])
    lines += markdown_table(["parameter", "true", "estimated", "error"], rows)
    lines += ["", "## Views", ""]
    vrows = []
    for k, v in enumerate(result.views):
        c, p = result.view_rms_px["camera"][k], result.view_rms_px["projector"][k]
        vrows.append(
            [
                str(k),
                f"{v.pose.center_m[2]:.3f}",
                f"{v.pose.tilt_deg:.1f}",
                "yes" if v.camera_px is not None else "no",
                "" if v.projector_px is None else str(int(np.all(np.isfinite(v.projector_px), axis=1).sum())),
                "" if math.isnan(c) else f"{c:.4f}",
                "" if math.isnan(p) else f"{p:.4f}",
            ]
        )
    lines += markdown_table(
        ["pose", "depth (m)", "tilt (deg)", "found", "projector corners", "camera RMS (px)", "projector RMS (px)"],
        vrows,
    )
    lines += ["", "![poses and residuals](calibration.png)", ""]
    return "\n".join(lines)


def _finite_or_none(x: float) -> float | None:
    return None if math.isnan(x) else float(x)


def write_calibration(
    out_dir: str | Path,
    result: CalibrationResult,
    *,
    target: CalibrationTarget,
    truth: Rig,
    settings: dict,
    command: str,
    overwrite: bool = False,
) -> dict[str, Path]:
    """Write the folder (module docstring) whole or not at all; returns {key: path}."""
    from simbench.io import json_bytes, output_directory, write_files
    from simbench.rig import rig_to_dict, rig_toml

    files = {
        "rig": "rig.toml",
        "report": "report.md",
        "figure": "calibration.png",
        "figure_pdf": "calibration.pdf",
        "manifest": "calibration.json",
    }
    manifest = {
        "files": {k: v for k, v in files.items() if k != "manifest"},
        "command": command,
        "settings": settings,
        "target": target.to_dict(),
        "rms_px": result.rms_px,
        "errors": rig_errors(result.rig, truth),
        "true_rig": rig_to_dict(truth),
        "rig": rig_to_dict(result.rig),
        "views": [
            {
                "center_m": list(v.pose.center_m),
                "rotation_deg": list(v.pose.rotation_deg),
                "found": v.camera_px is not None,
                "camera_rms_px": _finite_or_none(result.view_rms_px["camera"][k]),
                "projector_rms_px": _finite_or_none(result.view_rms_px["projector"][k]),
            }
            for k, v in enumerate(result.views)
        ],
        "used_views": list(result.used_views),
    }
    contents = {
        "rig": rig_toml(result.rig).encode(),
        "report": calibration_markdown(result, target=target, truth=truth, settings=settings, command=command).encode(),
    }
    figure = calibration_figure(result, target=target, truth=truth)
    contents["figure"], contents["figure_pdf"] = figure["png"], figure["pdf"]
    # each file's SHA-256: a rerun into the folder replaces it only while no file was changed since
    # (an edited rig.toml is the user's: --overwrite to replace it)
    manifest["sha256"] = {k: hashlib.sha256(data).hexdigest() for k, data in contents.items()}
    contents["manifest"] = json_bytes(manifest)
    out = Path(out_dir)
    with output_directory(out, manifest=files["manifest"], overwrite=overwrite) as tmp:
        write_files({tmp / files[k]: data for k, data in contents.items()})
    return {k: out / name for k, name in files.items()}
