"""The paper's qualitative figures: Fig. 6 (decoder stages), Fig. 11-13 (depth maps and point
clouds of plaster geometries, a bust and two cluttered colour scenes); and, not in the paper,
specular highlights seen by every system (``scenes/specular.toml``: a brushed aluminium sphere,
a glossy painted box and a polished chrome tile before a matte wall).

Writes into ``figures/``: ``fig6_stages.png``; per scene ``<fig>_<scene>.png`` (capture,
decoded depth, error against ground truth, shaded 3-D view) and ``<fig>_<scene>.ply`` (the
decoded point cloud with the capture's colours, every ``ply_stride``-th pixel per axis to keep
the repository small; ``simbench decode --ply`` writes full clouds); ``summary.md``/``.csv``
with each scene's scores; ``specular_systems.png`` (what each system recorded, its depth and
its error) with ``specular.md``/``.csv`` (per system and object: completeness, MAE and the share
of decoded pixels more than 5 mm wrong); ``figures.provenance.json``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from simbench.experiments.common import RunConfig, Session, Split, made_by, scene_errors
from simbench.experiments.hard_scenes import WRONG_MM, object_scores
from simbench.metrics import edge_band
from simbench.report import figure_png, markdown_table, panel_row, table_text
from simbench.io import ply_bytes
from simbench.metrics import points_from_depth

if TYPE_CHECKING:
    from simbench.decode.pipeline import DecodeResult
    from simbench.experiments.common import Capture
    from simbench.rig import Intrinsics

__all__ = [
    "FIGURE_SCENES",
    "FIG6_SCENE",
    "SPECULAR_SCENE",
    "SPECULAR_SYSTEMS",
    "SPLIT",
    "run_figures",
    "figures_parts",
    "measure_figure",
    "write_figures",
    "measure_specular",
    "specular_parts",
    "specular_files",
    "shown_raw",
    "shaded_view",
    "stages_figure",
]

# scene -> paper figure
FIGURE_SCENES = {"geometries": "fig11", "bust": "fig12", "clutter_pink_cyan": "fig13a", "clutter_pear_hat": "fig13b"}
FIG6_SCENE = "geometries"

# specular highlights seen by every system: the proposed sensor with the paper's and the
# colour-robust decoder (at its operating point), then the registered systems
SPECULAR_SCENE = "specular"
SPECULAR_SYSTEMS = ("proposed/paper", "proposed/robust", "phase_shift", "kinect", "tof")
SPECULAR_KEYS = ("completeness", "gt_mae_mm", "wrong_share")

# the scores of each figure's scene (simbench.metrics.depth_errors keys), in summary.csv
SUMMARY_KEYS = (
    "mae_mm",
    "rmse_mm",
    "p95_mm",
    "completeness",
    "outlier_share",
    "stripe_order_errors",
    "stripe_order_error_rate",
)


def shaded_view(depth_m: np.ndarray, camera: Intrinsics) -> np.ndarray:
    """A grey 3-D rendering of a depth map: Lambertian shading of the surface normals
    (from the point cloud's image-space derivatives) under a light at the camera.

    Returns
    -------
    ndarray, shape (H, W), float32 in [0, 1]; NaN where the depth is NaN
    """
    p = points_from_depth(depth_m, camera)
    dx = np.gradient(p, axis=1)
    dy = np.gradient(p, axis=0)
    n = np.cross(dx, dy)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    view = -p / np.linalg.norm(p, axis=-1, keepdims=True)
    return np.abs(np.sum(n * view, axis=-1)).astype(np.float32)


def _depth_range(depth_m: np.ndarray) -> tuple[float, float]:
    finite = depth_m[np.isfinite(depth_m)]
    return tuple(np.percentile(finite, [1, 99])) if finite.size else (0.0, 1.0)


def stages_figure(cap: Capture, result: DecodeResult, *, title: str) -> bytes:
    """Paper Fig. 6: capture, intensity, wrapped phase, De Bruijn stripes, unwrapped phase,
    depth, 3-D view."""
    st = result.stages
    plt, fig, axes = panel_row(7, width=3.4)
    stripes = st["stripe_code"].astype(np.float32)
    stripes[stripes < 0] = np.nan
    panels = [
        ("(a) capture", cap.image, {}),
        ("(b) intensity (Eq. 9)", st["intensity"], {"cmap": "gray"}),
        ("(c) wrapped phase", st["wrapped_phase"], {"cmap": "twilight"}),
        ("(d) De Bruijn stripes", stripes, {"cmap": "coolwarm"}),
        ("(e) unwrapped phase", st["unwrapped_phase"], {"cmap": "viridis"}),
        (
            "(f) depth",
            result.depth_m,
            {"cmap": "viridis", "vmin": _depth_range(result.depth_m)[0], "vmax": _depth_range(result.depth_m)[1]},
        ),
        ("(g) 3-D view", shaded_view(result.depth_m, cap.scene.rig.camera), {"cmap": "gray", "vmin": 0, "vmax": 1}),
    ]
    for ax, (name, img, kw) in zip(axes, panels):
        ax.imshow(img, **kw)
        ax.set_title(name, fontsize=9)
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title, fontsize=10)
    return figure_png(fig, dpi=90)


def scene_figure(cap: Capture, result: DecodeResult, *, title: str) -> bytes:
    plt, fig, axes = panel_row(4)
    lo, hi = _depth_range(result.depth_m)
    err = (result.depth_m - cap.gt.depth_m) * 1000.0
    axes[0].imshow(cap.image)
    axes[0].set_title("capture")
    im = axes[1].imshow(result.depth_m, cmap="viridis", vmin=lo, vmax=hi)
    axes[1].set_title("decoded depth (m); white = invalid")
    fig.colorbar(im, ax=axes[1], shrink=0.7)
    im = axes[2].imshow(err, cmap="coolwarm", vmin=-2, vmax=2)
    axes[2].set_title("depth - ground truth (mm)")
    fig.colorbar(im, ax=axes[2], shrink=0.7)
    axes[3].imshow(shaded_view(result.depth_m, cap.scene.rig.camera), cmap="gray", vmin=0, vmax=1)
    axes[3].set_title("3-D view (shaded decoded surface)")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    return figure_png(fig, dpi=80)


def figures_parts(config: RunConfig) -> list[str]:
    """The scenes: the paper's figures' (:data:`FIGURE_SCENES`), then the specular one, a part
    per system that records it (:func:`specular_parts`)."""
    return [*FIGURE_SCENES, *specular_parts()]


def specular_parts() -> list[str]:
    """``specular/<system>`` for each system of :data:`SPECULAR_SYSTEMS` (the proposed sensor's
    two decoders in one part: they decode the same recording)."""
    return [f"{SPECULAR_SCENE}/{s}" for s in dict.fromkeys(name.partition("/")[0] for name in SPECULAR_SYSTEMS)]


def figures_cost(part: str) -> float:
    """A part's rank for a pool: phase shifting records 12 exposures, a scene one."""
    return 12.0 if part == f"{SPECULAR_SCENE}/phase_shift" else 1.0


def measure_figure(session: Session, name: str) -> dict:
    """One part: a system on the specular scene by :func:`measure_specular`; a figure's scene
    recorded, decoded and scored - its row, metrics and figure files ({name under ``figures/``:
    bytes})."""
    head, _, system = name.partition("/")
    if head == SPECULAR_SCENE:
        return measure_specular(session, system)
    cfg = session.config
    fig_id = FIGURE_SCENES[name]
    scene = session.scene(name)
    cap = session.capture(scene, f"figures/{name}")[0]
    result = session.decode(cap, cfg.decoder)
    m = scene_errors(cap, result, period_px=cfg.decoder.period_px, edge_band_px=cfg.edge_band_px)
    row = {"scene": name, "figure": fig_id, **{k: m[k] for k in SUMMARY_KEYS}, **cap.seeds}
    metrics = {f"figures/{name}/{k}": m[k] for k in ("mae_mm", "completeness", "stripe_order_error_rate")}
    title = (
        f"paper {fig_id.replace('fig', 'Fig. ')}: {name} - "
        f"MAE {m['mae_mm']:.3f} mm, completeness {100 * m['completeness']:.2f} % (the paper's decoder)"
        f"{cfg.figure_note()}"
    )
    s = cfg.ply_stride
    pts = points_from_depth(result.depth_m, scene.rig.camera)[::s, ::s]
    ok = np.isfinite(pts[..., 2])
    files = {
        f"{fig_id}_{name}.png": scene_figure(cap, result, title=title),
        f"{fig_id}_{name}.ply": ply_bytes(pts[ok], cap.image[::s, ::s][ok]),
    }
    if name == FIG6_SCENE:
        files["fig6_stages.png"] = stages_figure(
            cap, result, title=f"paper Fig. 6: the decoder's stages on {name}{cfg.figure_note()}"
        )
    return {"row": row, "metrics": metrics, "files": files}


def write_figures(session: Session, measured: list[dict]) -> dict:
    """The figures' files from :func:`measure_figure`'s results (in :func:`figures_parts`' order)."""
    cfg = session.config
    scenes, specular = measured[: len(FIGURE_SCENES)], measured[len(FIGURE_SCENES) :]
    files = {f"figures/{rel}": data for m in scenes for rel, data in m["files"].items()}
    rows = [m["row"] for m in scenes]
    metrics = {k: v for m in measured for k, v in m["metrics"].items()}
    cols = ["scene", "figure", *SUMMARY_KEYS, "render", "noise"]
    files["figures/summary.csv"] = table_text(rows, cols)
    cam = session.scene(FIG6_SCENE).rig.camera
    md = [
        "# Qualitative figures (paper Fig. 6, 11, 12, 13)",
        "",
        made_by(session, cam)
        + f"base seed {cfg.seed}, variant `{session.variant}`). Errors exclude a {cfg.edge_band_px}-px band at depth "
        f"edges; "
        f"completeness is over the seen and lit pixels. Point clouds keep every {cfg.ply_stride}-th pixel per axis.",
        "",
    ]
    md += markdown_table(
        [
            "figure",
            "scene",
            "MAE (mm)",
            "RMSE (mm)",
            "p95 (mm)",
            "completeness",
            "outliers > 5 mm",
            "stripe-order errors",
        ],
        [
            [
                r["figure"],
                r["scene"],
                f"{r['mae_mm']:.3f}",
                f"{r['rmse_mm']:.3f}",
                f"{r['p95_mm']:.3f}",
                f"{100 * r['completeness']:.2f} %",
                f"{100 * r['outlier_share']:.3f} %",
                f"{r['stripe_order_errors']} ({100 * r['stripe_order_error_rate']:.3f} %)",
            ]
            for r in rows
        ],
    )
    files["figures/summary.md"] = "\n".join(md) + "\n"
    files.update(specular_files(session, specular))
    session.write_results("figures/figures", files)
    return metrics


# each scene a part, the specular scene's a part per system (the run's workers take them side
# by side: each system records the scene on its own, phase shifting's 12 exposures the longest)
SPLIT = Split("figures", figures_parts, measure_figure, write_figures, cost=figures_cost)


def run_figures(session: Session) -> dict:
    """Every scene of :func:`figures_parts` measured, then the files written (:class:`Split`)."""
    return SPLIT.run(session)


def _specular_recordings(session: Session, system: str) -> dict:
    """Label of :data:`SPECULAR_SYSTEMS` -> (recording, depth map, what it recorded as an image)
    on the specular scene, for the labels of ``system`` (``proposed``: both decoders)."""
    names = [n for n in SPECULAR_SYSTEMS if n.partition("/")[0] == system]
    if not names:
        known = sorted(dict.fromkeys(n.partition("/")[0] for n in SPECULAR_SYSTEMS))
        raise ValueError(f"no specular system {system!r}; valid: {', '.join(known)}")
    cfg = session.config
    label = f"figures/{SPECULAR_SCENE}"
    raw = session.raw_scene(SPECULAR_SCENE)
    out = {}
    if system == "proposed":
        cap = session.capture(session.prepare(raw), label)[0]
        for name in names:
            params = cfg.decoder if name == "proposed/paper" else cfg.robust()
            out[name] = (cap, session.decode(cap, params, mode="calibrated"), shown_raw(cap.image, cap.image.shape[:2]))
    else:
        rec, depth = session.acquire(system, raw, label)[0]
        out[system] = (rec, depth, shown_raw(rec.raw, rec.scene.rig.camera.size_hw))
    return out


def shown_raw(raw: np.ndarray, size_hw: tuple[int, int]) -> np.ndarray:
    """A system's raw recording as one image to show, float32 in [0, 1]: a colour image as it
    is, a stack of frames (N, H, W) by its first frame, per-pixel samples (H, W, K) such as a
    ToF camera's taps by their mean; 8-bit images scaled by 255, other values (a 10-bit IR
    image, photo-electrons) by their 99.5th percentile."""
    a = np.asarray(raw)
    if a.shape[:2] != tuple(size_hw) and a.shape[1:3] == tuple(size_hw):
        a = a[0]
    if a.dtype == np.uint8:
        img = a.astype(np.float32) / 255.0
    else:
        img = a.astype(np.float32)
        finite = img[np.isfinite(img)]
        img = img / max(float(np.percentile(finite, 99.5)) if finite.size else 1.0, 1e-12)
    if img.ndim == 3 and img.shape[2] != 3:
        img = img.mean(axis=2)
    return np.clip(np.nan_to_num(img), 0.0, 1.0)


def measure_specular(session: Session, system: str) -> dict:
    """Specular highlights seen by one system of :data:`SPECULAR_SYSTEMS` (``proposed``: its two
    decoders): per object of ``scenes/specular.toml`` the completeness over the pixels the system
    lights, the MAE against ground truth and the share of decoded pixels more than 5 mm wrong,
    off an edge band (the run's, scaled to the system's focal length).  Returns its rows, metrics
    and the figure's panels - per label what it recorded, its depth and the truth, float32 arrays
    (:func:`specular_files` draws the figure from every system's)."""
    cfg = session.config
    recs = _specular_recordings(session, system)
    scene = session.raw_scene(SPECULAR_SCENE)
    main_focal = session.scene(SPECULAR_SCENE).rig.camera.focal_px
    rows, metrics, panels = [], {}, {}
    for name, (rec, depth, img) in recs.items():
        band_px = max(1, int(round(cfg.edge_band_px * rec.scene.rig.camera.focal_px / main_focal)))
        band = edge_band(rec.gt.depth_m, object_id=rec.gt.object_id, band_px=band_px)
        for i, obj in enumerate(scene.objects):
            region = rec.gt.lit & ~band & (rec.gt.object_id == i)
            sc = object_scores(rec, depth, region)
            rows.append({"system": name, "object": obj.name, "pixels": int(region.sum()), **sc, **rec.seeds})
            for k in SPECULAR_KEYS:
                metrics[f"figures/{SPECULAR_SCENE}/{name}/{obj.name}/{k}"] = sc[k]
        panels[name] = (img, depth.depth_m, rec.gt.depth_m)
    return {"rows": rows, "metrics": metrics, "panels": panels}


def specular_files(session: Session, measured: list[dict]) -> dict[str, bytes | str]:
    """The specular scene's table, figure and text from :func:`measure_specular`'s results (in
    :func:`specular_parts`' order), by their paths in the output folder."""
    cfg = session.config
    rows = [r for m in measured for r in m["rows"]]
    panels = {name: p for m in measured for name, p in m["panels"].items()}
    files = {
        "figures/specular.csv": table_text(rows, ["system", "object", "pixels", *SPECULAR_KEYS, "render", "noise"]),
        "figures/specular_systems.png": specular_figure(panels),
    }
    cam = session.scene(SPECULAR_SCENE).rig.camera
    md = [
        "# Specular highlights, every system",
        "",
        made_by(session, cam) + f"base seed {cfg.seed}, variant `{session.variant}`). Scene `scenes/specular.toml`: "
        "a brushed aluminium sphere (GGX alpha 0.2), a glossy red-painted box (0.08) and a polished chrome tile (0.05, "
        "turned to mirror the wall below it) before a matte white wall. Per object, over the pixels the system lights "
        f"off a {cfg.edge_band_px}-px edge band (scaled to each system's focal length): completeness, MAE against "
        f"ground truth, and the share of decoded pixels more than {WRONG_MM:g} mm wrong - depths the output does not "
        "mark. The proposed sensor by triangulation; the colour-robust decoder at its operating point. Figure: "
        "`specular_systems.png`.",
        "",
    ]
    md += markdown_table(
        ["system", "object", "pixels", "completeness", "MAE (mm)", f"> {WRONG_MM:g} mm wrong"],
        [
            [
                r["system"],
                r["object"],
                str(r["pixels"]),
                _pct(r["completeness"]),
                "-" if not np.isfinite(r["gt_mae_mm"]) else f"{r['gt_mae_mm']:.3f}",
                _pct(r["wrong_share"]),
            ]
            for r in rows
        ],
    )
    files["figures/specular.md"] = "\n".join(md) + "\n"
    return files


def _pct(x: float) -> str:
    return "-" if not np.isfinite(x) else f"{100 * x:.2f} %"


def _system_words(name: str) -> str:
    """A panel's system in words (a figure audit, 2026-11-30: the columns read 'proposed/paper')."""
    from simbench.systems import get_system

    if name.startswith("proposed/"):
        return {"paper": "paper's decoder", "robust": "colour-robust decoder"}.get(name.split("/")[1], name)
    return get_system(name).info().label


def specular_figure(panels: dict) -> bytes:
    """One column per system: what it recorded, its depth, its error against ground truth
    (``panels``: label -> (recorded image, depth, true depth), as :func:`measure_specular` gives)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(panels)
    fig, axes = plt.subplots(3, n, figsize=(3.4 * n, 8.2), constrained_layout=True, squeeze=False)
    lo, hi = _depth_range(next(iter(panels.values()))[2])
    for j, (name, (img, depth_m, truth_m)) in enumerate(panels.items()):
        axes[0, j].imshow(img, cmap=None if img.ndim == 3 else "gray", vmin=0, vmax=1)
        axes[0, j].set_title(f"{_system_words(name)}: recorded", fontsize=9)
        shown = axes[1, j].imshow(depth_m, cmap="viridis", vmin=lo, vmax=hi)
        axes[1, j].set_title("depth; white = no depth", fontsize=9)
        err = (depth_m - truth_m) * 1000.0
        im = axes[2, j].imshow(err, cmap="coolwarm", vmin=-WRONG_MM, vmax=WRONG_MM)
        axes[2, j].set_title(f"depth - truth (mm, clipped at +-{WRONG_MM:g})", fontsize=9)
        for ax in axes[:, j]:
            ax.set_xticks([])
            ax.set_yticks([])
    fig.colorbar(shown, ax=axes[1, :].tolist(), shrink=0.8, label="depth (m)")
    fig.colorbar(im, ax=axes[2, :].tolist(), shrink=0.8, label="depth - truth (mm)")
    fig.suptitle("Specular highlights: aluminium sphere, glossy box, chrome tile (scenes/specular.toml)")
    return figure_png(fig, dpi=80)
