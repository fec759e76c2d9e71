"""The end-to-end demo: render, decode and score the pipeline's acceptance scenes.

``simbench demo --out results/demo`` (run by ``make reproduce``) writes, per scene, a figure
(capture, decoded depth, error against ground truth) and the metrics, plus ``metrics.json``,
``summary.md``/``.csv`` and ``provenance.json`` for the whole run.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import logging
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from simbench.cache import RenderCache
from simbench.decode import decode, decode_reference
from simbench.sim.sensor import get_sensor
from simbench.experiments.common import RunConfig, figure_png, git_state, library_scene_path
from simbench.io import camera_full_scale, check_own_folder, json_bytes, write_files
from simbench.metrics import edge_band, score
from simbench.sim.scene import load_scene
from simbench.systems.proposed import acquire

log = logging.getLogger(__name__)

__all__ = ["demo_config", "DEFAULT_SCENES", "run_demo", "depth_figure"]

DEFAULT_SCENES = ("white_plane", "tilted_plane", "sphere", "step")


def demo_config(**overrides: object) -> RunConfig:
    """The demo's run settings: the ``minimal`` sensor (noise only), every object exactly where
    its scene file puts it (the demo checks the pipeline, not a lab's placement)."""
    return RunConfig(**{"sensor": "minimal", "placement_depth_mm": 0.0, "placement_tilt_deg": 0.0, **overrides})


def depth_figure(capture: np.ndarray, depth_m: np.ndarray, gt_depth_m: np.ndarray, *, title: str) -> bytes:
    """PNG bytes of a three-panel figure: capture, decoded depth, signed error (mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    err = (depth_m - gt_depth_m) * 1000.0
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    axes[0].imshow(capture)
    axes[0].set_title("capture")
    finite = depth_m[np.isfinite(depth_m)]
    lo, hi = np.percentile(finite, [1, 99]) if finite.size else (0, 1)
    im = axes[1].imshow(depth_m, cmap="viridis", vmin=lo, vmax=hi)
    axes[1].set_title("decoded depth (m), NaN = white")
    fig.colorbar(im, ax=axes[1], shrink=0.8)
    im = axes[2].imshow(err, cmap="coolwarm", vmin=-1.0, vmax=1.0)
    axes[2].set_title("depth - ground truth (mm)")
    fig.colorbar(im, ax=axes[2], shrink=0.8)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    return figure_png(fig, dpi=80)


def run_demo(
    out_dir: str | Path,
    *,
    config: RunConfig | None = None,
    scenes: tuple[str, ...] = DEFAULT_SCENES,
    cache_dir: str | Path | None = None,
    progress: Callable[[str], None] = log.info,
    command: str = "",
) -> dict:
    """Render (through the render cache in ``cache_dir``; None: none), decode and score each
    scene; write figures and tables to ``out_dir``.  ``command``: the command line that asked
    (recorded as "Made by"; default ``simbench demo --out OUT_DIR``).  Figures of scenes an earlier
    demo wrote there and this one does not are removed (the summary would not list them).

    A Mitsuba variant must already be selected.
    """
    import mitsuba as mi

    from simbench.sim.keys import versions

    config = config if config is not None else demo_config()
    out = Path(out_dir)
    sensor = get_sensor(config.sensor)
    pattern = config.decoder.pattern
    cache = RenderCache(cache_dir)
    rows = []
    names, scenes = scenes, [load_scene(library_scene_path(name)) for name in scenes]  # all checked before rendering
    check_own_folder(out, marker="provenance.json", written_by="simbench demo", what="demo --out")
    command = command or f"simbench demo --out {out_dir}"
    earlier = _earlier_scenes(out)
    files: dict[Path, bytes] = {}
    for i, (name, scene) in enumerate(zip(names, scenes)):
        t0 = time.perf_counter()
        # seeds from the base seed and each capture's label (simbench.seeds): scenes sharing a
        # rig and Z0 share the reference capture
        acq = acquire(
            scene, pattern=pattern, sensor=sensor, spp=config.spp, sampler=config.sampler, seed=config.seed, cache=cache
        )
        t1 = time.perf_counter()
        params = dataclasses.replace(config.decoder, z0_m=scene.reference_depth_m)
        # (a 10- or 12-bit camera's digital numbers at its own full scale, not uint16's)
        reference, capture = (camera_full_scale(a, bits=sensor.camera.bits) for a in (acq.reference, acq.capture))
        ref = decode_reference(reference, rig=acq.scene.rig, params=params)
        t2 = time.perf_counter()
        result = decode(capture, rig=acq.scene.rig, params=params, reference=ref)
        t3 = time.perf_counter()
        band_px = config.edge_band_px if name != "white_plane" else 0
        band = edge_band(acq.gt.depth_m, object_id=acq.gt.object_id, band_px=band_px) if band_px else None
        m = score(
            result.depth_m,
            acq.gt,
            camera=acq.scene.rig.camera,
            exclude=band,
            column_px=result.column_px,
            period_px=pattern.period_px,
            detail=True,
        )
        # timings go to the progress log only: result files must be identical on a re-run
        capture_seeds = acq.meta["seeds"][f"capture/{scene.name}"]
        row = {
            "scene": name,
            **m,
            "render_seed": capture_seeds["render"],
            "noise_seed": capture_seeds["noise"],
            "seeds": acq.meta["seeds"],
        }
        rows.append(row)
        files[out / f"{name}.png"] = depth_figure(
            acq.capture,
            result.depth_m,
            acq.gt.depth_m,
            title=f"{name}: MAE {m['gt_mae_mm']:.3f} mm, completeness {100 * m['completeness']:.2f} %",
        )
        progress(
            f"[{i + 1}/{len(names)}] {name}: MAE {m['gt_mae_mm']:.3f} mm, completeness "
            f"{100 * m['completeness']:.2f} %, stripe-order errors {m['stripe_order_errors']} (render {t1 - t0:.1f} s, "
            f"decode {t3 - t2:.2f} s)"
        )
    cfg = {**config.to_dict(), "scenes": list(names)}
    provenance = {
        "command": command,
        "config": cfg,
        "variant": mi.variant(),
        "versions": versions(),
        **git_state(),
    }
    files[out / "metrics.json"] = json_bytes({"rows": rows})
    files[out / "provenance.json"] = json_bytes(provenance)
    cols = [
        "scene",
        "gt_mae_mm",
        "gt_rmse_mm",
        "gt_median_mm",
        "gt_p95_mm",
        "completeness",
        "outlier_share",
        "stripe_order_errors",
        "stripe_order_error_rate",
        "n_scored",
        "render_seed",
        "noise_seed",
    ]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    files[out / "summary.csv"] = buf.getvalue().encode()
    md = [
        "# Pipeline demo: " + ", ".join(name.replace("_", " ") for name in names),
        "",
        f"Made by `{command}` (sensor `{config.sensor}`, {config.spp} spp, base seed "
        f"{config.seed}, "
        f"variant `{mi.variant()}`). Errors exclude a {config.edge_band_px}-px band at depth edges (none on the white "
        f"plane); "
        "completeness is over the pixels ground truth says are seen and lit.",
        "",
        "| scene | MAE (mm) | RMSE (mm) | p95 (mm) | completeness | outliers > 5 mm | stripe-order errors |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        md.append(
            f"| {r['scene']} | {r['gt_mae_mm']:.3f} | {r['gt_rmse_mm']:.3f} | {r['gt_p95_mm']:.3f} | "
            f"{100 * r['completeness']:.2f} % | "
            f"{100 * r['outlier_share']:.3f} % | {r['stripe_order_errors']} ({100 * r['stripe_order_error_rate']:.3f} "
            f"%) |"
        )
    files[out / "summary.md"] = ("\n".join(md) + "\n").encode()
    write_files(files)  # the folder's files together, or none of them
    for name in sorted(set(earlier) - set(names)):
        (out / f"{name}.png").unlink(missing_ok=True)
    return {"rows": rows, "provenance": provenance}


def _earlier_scenes(out: Path) -> list[str]:
    """The scenes an earlier demo in ``out`` recorded in its provenance (plain names), or none."""
    import json

    try:
        names = json.loads((out / "provenance.json").read_text(encoding="utf-8"))["config"]["scenes"]
    except (OSError, ValueError, KeyError, TypeError):
        return []
    return [n for n in names if isinstance(n, str) and n == Path(n).name and n not in ("", ".", "..")]
