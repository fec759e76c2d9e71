"""``simbench calibrate``: a rig calibrated as a lab does, through a sensor model."""

from __future__ import annotations

import sys
import time
from pathlib import Path


from simbench.seeds import DEFAULT_SEED
from simbench.cli.options import (
    MAX_DEPTH,
    SEED,
    SPP,
    add_cache_options,
    cache_of,
    calibration_defaults,
    distortion_models,
    int_in,
    samplers,
)


def _cmd_calibrate(args) -> int:
    from simbench.io import claim_output

    # one writer of an output folder at a time: a second fails before its work
    with claim_output(args.out):
        return _calibrate(args)


def _calibrate(args) -> int:
    from simbench.calibration import calibrate_rig, check_calibration, get_target, true_rig
    from simbench.calibration.procedure import DEFAULT_POSES
    from simbench.calibration.report import write_calibration
    from simbench.sim.sensor import get_sensor
    from simbench.io import check_output_directory
    from simbench.sim.mitsuba_dict import RenderSettings, check_sampler
    from simbench.rig import get_rig
    from simbench.variant import select_variant

    rig = get_rig(args.rig)
    target = get_target(args.target)
    sensor = get_sensor(args.camera)
    check_sampler(args.sampler, args.spp)
    check_sampler(args.sampler, args.corner_spp)
    check_output_directory(args.out, manifest="calibration.json", overwrite=args.overwrite)
    # an earlier calibration there is replaced: said with the result, as render says it (a docs
    # audit, 2026-11-30: calibrate replaced its own folder without a word)
    replaced = (Path(args.out) / "calibration.json").is_file()
    check_calibration(rig, target=target, sensor=sensor)
    if not args.no_cache:  # as render and decode check it (an audit: calibrate failed mid-run on a raw errno)
        from simbench.cache import CACHE_HINT, check_cache_location

        check_cache_location(args.cache, what="--cache", hint=CACHE_HINT)
    variant = select_variant(args.variant)
    advice = (
        f"(OpenCV asks for >= {DEFAULT_POSES}): its lens distortion and principal points are poorly determined "
        "(report.md: its errors against the true rig) - fine for trying the commands, not for results"
    )
    if args.poses < DEFAULT_POSES:  # said before minutes of rendering, not after (a second audit)
        print(f"simbench: warning: a rig from {args.poses} poses {advice}", file=sys.stderr, flush=True)
    cache = cache_of(args)
    render = RenderSettings(spp=args.spp, sampler=args.sampler, max_depth=args.max_depth, cache=cache)
    t0 = time.perf_counter()

    def progress(done: int, total: int) -> None:
        print(f"simbench: pose {done}/{total} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr, flush=True)

    result = calibrate_rig(
        rig,
        target=target,
        sensor=sensor,
        poses=args.poses,
        seed=args.seed,
        render=render,
        corner_spp=args.corner_spp,
        distortion=args.distortion,
        progress=progress,
    )
    settings = {
        "rig": str(args.rig),
        "target": str(args.target),
        "sensor": str(args.camera),
        "poses": args.poses,
        "seed": args.seed,
        "spp": args.spp,
        "corner_spp": args.corner_spp,
        "sampler": args.sampler,
        "max_depth": args.max_depth,
        "distortion": args.distortion,
        "variant": variant,
    }
    command = "simbench " + " ".join(sys.argv[1:]) if sys.argv[1:2] == ["calibrate"] else "simbench calibrate"
    files = write_calibration(
        args.out,
        result,
        target=target,
        truth=true_rig(rig, sensor),
        settings=settings,
        command=command,
        overwrite=args.overwrite,
    )
    rms = result.rms_px
    # the poses observed here (each observation one cache entry); the rest were read (the cache
    # also serves the poses' projector depth maps, which its hit count would add)
    observed = cache.made.get("calibration_view", (0, 0.0))[0]
    cached = f", {args.poses - observed} of {args.poses} poses from the cache" if cache.root is not None else ""
    print(
        f"calibrated {rig.name} through sensor model {args.camera} from {len(result.used_views)} of {args.poses} poses "
        f"({variant}{cached}) in {time.perf_counter() - t0:.1f} s: reprojection RMS camera {rms['camera']:.3f} px, "
        f"projector {rms['projector']:.3f} px, stereo {rms['stereo']:.3f} px -> {Path(args.out)}/"
    )
    for key, path in files.items():
        print(f"  {key:9s} {path.name}")
    if replaced:
        print("  (replaced an earlier calibration there)")
    if len(result.used_views) < min(args.poses, DEFAULT_POSES):  # poses the target's corners were not found in
        print(f"simbench: warning: a rig from {len(result.used_views)} of {args.poses} poses {advice}", file=sys.stderr)
    return 0


def add_parsers(sub, kw: dict) -> None:
    """Add this module's commands to the command line's subparsers."""
    s = sub.add_parser(
        "calibrate",
        help="calibrate a rig as a lab does: a printed target at seeded poses, rendered through the sensor model, "
        "solved with OpenCV; writes the estimated rig (rig.toml), a report and a figure",
        **kw,
    )
    s.add_argument("--rig", default="paper", help="the rig to calibrate: a preset (paper) or a rig TOML file")
    s.add_argument(
        "--target", default="checkerboard", help="calibration target: a preset (checkerboard) or a target TOML file"
    )
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default="paper",
        help="sensor model the calibration images go through (a preset or a sensor TOML file)",
    )
    cal = calibration_defaults()
    s.add_argument(
        "--poses",
        type=int_in(3, 200),
        default=cal["poses"],
        help=f"target poses (OpenCV asks for >= 10; default {cal['poses']})",
    )
    s.add_argument("--seed", type=SEED, default=DEFAULT_SEED, help="base seed of the poses, renders and noise")
    s.add_argument(
        "--spp",
        type=SPP,
        default=cal["spp"],
        help=f"samples per pixel of the phase-shifting and Gray-code frames (default {cal['spp']})",
    )
    s.add_argument(
        "--corner-spp",
        type=SPP,
        default=cal["corner_spp"],
        help=f"samples per pixel of the white frames the corners are found in (default {cal['corner_spp']})",
    )
    s.add_argument(
        "--sampler",
        choices=samplers(),
        default=cal["sampler"],
        help="Mitsuba sample generator (multijitter: stratified edges for the corner detector)",
    )
    s.add_argument(
        "--max-depth",
        type=MAX_DEPTH,
        default=cal["max_depth"],
        help=f"longest light path (default {cal['max_depth']}: direct light; one board)",
    )
    s.add_argument(
        "--distortion",
        choices=distortion_models(),
        default="radial",
        help="lens model fitted: radial (k1, k2; the default) or radial_tangential (also p1, p2, Bouguet's default)",
    )
    s.add_argument("--out", required=True, help="output folder (written whole or not at all)")
    s.add_argument("--overwrite", action="store_true", help="replace the output folder even if it holds other files")
    add_cache_options(s)
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_calibrate)
