"""The common case in three calls - record a scene with a depth system (render it and pass it
through the system's sensor), decode its depth, score it::

    import simbench

    rec = simbench.record("scenes/step.toml", system="proposed", sensor="paper")
    depth = simbench.depth(rec)
    simbench.score(depth, rec)  # {'mae_mm': ..., 'completeness': ..., ...}

(``simbench.sim.render`` and ``simbench.decode`` name the renderer's module and the decoder's
package, hence ``record`` and ``depth``.)

With the command line's defaults (``simbench render``: seed :data:`simbench.seeds.DEFAULT_SEED`,
:data:`simbench.sim.mitsuba_dict.DEFAULT_SPP` samples of the ``multijitter`` sampler, the render
cache in ``.cache/simbench``), so ``record`` gives the images ``simbench render`` writes for the
same scene, system, sensor and seed; ``depth`` decodes as ``simbench decode`` does (the proposed
sensor: the paper's decoder against the reference plane, Sec. 5.4), and ``score`` gives
``simbench score``'s numbers.  The Mitsuba variant is chosen at the first recording
(:func:`simbench.variant.select_variant`) unless one is set already.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import os
import sys
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from simbench import SimbenchWarning
from simbench.systems.recording_checks import (  # (here since the API warned of them first; ablate tables them)
    CLIPPED_CAPTURE_SHARE,  # noqa: F401
    CLIPPED_REFERENCE_SHARE,
    DARK_CAPTURE_LEVEL,  # noqa: F401
    OUT_OF_RANGE_SHARE,  # noqa: F401
    exposure_warnings,
    recording_warnings,
)
from simbench.cache import RenderCache

if TYPE_CHECKING:
    from simbench.decode import DecoderParams
    from simbench.pattern import PatternSpec
    from simbench.sim.scene import SceneSpec
    from simbench.rig import Rig
    from simbench.sim.sensor import SensorModel
    from simbench.systems import Recording, SystemDepth

__all__ = [
    "Recorded",
    "record",
    "depth",
    "score",
    "SimbenchWarning",
    "DEFAULT_CACHE",
    "RENDER_CACHE_VARIABLE",
    "SEED_RANGE",
    "SPP_RANGE",
    "MAX_DEPTH_RANGE",
    "MIN_CONFIDENCE_RANGE",
    "EDGE_BAND_RANGE_PX",
    "CAMERA_SCALE_RANGE",
]

# The render cache folder of the command line and of this API: $SIMBENCH_RENDER_CACHE, else
# .cache/simbench under the working folder.  (A new user's audit, 2026-11-30: a library scene
# rendered from two working folders rendered twice, and SIMBENCH_CACHE_DIR - the folder of the
# small per-user memos, simbench.cache.user_cache_dir - read as if it were this one.)
RENDER_CACHE_VARIABLE = "SIMBENCH_RENDER_CACHE"
DEFAULT_CACHE = os.environ.get(RENDER_CACHE_VARIABLE) or ".cache/simbench"
# the ranges the command line's options take too (simbench.cli.options)
SEED_RANGE = (0, 2**63 - 1)
"""Seeds :func:`record` takes, inclusive (``--seed``): exact in JSON and NumPy (63 bits)."""
SPP_RANGE = (1, 1 << 16)
"""Samples per pixel :func:`record` takes, inclusive (``--spp``; the sampler may ask more of a count)."""
MAX_DEPTH_RANGE = (2, 1024)
"""Path lengths :func:`record` takes, inclusive (``--max-depth``; 2 = direct light; Mitsuba's -1,
unbounded, is not offered: Russian roulette ends paths anyway)."""
MIN_CONFIDENCE_RANGE = (0.0, 1e6)
"""Confidence thresholds :func:`depth` takes, inclusive (``--min-confidence``), in the systems'
own units (the fringe SNR is < ~1e3)."""
EDGE_BAND_RANGE_PX = (0, 1000)
"""Edge bands :func:`score` takes, inclusive, in pixels (``--edge-band``)."""


@dataclass(frozen=True)
class Recorded:
    """A scene recorded by one depth system, with what decoding it needs.

    ``recording`` holds the raw frame(s) (:attr:`raw`), the scene as the system saw it and its
    ground truth (:attr:`gt`: depth, projector column, lit pixels, object ids at the system's
    pixels); ``calibration`` what the system decodes with (the proposed sensor's reference
    plane); ``settings`` how it was made (system, sensor, seed, spp, sampler, variant)."""

    system: str
    recording: Recording
    calibration: Any
    settings: dict = field(default_factory=dict)
    # what the system's folder records about it (meta.json / device.json):
    # :meth:`simbench.systems.DepthSystem.write_recording` writes it with the frames
    meta: dict = field(default_factory=dict)
    # the sensor model the proposed sensor records through (record() sets it; a Recorded made by
    # hand without it: the preset settings["sensor"] names)
    sensor: SensorModel | None = None

    @property
    def raw(self) -> np.ndarray:
        """What the system recorded (the proposed sensor: its 8-bit colour image)."""
        return self.recording.raw

    @property
    def gt(self) -> Any:
        """Ground truth at the system's pixels (:class:`simbench.sim.truth.GroundTruth`)."""
        return self.recording.gt

    @property
    def scene(self) -> SceneSpec:
        return self.recording.scene

    @property
    def pattern(self) -> PatternSpec | None:
        """The coded pattern the recording was made with (the proposed sensor's; None for a system
        that projects none of ours): :func:`depth` decodes with it."""
        if "pattern" not in self.meta:
            return None
        from simbench.systems.proposed import recorded_pattern

        return recorded_pattern(self.meta, where="the recording")


def _ensure_variant(variant: str | None) -> str:
    mi = sys.modules.get("mitsuba")
    if mi is not None and mi.variant() is not None and variant in (None, mi.variant()):
        return mi.variant()
    from simbench.variant import select_variant

    return select_variant(variant)


# record's options that a system may not take, with the command line's names for them
_RECORDING_FLAGS = {
    "sensor": "--sensor",
    "pattern": "--period, --order, --sequence, --channels",
    "calibration_frames": "--calibration-frames",
    "camera_scale": "--camera-scale",
}

CAMERA_SCALE_RANGE = (0.0, 4.0)
"""Camera resolution factors :func:`record` takes (``--camera-scale``, the run option
``run.camera_scale``): above the first, up to the second; the pattern's period must still be
resolved (the smallest scale accepted is in the error)."""


def scaled_rig(rig: Rig, camera_scale: float, *, period_px: float | None) -> Rig:
    """``rig`` with its camera's resolution times ``camera_scale`` (:func:`simbench.rig.scale_camera`)
    for :func:`record`, refused - before any render - where the factor gives no whole image size,
    or where it takes the fringe's period (``period_px`` projector px; None: no fringe) under
    :data:`simbench.decode.params.MIN_CAMERA_PERIOD_PX` camera pixels (a new user's audit: at 0.1
    the render exited 0, and its folder's decode blamed the reference capture or the calibration;
    phase shifting decoded 74 % of the step, 11.8 mm off, without a word)."""
    from simbench.decode.params import MIN_CAMERA_PERIOD_PX
    from simbench.rig import scale_camera

    try:
        scaled = scale_camera(rig, camera_scale)
    except ValueError as exc:
        raise ValueError(f"camera_scale (--camera-scale): {exc}") from None
    if period_px:
        t_cam = float(period_px) * scaled.camera.focal_px / scaled.projector.focal_px
        if t_cam < MIN_CAMERA_PERIOD_PX:
            # the least factor that both resolves the period and gives whole image sizes (a
            # multiple of 1/step: an audit, 2026-12-05, found the 0.19 suggested refused for them)
            step = math.gcd(rig.camera.width_px, rig.camera.height_px)
            least = math.ceil(step * camera_scale * MIN_CAMERA_PERIOD_PX / t_cam - 1e-9) / step
            raise ValueError(
                f"camera_scale (--camera-scale) {camera_scale:g} takes the fringe's period ({period_px:g} projector "
                f"px) to {t_cam:.2f} camera pixels, under the {MIN_CAMERA_PERIOD_PX:g} its decoding needs (Nyquist: "
                f"2): nothing would decode right; scale by {least:g} or more, a multiple of 1/{step} (or project a "
                "longer period)"
            )
    return scaled


def record(
    scene: str | Path | SceneSpec,
    *,
    system: str = "proposed",
    sensor: str | Path | SensorModel | None = None,
    seed: int | None = None,
    spp: int | None = None,
    sampler: str | None = None,
    max_depth: int = 6,
    calibration_frames: bool = False,
    pattern: PatternSpec | None = None,
    cache: str | Path | RenderCache | None = DEFAULT_CACHE,
    variant: str | None = None,
    camera_scale: float = 1.0,
) -> Recorded:
    """Render and record ``scene`` (a scene file, a library scene by name - ``"step"`` - or a
    loaded scene) with the depth system ``system`` (:func:`simbench.systems.system_names`), the
    proposed one through the sensor model ``sensor`` (a preset of
    :func:`simbench.sim.sensor.get_sensor`, a TOML file or a
    :class:`simbench.sim.sensor.SensorModel`, e.g. one of :func:`simbench.sim.sensor.with_effects`;
    None = ``paper``).
    A ``sensor``, ``pattern`` or ``calibration_frames`` that the system does not record with
    (:attr:`simbench.systems.SystemInfo.recording_options`: the competitors carry their own
    devices) is a ``ValueError``.

    ``calibration_frames``: the proposed sensor also records the reference plane under black and
    each primary, which the colour-robust decoder needs.  ``pattern``: what the proposed sensor
    projects (default: the paper's, at the scene projector's size, as ``simbench render`` makes it;
    the other systems project their own).  ``cache``: the render
    cache folder or a :class:`simbench.cache.RenderCache` (None: render everything, store
    nothing).  ``camera_scale``: the scene rig's camera resolution times this factor, its field
    of view and pose kept (:func:`simbench.rig.scale_camera`; 0.5: 640x480 for the paper's
    camera, as ``simbench reproduce --quick`` renders), for the systems that record with the
    scene's rig; the recording's rig is the scaled one, so that its folder decodes as it is.

    Examples
    --------
    >>> import simbench
    >>> rec = simbench.record("scenes/white_plane.toml", spp=4, cache=None)  # doctest: +SKIP
    >>> rec.raw.shape, rec.raw.dtype  # doctest: +SKIP
    ((960, 1280, 3), dtype('uint8'))
    """
    from simbench.decode import DecoderParams
    from simbench.sim.sensor import SensorModel, check_rig_lens, get_sensor
    from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP, check_sampler
    from simbench.experiments.common import scene_file
    from simbench.sim.scene import load_scene
    from simbench.seeds import DEFAULT_SEED, SeedLog
    from simbench.systems import RenderSettings, SystemOptions, acquire, get_system

    from simbench import validate as v
    from simbench.sim.scene import SceneSpec

    # the command line's checks (its options' ranges), so that a bad argument names itself
    if not isinstance(scene, (str, Path, SceneSpec)):
        raise ValueError(f"scene must be a scene file (str or Path) or a SceneSpec, got {type(scene).__name__}")
    if not (cache is None or isinstance(cache, (str, Path, RenderCache))):
        raise ValueError(f"cache must be a folder (str or Path), a RenderCache or None, got {type(cache).__name__}")
    seed = DEFAULT_SEED if seed is None else v.integer(seed, "seed", lo=SEED_RANGE[0], hi=SEED_RANGE[1])
    spp = DEFAULT_SPP if spp is None else v.integer(spp, "spp", lo=SPP_RANGE[0], hi=SPP_RANGE[1])
    max_depth = v.integer(max_depth, "max_depth", lo=MAX_DEPTH_RANGE[0], hi=MAX_DEPTH_RANGE[1])
    sampler = DEFAULT_SAMPLER if sampler is None else sampler
    check_sampler(sampler, spp)
    camera_scale = v.number(
        camera_scale, "camera_scale", lo=CAMERA_SCALE_RANGE[0], lo_open=True, hi=CAMERA_SCALE_RANGE[1]
    )
    given = {
        "sensor": sensor is not None,
        "pattern": pattern is not None,
        "calibration_frames": bool(calibration_frames),
        "camera_scale": camera_scale != 1.0,
    }
    sensor_model = sensor if isinstance(sensor, SensorModel) else get_sensor("paper" if sensor is None else sensor)
    spec = scene if isinstance(scene, SceneSpec) else load_scene(scene_file(scene))
    if pattern is None and system == "proposed":
        # the paper's pattern at the scene's projector, as `simbench render` makes it (a scene
        # with a projector of its own size was refused: "pattern size (1140, 1824) differs")
        from simbench.pattern import pattern_from_options

        pattern = pattern_from_options(spec.rig.projector.size_hw)
    options = SystemOptions(sensor=sensor_model, decoder=None if pattern is None else DecoderParams(pattern=pattern))
    the_system = get_system(system, options)
    info = the_system.info()
    takes = info.recording_options  # None: a system that does not say takes what applies to it
    stray = [] if takes is None else [name for name, yes in given.items() if yes and name not in takes]
    if stray:  # (they were ignored without a word)
        uses = f"it records with {', '.join(takes)} only" if takes else "its own device"
        verb = "does" if len(stray) == 1 else "do"
        named = " and ".join(f"{k} ({_RECORDING_FLAGS[k]})" for k in stray)
        raise ValueError(
            f"{named} {verb} not apply to the {system} system ({uses}): leave {'it' if len(stray) == 1 else 'them'} out"
        )
    if camera_scale != 1.0:
        spec = dataclasses.replace(spec, rig=scaled_rig(spec.rig, camera_scale, period_px=info.period_px))
    if info.uses_scene_rig:  # (the competitors replace the scene's rig with their own)
        check_rig_lens(spec.rig, sensor_model, where=f"scene {scene if isinstance(scene, (str, Path)) else spec.name}")
    from simbench.sim.timeline import is_moving, placement_warnings
    from simbench.systems import capture_window

    # a moving object is followed over the system's capture (it may come into view during it)
    window = capture_window(the_system, the_system.prepare(spec)) if is_moving(spec) else (0.0, 0.0)
    for told in placement_warnings(spec, window_s=window):
        warnings.warn(f"scene {spec.name}: {told}", SimbenchWarning, stacklevel=2)
    used_variant = _ensure_variant(variant)
    store = cache if isinstance(cache, RenderCache) else RenderCache(None if cache is None else str(cache))
    settings = {
        "system": system,
        # (a system that carries its own device records with no sensor model of ours)
        "sensor": (sensor_model.name if isinstance(sensor, SensorModel) else str(sensor or "paper"))
        if takes is None or "sensor" in takes
        else None,
        "seed": seed,
        "spp": spp,
        "sampler": sampler,
        "max_depth": max_depth,
        "variant": used_variant,
        "camera_scale": camera_scale,
    }
    if system == "proposed":
        from simbench.systems.proposed import acquire_with_calibration

        acq, calibration = acquire_with_calibration(
            spec,
            pattern=the_system.pattern,
            sensor=sensor_model,
            spp=spp,
            sampler=sampler,
            seed=seed,
            max_depth=max_depth,
            with_calibration=calibration_frames,
            cache=store,
        )
        from simbench.systems import Recording

        rec = Recording(system, acq.scene, acq.capture, acq.gt, dict(acq.meta["seeds"]))
        meta = {**acq.meta, **_scene_record(scene, spec), "camera_scale": camera_scale}
        told_all = recording_warnings(spec, rec.gt, DecoderParams(pattern=the_system.pattern))
        if (np.asarray(rec.gt.object_id) >= 0).any():  # (none seen: the render's own error says it)
            told_all += exposure_warnings(rec.raw, acq.scene, sensor_model)
            if calibration is not None:  # the white board itself (a docs check: room light at 0.5 of the
                # projector's white clipped 3.2 % of the reference plane and none of the capture, unsaid)
                told_all += exposure_warnings(
                    calibration.image,
                    acq.scene,
                    sensor_model,
                    what="reference plane's capture",
                    clipped_share=CLIPPED_REFERENCE_SHARE,
                )
        told_all += motion_warnings(acq.scene, rec.gt, the_system)
        for told in told_all:
            warnings.warn(f"scene {spec.name}: {told}", SimbenchWarning, stacklevel=2)
        return Recorded(system, rec, calibration, settings, meta=meta, sensor=sensor_model)
    seeds = SeedLog(seed)
    render_settings = RenderSettings(spp=spp, sampler=sampler, max_depth=max_depth, cache=store)
    prepared = the_system.prepare(spec)
    calibration = the_system.calibrate(prepared, seeds=seeds, render=render_settings)
    rec = acquire(
        the_system, prepared, spec.name, seeds=seeds, render=render_settings, calibration=calibration, prepared=True
    )[0]
    told_all = [*recording_warnings(spec, rec.gt), *motion_warnings(rec.scene, rec.gt, the_system)]
    seen = (np.asarray(rec.gt.object_id) >= 0).any()  # (none seen: the render's own error says it)
    # a system recording through our sensor model; one that does not say, where its frames read as a
    # camera's (an extender's audit, 2026-11-30: an ideal depth camera's metres, 1 m and more, were
    # told "50 % of the capture's pixels are clipped ... auto exposure")
    through_sensor = "sensor" in takes if takes is not None else _camera_values(rec.raw)
    if seen and through_sensor:
        told_all += exposure_warnings(rec.raw, rec.scene, sensor_model)
    for told in told_all:
        warnings.warn(f"scene {spec.name}: {told}", SimbenchWarning, stacklevel=2)
    meta = {
        **_scene_record(scene, spec),
        "camera_scale": camera_scale,
        "spp": spp,
        "sampler": sampler,
        "max_depth": max_depth,
        "seed": seed,
        "seeds": dict(seeds.used),
        "variant": used_variant,
    }
    if takes is None or "sensor" in takes:
        # the sensor model it recorded through, and its exposure, as the proposed sensor's meta.json
        # holds them (an audit: two phase-shift folders of one scene through two sensor models
        # differed only in their files' checksums)
        from simbench.sim.photometry import exposure_s, white_board
        from simbench.sim.sensor import sensor_to_dict

        meta["sensor"] = sensor_to_dict(sensor_model)
        meta["exposure_s"] = (
            exposure_s(sensor_model, prepared.rig, **white_board(prepared)) if sensor_model.is_physical else None
        )
    return Recorded(system, rec, calibration, {**settings, "seeds": dict(seeds.used)}, meta=meta, sensor=sensor_model)


def _camera_values(raw: np.ndarray) -> bool:
    """Whether ``raw`` holds what a camera records (:func:`exposure_warnings`' inputs): an ADC's
    integer codes, or light in [0, 1]."""
    a = np.asarray(raw)
    if np.issubdtype(a.dtype, np.integer):
        return True
    finite = a[np.isfinite(a)] if np.issubdtype(a.dtype, np.floating) else a
    return bool(finite.size == 0 or (finite.min() >= 0.0 and finite.max() <= 1.0))


# an object whose image travels more than this share of its own extent (along its motion) during
# the capture is mostly smeared into what lies behind it: most of its pixels see it for part of the
# capture only, and decode a blend of it and the background, or the background (an audit,
# 2026-11-30: a sphere crossing the view at 40 m/s, invisible in the capture, decoded at the wall's
# depth, 360 mm wrong, at confidence 7-8, without a word)
SMEAR_EXTENT_SHARE = 0.5
# a system that combines several exposures (SystemInfo.captures > 1: phase shifting's 12) assumes
# the scene still across them: warned where a surface moves more than this during the sequence
# (the motion study, results/motion.md: 4-step phase shifting's MAE doubles between 3 and 10 mm/s,
# 1-3 mm over its 0.32 s sequence)
STILL_TRAVEL_MM = 1.0


def motion_warnings(scene: SceneSpec, gt, system) -> list[str]:
    """What a moving scene's recording cannot be trusted for, from its time model and the truth at
    mid-capture (``scene``: the system's prepared scene; ``gt``: its
    :class:`simbench.sim.truth.GroundTruth` with ``motion_px``): an object smeared over more than
    :data:`SMEAR_EXTENT_SHARE` of its own image extent; a multi-exposure system's scene moving more
    than :data:`STILL_TRAVEL_MM` during its sequence; a blur the time slices sample more coarsely
    than :data:`simbench.sim.motion.MAX_SLICE_MOTION_PX` (their count is capped at
    :data:`simbench.sim.motion.MAX_SLICES`).  Nothing for a static scene."""
    from simbench.rig import pixel_rays
    from simbench.sim.motion import MAX_SLICE_MOTION_PX, MAX_SLICES
    from simbench.sim.scene import OBJECT_KIND_TABLE
    from simbench.sim.timeline import image_speed_px_s, is_moving, slice_count

    if gt.motion_px is None or not is_moving(scene):
        return []
    t0, t1 = system.capture_window_s(scene)
    duration = t1 - t0
    out = []
    motion = np.asarray(gt.motion_px, np.float64)
    object_id = np.asarray(gt.object_id)
    rows, cols = np.indices(object_id.shape)
    rays = None
    for k, obj in enumerate(scene.objects):
        sel = object_id == k
        if obj.motion is None or obj.motion.is_static or not sel.any():
            continue
        travel = np.hypot(motion[sel, 0], motion[sel, 1])
        worst = int(np.argmax(travel))
        if travel[worst] > 0:
            direction = motion[sel][worst] / travel[worst]
            along = cols[sel] * direction[0] + rows[sel] * direction[1]
            extent = float(along.max() - along.min() + 1.0)
            if travel[worst] > SMEAR_EXTENT_SHARE * extent:
                out.append(
                    f"object {obj.name!r} moves {travel[worst]:.0f} px across the image during the "
                    f"{duration * 1e3:.3g} ms capture, more than {SMEAR_EXTENT_SHARE:g} of its own {extent:.0f} px "
                    "extent: most of its pixels see it for part of the capture only, and their depth is a blend of it "
                    "and what lies behind it, or the background's - at full confidence (docs/motion.md)"
                )
        if system.info().captures > 1:
            if rays is None:
                rays = pixel_rays(scene.rig.camera)
            m = obj.motion
            points = rays[sel] * np.asarray(gt.depth_m, np.float64)[sel, None]
            # the rotation's centre as the motion turns about it: its own, or the object's position
            position = dict(obj.params)[OBJECT_KIND_TABLE[obj.kind].position_key]
            centre = np.asarray(m.centre_m if m.centre_m is not None else position, np.float64)
            reach = float(np.linalg.norm(points - centre, axis=1).max())
            moved_mm = (
                1e3
                * duration
                * (float(np.linalg.norm(m.velocity_m_s)) + np.radians(abs(m.angular_velocity_deg_s)) * reach)
            )
            if moved_mm > STILL_TRAVEL_MM:
                out.append(
                    f"object {obj.name!r} moves up to {moved_mm:.3g} mm during the {duration:.3g} s sequence of "
                    f"{system.info().captures} exposures, which the {system.name} decode assumes still: beyond "
                    f"~{STILL_TRAVEL_MM:g} mm its error grows many-fold (results/motion.md: 4-step phase shifting's "
                    "MAE doubles between 3 and 10 mm/s)"
                )
    # each exposure's blur is rendered over its own window (phase shifting's frames, the ToF's
    # samples; one window for the others, the Kinect's whole rolling readout)
    frames = getattr(system, "frame_windows_s", None)
    for w0, w1 in frames(scene) if frames is not None else [(t0, t1)]:
        # the fastest in-view motion over a slice's length (the slices are even in time)
        reach = image_speed_px_s(scene, scene.rig.camera, w0, w1) * (w1 - w0)
        n = slice_count(scene, scene.rig.camera, (w0, w1))
        if reach / n > MAX_SLICE_MOTION_PX * 1.001:
            out.append(
                f"the blur is sampled in {n} time slices (at most {MAX_SLICES}) over an exposure in which the image "
                f"moves at up to {reach:.0f} px an exposure: {reach / n:.2f} px a slice, more than "
                f"{MAX_SLICE_MOTION_PX:g} - a strobed sequence of images, not a smooth blur; lower the speed or the "
                "exposure"
            )
            break
    return out


def _scene_record(scene, spec: SceneSpec) -> dict:
    """What a recording's manifest says of its scene: its name, the file it was read from (as
    given; None for a SceneSpec) and the SHA-256 of everything about it that affects a render
    (:func:`simbench.sim.scene.scene_fingerprint`), so that two scenes of one name - a static and
    a moving board, say - are told apart (a fourth audit: only the name was recorded)."""
    from simbench.io import json_bytes
    from simbench.sim.scene import scene_fingerprint

    return {
        "scene": spec.name,
        "scene_file": str(scene) if isinstance(scene, (str, Path)) else None,
        "scene_sha256": hashlib.sha256(json_bytes(scene_fingerprint(spec))).hexdigest(),
    }


def _decoding_rig(rig, recorded: Recorded, options, *, mode: str, told: list[str]) -> Rig:
    """``rig`` (a Rig or a rig TOML) checked as ``simbench decode --rig`` checks it: a calibration
    of the rig ``recorded`` was recorded with, for a system that decodes with the scene's rig.  The
    checks' warnings (a rig within the tolerance but off) go into ``told``, for the caller to give
    as :class:`SimbenchWarning` (an audit, 2026-12-05: logged, they passed a script that made
    SimbenchWarning an error, with a rig's baseline 1.6 % long: 17 mm MAE)."""
    from simbench.rig import Rig, load_rig
    from simbench.systems import get_system
    from simbench.systems.files import check_rig_on_a_plane, refuse_another_rig

    if isinstance(rig, (str, Path)):
        name, rig = str(rig), load_rig(rig)
    elif isinstance(rig, Rig):
        name = repr(rig.name) if rig.name else "given"
    else:
        raise ValueError(f"rig must be a Rig, a rig TOML file (str or Path) or None, got {type(rig).__name__}")
    system = get_system(recorded.system, options)
    if not system.info().uses_scene_rig:
        raise ValueError(
            f"rig applies to systems decoding with the scene's rig; the {recorded.system} system keeps its device's "
            "factory calibration: leave rig out"
        )
    label = f"rig {name}"
    recorded_rig = recorded.recording.scene.rig
    if rig.camera.size_hw != recorded_rig.camera.size_hw:
        raise ValueError(
            f"{label}: camera {rig.camera.width_px}x{rig.camera.height_px}, but the recording's is "
            f"{recorded_rig.camera.width_px}x{recorded_rig.camera.height_px}"
        )
    refuse_another_rig(rig, recorded_rig, rig_path=None, capture="the recording", label=label)
    if recorded.system == "proposed":
        from simbench.decode import DecoderParams
        from simbench.systems.proposed_folder import check_reference_plane

        # the recording's reference plane, decoded with this rig, must lie at its Z0 (as a folder's is)
        params = DecoderParams(
            pattern=recorded.pattern or system.pattern, z0_m=recorded.recording.scene.reference_depth_m
        )
        plane = recorded.calibration.reference_map(params, rig=rig)
        check_reference_plane(
            plane,
            rig,
            reference_path="of the recording",
            rig_path=name,
            recorded_z0=True,
            mode=mode,
            rig_option="rig=",
            tell=told.append,
        )
    else:
        check_rig_on_a_plane(rig, recorded_rig, rig_path=None, capture="the recording", label=label, tell=told.append)
    return rig


def depth(
    recorded: Recorded,
    *,
    decoder: str | DecoderParams = "paper",
    mode: str | None = None,
    min_confidence: float | None = None,
    rig: Rig | str | Path | None = None,
    decoder_settings: Mapping[str, object] | None = None,
) -> SystemDepth:
    """``recorded`` decoded the way its system decodes, into depth (float32 metres, NaN where
    invalid), a validity mask and a per-pixel confidence (:class:`simbench.systems.SystemDepth`).

    ``rig``: the rig the decoder believes (a :class:`simbench.rig.Rig` or a rig TOML, e.g.
    ``simbench calibrate``'s rig.toml), as ``simbench decode --rig`` takes it; None = the rig it
    was recorded with.  It must be a calibration of that rig - the same camera size, no
    parameter far off (:func:`simbench.rig.rig_differences`), its reference plane (the proposed
    sensor's) or a plane at 1 m (phase shifting) triangulated within tolerance - else a
    ``ValueError``; systems that keep their device's factory calibration (Kinect, ToF) take none.

    For the proposed sensor, ``decoder`` is ``"paper"`` (the paper's decoder), ``"robust"`` (our
    colour-robust decoder at its operating point; needs ``record(..., calibration_frames=True)``)
    or a :class:`simbench.decode.DecoderParams`; ``mode`` ``"reference"`` (default: the reference
    plane, paper Sec. 5.4; a DecoderParams' own mode where it is given one) or ``"calibrated"``
    (triangulation with the rig, Eq. 15).  ``mode`` and ``min_confidence``, given, replace the
    DecoderParams' own.
    ``min_confidence``: the operating point, pixels below it holes (every system; in the system's
    own unit, :attr:`simbench.systems.SystemInfo.confidence`); for the proposed sensor the
    decoder's own threshold, as ``simbench decode --min-confidence`` sets it - in [0, 1e4] (the
    fringe SNR's cap; other systems' units: [0, 1e6]), and below the colour-robust decoder's
    default (3) it keeps more pixels, not fewer.
    ``decoder_settings``: settings on top of the named decoder's (``"paper"`` or ``"robust"``,
    with the recorded pattern), as ``simbench decode --decoder NAME=VALUE`` gives them
    (:func:`simbench.decode.params.with_changes`), e.g. ``depth(rec, decoder="robust",
    decoder_settings={"voting": False})``; a DecoderParams carries its own.
    """
    from simbench.decode import DecoderParams, robust_params
    from simbench.decode.params import with_changes
    from simbench.decode.pipeline import code_order_doubt, code_succession_doubt, without_depth
    from simbench.systems.proposed import describe_pattern
    from simbench.sim.sensor import get_sensor
    from simbench.systems import SystemDepth, SystemOptions, get_system

    from simbench import validate as v

    if not isinstance(recorded, Recorded):
        raise ValueError(f"depth() decodes what record() returned, got {type(recorded).__name__}")
    if mode is not None:
        v.choice(mode, "mode", ("reference", "calibrated"))
    if min_confidence is not None:
        min_confidence = v.number(
            min_confidence, "min_confidence", lo=MIN_CONFIDENCE_RANGE[0], hi=MIN_CONFIDENCE_RANGE[1]
        )
    if decoder_settings is not None:
        if not isinstance(decoder_settings, Mapping):
            raise ValueError(
                f"decoder_settings must be a mapping of decoder settings, got {type(decoder_settings).__name__}"
            )
        if not isinstance(decoder, str):
            raise ValueError(
                "decoder_settings= go on top of decoder='paper' or 'robust'; a DecoderParams carries its own (give "
                "dataclasses.replace(params, ...) instead)"
            )
        # (a review: each was dropped without a word) the scene's own Z0 is the reference plane's
        if "z0_m" in decoder_settings:
            raise ValueError(
                "decoder_settings: z0_m is the recording's own (its reference plane's depth): leave it out"
            )
        for name, given in (("mode", mode), ("min_confidence", min_confidence)):
            if name in decoder_settings and given is not None and decoder_settings[name] != given:
                raise ValueError(
                    f"{name}={given!r} and decoder_settings {name}={decoder_settings[name]!r} disagree: give one"
                )
    # the mode a DecoderParams or the settings name, else reference matching
    own_mode = decoder.mode if not isinstance(decoder, str) else (decoder_settings or {}).get("mode", "reference")
    rec = recorded.recording
    options = SystemOptions(sensor=recorded.sensor or get_sensor(recorded.settings.get("sensor") or "paper"))
    scene = rec.scene
    if rig is not None:
        asked = mode or own_mode
        told: list[str] = []
        scene = dataclasses.replace(scene, rig=_decoding_rig(rig, recorded, options, mode=asked, told=told))
        for message in told:
            warnings.warn(message, SimbenchWarning, stacklevel=2)
    if recorded.system == "proposed":
        system = get_system("proposed", options)
        # the pattern it was recorded with (an audit: a period-30 recording was decoded with the
        # default period 21, 2.17 mm MAE and 88 % stripe-order errors without a word)
        pattern = recorded.pattern or system.pattern
        if isinstance(decoder, str):
            if decoder not in ("paper", "robust"):
                raise ValueError(f"decoder must be 'paper', 'robust' or a DecoderParams, got {decoder!r}")
            params = DecoderParams(pattern=pattern)
            params = robust_params(params) if decoder == "robust" else params
            if decoder_settings is not None:
                params = with_changes(params, dict(decoder_settings))
        else:
            params = decoder
        if not params.pattern.projects_as(pattern):
            recorded_as = "the one recorded" if recorded.pattern else "the paper's (no pattern recorded)"
            raise ValueError(
                f"the decoder's pattern ({describe_pattern(params.pattern)}) is not {recorded_as} "
                f"({describe_pattern(pattern)}): decode with dataclasses.replace(params, pattern=recorded.pattern), "
                "or name the decoder ('paper', 'robust') and give decoder_settings={...} on top of it"
            )
        if min_confidence is not None:
            # the decode's own threshold, as `simbench decode --min-confidence` sets it (an audit:
            # thresholding after the robust decoder's own 3 ignored any value below it)
            params = dataclasses.replace(params, min_confidence=min_confidence)
        # mode given: it; else a DecoderParams' own (a review: mode=None decoded DecoderParams(mode="calibrated")
        # by reference matching)
        mode = mode or own_mode
        if params.unmix and not recorded.calibration.frames:
            raise ValueError(
                "the colour-robust decoder unmixes with the reference plane's calibration frames: record with "
                "calibration_frames=True"
            )
        from simbench.decode.pipeline import capture_warnings

        for told in capture_warnings(rec.raw, rig=scene.rig, params=params):  # as `simbench decode` warns
            warnings.warn(told, SimbenchWarning, stacklevel=2)
        result = system.decode(rec.raw, recorded.calibration, scene=scene, params=params, mode=mode)
        # as `simbench decode`: a capture whose stripes do not read in the pattern's order (mirrored,
        # red and green swapped) gives no depth rather than half of it wrong
        doubt = code_order_doubt(result.detail.window_succession)
        if doubt:
            warnings.warn(f"no pixel decoded: {doubt}", SimbenchWarning, stacklevel=2)
            result = dataclasses.replace(without_depth(result), detail=without_depth(result.detail))
        else:
            from simbench.decode.pipeline import registration_warning

            # as the system decoded it: the scene's Z0, the mode asked (the paper's decoder measures no
            # registration: it is measured here, against the reference capture's in reference mode)
            used = dataclasses.replace(params, mode=mode, z0_m=scene.reference_depth_m)
            ref = None
            if mode == "reference":  # the decode's own (cached): what its registration was measured against
                ref = recorded.calibration.reference_map(dataclasses.replace(used, mode="reference"), rig=scene.rig)
            told = registration_warning(rec.raw, result.detail, rig=scene.rig, params=used, reference=ref)
            if told:
                warnings.warn(told, SimbenchWarning, stacklevel=2)
            told = code_succession_doubt(result.detail.window_succession, pattern_known=True)
            if told:
                warnings.warn(told, SimbenchWarning, stacklevel=2)
    else:
        if not (isinstance(decoder, str) and decoder == "paper") or mode is not None or decoder_settings is not None:
            raise ValueError(
                f"the {recorded.system} system decodes its own way: decoder, decoder_settings and mode are the "
                "proposed's"
            )
        result = get_system(recorded.system, options).decode(rec.raw, recorded.calibration, scene=scene)
    if min_confidence is None or recorded.system == "proposed":
        return result
    if result.confidence is None:
        raise ValueError(f"the {recorded.system} system has no confidence to threshold")
    keep = result.valid & (result.confidence >= float(min_confidence))
    return SystemDepth(
        depth_m=np.where(keep, result.depth_m, np.nan).astype(np.float32),
        valid=keep,
        confidence=result.confidence,
        column_px=result.column_px,
        detail=result.detail,
    )


def score(depth: SystemDepth | np.ndarray, recorded: Recorded, *, edge_band_px: int = 0) -> dict:
    """``simbench score``'s numbers for a decoded ``depth`` of ``recorded``
    (:func:`simbench.metrics.depth_errors`): MAE, RMSE, median and p95 error (mm), completeness
    over the lit pixels, the share of outliers more than 5 mm off and, where the system decodes
    projector columns, stripe-order errors; pixels within ``edge_band_px`` of a depth edge are
    left out of the errors (the completeness still counts them).  Of a moving recording, against
    its truth at mid-capture, with ``image_motion_px``: its fastest pixel's image motion over the
    capture (:data:`simbench.metrics.MOVING_TRUTH_NOTE`).  With every decoded pixel's counts
    and wrong share (:func:`simbench.metrics.every_decoded_pixel`: ``n_decoded``,
    ``n_decoded_outside``, ``wrong_share_all``), the lit region's errors leaving those out."""
    from simbench.metrics import depth_errors, edge_band, every_decoded_pixel, image_motion_px
    from simbench.metrics import implausible_columns, implausible_depth
    from simbench.systems import get_system

    from simbench import validate as v

    if isinstance(depth, Recorded) or not isinstance(recorded, Recorded):
        raise ValueError(
            f"score(depth, recorded): a depth map (or depth()'s result) and what record() returned, got "
            f"{type(depth).__name__} and {type(recorded).__name__}"
        )
    edge_band_px = v.integer(edge_band_px, "edge_band_px", lo=EDGE_BAND_RANGE_PX[0], hi=EDGE_BAND_RANGE_PX[1])
    gt = recorded.gt
    depth_m = np.asarray(getattr(depth, "depth_m", depth), dtype=np.float32)
    if depth_m.shape != gt.depth_m.shape:
        raise ValueError(f"depth of shape {depth_m.shape} does not match the recording's {gt.depth_m.shape}")
    exclude = edge_band(gt.depth_m, object_id=gt.object_id, band_px=edge_band_px) if edge_band_px > 0 else None
    column = getattr(depth, "column_px", None)
    pattern = recorded.pattern
    period = None if column is None else pattern.period_px if pattern else get_system(recorded.system).info().period_px
    kw = {"column_px": column, "gt_column_px": gt.column_px, "period_px": period} if period else {}
    # as `simbench score`: a map in other units, or of another scene, is scored with a warning
    for warning in implausible_depth(depth_m, gt.depth_m, np.asarray(gt.lit, bool)):
        warnings.warn(f"score: the depth map: {warning}", SimbenchWarning, stacklevel=2)
    if kw:
        for warning in implausible_columns(column, gt.column_px):
            warnings.warn(f"score: the depth's column_px: {warning}", SimbenchWarning, stacklevel=2)
    scores = depth_errors(depth_m, gt.depth_m, region=gt.lit, exclude=exclude, **kw)
    # as `simbench score`: every decoded pixel too, those outside the lit region included
    scores.update(every_decoded_pixel(depth_m, gt.depth_m, gt.lit))
    if getattr(gt, "motion_px", None) is not None:  # as `simbench score`: the truth is one moving instant
        scores["image_motion_px"] = image_motion_px(gt.motion_px)
    return scores
