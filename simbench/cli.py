"""Command line: each subcommand parses its arguments and calls one library function.

Errors are one line on stderr and exit status 2 (``--debug`` shows the traceback).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from simbench.seeds import DEFAULT_SEED

__all__ = ["main"]


class _Parser(argparse.ArgumentParser):
    """argparse with the CLI's error convention: one line on stderr, exit status 2."""

    def error(self, message: str):  # noqa: D102 - argparse's hook
        where = self.prog.split(" ", 1)[1] + ": " if " " in self.prog else ""
        self.exit(2, f"simbench: error: {where}{message} (see {self.prog} --help)\n")


class _Formatter(argparse.HelpFormatter):
    """Every option's help ends with its default (unless it has none or says it already)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if (
            action.default is None
            or action.default is False
            or action.default == argparse.SUPPRESS
            or "default" in text
            or action.required
            or not action.option_strings
        ):
            return text
        return f"{text} (default: %(default)s)"


def _checked(convert, check: str, what: str, **limits):
    """An argparse type: ``convert(text)`` checked by ``simbench.validate.<check>``."""

    def parse(text: str):
        from simbench import validate

        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
        try:
            return getattr(validate, check)(value, "value", **limits)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc).replace("value must", "must")) from None

    parse.__name__ = check
    return parse


def _int(lo: int | None = None, hi: int | None = None):
    """An argparse type: an integer checked by :func:`simbench.validate.integer`."""
    return _checked(int, "integer", "an integer", lo=lo, hi=hi)


def _float(**limits):
    """An argparse type: a number checked by :func:`simbench.validate.number`."""
    return _checked(float, "number", "a number", **limits)


# seeds: SeedSequence takes any non-negative integer; 63 bits keep them exact in JSON and NumPy
_SEED = _int(0, 2**63 - 1)
_SPP = _int(1, 1 << 16)

# the render cache's folder, relative to the working folder (every command that renders or reads it)
DEFAULT_CACHE = ".cache/simbench"

_SIZE_UNITS = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def _size_bytes(text: str) -> int:
    """An argparse type: a size in bytes, ``du``'s way (``500M``, ``10G``, ``1.5GiB``; K, M,
    G, T are powers of 1024)."""
    import re

    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([KMGT]?)(?:i?B)?\s*", text, flags=re.IGNORECASE)
    if m is None:
        raise argparse.ArgumentTypeError(f"expected a size such as 500M, 10G or 1.5GiB, got {text!r}")
    return int(float(m.group(1)) * _SIZE_UNITS[m.group(2).upper()])


def _human_bytes(n: float) -> str:
    """``n`` bytes in the largest binary unit it reaches, as ``du -h`` writes sizes."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(n) < 1024:
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} TiB"


def _add_render_options(s, *, quick_spp: int | None = None) -> None:
    """--spp and --sampler, one definition for every subcommand that renders."""
    from simbench.sim.mitsuba_dict import DEFAULT_SAMPLER, DEFAULT_SPP, SAMPLERS

    quick = f", {quick_spp} with --quick" if quick_spp else ""
    s.add_argument(
        "--spp", type=_SPP, default=None, help=f"path-tracing samples per pixel (default: {DEFAULT_SPP}{quick})"
    )
    s.add_argument(
        "--sampler",
        choices=SAMPLERS,
        default=DEFAULT_SAMPLER,
        help="Mitsuba sample generator (results/render_noise.md compares them)",
    )


def _add_cache_options(s) -> None:
    s.add_argument(
        "--cache",
        default=DEFAULT_CACHE,
        help="render cache folder (renders and ground truth keyed by everything that affects them)",
    )
    s.add_argument("--no-cache", action="store_true", help="render everything, store nothing")


def _cache_of(args):
    from simbench.cache import RenderCache

    return RenderCache(None if args.no_cache else args.cache)


def _render_settings(args) -> tuple[int, str]:
    """(spp, sampler) of the parsed options, checked together before anything renders."""
    from simbench.sim.mitsuba_dict import DEFAULT_SPP, check_sampler

    spp = args.spp if args.spp is not None else DEFAULT_SPP
    check_sampler(args.sampler, spp)
    return spp, args.sampler


# Mitsuba's path length: 1 sees only the emitters, so the projector's light needs >= 2
_MAX_DEPTH = _int(2, 1024)


def _calibration_defaults() -> dict:
    """The defaults of `simbench calibrate`: those the experiments' calibrated rig uses, so
    that both share their cached observations."""
    from simbench.calibration import procedure as p

    return {
        "poses": p.DEFAULT_POSES,
        "spp": p.CALIBRATION_SPP,
        "corner_spp": p.CALIBRATION_CORNER_SPP,
        "sampler": p.CALIBRATION_SAMPLER,
        "max_depth": p.CALIBRATION_MAX_DEPTH,
    }


def _distortion_models() -> list[str]:
    from simbench.calibration.procedure import DISTORTION_MODELS

    return list(DISTORTION_MODELS)


def _samplers() -> tuple[str, ...]:
    from simbench.sim.mitsuba_dict import SAMPLERS

    return SAMPLERS


def _system_names() -> list[str]:
    from simbench.systems import system_names

    return system_names()


def _cmd_pattern(args) -> int:
    from simbench.io import save_png
    from simbench.pattern import fringe_pattern, quantize

    spec = _pattern_spec(args, (args.height, args.width))
    path = save_png(args.out, quantize(fringe_pattern(spec)))
    codes = "".join(map(str, spec.codes()))
    print(f"pattern {args.width}x{args.height}, period {args.period} px, codes {codes} (window {args.order}) -> {path}")
    return 0


def _pattern_spec(args, size_hw: tuple[int, int]):
    """The PatternSpec of the pattern options (:func:`_add_pattern_options`) at ``size_hw``."""
    from simbench.pattern import PatternSpec, parse_sequence

    try:
        sequence = None if args.sequence is None else parse_sequence(args.sequence)
    except ValueError as exc:
        raise ValueError(f"--sequence: {exc}") from None
    given = {"period_px": args.period, "order": args.order, "channels": args.channels}
    return PatternSpec(size_hw=size_hw, sequence=sequence, **{k: v for k, v in given.items() if v is not None})


def _recorded_pattern(args, recorded):
    """The pattern a recording folder records, with any pattern option given on the command line
    checked against it: a contradiction is an error, never a silent re-decode with other values."""
    from simbench.pattern import parse_sequence
    from simbench.systems.proposed import describe_pattern

    given = {
        "--period": (args.period, recorded.period_px),
        "--order": (args.order, recorded.order),
        "--channels": (args.channels, recorded.channels),
        "--sequence": (
            None if args.sequence is None else parse_sequence(args.sequence),
            tuple(int(c) for c in recorded.codes()),
        ),
    }
    for option, (value, rec) in given.items():
        if value is not None and value != rec:
            raise ValueError(
                f"{option} {args.sequence if option == '--sequence' else value} contradicts the recording, made with "
                f"the pattern {describe_pattern(recorded)} (meta.json); leave {option} out to decode it as recorded"
            )
    return recorded


def _cmd_render(args) -> int:
    from simbench import api
    from simbench.decode import DecoderParams
    from simbench.io import check_output_directory
    from simbench.sim.scene import load_scene
    from simbench.sim.sensor import get_sensor
    from simbench.systems import SystemOptions, get_system, recording_manifest, system_names

    if args.system not in system_names():  # an unknown name fails before anything else
        get_system(args.system)
    scene = load_scene(args.scene)
    pattern = _pattern_spec(args, scene.rig.projector.size_hw)
    # the proposed sensor projects the pattern options' pattern; the other systems their own
    system = get_system(
        args.system, SystemOptions(sensor=get_sensor(args.camera), decoder=DecoderParams(pattern=pattern))
    )
    spp, sampler = _render_settings(args)
    # before minutes of rendering
    check_output_directory(args.out, manifest=recording_manifest(system), overwrite=args.overwrite)
    if not args.no_cache:
        from simbench.cache import check_cache_location

        cache_dir, out_dir = Path(args.cache).resolve(), Path(args.out).resolve()
        if cache_dir == out_dir or out_dir in cache_dir.parents or cache_dir in out_dir.parents:
            raise ValueError(
                f"--cache {args.cache} and --out {args.out} overlap: the render cache needs its own folder"
            )
        check_cache_location(args.cache, what="--cache")
    t0 = time.perf_counter()
    cache = _cache_of(args)
    rec = api.record(
        args.scene,
        system=args.system,
        sensor=args.camera,
        seed=args.seed,
        spp=spp,
        sampler=sampler,
        max_depth=args.max_depth,
        calibration_frames=args.calibration_frames,
        pattern=pattern,
        cache=cache,
        variant=args.variant,
    )
    _check_visible(rec.gt, scene)
    files = system.write_recording(
        Path(args.out), rec.raw, rec.calibration, scene=rec.scene, gt=rec.gt, meta=rec.meta, overwrite=args.overwrite
    )
    cached = f", {cache.hits} of {cache.hits + cache.misses} from the render cache" if cache.root is not None else ""
    print(
        f"rendered {scene.name} with the {system.info().label} ({rec.settings['variant']}, {spp} spp {sampler}, seed "
        f"{args.seed}{cached}) in {time.perf_counter() - t0:.1f} s -> {Path(args.out)}/"
    )
    for key, path in files.items():
        print(f"  {key:17s} {path.name}")
    return 0


def _check_visible(gt, scene) -> None:
    """A render in which no object of the scene reaches the camera is an error, not a folder of
    black images (objects behind the camera, far outside its view, or too small to see)."""
    if not np.isfinite(gt.depth_m).any():
        raise ValueError(
            f"scene {scene.name!r}: no object is visible to the camera (every one is behind it, outside its field of "
            "view or smaller than a pixel); nothing was written"
        )


def _manifest_of(path: Path) -> dict | None:
    """The sealed manifest (``meta.json``, or a competitor's ``device.json``) of the recording
    folder holding ``path`` (checked: the manifest's own seal, and ``path``'s recorded SHA-256
    when it lists it), or None when there is none.  A folder mixing the files of two renders,
    or whose manifest was edited, is refused."""
    from simbench.manifest import ManifestError, file_sha256, read_manifest

    for name in ("meta.json", "device.json"):
        meta = path.parent / name
        if not meta.exists():
            continue
        data = read_manifest(meta, verify_files=False)
        for key, listed in data["files"].items():
            if listed == path.name and file_sha256(path) != data["sha256"][key]:
                raise ManifestError(
                    f"{path} does not match {meta} (SHA-256 differs): the folder mixes files of two renders"
                )
        return data
    return None


def _z0_for(reference: Path, z0: float | None) -> float:
    """Z0: the reference's folder records it (a --z0 that contradicts it is an error); without
    a recording, --z0 or 1 m."""
    from simbench.systems.proposed import recorded_z0

    meta = _manifest_of(reference)
    if meta is None:
        return z0 if z0 is not None else 1.0
    recorded = recorded_z0(meta, where=str(reference.parent / "meta.json"))
    if z0 is not None and z0 != recorded:
        raise ValueError(
            f"--z0 {z0!r} contradicts {reference.parent / 'meta.json'}, whose reference plane was recorded at Z0 = "
            f"{recorded!r} m; leave --z0 out to decode it as recorded"
        )
    return recorded


def _cmd_calibrate(args) -> int:
    from simbench.calibration import calibrate_rig, get_target, true_rig
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
    variant = select_variant(args.variant)
    cache = _cache_of(args)
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
    cached = f", {cache.hits} of {cache.hits + cache.misses} poses from the cache" if cache.root is not None else ""
    print(
        f"calibrated {rig.name} through sensor model {args.camera} from {len(result.used_views)} of {args.poses} poses "
        f"({variant}{cached}) in {time.perf_counter() - t0:.1f} s: reprojection RMS camera {rms['camera']:.3f} px, "
        f"projector {rms['projector']:.3f} px, stereo {rms['stereo']:.3f} px -> {Path(args.out)}/"
    )
    for key, path in files.items():
        print(f"  {key:9s} {path.name}")
    return 0


def _cmd_decode(args) -> int:
    from simbench.cache import RenderCache
    from simbench.decode import DecoderParams, decode, robust_params
    from simbench.decode.persist import lookup_decoded_reference
    from simbench.io import json_bytes, load_image, npy_bytes, ply_bytes, png_bytes, write_files
    from simbench.metrics import points_from_depth
    from simbench.rig import load_rig

    if Path(args.out).suffix != ".npy":
        raise ValueError(f"--out must name a .npy file, got {args.out}")
    if args.ply and Path(args.ply).suffix.lower() != ".ply":
        raise ValueError(f"--ply must name a .ply file, got {args.ply}")
    if args.debug_dir and Path(args.debug_dir).exists() and not Path(args.debug_dir).is_dir():
        raise ValueError(f"--debug-dir {args.debug_dir} exists and is not a folder")
    # bad values fail before any file is read (on the decoder they will change)
    _decoder_overrides(robust_params() if args.robust else DecoderParams(), args.decoder or [])
    overrides = []  # explicit options that replace what a recording holds, announced with the result
    if Path(args.capture).is_dir():
        from simbench.manifest import read_manifest
        from simbench.systems.proposed import RENDER_MANIFEST
        from simbench.systems import system_of_recording

        if system_of_recording(args.capture) != "proposed":
            return _decode_recording(args)
        folder = Path(args.capture)
        read_manifest(folder / RENDER_MANIFEST)  # the whole folder as recorded: every file's SHA-256
        args.capture = str(folder / "capture.png")
        if args.rig is not None:
            overrides.append(f"rig {args.rig} instead of the recorded rig.toml")
        if args.reference is not None:
            overrides.append(f"reference {args.reference} instead of the recorded reference.png")
        args.rig = args.rig or str(folder / "rig.toml")
        args.reference = args.reference or str(folder / "reference.png")
    if args.rig is None:
        if not Path(args.capture).exists():
            raise FileNotFoundError(f"{args.capture} not found")
        raise ValueError("--rig is required when CAPTURE is an image (or give a folder written by `simbench render`)")
    _check_outputs_apart_from_inputs(args)
    _check_decode_outputs(args)
    rig = load_rig(args.rig)
    manifests = {p: _manifest_of(Path(p)) for p in (args.capture, args.reference, args.rig) if p and Path(p).is_file()}
    _check_same_recording_rig(args, manifests)
    capture = load_image(args.capture, expected_size_hw=rig.camera.size_hw)
    reference = None
    z0 = args.z0 if args.z0 is not None else 1.0
    if args.mode == "reference":
        if args.reference is None:
            raise ValueError("--reference is required in reference mode (or use --mode calibrated)")
        reference = load_image(args.reference, expected_size_hw=rig.camera.size_hw)
        z0 = _z0_for(Path(args.reference), args.z0)
    recorded = manifests.get(args.capture)
    if recorded is not None and recorded["files"].get("capture") != Path(args.capture).name:
        recorded = None  # an image beside a recording, not its capture: decoded as any image
    if recorded is not None:
        from simbench.systems.proposed import recorded_pattern

        pattern = _recorded_pattern(
            args, recorded_pattern(recorded, where=str(Path(args.capture).parent / "meta.json"))
        )
        if pattern.size_hw != rig.projector.size_hw:
            raise ValueError(
                f"the recording's pattern is {pattern.size_hw[1]}x{pattern.size_hw[0]}, the rig's projector "
                f"{rig.projector.width_px}x{rig.projector.height_px}: --rig {args.rig} is not this recording's rig"
            )
    else:
        pattern = _pattern_spec(args, rig.projector.size_hw)
    params = DecoderParams(pattern=pattern, mode=args.mode, z0_m=z0, depth_range_m=(args.near, args.far))
    if args.robust:
        params = robust_params(params)
    params = _decoder_overrides(params, args.decoder or [])
    if args.min_confidence is not None:
        params = replace(params, min_confidence=args.min_confidence)
    cache = RenderCache(None if args.no_cache else args.cache)
    store_reference = lambda: None  # noqa: E731
    if params.unmix:
        reference, store_reference = _calibrated_reference(args, rig, params, reference, cache=cache)
    elif reference is not None:
        reference, store_reference = lookup_decoded_reference(reference, rig=rig, params=params, cache=cache)
    if reference is not None:
        _check_reference_plane(reference, rig, args)
    t0 = time.perf_counter()
    result = decode(capture, rig=rig, params=params, reference=reference)
    dt = time.perf_counter() - t0
    # every output is written, or none is (an unwritable --ply must not leave depth.npy behind)
    files = {Path(args.out): npy_bytes(result.depth_m), _confidence_path(args): npy_bytes(result.confidence)}
    ref_note = (
        ""
        if reference is None
        else (
            ", reference map from the cache"
            if cache.hits
            else ", reference decoded" + ("" if cache.root is None else " and cached")
        )
    )
    over = "; overriding the recording: " + ", ".join(overrides) if overrides else ""
    threshold = (
        f"holes below {params.min_confidence:g}" if params.min_confidence > 0 else "no threshold: every decoded pixel"
    )
    msg = (
        f"decoded {result.valid.mean() * 100:.2f} % of pixels in {dt * 1000:.0f} ms "
        f"({args.mode} mode, Z0 = {z0} m{ref_note}{over}) -> {args.out}, confidence (fringe SNR"
        f"{', capped by the phase stability' if params.phase_stability else ''}; {threshold}) -> "
        f"{_confidence_path(args)}"
    )
    if args.ply:
        pts = points_from_depth(result.depth_m, rig.camera)
        ok = result.valid
        files[Path(args.ply)] = ply_bytes(pts[ok], capture[ok] if capture.dtype == np.uint8 else None)
        msg += f", {args.ply}"
    if args.debug_dir:
        d = Path(args.debug_dir)
        files[d / "column.npy"] = npy_bytes(result.column_px)
        files[d / "valid.npy"] = npy_bytes(result.valid)
        files[d / "confidence.npy"] = npy_bytes(result.confidence)
        for name, arr in result.stages.items():
            files[d / f"{name}.npy"] = npy_bytes(arr)
        files[d / "wrapped_phase.png"] = png_bytes(_to_u8(result.stages["wrapped_phase"], -np.pi, np.pi))
        files[d / "intensity.png"] = png_bytes(_to_u8(result.stages["intensity"], 0.0, 1.0))
        files[d / "depth.png"] = png_bytes(_to_u8(result.depth_m, *_finite_range(result.depth_m)))
        stages = sorted(p.name for p in files if p.parent == d)
        files[d / "stages.json"] = json_bytes({"command": "simbench decode", "capture": args.capture, "files": stages})
        msg += f", stages in {d}/"
    if len({p.resolve() for p in files}) != len(files):
        raise ValueError("--out, --confidence, --ply and the --debug-dir files must be different paths")
    # only now, the decode done: a failed decode leaves nothing behind, not even a cache entry; and
    # before the outputs, so that a cache that cannot take the entry fails with no output written
    store_reference()
    write_files(files)
    print(msg)
    return 0


def _check_outputs_apart_from_inputs(args) -> None:
    """No output of a decode may overwrite a recording's file (``--out FOLDER/gt_depth.npy``
    replaced the ground truth) or one of its inputs."""
    from simbench.manifest import listed_files

    protected: set[Path] = set()
    folders: set[Path] = set()  # recording folders among the inputs'
    for p in (args.capture, args.reference, args.rig, getattr(args, "calibration", None)):
        if p:
            protected.add(Path(p).resolve())
            folder = Path(p) if Path(p).is_dir() else Path(p).parent
            listed = listed_files(folder / "meta.json") | listed_files(folder / "device.json")
            protected |= listed
            folders |= {f.parent for f in listed}
    outputs = [Path(args.out), _confidence_path(args)] + ([Path(args.ply)] if args.ply else [])
    if args.debug_dir and Path(args.debug_dir).resolve() in folders:
        raise ValueError(f"--debug-dir {args.debug_dir} is a recording's folder: its stage images would mix with it")
    for out in outputs:
        if out.resolve() in protected:
            raise ValueError(
                f"{out} is a file of the recording being decoded (or an input): choose another output path"
            )


def _confidence_path(args) -> Path:
    """Where ``decode`` writes the confidence map: ``--confidence``, else NAME_confidence.npy
    beside ``--out``."""
    if args.confidence:
        return Path(args.confidence)
    out = Path(args.out)
    return out.with_name(f"{out.stem}_confidence.npy")


def _check_decode_outputs(args) -> None:
    """Every output of a decode writable before the decode starts: --out, --ply, --debug-dir
    and the reference cache (a folder in the way, a file above one, no permission)."""
    from simbench.cache import check_cache_location
    from simbench.io import check_output_file, check_own_folder

    check_output_file(args.out, what="--out")
    check_output_file(_confidence_path(args), what="--confidence")
    if Path(args.out).resolve() == _confidence_path(args).resolve():
        raise ValueError(f"--confidence {_confidence_path(args)} is --out: give another path")
    if args.ply:
        check_output_file(args.ply, what="--ply")
    if args.debug_dir:
        check_own_folder(args.debug_dir, marker="stages.json", written_by="simbench decode", what="--debug-dir")
        debug, out = Path(args.debug_dir).resolve(), Path(args.out).resolve()
        if debug == out or out in debug.parents:
            raise ValueError(f"--debug-dir {args.debug_dir} is --out {args.out} or under it: give another folder")
    if not args.no_cache:
        check_cache_location(args.cache, what="--cache")


def _check_reference_plane(reference, rig, args) -> None:
    """The decoded reference must triangulate, with the rig, to a plane at its Z0: a reference
    of another rig (or a wrong --z0) decoded 100 % at hundreds of mm of error before."""
    from simbench.decode import REFERENCE_Z0_TOLERANCE, reference_plane_offset

    offset = reference_plane_offset(reference, rig)
    if np.isfinite(offset) and abs(offset) > REFERENCE_Z0_TOLERANCE:
        z = reference.z0_m * (1 + offset)
        raise ValueError(
            f"the reference plane {args.reference} triangulates with the rig {args.rig} to Z = {z:.3f} m, not its Z0 = "
            f"{reference.z0_m:g} m ({100 * offset:+.1f} %, more than {100 * REFERENCE_Z0_TOLERANCE:.0f} %): was it "
            "captured with this rig, and at this Z0?"
        )


def _check_same_recording_rig(args, manifests: dict) -> None:
    """A reference from another recording folder must have been recorded with the capture's rig
    (their manifests' rig.toml digests): a reference of another baseline decodes to wrong
    depths everywhere without a word."""
    cap, ref = manifests.get(args.capture), manifests.get(args.reference)
    if cap is None or ref is None or cap is ref:
        return
    a, b = cap["sha256"].get("rig"), ref["sha256"].get("rig")
    if a is not None and b is not None and a != b:
        raise ValueError(
            f"--reference {args.reference} was recorded with another rig than {args.capture} (their folders' rig.toml "
            "differ): a reference plane belongs to the rig it was captured with"
        )


def _calibrated_reference(args, rig, params, reference, *, cache=None):
    """The decoded reference with its coupling matrix (the colour-robust decoder's unmixing):
    the reference capture (``reference``, or read from --reference in calibrated mode) and the
    calibration frames beside it (or in --calibration); with the function that caches it
    (:func:`simbench.decode.persist.lookup_decoded_reference`)."""
    from simbench.decode.persist import lookup_decoded_reference
    from simbench.io import load_image
    from simbench.pattern import CALIBRATION_FRAMES

    if args.reference is None:
        raise ValueError(
            "the colour-robust decoder (unmix) calibrates on the reference plane: give --reference (and its "
            "calibration frames)"
        )
    folder = Path(args.calibration) if args.calibration is not None else Path(args.reference).parent
    paths = {k: folder / f"calibration_{k}.png" for k in CALIBRATION_FRAMES}
    missing = [p.name for p in paths.values() if not p.is_file()]
    if missing:
        raise ValueError(
            f"the colour-robust decoder needs the calibration frames {missing} in {folder}/ (render with `simbench "
            f"render --calibration-frames`, or give --calibration FOLDER)"
        )
    for p in paths.values():
        _manifest_of(p)
    frames = {k: load_image(p, expected_size_hw=rig.camera.size_hw) for k, p in paths.items()}
    if reference is None:
        reference = load_image(args.reference, expected_size_hw=rig.camera.size_hw)
    z0 = _z0_for(Path(args.reference), args.z0)
    ref_params = replace(params, mode="reference", z0_m=z0)
    return lookup_decoded_reference(
        reference,
        rig=rig,
        params=ref_params,
        primaries=[frames[k] for k in CALIBRATION_FRAMES[1:]],
        dark=frames["dark"],
        cache=cache,
    )


def _finite_range(a: np.ndarray) -> tuple[float, float]:
    f = a[np.isfinite(a)]
    return (float(f.min()), float(f.max())) if f.size else (0.0, 1.0)


def _to_u8(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    x = (np.nan_to_num(np.asarray(a, dtype=np.float64), nan=lo) - lo) / max(hi - lo, 1e-12)
    return np.rint(np.clip(x, 0, 1) * 255).astype(np.uint8)


def _cmd_cache_info(args) -> int:
    import shutil
    import time

    from simbench.cache import cache_entries

    entries = cache_entries(args.cache)
    kinds: dict[str, list] = {}
    for c in entries:
        kinds.setdefault(c.kind, []).append(c)
    total = sum(c.size_bytes for c in entries)
    free = shutil.disk_usage(args.cache).free
    print(f"cache {args.cache}: {len(entries)} entries, {_human_bytes(total)} ({_human_bytes(free)} free on its disk)")
    if not entries:
        return 0

    def day(t: float) -> str:
        return time.strftime("%Y-%m-%d %H:%M", time.localtime(t))

    rows = sorted(kinds.items(), key=lambda kv: (-sum(c.size_bytes for c in kv[1]), kv[0]))
    print(f"{'kind':<18} {'entries':>8} {'size':>11}   last used (least .. most recently)")
    for kind, cs in rows:
        used = f"{day(cs[0].last_used_s)} .. {day(cs[-1].last_used_s)}"  # least recently used first
        print(f"{kind:<18} {len(cs):>8} {_human_bytes(sum(c.size_bytes for c in cs)):>11}   {used}")
    return 0


def _cmd_cache_prune(args) -> int:
    from simbench.cache import cache_entries, prune_cache

    if args.max_size is None and args.unused_days is None:
        raise ValueError("cache prune: give --max-size, --unused-days or both (what to keep)")
    before = cache_entries(args.cache)
    result = prune_cache(
        args.cache,
        max_bytes=args.max_size,
        unused_for_s=None if args.unused_days is None else args.unused_days * 86400.0,
        dry_run=args.dry_run,
    )
    removed = result.entries
    gone = sum(c.size_bytes for c in removed)
    left = sum(c.size_bytes for c in before) - gone
    verb = "would remove" if args.dry_run else "removed"
    if args.dry_run:
        for path in result.paths:
            print(f"would remove {path}")
    extra = f" and {len(result.leftovers)} leftovers of killed writers" if result.leftovers else ""
    print(
        f"cache {args.cache}: {verb} {len(removed)} entries ({_human_bytes(gone)}), the least recently used{extra}; "
        f"{len(before) - len(removed)} kept ({_human_bytes(left)})"
    )
    return 0


def _cmd_score(args) -> int:
    from simbench.io import load_npy
    from simbench.metrics import depth_errors, edge_band

    if args.period <= 2:
        raise ValueError(f"--period must be > 2 projector px, got {args.period}")
    gt = _depth_map(load_npy(args.gt), args.gt, what="ground truth")
    if not np.isfinite(gt).any():
        raise ValueError(f"{args.gt}: the ground truth has no finite depth: nothing to score against")
    depth = _depth_map(load_npy(args.depth, expected_shape=gt.shape), args.depth, what="depth map")
    gt_dir = Path(args.gt).parent
    lit_path = Path(args.lit) if args.lit else gt_dir / "gt_lit.npy"
    col_gt_path = Path(args.gt_column) if args.gt_column else gt_dir / "gt_column.npy"
    for p in (Path(args.gt), lit_path, col_gt_path):  # inside a recording folder: as recorded
        if p.is_file():
            _manifest_of(p)
    region = load_npy(lit_path, expected_shape=gt.shape).astype(bool) if lit_path.is_file() else np.isfinite(gt)
    exclude = None
    if args.edge_band < 0:
        raise ValueError(f"--edge-band must be >= 0, got {args.edge_band}")
    if args.edge_band > 0:
        obj_path = gt_dir / "gt_object_id.npy"
        obj = load_npy(obj_path, expected_shape=gt.shape) if obj_path.is_file() else None
        exclude = edge_band(gt, object_id=obj, band_px=args.edge_band)
    kw = {}
    if args.column:
        kw = {
            "column_px": load_npy(args.column, expected_shape=gt.shape),
            "gt_column_px": load_npy(col_gt_path, expected_shape=gt.shape),
            "period_px": args.period,
        }
    m = depth_errors(depth, gt, region=region, exclude=exclude, **kw)
    if not m["n_region"]:
        raise ValueError(
            f"no pixel to score: the region ({lit_path.name if lit_path.is_file() else 'finite ground truth'}) "
            "holds no pixel with a finite ground truth off the edge band"
        )
    if args.json:  # strict JSON: a metric with nothing to measure is null, not NaN
        clean = {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in m.items()}
        print(json.dumps(clean, indent=2, sort_keys=True, allow_nan=False))
    else:
        print(
            f"MAE {m['mae_mm']:.4f} mm  RMSE {m['rmse_mm']:.4f} mm  median {m['median_mm']:.4f} mm  p95 "
            f"{m['p95_mm']:.4f} mm"
        )
        print(
            f"completeness {100 * m['completeness']:.2f} % of {m['n_region']} pixels, outliers (> 5 mm) "
            f"{100 * m['outlier_share']:.3f} %"
        )
        if "stripe_order_errors" in m:
            print(
                f"stripe-order errors {m['stripe_order_errors']} ({100 * m['stripe_order_error_rate']:.4f} % of valid "
                f"pixels)"
            )
    return 0


def _depth_map(a: np.ndarray, path, *, what: str) -> np.ndarray:
    """``a`` if it is a 2-D map of real numbers (metres), else a one-line error naming the file."""
    if a.ndim != 2:
        raise ValueError(f"{path}: {what} must be a 2-D depth map, got shape {a.shape}")
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{path}: {what} must hold real numbers (metres), got dtype {a.dtype}")
    return a


def _cmd_demo(args) -> int:
    from simbench.experiments.demo import DEFAULT_SCENES, demo_config, run_demo
    from simbench.variant import select_variant

    spp, sampler = _render_settings(args)
    select_variant(args.variant)
    cfg = demo_config(spp=spp, sampler=sampler, seed=args.seed, sensor=args.camera)
    scenes = tuple(args.scenes) if args.scenes else DEFAULT_SCENES
    cache_dir = None if args.no_cache else args.cache
    run_demo(args.out, config=cfg, scenes=scenes, cache_dir=cache_dir, progress=lambda s: print(s, flush=True))
    print(f"wrote {args.out}/summary.md, metrics.json, provenance.json and one figure per scene")
    return 0


def _decode_recording(args) -> int:
    """``simbench decode FOLDER``: a recording of a system other than the proposed sensor,
    decoded the system's way (:meth:`simbench.systems.DepthSystem.decode`)."""
    from simbench.io import npy_bytes, ply_bytes, write_files
    from simbench.metrics import points_from_depth
    from simbench.systems import get_system, system_of_recording

    name = system_of_recording(args.capture)
    system = get_system(name)
    # the proposed sensor's options mean nothing to another system's folder: refused, not ignored
    given = {
        "--z0": args.z0,
        "--period": args.period,
        "--order": args.order,
        "--sequence": args.sequence,
        "--channels": args.channels,
        "--reference": args.reference,
        "--calibration": args.calibration,
        "--robust": args.robust or None,
        "--decoder": args.decoder or None,
        "--mode": None if args.mode == "reference" else args.mode,
    }
    stray = [k for k, v in given.items() if v is not None]
    if stray:
        raise ValueError(
            f"{args.capture} is a {name} recording: {', '.join(stray)} apply to the proposed sensor's folders only "
            f"(a {name} folder decodes the {name} way, with what it recorded)"
        )
    _check_outputs_apart_from_inputs(args)
    _check_decode_outputs(args)
    raw, cal, scene = system.read_recording(Path(args.capture))
    if args.rig is not None:  # e.g. the rig `simbench calibrate` estimated, instead of the recorded one
        from simbench.rig import load_rig

        rig = load_rig(args.rig)
        if rig.camera.size_hw != scene.rig.camera.size_hw:
            raise ValueError(
                f"--rig {args.rig}: camera {rig.camera.width_px}x{rig.camera.height_px}, but the recording's is "
                f"{scene.rig.camera.width_px}x{scene.rig.camera.height_px}"
            )
        scene = replace(scene, rig=rig)
    t0 = time.perf_counter()
    res = system.decode(raw, cal, scene=scene)
    dt = time.perf_counter() - t0
    info = system.info()
    if args.min_confidence is not None:
        if res.confidence is None:
            raise ValueError(f"--min-confidence: the {name} system gives no confidence map")
        from simbench.decode.pipeline import apply_min_confidence

        res = apply_min_confidence(res, args.min_confidence)
    confidence = res.confidence if res.confidence is not None else np.zeros(res.depth_m.shape, np.float32)
    files = {Path(args.out): npy_bytes(res.depth_m), _confidence_path(args): npy_bytes(confidence)}
    over = f"; overriding the recording: rig {args.rig} instead of the recorded one" if args.rig is not None else ""
    meaning = info.confidence + (
        f"; and, by --min-confidence, below {args.min_confidence:g}" if args.min_confidence is not None else ""
    )
    msg = (
        f"decoded {res.valid.mean() * 100:.2f} % of pixels in {dt * 1000:.0f} ms ({info.label}{over}) -> "
        f"{args.out}, confidence ({meaning}) -> {_confidence_path(args)}"
    )
    if args.ply:
        files[Path(args.ply)] = ply_bytes(points_from_depth(res.depth_m, scene.rig.camera)[res.valid])
        msg += f", {args.ply}"
    write_files(files)
    print(msg)
    return 0


def _cmd_ablate(args) -> int:
    from simbench.experiments.ablate import BUILTIN_STUDIES, check_sweep, load_sweep, run_sweep
    from simbench.variant import select_variant

    names = list(BUILTIN_STUDIES) if args.sweep == ["builtin"] else args.sweep
    sweeps = [load_sweep(n) for n in names]  # every file checked before any run starts
    for sweep in sweeps:
        check_sweep(sweep)  # and every run's values
    select_variant(args.variant)
    command = (
        "simbench ablate " + " ".join(sys.argv[2:])
        if sys.argv[0].endswith("simbench")
        else "simbench ablate " + " ".join(args.sweep)
    )
    for sweep in sweeps:
        t0 = time.perf_counter()
        if args.fresh:
            (Path(args.out) / f"{sweep.name}.runs.jsonl").unlink(missing_ok=True)
        rows = run_sweep(
            sweep,
            out_dir=args.out,
            cache_dir=None if args.no_cache else args.cache,
            workers=args.workers,
            scheduler=args.scheduler,
            variant=args.variant,
            progress=lambda s: print(s, flush=True),
            command=command,
        )
        failed = sum(1 for r in rows if r["error"])
        print(
            f"ablation {sweep.name}: {len(rows)} runs ({failed} failed) in {time.perf_counter() - t0:.0f} s -> "
            f"{args.out}/{sweep.name}.csv, .md, .png"
        )
    return 0


def _cmd_bench(args) -> int:
    from simbench.experiments.bench import run_decode_benchmark, stage_table

    rig = None
    if args.rig is not None:
        from simbench.rig import load_rig

        rig = load_rig(args.rig)
    res = run_decode_benchmark(
        repeats=args.repeats, device=args.device, scene=args.scene, rig=rig, mode=args.mode, robust=args.robust
    )
    setup = ", ".join(
        [res["scene"]]
        + ([f"rig {args.rig}"] if rig is not None else [])
        + ([f"{args.mode} mode"] if args.mode else [])
        + (["colour-robust decoder"] if args.robust else [])
    )
    print(
        json.dumps(res, indent=2)
        if args.json
        else f"{res['device']} decode of one {res['size_wh'][0]}x{res['size_wh'][1]} capture ({setup}): median "
        f"{res['median_ms']:.1f} ms, "
        f"min {res['min_ms']:.1f} ms over {res['repeats']} runs ({res['threads']} threads)"
    )
    if res["stages_ms"] and not args.json:
        print("per stage, mean per decode (row bands run in parallel threads, so the sum exceeds the wall time):")
        print(stage_table(res["stages_ms"]))
    if args.max_ms is not None and res["median_ms"] > args.max_ms:
        raise ValueError(f"decode median {res['median_ms']:.1f} ms exceeds --max-ms {args.max_ms}")
    return 0


def _cmd_reproduce(args) -> int:
    from simbench.experiments.common import RunConfig
    from simbench.sim.sensor import get_sensor
    from simbench.experiments.reproduce import (
        check_targets,
        check_threshold_names,
        check_thresholds,
        load_thresholds,
        reproduce,
        write_thresholds,
    )
    from simbench.variant import select_variant

    # everything a user can get wrong is checked before the first render
    check_targets(args.targets)
    if args.check:
        check_threshold_names(load_thresholds(args.check), args.targets, path=args.check)
    if args.write_thresholds:
        from simbench.io import check_output_file

        check_output_file(args.write_thresholds, what="--write-thresholds")
    if args.camera is not None:
        get_sensor(args.camera)
    overrides = {
        k: v
        for k, v in (
            ("seed", args.seed),
            ("spp", args.spp),
            ("fig9_repeats", args.repeats),
            ("sensor", args.camera),
            ("sampler", args.sampler),
        )
        if v is not None
    }
    config = RunConfig.preset(quick=args.quick, **overrides)  # checks spp against the sampler
    if args.decoder:
        config = replace(config, decoder=_decoder_overrides(config.decoder, args.decoder))
    out = args.out or ("results/quick" if args.quick else "results")
    select_variant(args.variant)
    command = (
        "simbench " + " ".join(sys.argv[1:])
        if sys.argv[0].endswith("simbench")
        else "simbench reproduce " + " ".join(args.targets)
    )
    metrics = reproduce(
        args.targets,
        config=config,
        out_dir=out,
        cache_dir=None if args.no_cache else args.cache,
        progress=lambda s: print(s, flush=True),
        command=command,
        workers=args.workers,
    )
    if args.write_thresholds:
        path = write_thresholds(args.write_thresholds, metrics, margin=args.margin, command=command)
        print(f"wrote thresholds {path}")
    if args.check:
        failures = check_thresholds(metrics, args.check)
        if failures:
            for f in failures:
                print(f"simbench: regression: {f}", file=sys.stderr)
            print(f"simbench: {len(failures)} metric(s) worse than {args.check}", file=sys.stderr)
            return 1
        print(f"all metrics within {args.check}")
    return 0


def _decoder_overrides(params, items: list[str]):
    """``name=value`` pairs (values parsed as TOML scalars; a bare word is a string) applied to
    DecoderParams by :func:`simbench.decode.with_changes`; ``without=NAME`` (or a list) switches
    the paper decoder's added checks off."""
    import dataclasses
    import tomllib

    from simbench.decode import with_changes

    names = {f.name for f in dataclasses.fields(params)} | {"without"}
    changes = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or key not in names:
            raise ValueError(f"--decoder takes name=value with name one of {sorted(names)}; got {item!r}")
        try:
            changes[key] = tomllib.loads(f"v = {text}")["v"]
        except tomllib.TOMLDecodeError:
            changes[key] = text  # a bare word: phase_method=ftp
    try:
        return with_changes(params, changes)
    except ValueError as exc:
        raise ValueError(f"--decoder: {exc}") from None


def _cmd_crosstalk(args) -> int:
    from simbench.experiments.table1 import PAPER_TABLE1
    from simbench.io import atomic_write_text
    from simbench.experiments.crosstalk import crosstalk_report

    text = crosstalk_report({name: srgb for name, (srgb, _) in PAPER_TABLE1.items()})
    print(text)
    if args.out:
        atomic_write_text(
            args.out,
            text.replace(
                "# Projector-to-camera crosstalk matrices",
                f"# Projector-to-camera crosstalk matrices\n\nMade by `simbench crosstalk --out {args.out}`.",
                1,
            ),
        )
        print(f"wrote {args.out}")
    return 0


def _add_pattern_options(s: argparse.ArgumentParser) -> None:
    """The pattern's options, shared by every command that makes or reads the pattern."""
    # None = not given: a recording folder is decoded with the pattern it records, and an option
    # given explicitly that contradicts it is an error (_recorded_pattern)
    s.add_argument("--period", type=_int(4, 16384), help="fringe period T in projector pixels (default: 21)")
    s.add_argument("--order", type=_int(2, 16), help="window length n (De Bruijn cycle = 2**n stripes; default: 3)")
    s.add_argument("--sequence", help="stripe codes of one cycle, e.g. 00010111 (default: B(2, order))")
    s.add_argument(
        "--channels",
        help="colour channels of code 1, code 0 and the fringe (rgb: the paper's red/green stripes, blue fringe; "
        "default: rgb)",
    )


def _parser() -> argparse.ArgumentParser:
    from simbench.validate import MAX_SIDE_PX

    kw = {"formatter_class": _Formatter}
    p = _Parser(
        prog="simbench",
        description="Simulation testbed for single-shot structured-light depth sensing (Li et al., Sensors 2017).",
        **kw,
    )
    p.add_argument("--debug", action="store_true", help="show tracebacks")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("pattern", help="write the colour sequence coded fringe pattern (PNG)", **kw)
    s.add_argument("--out", required=True, help="PNG file to write")
    s.add_argument(
        "--width", type=_int(1, MAX_SIDE_PX), default=1824, help="pattern width, projector px (the LightCrafter 4500's)"
    )
    s.add_argument("--height", type=_int(1, MAX_SIDE_PX), default=1140, help="pattern height, projector px")
    _add_pattern_options(s)
    s.set_defaults(fn=_cmd_pattern)

    s = sub.add_parser(
        "render", help="render a scene with a depth system: its raw frames, calibration, ground truth, metadata", **kw
    )
    s.add_argument("scene", help="scene TOML file (see scenes/README.md)")
    s.add_argument(
        "--system",
        default="proposed",
        help=f"depth system (registered: {', '.join(_system_names())}); the others replace the scene's rig with their "
        f"own",
    )
    s.add_argument(
        "--out", required=True, help="output folder (written whole or not at all; an earlier render there is replaced)"
    )
    s.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output folder even if it holds files render did not write (e.g. decoded depth)",
    )
    _add_render_options(s)
    _add_cache_options(s)
    s.add_argument(
        "--calibration-frames",
        action="store_true",
        help="also record the reference plane under black and each primary (calibration_*.png), which `simbench "
        "decode --robust` needs",
    )
    s.add_argument(
        "--seed",
        type=_SEED,
        default=DEFAULT_SEED,
        help="base seed (every render and noise seed derives from it and a label; all recorded in the manifest)",
    )
    s.add_argument("--max-depth", type=_MAX_DEPTH, default=6, help="longest light path (2 = direct light only)")
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default="paper",
        help="sensor model: a preset (paper: the Flea3 + LightCrafter physics; paper_sim: the paper's 3ds Max "
        "simulation, a linear noise-free RGB camera; minimal: noise only; ideal: nothing) or a sensor TOML file",
    )
    _add_pattern_options(s)
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_render)

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
    cal = _calibration_defaults()
    s.add_argument(
        "--poses",
        type=_int(3, 200),
        default=cal["poses"],
        help=f"target poses (OpenCV asks for >= 10; default {cal['poses']})",
    )
    s.add_argument("--seed", type=_SEED, default=DEFAULT_SEED, help="base seed of the poses, renders and noise")
    s.add_argument(
        "--spp",
        type=_SPP,
        default=cal["spp"],
        help=f"samples per pixel of the phase-shifting and Gray-code frames (default {cal['spp']})",
    )
    s.add_argument(
        "--corner-spp",
        type=_SPP,
        default=cal["corner_spp"],
        help=f"samples per pixel of the white frames the corners are found in (default {cal['corner_spp']})",
    )
    s.add_argument(
        "--sampler",
        choices=_samplers(),
        default=cal["sampler"],
        help="Mitsuba sample generator (multijitter: stratified edges for the corner detector)",
    )
    s.add_argument(
        "--max-depth",
        type=_MAX_DEPTH,
        default=cal["max_depth"],
        help=f"longest light path (default {cal['max_depth']}: direct light; one board)",
    )
    s.add_argument(
        "--distortion",
        choices=_distortion_models(),
        default="radial",
        help="lens model fitted: radial (k1, k2) or radial_tangential (also p1, p2, Bouguet's default)",
    )
    s.add_argument("--out", required=True, help="output folder (written whole or not at all)")
    s.add_argument("--overwrite", action="store_true", help="replace the output folder even if it holds other files")
    _add_cache_options(s)
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_calibrate)

    s = sub.add_parser("decode", help="decode a capture into a depth map (.npy, metres, NaN = invalid)", **kw)
    s.add_argument(
        "capture",
        help="the capture (PNG/TIFF, or .npy for float images), or a folder written by `simbench render` (any "
        "--system; its reference, rig and calibration frames are used)",
    )
    s.add_argument("--reference", help="reference-plane capture (reference mode)")
    s.add_argument(
        "--rig",
        help="rig TOML file (required unless CAPTURE is a render folder; given with a folder, it replaces the folder's "
        "rig: e.g. the rig.toml of `simbench calibrate`)",
    )
    s.add_argument("--out", required=True, help="depth map to write (.npy, float32 metres, NaN = invalid)")
    s.add_argument(
        "--confidence",
        help="confidence map to write (.npy, float32, the system's own unit: the proposed sensor's is the fringe SNR; "
        "default: NAME_confidence.npy beside --out)",
    )
    s.add_argument(
        "--min-confidence",
        type=_float(lo=0.0, hi=1e6),
        default=None,
        help="the operating point: decoded pixels whose confidence is below it become holes (default: the decoder's "
        "own: for the colour-robust decoder simbench.decode.ROBUST_MIN_CONFIDENCE, none for the paper's decoder, each "
        "competitor's validity threshold)",
    )
    s.add_argument("--ply", help="also write the point cloud as PLY")
    s.add_argument("--debug-dir", help="write every decoder stage here")
    s.add_argument(
        "--mode",
        choices=("reference", "calibrated"),
        default="reference",
        help="reference: match against the reference plane (paper Sec. 5.4); calibrated: triangulate with the rig",
    )
    s.add_argument(
        "--z0",
        type=_float(lo=0.0, hi=100.0, lo_open=True),
        default=None,
        help="reference depth, m (default: meta.json beside the reference, else 1.0)",
    )
    s.add_argument(
        "--near", type=_float(lo=0.0, hi=100.0, lo_open=True), default=0.75, help="working range near end, m"
    )
    s.add_argument("--far", type=_float(lo=0.0, hi=100.0, lo_open=True), default=1.75, help="working range far end, m")
    _add_pattern_options(s)
    s.add_argument(
        "--robust",
        action="store_true",
        help="our colour-robust decoder (unmixing, colour normalisation, weighted intensity) instead of the paper's; "
        "needs the calibration frames",
    )
    s.add_argument(
        "--calibration",
        default=None,
        help="folder holding calibration_{dark,red,green,blue}.png (`simbench render --calibration-frames`; default: "
        "the --reference folder)",
    )
    s.add_argument(
        "--decoder",
        nargs="*",
        metavar="NAME=VALUE",
        help="other decoder parameters, e.g. phase_method=ftp voting=false",
    )
    s.add_argument(
        "--cache",
        default=DEFAULT_CACHE,
        help="cache folder for decoded reference planes (keyed by the reference's bytes, rig, decoder settings and "
        "decoder code)",
    )
    s.add_argument("--no-cache", action="store_true", help="decode the reference plane every time, store nothing")
    s.set_defaults(fn=_cmd_decode)

    s = sub.add_parser("score", help="score a depth map against ground truth", **kw)
    s.add_argument("depth", help="depth map .npy (metres, NaN = invalid)")
    s.add_argument("--gt", required=True, help="ground-truth depth .npy (gt_lit.npy beside it defines the region)")
    s.add_argument("--lit", help="region mask .npy (default: gt_lit.npy beside --gt, else all finite GT)")
    s.add_argument("--column", help="decoded projector columns .npy, for stripe-order errors")
    s.add_argument("--gt-column", help="true columns .npy (default: gt_column.npy beside --gt)")
    s.add_argument(
        "--period",
        type=_float(lo=2.0, hi=16384.0, lo_open=True),
        default=21.0,
        help="fringe period, projector px (a column off by more than half of it is a stripe-order error)",
    )
    s.add_argument("--edge-band", type=_int(0, 1000), default=0, help="exclude pixels this close to depth edges (px)")
    s.add_argument("--json", action="store_true", help="print the scores as JSON")
    s.set_defaults(fn=_cmd_score)

    s = sub.add_parser("demo", help="render, decode and score the pipeline scenes into a results folder", **kw)
    s.add_argument("--out", default="results/demo", help="output folder")
    _add_render_options(s)
    _add_cache_options(s)
    s.add_argument("--seed", type=_SEED, default=DEFAULT_SEED, help="base seed")
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default="minimal",
        help="sensor model: preset (ideal, minimal, paper) or TOML file",
    )
    s.add_argument("--scenes", nargs="*", help="scene names in scenes/ (default: the four pipeline scenes)")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_demo)

    s = sub.add_parser("reproduce", help="regenerate the paper's Table 1, Table 3, Fig. 9 and figures", **kw)
    s.add_argument(
        "targets",
        nargs="*",
        default=["all"],
        help="table1, table3, fig9, figures, budget, render_noise, flatness or all (default)",
    )
    s.add_argument("--quick", action="store_true", help="640x480, 4 spp, 3 recordings per depth (the CI benchmark)")
    s.add_argument("--out", default=None, help="output folder (default: results, or results/quick with --quick)")
    s.add_argument("--cache", default=DEFAULT_CACHE, help="render cache folder")
    s.add_argument("--no-cache", action="store_true", help="render everything, store nothing")
    s.add_argument("--seed", type=_SEED, default=None, help=f"base seed (default {DEFAULT_SEED})")
    _add_render_options(s, quick_spp=4)
    s.add_argument(
        "--repeats", type=_int(1, 1000), default=None, help="recordings per Fig. 9 depth (default: 10, 3 with --quick)"
    )
    s.add_argument(
        "--sensor",
        "--camera",
        dest="camera",
        default=None,
        help="sensor model: preset (ideal, minimal, paper) or TOML file (default: paper)",
    )
    s.add_argument(
        "--decoder", nargs="*", metavar="NAME=VALUE", help="decoder parameter overrides, e.g. sigma_periods=0.4"
    )
    s.add_argument("--check", help="thresholds TOML: exit 1 when a metric is worse")
    s.add_argument("--write-thresholds", help="write a thresholds TOML from this run's metrics")
    s.add_argument(
        "--margin", type=_float(lo=0.0, hi=10.0), default=0.25, help="relative margin for --write-thresholds"
    )
    s.add_argument(
        "--workers",
        type=_int(1, 64),
        default=1,
        help=(
            "worker processes, one target each at a time (same outputs as 1; the quick run on 2 cores: "
            "156 s instead of 189 s cold, 9.5 s instead of 13.9 s warm)"
        ),
    )
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_reproduce)

    s = sub.add_parser(
        "crosstalk",
        help="print the projector-to-camera crosstalk matrices of white and the paper's seven colours",
        **kw,
    )
    s.add_argument("--out", help="also write them as Markdown here")
    s.set_defaults(fn=_cmd_crosstalk)

    s = sub.add_parser(
        "ablate",
        help="run ablation sweeps (TOML files or built-in study names; 'builtin' = all built-in studies)",
        **kw,
    )
    s.add_argument("sweep", nargs="+", help="sweep TOML file(s), built-in study name(s), or 'builtin'")
    s.add_argument("--out", default="results/ablations", help="output folder")
    s.add_argument("--workers", type=_int(1, 256), default=1, help="local worker processes")
    s.add_argument("--fresh", action="store_true", help="forget finished runs (the run log) and redo every run")
    s.add_argument(
        "--scheduler", default=None, help="Dask distributed scheduler address (tcp://host:8786): run there instead"
    )
    s.add_argument("--cache", default=DEFAULT_CACHE, help="render cache folder")
    s.add_argument("--no-cache", action="store_true", help="render everything, store nothing")
    s.add_argument("--variant", default=None, help="Mitsuba variant (default: the fastest this machine runs)")
    s.set_defaults(fn=_cmd_ablate)

    s = sub.add_parser("cache", help="what the render cache holds, and pruning it", **kw)
    cache_sub = s.add_subparsers(dest="cache_command", required=True, parser_class=_Parser)
    c = cache_sub.add_parser("info", help="entries and size per kind, when they were last used, free disk", **kw)
    c.add_argument("--cache", default=DEFAULT_CACHE, help="render cache folder")
    c.set_defaults(fn=_cmd_cache_info)
    c = cache_sub.add_parser(
        "prune",
        help="remove the least recently used entries (a hit marks an entry used; removed ones are made again "
        "when next needed)",
        **kw,
    )
    c.add_argument("--cache", default=DEFAULT_CACHE, help="render cache folder")
    c.add_argument(
        "--max-size",
        type=_size_bytes,
        default=None,
        help="keep at most this much, the most recently used (e.g. 10G; K, M, G, T are powers of 1024)",
    )
    c.add_argument(
        "--unused-days",
        type=_float(lo=0.0),
        default=None,
        help="remove every entry not used for this many days",
    )
    c.add_argument("--dry-run", action="store_true", help="only say what would be removed")
    c.set_defaults(fn=_cmd_cache_prune)

    s = sub.add_parser("bench", help="benchmark a decoder at its native resolution (the paper's: 1280x960)", **kw)
    s.add_argument(
        "--system", "--device", dest="device", default="proposed", choices=_system_names(), help="whose decoder"
    )
    s.add_argument(
        "--scene",
        default="plane",
        choices=["plane", "shadow"],
        help="proposed decoder: a fully lit plane, or with a projector shadow (the path real scenes take)",
    )
    s.add_argument(
        "--rig",
        default=None,
        help="proposed decoder: decode with this rig (TOML, e.g. from simbench calibrate; the capture is made with "
        "the paper's rig), its lens distortion included",
    )
    s.add_argument(
        "--mode",
        default=None,
        choices=["reference", "calibrated"],
        help="proposed decoder: reference-plane matching or triangulation with the rig (default: the decoder's)",
    )
    s.add_argument(
        "--robust",
        action="store_true",
        help="proposed decoder: time our colour-robust decoder (with its calibration frames) instead of the paper's",
    )
    s.add_argument("--repeats", type=_int(1, 100000), default=20, help="timed decodes (after one warm-up)")
    s.add_argument(
        "--max-ms", type=_float(lo=0.0, lo_open=True), default=None, help="fail when the median exceeds this"
    )
    s.add_argument("--json", action="store_true", help="print the timings as JSON")
    s.set_defaults(fn=_cmd_bench)
    return p


class _StderrHandler(logging.StreamHandler):
    """Library messages (``logging``, logger ``simbench``) as ``simbench: ...`` lines on the
    current ``sys.stderr`` (looked up per record, so redirected streams see them)."""

    def __init__(self) -> None:
        super().__init__()
        self.setFormatter(logging.Formatter("simbench: %(message)s"))

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def _report_library_messages() -> None:
    logger = logging.getLogger("simbench")
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        logger.addHandler(_StderrHandler())
    logger.setLevel(logging.WARNING)


# options that name files or folders (an empty value is refused for every one)
_PATH_OPTIONS = (
    "out",
    "confidence",
    "ply",
    "debug_dir",
    "write_thresholds",
    "check",
    "cache",
    "calibration",
    "reference",
    "rig",
    "gt",
    "lit",
    "column",
    "gt_column",
)


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit status (0 ok, 1 a bug or a failed check, 2 bad input)."""
    from simbench.threads import single_thread_blas

    single_thread_blas()
    _report_library_messages()
    try:
        args = _parser().parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error already printed as one line
        return exc.code if isinstance(exc.code, int) else 2
    empty = [name for name in _PATH_OPTIONS if getattr(args, name, None) == ""]
    if empty:  # "" would mean the working folder to some writers (demo, reproduce wrote into it)
        print(f"simbench: error: --{empty[0].replace('_', '-')}: an empty path; give a file or folder", file=sys.stderr)
        return 2
    previous = _on_sigterm_raise()
    try:
        return args.fn(args)
    except KeyboardInterrupt:
        print("simbench: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print(_TERMINATED_LINE, file=sys.stderr)
        _quiet_finalizers(args)
        return 143
    except BrokenPipeError:  # `simbench ... | head`: the reader has gone; stop quietly, as `yes | head` does
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # the exit's flush is not a 2nd error
        except (OSError, ValueError, AttributeError):  # a stdout without a descriptor (a test's buffer)
            pass
        return 141
    except MemoryError:
        if args.debug:
            raise
        print("simbench: error: out of memory (the inputs ask for more than this machine has)", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 - SIGTERM re-wrapped by a render (simbench.termination)
        from simbench import termination

        if not termination.requested():
            return _report_error(exc, args)
        print(_TERMINATED_LINE, file=sys.stderr)
        _quiet_finalizers(args)
        return 143
    finally:
        if previous is not None:
            import signal

            signal.signal(signal.SIGTERM, previous)


def _report_error(exc: Exception, args) -> int:
    """One line for a failed command: exit 2 for bad input (missing or unreadable files,
    invalid values), 1 for anything else, a bug (``--debug``: the traceback instead)."""
    if args.debug:
        raise exc
    if isinstance(exc, (ValueError, OSError)):
        print(f"simbench: error: {_one_line(exc)}{_disk_full_hint(exc, args)}", file=sys.stderr)
        return 2
    print(
        f"simbench: internal error ({type(exc).__name__}: {_one_line(exc)}); rerun with --debug for the traceback "
        f"and please report it",
        file=sys.stderr,
    )
    return 1


_TERMINATED_LINE = "simbench: terminated (SIGTERM); partial outputs and cache locks removed"


def _quiet_finalizers(args) -> None:
    """After SIGTERM, objects the signal interrupted half-built may fail in their finalizers at
    exit (a ``ZipFile`` whose ``__init__`` it cut short: "Exception ignored in ZipFile.__del__",
    seen in CI), which printed tracebacks after the one-line message: those are dropped (kept
    with ``--debug``).  Their files are the temporaries the unwinding already removed."""
    if not getattr(args, "debug", False):
        sys.unraisablehook = lambda unraisable: None


class _Terminated(BaseException):
    """SIGTERM (``kill``, a job scheduler's stop) raised in the main thread, as Ctrl-C raises
    KeyboardInterrupt: the ``with`` blocks unwind, so temporary folders go and cache locks are
    released and removed, and the exit says so."""


def _on_sigterm_raise():
    """Turn SIGTERM into :class:`_Terminated` while a command runs; returns the handler to
    restore (None off the main thread, where signals cannot be handled)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum, frame):
        f = frame
        while f is not None:
            # an exception raised inside an import breaks a C extension's initialisation (Mitsuba's
            # aborts the interpreter at exit): ask again once the import is done
            if f.f_code.co_filename.startswith("<frozen importlib"):
                threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGTERM)).start()
                return
            f = f.f_back
        from simbench import termination

        termination.request()
        termination.run_or_hold(_raise_terminated)  # not inside a cache lock's taking or letting go

    return signal.signal(signal.SIGTERM, handler)


def _raise_terminated() -> None:
    raise _Terminated()


def _disk_full_hint(exc: BaseException, args) -> str:
    """For a full disk: how much is free where the write failed, and how to free the cache."""
    import shutil

    from simbench.io import DISK_FULL_ERRNOS

    if not isinstance(exc, OSError) or exc.errno not in DISK_FULL_ERRNOS:
        return ""
    where = Path(exc.filename) if exc.filename else Path(".")
    while not where.exists() and where != where.parent:
        where = where.parent
    try:
        free = f"{_human_bytes(shutil.disk_usage(where).free)} free there now; "
    except OSError:
        free = ""
    cache = getattr(args, "cache", None) or DEFAULT_CACHE
    return (
        f" ({free}`simbench cache info --cache {cache}` shows what the render cache holds, "
        f"`simbench cache prune --cache {cache} --max-size SIZE` frees it)"
    )


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__


if __name__ == "__main__":
    sys.exit(main())
