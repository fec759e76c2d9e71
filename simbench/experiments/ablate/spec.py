"""The sweep specification: the sweep file's schema, the parameters a sweep may vary, the
built-in studies and the expansion into runs (:mod:`simbench.experiments.ablate`)."""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import json
import logging
from pathlib import Path

from simbench import validate
from simbench.io import read_toml
from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP
from simbench.seeds import DEFAULT_SEED, repetition_seed

log = logging.getLogger(__name__)

__all__ = [
    "PARAMETERS",
    "DEFAULTS",
    "METRICS",
    "REF_METRICS",
    "MODES",
    "EDGE_BAND_PX",
    "Sweep",
    "sweep_from_dict",
    "load_sweep",
    "expand",
    "BUILTIN_STUDIES",
    "STUDIES_DIR",
]

STUDIES_DIR = Path(__file__).resolve().parents[2] / "studies"
# by triangulation with the rig (paper Eq. 15), then the same scores against the separately
# captured reference plane (Sec. 5.4), prefixed ``ref_``
METRICS = (
    "plane_mae_mm",
    "gt_mae_mm",
    "gt_rmse_mm",
    "gt_p95_mm",
    "outlier_share",
    "edge5_mae_mm",
    "completeness",
    "stripe_order_errors",
    "stripe_order_error_rate",
)
REF_METRICS = ("ref_plane_mae_mm", "ref_gt_mae_mm", "ref_edge5_mae_mm", "ref_completeness", "ref_stripe_order_errors")
MODES = {"calibrated": "", "reference": "ref_"}
EDGE_BAND_PX = 5  # edge5_mae_mm: the MAE outside this band at depth edges (issue 2's protocol for shapes)


def _decoder_fields() -> dict[str, str]:
    from simbench.decode import DecoderParams

    # mode: every run is scored in both modes (MODES)
    skip = {"pattern", "z0_m", "threads", "mode"}
    return {
        f"decoder.{f.name}": f"DecoderParams.{f.name}" for f in dataclasses.fields(DecoderParams) if f.name not in skip
    }


def _parameters() -> dict[str, str]:
    p = {
        "pattern.period_px": "fringe period T (projector px)",
        "pattern.order": "De Bruijn window length n of B(2, n)",
        "pattern.sequence": "explicit stripe code sequence (0/1 string)",
        "pattern.channels": "colour channels of code 1, code 0 and the fringe (paper: rgb)",
        "sensor.preset": "sensor model: a preset (ideal, minimal, paper) or a TOML file",
        "sensor.effects": "list of physical effects switched on over the ideal model",
        "sensor.source": "where sensor.effects take their values from (default paper)",
        "scene.name": "a scene of scenes/ by name, or your own scene TOML by its path (ending in .toml)",
        "scene.srgb8": "repaint every object with this 8-bit sRGB colour",
        "scene.subsurface": "make every object translucent as this medium (simbench.sim.subsurface.MEDIA) or opaque "
        "('none'); not given: as the scene file says",
        "scene.depth_m": "move the scene so its first object's placement (its center_m, or a mesh's translate_m: its "
        "origin) is at this depth",
        "scene.tilt_deg": "rotation of the first object about the vertical axis (deg)",
        "scene.speed_m_s": "speed of the first object (m/s; simbench.sim.motion), in the scene.motion direction",
        "scene.motion": "direction of that motion: lateral (+x, sideways) or axial (-z, towards the camera); "
        "default lateral",
        "scene.spin_deg_s": "rotation speed of the first object about the vertical axis through it (deg/s; its "
        "scene file's axis and centre where it gives them)",
        "decoder.without": "the paper decoder's added checks switched off (simbench.decode.PAPER_ADDED_CHECKS): "
        "none, all, a name or a list of names",
        "run.spp": "samples per pixel",
        "run.sampler": "Mitsuba sample generator",
        "run.camera_scale": "camera resolution factor",
        "run.max_depth": "path length",
        "run.placement_depth_mm": "placement tolerance in depth (every object placed, seeded)",
        "run.placement_tilt_deg": "placement tolerance in tilt",
        "run.board_bow_mm_per_m": "bow of every placed board and the reference board (mm of sag per metre, seeded "
        "sign)",
        "run.board_waviness_mm": "ripple amplitude of every placed board and the reference board (mm, seeded phase)",
        "run.rig": "the rig the decoder believes: true, or calibrated (simbench calibrate through the run's sensor)",
        "run.calibration_poses": "target poses of that calibration",
        "run.calibration_bow_mm_per_m": "bow of the printed calibration target (mm of sag per metre)",
        "run.calibration_waviness_mm": "ripple amplitude of the printed calibration target (mm)",
    }
    p.update(_decoder_fields())
    return p


PARAMETERS = _parameters()
_SENSOR_TABLES = ("camera", "camera.lens", "projector", "projector.lens", "spectral", "ambient")
DEFAULTS = {
    "scene.name": "plane_white",
    "sensor.preset": "paper",
    "run.spp": DEFAULT_SPP,
    "run.sampler": DEFAULT_SAMPLER,
    "run.camera_scale": 1.0,
    "run.max_depth": 6,
    "run.placement_depth_mm": 10.0,
    "run.placement_tilt_deg": 2.0,
    "run.board_bow_mm_per_m": 0.0,
    "run.board_waviness_mm": 0.0,
    "run.rig": "true",
    "run.calibration_poses": 10,
    "run.calibration_bow_mm_per_m": 0.0,
    "run.calibration_waviness_mm": 0.0,
}


def _check_name(name: str) -> None:
    if name in PARAMETERS:
        return
    table, _, key = name.rpartition(".")
    if name.startswith("sensor.") and table[len("sensor.") :] in _SENSOR_TABLES and key:
        return
    raise ValueError(
        f"unknown sweep parameter {name!r}; valid: {sorted(PARAMETERS)} and sensor.<table>.<key> with <table> one of "
        f"{list(_SENSOR_TABLES)}"
    )


@dataclasses.dataclass(frozen=True)
class Sweep:
    name: str
    description: str
    base: dict
    axes: tuple[tuple[str, tuple], ...]
    combine: str = "grid"
    repeats: int = 1
    seed: int = DEFAULT_SEED
    plot_metric: str = "gt_mae_mm"
    path: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or not all(c.isalnum() or c in "-_" for c in self.name):
            raise ValueError(
                f"sweep name must be letters, digits, - and _, got {self.name!r} (a study without a `name` key is "
                "named by its file's stem: give it a `name`)"
            )
        if not isinstance(self.base, dict):
            raise ValueError(f"[base] must be a table, got {self.base!r}")
        for k in self.base:
            _check_name(k)
        if not self.axes:
            raise ValueError("a sweep needs at least one [[axis]]")
        for k, values in self.axes:
            _check_name(k)
            if not values:
                raise ValueError(f"axis {k!r} has no values")
        names = [k for k, _ in self.axes]
        if len(set(names)) != len(names):
            raise ValueError(f"an axis is given twice: {names}")
        both = sorted(set(names) & set(self.base))
        if both:  # the axis would override the base silently
            raise ValueError(f"{both} both in [base] and as an [[axis]]: give each in one place")
        if self.combine not in ("grid", "zip"):
            raise ValueError(f"combine must be 'grid' or 'zip', got {self.combine!r}")
        if self.combine == "zip" and len({len(v) for _, v in self.axes}) != 1:
            raise ValueError("zipped axes must have the same number of values")
        object.__setattr__(self, "repeats", validate.integer(self.repeats, "repeats", lo=1, hi=10000))
        object.__setattr__(self, "seed", validate.integer(self.seed, "seed", lo=0, hi=2**63 - 1))
        if not isinstance(self.description, str):
            raise ValueError(f"description must be a string, got {self.description!r}")

        if self.plot_metric not in METRICS + REF_METRICS:
            raise ValueError(f"plot_metric must be one of {list(METRICS + REF_METRICS)}, got {self.plot_metric!r}")


def sweep_from_dict(data: dict, *, where: str = "sweep") -> Sweep:
    allowed = {"name", "description", "base", "axis", "combine", "repeats", "seed", "plot_metric"}
    bad = sorted(set(data) - allowed)
    if bad:
        raise ValueError(f"{where}: unknown key(s) {bad}; valid: {sorted(allowed)}")
    axes = []
    if not isinstance(data.get("axis", []), list):
        raise ValueError(f"{where}: axis must be an array of tables ([[axis]])")
    for i, ax in enumerate(data.get("axis", [])):
        extra = sorted(set(ax) - {"name", "values"}) if isinstance(ax, dict) else []
        if extra:
            raise ValueError(
                f"{where}: axis {i + 1} holds {extra} beside 'name' and 'values' (in TOML a key written after an "
                "[[axis]] table belongs to that axis: write the sweep's own keys before the first [[axis]])"
            )
        if not isinstance(ax, dict) or set(ax) != {"name", "values"} or not isinstance(ax["values"], list):
            raise ValueError(f"{where}: axis {i + 1} needs exactly 'name' and a list 'values'")
        axes.append((ax["name"], tuple(tuple(v) if isinstance(v, list) else v for v in ax["values"])))
    try:
        return Sweep(
            name=data.get("name", ""),
            description=data.get("description", ""),
            base=data.get("base", {}),
            axes=tuple(axes),
            combine=data.get("combine", "grid"),
            repeats=data.get("repeats", 1),
            seed=data.get("seed", 2017),
            plot_metric=data.get("plot_metric", "gt_mae_mm"),
            path=where,
        )
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None


BUILTIN_STUDIES = (
    "design_choices",
    "debruijn_order",
    "period",
    "pattern_colours",
    "phase_method",
    "voting",
    "noise_ambient",
    "surface_colour",
    "paper_checks",
    "lateral_colour",
    "subsurface",
    "calibration_effort",
)


def load_sweep(path_or_name: str | Path) -> Sweep:
    """A sweep file, or a built-in study by name (:data:`BUILTIN_STUDIES`)."""
    p = Path(path_or_name)
    where = str(p)
    if not p.suffix and str(path_or_name) in BUILTIN_STUDIES:
        p = STUDIES_DIR / f"{path_or_name}.toml"
        where = f"simbench/studies/{p.name}"  # the same on every machine
    elif not p.is_file() and not p.suffix:
        raise ValueError(f"no sweep file {p} and no built-in study of that name; built-in: {list(BUILTIN_STUDIES)}")
    data = read_toml(p, what="sweep")
    data.setdefault("name", p.stem)
    return sweep_from_dict(data, where=where)


def expand(sweep: Sweep) -> list[dict]:
    """Every run: ``{"run": index, "repeat": r, "params": {...}, "seed": s, "key": ...}``.
    Repetition ``r`` has the same seed in every parameter set (common random numbers)."""
    names = [k for k, _ in sweep.axes]
    value_lists = [v for _, v in sweep.axes]
    combos = itertools.product(*value_lists) if sweep.combine == "grid" else zip(*value_lists)
    runs = []
    for combo in combos:
        params = {**DEFAULTS, **sweep.base, **dict(zip(names, combo))}
        for r in range(sweep.repeats):
            seed = repetition_seed(sweep.seed, r)
            key = hashlib.sha256(
                json.dumps({"params": params, "repeat": r, "seed": seed}, sort_keys=True, default=str).encode()
            ).hexdigest()[:16]
            runs.append({"run": len(runs), "repeat": r, "params": params, "seed": seed, "key": key})
    return runs


# ------------------------------------------------------------------------------ one run
