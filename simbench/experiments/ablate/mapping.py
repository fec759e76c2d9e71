"""From a run's parameters (names of :data:`~simbench.experiments.ablate.spec.PARAMETERS`) to
the sensor model, scene and decoder settings it runs with."""

from __future__ import annotations

import dataclasses
import logging
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from simbench.decode import DecoderParams
    from simbench.device import SensorModel
    from simbench.scene import SceneSpec

from simbench.experiments.ablate.spec import PARAMETERS

log = logging.getLogger(__name__)

__all__ = ["sensor_for", "scene_for", "decoder_for"]


def sensor_for(params: dict) -> SensorModel:
    from simbench.device import (
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
            if key not in node:
                raise ValueError(
                    f"unknown sensor field {k!r}; fields of [{'.'.join(tables)}]: "
                    f"{sorted(x for x in node if not isinstance(node[x], dict))}"
                )
            node[key] = list(v) if isinstance(v, tuple) else v
        data["name"] = f"{sensor.name}*"
        sensor = sensor_from_dict(data, where="sweep sensor")
    return sensor


def scene_for(params: dict) -> SceneSpec:
    from simbench.experiments.common import SCENES_DIR
    from simbench.scene import load_scene, paint_reflectance

    scene = load_scene(SCENES_DIR / f"{params['scene.name']}.toml")
    objs = list(scene.objects)
    if "scene.srgb8" in params:
        rgb = paint_reflectance(params["scene.srgb8"])
        objs = [dataclasses.replace(o, material=dataclasses.replace(o.material, rgb=rgb)) for o in objs]
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
    return dataclasses.replace(scene, objects=tuple(objs))


def decoder_for(params: dict) -> DecoderParams:
    from simbench.decode import DecoderParams
    from simbench.pattern import PatternSpec, parse_sequence

    fields = {k.split(".", 1)[1]: v for k, v in params.items() if k.startswith("decoder.")}
    for k in ("depth_range_m",):
        if k in fields and isinstance(fields[k], list):
            fields[k] = tuple(fields[k])
    kinds = {"pattern.period_px": int, "pattern.order": int, "pattern.channels": str}
    pattern = {k.split(".", 1)[1]: kinds[k](v) for k, v in params.items() if k in kinds}
    if "pattern.sequence" in params:
        pattern["sequence"] = parse_sequence(str(params["pattern.sequence"]))
    return DecoderParams(pattern=PatternSpec(**pattern), **fields)
