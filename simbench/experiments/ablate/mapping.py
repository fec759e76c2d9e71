"""From a run's parameters (names of :data:`~simbench.experiments.ablate.spec.PARAMETERS`) to
the sensor model, scene and decoder settings it runs with."""

from __future__ import annotations

import dataclasses
from pathlib import Path
import os
import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simbench.decode import DecoderParams
    from simbench.sim.sensor import SensorModel
    from simbench.experiments.ablate.spec import Sweep
    from simbench.experiments.common import RunConfig
    from simbench.sim.scene import SceneSpec

from simbench.experiments.ablate.spec import PARAMETERS

log = logging.getLogger(__name__)

__all__ = ["sensor_for", "scene_for", "decoder_for", "run_config_for", "check_sweep"]


def sensor_for(params: dict) -> SensorModel:
    from simbench.sim.sensor import (
        Lens,
        get_sensor,
        sensor_from_dict,
        sensor_to_dict,
        with_effects,
    )

    if "sensor.effects" in params:
        effects = params["sensor.effects"]
        effects = [effects] if isinstance(effects, str) else list(effects)
        sensor = with_effects(
            get_sensor("ideal"),
            get_sensor(params.get("sensor.source", "paper")),
            effects,
            name="ideal+" + "+".join(effects) if effects else "ideal",
        )
    else:
        sensor = get_sensor(params["sensor.preset"])
    overrides = {k: v for k, v in params.items() if k.startswith("sensor.") and k not in PARAMETERS}
    if overrides:
        data = sensor_to_dict(sensor)
        for k, v in overrides.items():
            *tables, key = k.split(".")[1:]
            node = data
            for t in tables:
                node = node[t]
            # a lens field left out of the dict at its default (lateral colour) is still a field
            optional = {f.name for f in dataclasses.fields(Lens)} if tables[-1:] == ["lens"] else set()
            if key not in node and key not in optional:
                raise ValueError(
                    f"unknown sensor field {k!r}; fields of [{'.'.join(tables)}]: "
                    f"{sorted(x for x in node if not isinstance(node[x], dict))}"
                )
            node[key] = list(v) if isinstance(v, tuple) else v
        data["name"] = f"{sensor.name}*"
        sensor = sensor_from_dict(data, where="sweep sensor")
    return sensor


def scene_path(value: object) -> Path:
    """The scene file ``scene.name`` names: a scene of ``scenes/`` by name, or a researcher's own
    scene TOML by its path (one ending in ``.toml`` or holding a folder; relative to the working
    folder, as ``sensor.preset``'s files are).  Raises ValueError where there is no such file."""
    from simbench.experiments.common import library_scene_path

    if isinstance(value, str) and (value.endswith(".toml") or "/" in value or os.sep in value):
        path = Path(value).expanduser()
        if not path.is_file():
            raise ValueError(f"scene.name: no scene file {value!r} (from {Path.cwd()})")
        return path
    return library_scene_path(value)


def scene_for(params: dict) -> SceneSpec:
    from simbench.sim.scene import load_scene, paint_reflectance, with_subsurface

    scene = load_scene(scene_path(params["scene.name"]))
    objs = list(scene.objects)
    if "scene.srgb8" in params:
        rgb = paint_reflectance(params["scene.srgb8"])
        objs = [dataclasses.replace(o, material=dataclasses.replace(o.material, rgb=rgb)) for o in objs]
    from simbench import validate
    from simbench.sim.scene import MAX_ANGLE_DEG, SCENE_EXTENT_M

    if "scene.depth_m" in params:
        validate.number(params["scene.depth_m"], "scene.depth_m", lo=0.0, lo_open=True, hi=SCENE_EXTENT_M)
    if "scene.tilt_deg" in params:
        validate.number(params["scene.tilt_deg"], "scene.tilt_deg", lo=-MAX_ANGLE_DEG, hi=MAX_ANGLE_DEG)
    if "scene.depth_m" in params or "scene.tilt_deg" in params:
        first = dict(objs[0].params)
        key = "center_m" if "center_m" in first else "translate_m"
        if "scene.depth_m" in params:
            dz = float(params["scene.depth_m"]) - first[key][2]
            for i, o in enumerate(objs):
                q = dict(o.params)
                k = "center_m" if "center_m" in q else "translate_m"
                q[k] = (q[k][0], q[k][1], q[k][2] + dz)
                objs[i] = dataclasses.replace(o, params=tuple(sorted(q.items())))
        if "scene.tilt_deg" in params:
            q = dict(objs[0].params)
            rx, _, rz = q.get("rotation_deg", (0.0, 0.0, 0.0))
            q["rotation_deg"] = (rx, float(params["scene.tilt_deg"]), rz)
            objs[0] = dataclasses.replace(objs[0], params=tuple(sorted(q.items())))
    if "scene.speed_m_s" in params:
        # the first object's velocity, speed 0 included (until 2026-11-30 a speed of 0 kept the scene
        # file's own motion, so a sweep's "still" row moved, and any other speed dropped the file's
        # rotation): its rotation, if the file gives one, is kept
        from simbench.experiments.motion import DIRECTIONS
        from simbench.sim.motion import MAX_SPEED_M_S, Motion

        speed = validate.number(params["scene.speed_m_s"], "scene.speed_m_s", lo=-MAX_SPEED_M_S, hi=MAX_SPEED_M_S)
        direction = validate.choice(params.get("scene.motion", "lateral"), "scene.motion", DIRECTIONS)
        velocity = tuple(speed * u for u in DIRECTIONS[direction])
        motion = dataclasses.replace(objs[0].motion or Motion(), velocity_m_s=velocity)
        objs[0] = dataclasses.replace(objs[0], motion=None if motion.is_static else motion)
    elif "scene.motion" in params:
        validate.choice(params["scene.motion"], "scene.motion", ("lateral", "axial"))
        # (a third new user's audit: a direction alone moved nothing, without a word)
        raise ValueError(
            "scene.motion gives the direction of scene.speed_m_s, which this run has not: give both "
            "(scene.speed_m_s = 0 for a still run)"
        )
    if "scene.spin_deg_s" in params:
        # the first object turning about the vertical axis through its own position (its file's
        # axis and centre, if it gives them), 0 = not turning; its translation is kept (an audit,
        # 2026-11-30: a sweep could not set rotation at all)
        from simbench.sim.motion import MAX_ANGULAR_DEG_S, Motion

        spin = validate.number(
            params["scene.spin_deg_s"], "scene.spin_deg_s", lo=-MAX_ANGULAR_DEG_S, hi=MAX_ANGULAR_DEG_S
        )
        motion = dataclasses.replace(objs[0].motion or Motion(), angular_velocity_deg_s=spin)
        objs[0] = dataclasses.replace(objs[0], motion=None if motion.is_static else motion)
    scene = dataclasses.replace(scene, objects=tuple(objs))
    if "scene.subsurface" in params:  # absent: as the scene file says
        medium = params["scene.subsurface"]
        scene = with_subsurface(scene, None if medium == "none" else medium)
    return scene


def _text(value: object, name: str) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{name} must be a string, got {value!r}")
    return value


def decoder_for(params: dict) -> DecoderParams:
    from simbench.decode import DecoderParams, with_changes
    from simbench.pattern import PatternSpec, parse_sequence

    from simbench import validate

    fields = {k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("decoder.")}
    # checked, not cast (a new user's audit: period_px = 21.9 ran as 21 and was tabled as 21.9)
    kinds = {
        "pattern.period_px": lambda v, k: validate.integer(v, k),
        "pattern.order": lambda v, k: validate.integer(v, k),
        "pattern.channels": _text,
    }
    pattern = {k.split(".", 1)[1]: kinds[k](v, k) for k, v in params.items() if k in kinds}
    if "pattern.sequence" in params:
        pattern["sequence"] = parse_sequence(str(params["pattern.sequence"]))
    return with_changes(DecoderParams(pattern=PatternSpec(**pattern)), fields)


def run_config_for(params: dict, *, seed: int, sensor: SensorModel, decoder: DecoderParams) -> RunConfig:
    """The run settings of one parameter set (``run.*``), each value checked as the command
    line checks it (an integer is not NaN, a sample count not 0)."""
    from simbench import validate
    from simbench.experiments.common import RunConfig

    def num(name: str, **limits) -> float:
        return validate.number(params[name], name, **limits)

    def integer(name: str, **limits) -> int:
        return validate.integer(params[name], name, **limits)

    return RunConfig(
        sensor=sensor.name,
        spp=integer("run.spp", lo=1, hi=1 << 16),
        sampler=validate.choice(params["run.sampler"], "run.sampler", _samplers()),
        camera_scale=num("run.camera_scale", lo=0.0, lo_open=True, hi=4.0),
        max_depth=integer("run.max_depth", lo=2, hi=1024),
        seed=int(seed),
        placement_depth_mm=num("run.placement_depth_mm", lo=0.0),
        placement_tilt_deg=num("run.placement_tilt_deg", lo=0.0),
        board_bow_mm_per_m=num("run.board_bow_mm_per_m"),
        board_waviness_mm=num("run.board_waviness_mm", lo=0.0),
        decoder=decoder,
        rig=str(params["run.rig"]),
        calibration_poses=integer("run.calibration_poses", lo=3, hi=200),
        calibration_bow_mm_per_m=num("run.calibration_bow_mm_per_m"),
        calibration_waviness_mm=num("run.calibration_waviness_mm", lo=0.0),
    )


def _samplers() -> tuple[str, ...]:
    from simbench.sim.mitsuba_dict import SAMPLERS

    return SAMPLERS


def check_sweep(sweep: Sweep) -> None:
    """Build every run's sensor, decoder, scene and run settings without rendering anything:
    a value that cannot run (``decoder.voting = "maybe"``, ``run.spp = 0``, a sensor preset
    that is no TOML file, a scene name outside ``scenes/``) fails here, before the first run,
    not as a failed row after minutes of others.

    Raises
    ------
    ValueError
        Naming the sweep, the run's parameter values and what is wrong.
    """
    from simbench.experiments.ablate.spec import expand

    seen: set[str] = set()
    for run in expand(sweep):
        params = run["params"]
        key = repr(sorted(params.items(), key=lambda kv: kv[0]))
        if key in seen:  # repeats differ only in their seed
            continue
        seen.add(key)
        try:
            decoder = decoder_for(params)
            sensor = sensor_for(params)
            run_config_for(params, seed=run["seed"], sensor=sensor, decoder=decoder)
            scene_for(params)
        except (ValueError, TypeError, OSError) as exc:
            axes = {k: params[k] for k, _ in sweep.axes}
            msg = (str(exc).splitlines() or [type(exc).__name__])[0]
            raise ValueError(f"sweep {sweep.name!r}, run {run['run']} {axes}: {msg}") from None
