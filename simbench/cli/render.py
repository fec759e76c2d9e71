"""``simbench pattern`` and ``simbench render``: the pattern image, and a scene recorded by a depth system."""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

from simbench.seeds import DEFAULT_SEED
from simbench.cli.options import (
    CAMERA_SCALE,
    MAX_DEPTH,
    SEED,
    add_cache_options,
    add_pattern_options,
    add_render_options,
    cache_of,
    int_in,
    pattern_spec,
    registered_systems,
    render_settings,
)


def _cmd_pattern(args) -> int:
    from simbench.io import check_output_file, save_png
    from simbench.pattern import fringe_pattern, quantize

    spec = pattern_spec(args, (args.height, args.width))
    check_output_file(args.out, what="--out")  # a folder, or one this process may not write in
    path = save_png(args.out, quantize(fringe_pattern(spec)))
    codes = "".join(map(str, spec.codes()))
    if len(codes) > 64:  # a long window's cycle (order 12: 4096 codes) is no line to read
        codes = f"{codes[:32]}...{codes[-8:]} ({len(codes)} codes)"
    print(
        f"pattern {args.width}x{args.height}, period {spec.period_px} px, codes {codes} (window {spec.order}) -> {path}"
    )
    return 0


def _cmd_render(args) -> int:
    from simbench.io import claim_output

    # one writer of an output folder at a time: a second fails before its work
    with claim_output(args.out):
        return _render(args)


def _render(args) -> int:
    from simbench import api, cache as cache_module
    from simbench.decode import DecoderParams
    from simbench.experiments.common import scene_file
    from simbench.io import check_output_directory
    from simbench.sim.scene import load_scene
    from simbench.sim.sensor import get_sensor
    from simbench.systems import RECORDING_MANIFESTS, SystemOptions, get_system, system_names

    if args.system not in system_names():  # an unknown name fails before anything else
        get_system(args.system)
    scene = load_scene(scene_file(args.scene))
    pattern = pattern_spec(args, scene.rig.projector.size_hw)
    # a system that projects a coded pattern projects the pattern options'; the others their own
    system = get_system(
        args.system, SystemOptions(sensor=get_sensor(args.camera or "paper"), decoder=DecoderParams(pattern=pattern))
    )
    info = system.info()
    options = info.recording_options  # None: a system that does not say takes what applies
    if args.camera_scale != 1.0 and (options is None or "camera_scale" in options):
        from simbench.api import scaled_rig

        # the camera the render will have, refused before anything else where it cannot be (a
        # system with its own device is refused the option by simbench.record)
        scene = dataclasses.replace(scene, rig=scaled_rig(scene.rig, args.camera_scale, period_px=info.period_px))
    pattern_given = any(getattr(args, k) is not None for k in ("period", "order", "sequence", "channels"))
    takes_pattern = options is None or "pattern" in options
    if options is not None and "pattern" in options:  # a system that projects the coded pattern
        import logging

        from simbench.decode.params import pattern_on_rig_warnings

        # (a rig no decoder reads is refused by the system's prepare(), before any render)
        # what the pattern on this rig will give the decoder (its default working range), before
        # minutes of rendering (a new user's audit: each was found only after the decode)
        for told in pattern_on_rig_warnings(scene.rig, DecoderParams(pattern=pattern)):
            logging.getLogger("simbench").warning("%s: %s", args.scene, told)
    spp, sampler = render_settings(args)
    # before minutes of rendering
    check_output_directory(args.out, manifest=RECORDING_MANIFESTS, overwrite=args.overwrite)
    replaced = _earlier_recording(Path(args.out))
    if replaced:
        # what --overwrite takes with it (a bring-your-own-decoder audit, 2026-12-05: a depth map
        # of one's own in the folder went without a word)
        from simbench.io import not_recorded
        from simbench.systems import RECORDING_MANIFESTS

        extra, changed = not_recorded(Path(args.out), RECORDING_MANIFESTS)
        theirs = sorted(extra + changed)
        if theirs:
            shown = ", ".join(theirs[:8]) + (f" and {len(theirs) - 8} more" if len(theirs) > 8 else "")
            replaced += f", and with it {len(theirs)} file(s) it did not record or that changed since: {shown}"

    if not args.no_cache:
        from simbench.cache import CACHE_HINT, check_cache_location

        cache_dir, out_dir = Path(args.cache).resolve(), Path(args.out).resolve()
        if cache_dir == out_dir or out_dir in cache_dir.parents or cache_dir in out_dir.parents:
            raise ValueError(
                f"--cache {args.cache} and --out {args.out} overlap: the render cache needs its own folder"
            )
        check_cache_location(args.cache, what="--cache", hint=CACHE_HINT)
    t0 = time.perf_counter()
    cache = cache_of(args)

    def made(kind: str, seconds: float) -> None:
        # progress on a cold render (a minute or more): each entry that took a while to make (a
        # render that fails at once - nothing in view - keeps its one line of error)
        if seconds >= cache_module.PROGRESS_MIN_S:
            print(
                f"simbench: {kind} made in {seconds:.1f} s ({time.perf_counter() - t0:.0f} s so far)",
                file=sys.stderr,
                flush=True,
            )

    cache.on_made = made
    rec = api.record(
        args.scene,
        system=args.system,
        sensor=args.camera,
        seed=args.seed,
        spp=spp,
        sampler=sampler,
        max_depth=args.max_depth,
        calibration_frames=args.calibration_frames,
        # (a system that projects no coded pattern is refused one only when the options gave it)
        pattern=pattern if pattern_given or takes_pattern else None,
        cache=cache,
        variant=args.variant,
        camera_scale=args.camera_scale,
    )
    _check_visible(rec.gt, scene)
    files = system.write_recording(
        Path(args.out), rec.raw, rec.calibration, scene=rec.scene, gt=rec.gt, meta=rec.meta, overwrite=args.overwrite
    )
    # entries read and made, not "n of m": a warm run looks up fewer entries than a cold one made
    # (a cached result spares the lookups of what it was made from)
    damaged = f" ({cache.damaged} of them damaged entries, re-made)" if cache.damaged else ""
    if cache.unstored:
        damaged += (
            f", {cache.unstored} not stored ({'the cache is read only' if cache.read_only else 'its disk is full'})"
        )
    cached = (
        f", render cache: {cache.hits} entries read, {cache.misses} made{damaged}" if cache.root is not None else ""
    )
    at = ""
    if args.camera_scale != 1.0:  # (a new user's audit: only the lens line's rig name said it)
        cam = scene.rig.camera  # (scaled above)
        at = f" at {cam.width_px}x{cam.height_px} (--camera-scale {args.camera_scale:g})"
    print(
        f"rendered {scene.name}{at} with the {info.label} ({rec.settings['variant']}, {spp} spp {sampler}, "
        f"seed {args.seed}{cached}) in {time.perf_counter() - t0:.1f} s -> {Path(args.out)}/"
    )
    t_exp = rec.meta.get("exposure_s")
    if t_exp:  # (an audit: only meta.json said it)
        from simbench.sim.sensor import PhysicalCamera

        cam = rec.sensor.camera if rec.sensor is not None else None
        how = (
            f"the auto exposure: the white board at {100 * cam.auto_exposure_fraction:.0f} % of the full well"
            if isinstance(cam, PhysicalCamera) and cam.exposure_s is None
            else "as the sensor model sets it"
        )
        print(f"  exposure {t_exp * 1e3:.4g} ms ({how})")
    if not info.uses_scene_rig:  # (a new user's audit: their own rig was set aside without a word)
        h, w = info.size_hw
        print(f"  (with the {info.label}'s own {w}x{h} rig: the scene's rig {scene.rig.name!r} set aside)")
    elif rec.sensor is not None:
        # (a new user's audit: an undistorted rig of their own came back in rig.toml with the
        # sensor model's lens distortion, without a word)
        from simbench.sim.sensor import apply_to_rig

        lensed = apply_to_rig(scene.rig, rec.sensor)
        if lensed is not scene.rig:
            print(
                f"  (the sensor model's lens distortion is on rig {scene.rig.name!r}: camera "
                f"{_coefficients(lensed.camera.distortion)}, projector {_coefficients(lensed.projector.distortion)}, "
                "as rig.toml records; --sensor minimal or ideal renders the rig's own lenses)"
            )
    if replaced:
        print(f"  (replaced {replaced} there)")
    for key, path in files.items():
        print(f"  {key:17s} {path.name}")
    if hasattr(rec.calibration, "reference_map"):  # a system decoding against the scene's reference plane
        _warn_reference_outside_range(scene, rec.meta)
    return 0


def _coefficients(d) -> str:
    """Lens distortion coefficients in OpenCV's order, the trailing zeros left out."""
    names = ("k1", "k2", "p1", "p2", "k3")
    shown = [f"{n} = {float(v):g}" for n, v in zip(names, d) if float(v) != 0.0]
    return ", ".join(shown) or "none"


def _warn_reference_outside_range(scene, meta: dict) -> None:
    """A reference plane outside the decoder's default working range is legal, but the decode
    then needs --near/--far around it, and the exposure set for a white board there may be
    long past any camera's (a new user's audit: Z0 = 100 m gave a 270-s exposure, and its
    decode pointed at saturation, not at the distance)."""
    from simbench.systems.files import WORKING_RANGE_M

    z0 = float(scene.reference_depth_m)
    near, far = WORKING_RANGE_M
    if near <= z0 <= far:
        return
    exposure = meta.get("exposure_s")
    told = f"; the exposure set for a white board there: {exposure:.3g} s" if isinstance(exposure, float) else ""
    print(
        f"simbench: warning: {scene.name}: its reference plane (reference_depth_m = {z0:g} m) lies outside the "
        f"decoder's default working range {near:g}-{far:g} m (decode needs --near/--far around it){told}",
        file=sys.stderr,
    )


def _earlier_recording(out: Path) -> str:
    """What the recording folder ``out`` holds before a render replaces it (its scene and
    system, as its manifest names them), or "" when it is absent or empty."""
    from simbench.manifest import json_object
    from simbench.systems import RECORDING_MANIFESTS

    if not out.is_dir() or not any(out.iterdir()):
        return ""
    for name in RECORDING_MANIFESTS:
        try:
            meta = json_object(out / name)
        except (OSError, ValueError):
            continue
        scene = meta.get("scene")
        scene = scene.get("name") if isinstance(scene, dict) else scene
        system = meta.get("system") or meta.get("device") or "?"
        return f"a {system} recording" + (f" of scene {scene}" if scene else "")
    return ""  # no manifest: check_output_directory refused the folder already


def _check_visible(gt, scene) -> None:
    """A render in which no object of the scene reaches the camera is an error, not a folder of
    black images (objects behind the camera, far outside its view, or too small to see)."""
    if not np.isfinite(gt.depth_m).any():
        raise ValueError(
            f"scene {scene.name!r}: no object is visible to the camera (every one is behind it, outside its field of "
            "view or smaller than a pixel); nothing was written"
        )


def add_parsers(sub, kw: dict) -> None:
    """Add this module's commands to the command line's subparsers."""
    from simbench.systems import DEFAULT_SYSTEM
    from simbench.validate import MAX_SIDE_PX

    s = sub.add_parser("pattern", help="write the colour sequence coded fringe pattern (PNG)", **kw)
    s.add_argument("--out", required=True, help="PNG file to write")
    s.add_argument(
        "--width",
        type=int_in(1, MAX_SIDE_PX),
        default=1824,
        help="pattern width, projector px (the LightCrafter 4500's)",
    )
    s.add_argument("--height", type=int_in(1, MAX_SIDE_PX), default=1140, help="pattern height, projector px")
    add_pattern_options(s)
    s.set_defaults(fn=_cmd_pattern)

    s = sub.add_parser(
        "render", help="render a scene with a depth system: its raw frames, calibration, ground truth, metadata", **kw
    )
    s.add_argument(
        "scene",
        help="scene TOML file, or a library scene by name from any folder (step: scenes/step.toml; scenes/README.md)",
    )
    s.add_argument(
        "--system",
        default=DEFAULT_SYSTEM,
        help=f"depth system (registered: {', '.join(registered_systems())}); the colour-fringe sensor and phase "
        "shifting record with the scene's rig, a device with its own (the Kinect, the ToF camera) sets it aside and "
        "says so",
    )
    s.add_argument(
        "--out", required=True, help="output folder (written whole or not at all; an earlier render there is replaced)"
    )
    s.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output folder even if it holds files render did not write (e.g. decoded depth)",
    )
    add_render_options(s)
    add_cache_options(s)
    s.add_argument(
        "--calibration-frames",
        action="store_true",
        help="also record the reference plane under black and each primary (calibration_*.png), which `simbench "
        "decode --robust` needs",
    )
    s.add_argument(
        "--seed",
        type=SEED,
        default=DEFAULT_SEED,
        help="base seed (every render and noise seed derives from it and a label; all recorded in the manifest)",
    )
    s.add_argument("--max-depth", type=MAX_DEPTH, default=6, help="longest light path (2 = direct light only)")
    s.add_argument(
        "--camera-scale",
        type=CAMERA_SCALE,
        default=1.0,
        help="the scene rig's camera resolution times this factor, in (0, 4], field of view and pose kept: a sensor "
        "of as many more or fewer pixels of the same pitch behind a lens as much longer or shorter at the same "
        "f-number (the same light per pixel; defocus blur in pixels scales with the factor squared). 0.5: 640x480 "
        "for the paper's camera, as reproduce --quick renders; 0.25 for a test render in seconds. The factor must "
        "give whole image sizes and keep the fringe's period at 4 camera pixels or more. The recording's rig.toml "
        "holds the scaled camera, so that the folder decodes as it is (for the systems that record with the scene's "
        "rig)",
    )
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default=None,
        help="sensor model: a preset (paper: the Flea3 + LightCrafter physics; paper_sim: the paper's 3ds Max "
        "simulation, a linear noise-free RGB camera; minimal: noise only; ideal: nothing) or a sensor TOML file "
        "(default: paper; for the systems that record through one: the others carry their own devices)",
    )
    add_pattern_options(s)
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_render)
