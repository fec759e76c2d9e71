"""The colour-fringe (proposed) sensor's recording folder - its manifest (``meta.json``), the
pattern and Z0 it records - and its captures decoded from files: a recording folder of
``simbench render`` or a capture image with a rig file, against a reference-plane capture
(reference mode) or by triangulation with the rig (calibrated mode), with the paper's decoder or
the colour-robust one (which calibrates on the reference plane and its calibration frames).

What a recording records is what it decodes with: its pattern, rig, reference and Z0; an option
that contradicts the recording is an error, one that replaces a recorded file is announced with
the result.  The decoded reference plane is cached (:mod:`simbench.decode.persist`).
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections import ChainMap
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from simbench.optics import undistort_image
from simbench.pattern import PatternSpec

if TYPE_CHECKING:
    from simbench.decode import ReferenceMap
    from simbench.rig import Rig

from simbench.systems.files import (
    WORKING_RANGE_M,
    DecodeRequest,
    FileDecode,
    check_outputs,
    recording_manifest_of,
    refuse_another_rig,
    tell_or_log,
)

__all__ = [
    "RENDER_MANIFEST",
    "check_reference_plane",
    "decode_capture_files",
    "describe_pattern",
    "pattern_record",
    "recorded_adc_bits",
    "recorded_pattern",
    "recorded_z0",
]

# the manifest of a proposed-sensor recording folder (simbench.manifest)
RENDER_MANIFEST = "meta.json"


def _recorded_pattern(request: DecodeRequest, recorded):
    """The pattern a recording folder records, with any pattern option of the request checked
    against it: a contradiction is an error, never a silent re-decode with other values."""
    from simbench.pattern import parse_sequence

    given = {
        "--period": (request.period_px, recorded.period_px),
        "--order": (request.order, recorded.order),
        "--channels": (request.channels, recorded.channels),
        "--sequence": (
            None if request.sequence is None else parse_sequence(request.sequence),
            tuple(int(c) for c in recorded.codes()),
        ),
    }
    for option, (value, rec) in given.items():
        if value is not None and value != rec:
            raise ValueError(
                f"{option} {request.sequence if option == '--sequence' else value} contradicts the recording, made "
                f"with the pattern {describe_pattern(recorded)} (meta.json); leave {option} out to decode it as "
                "recorded"
            )
    return recorded


def _z0_for(reference: Path, z0: float | None, *, option: str = "--z0") -> float:
    """Z0: the reference's folder records it (a ``z0_m`` that contradicts it is an error, named
    as ``option`` gave it); without a recording, ``z0_m`` or 1 m."""
    meta = recording_manifest_of(reference)
    if meta is None:
        return z0 if z0 is not None else 1.0
    recorded = recorded_z0(meta, where=str(reference.parent / "meta.json"))
    if z0 is not None and z0 != recorded:
        given = f"{option}{z0!r}" if option.endswith("=") else f"{option} {z0!r}"
        raise ValueError(
            f"{given} contradicts {reference.parent / 'meta.json'}, whose reference plane was recorded at "
            f"Z0 = {recorded!r} m; leave {option.split('=')[0]} out to decode it as recorded"
        )
    return recorded


def _decoder_names(request: DecodeRequest) -> set[str]:
    """The parameters the request's ``--decoder name=value`` items set."""
    return {item.partition("=")[0] for item in request.decoder}


def _asked_z0(request: DecodeRequest, params) -> tuple[float | None, str]:
    """The Z0 the request gives (``--z0``, else ``--decoder z0_m=``, read from ``params``, the
    request's decoder parameters) and the option that gave it; None where neither does."""
    if request.z0_m is not None:
        return request.z0_m, "--z0"
    if "z0_m" in _decoder_names(request):
        return params.z0_m, "--decoder z0_m="
    return None, "--z0"


def _decoder_params(request: DecodeRequest, base=None):
    """The decoder's parameters: the paper's or the colour-robust ones, with the request's
    ``name=value`` settings (:func:`simbench.decode.with_assignments`)."""
    from simbench.decode import DecoderParams, robust_params, with_assignments

    base = base if base is not None else DecoderParams()
    if not request.robust:
        return with_assignments(base, request.decoder)
    robust = robust_params(base)
    try:
        return with_assignments(robust, request.decoder)
    except ValueError as exc:
        # (a new user's audit, 2026-11-30: --robust --decoder phase_method=ftp, the help's own example,
        # was refused for settings the user never gave): the preset's switches that the request's
        # settings exclude, all of them, named in one line
        flags = ("carrier_bank", "centroid_correction", "phase_stability", "narrow_snr")
        off, message = [], str(exc)
        while True:
            named = [n for n in flags if n in message and n not in off and getattr(robust, n) is True]
            if not named:
                break
            off += named
            try:
                with_assignments(robust, [*request.decoder, *(f"{n}=false" for n in off)])
                message = ""
            except ValueError as again:
                message = str(again)
        if not off or message:
            raise
        raise ValueError(
            f"{exc}; --robust sets {', '.join(f'{n}=true' for n in off)}: add --decoder "
            + " ".join(f"{n}=false" for n in off)
            + " to use it so"
        ) from None


def _camera_image(path: str | Path, rig, request: DecodeRequest, *, hint: bool = True) -> np.ndarray:
    """An image of the decode (the capture, the reference, a calibration frame) at its camera's
    full scale (:func:`simbench.io.adc_full_scale`): the ADC bits its recording's manifest
    records, else ``--bits``, else the dtype's range - with a warning where a 16-bit image's
    values all fit in 10 or 12 bits (a 12-bit camera's frame read as 16-bit decodes at a
    sixteenth of its brightness: half the pixels lost, and no other word of it) - then as linear
    light, by ``--encoding`` (:func:`simbench.io.linearize`)."""
    from simbench.io import adc_full_scale, check_encoding, linearize, load_image, narrow_uint16_hint

    path = Path(path)
    img = load_image(path, expected_size_hw=rig.camera.size_hw, bits=request.bits)
    if request.bits is not None and img.dtype.kind == "f":
        # (a docs audit, 2026-11-30: --bits was ignored for a float capture without a word)
        raise ValueError(
            f"--bits {request.bits}: {path} is a float image, read as full scale in [0, 1]; --bits is for integer "
            "images holding a camera's digital numbers (uint16): leave it out"
        )
    meta = recording_manifest_of(path)
    recorded = None
    encoding = check_encoding(request.encoding)
    if meta is not None and path.name in meta.get("files", {}).values():
        if encoding != "linear":
            raise ValueError(
                f"--encoding {encoding}: {path} is a simbench recording's image, whose camera records linear digital "
                "numbers; leave --encoding out to decode it as recorded"
            )
        recorded = recorded_adc_bits(meta, where=str(path.parent / RENDER_MANIFEST))
    if recorded is not None and request.bits is not None and request.bits != recorded:
        raise ValueError(
            f"--bits {request.bits} contradicts {path.parent / RENDER_MANIFEST}, whose camera recorded "
            f"{recorded}-bit digital numbers; leave --bits out to decode it as recorded"
        )
    bits = recorded if recorded is not None else request.bits
    if bits is None and hint:  # (not for a dark calibration frame: a 16-bit camera's reads low too)
        told = narrow_uint16_hint(img)
        if told:
            logging.getLogger("simbench").warning("%s: %s", path, told)
    return linearize(adc_full_scale(img, bits=bits, where=str(path)), encoding=encoding)


def decode_capture_files(request: DecodeRequest) -> FileDecode:
    """Decode the request's capture (an image with ``request.rig``, or a recording folder) with
    the colour-fringe sensor's decoder."""
    from simbench.cache import RenderCache
    from simbench.decode import DecoderParams, decode
    from simbench.decode.pipeline import code_order_doubt, code_succession_doubt, registration_warning, without_depth
    from simbench.decode.persist import lookup_decoded_reference
    from simbench.manifest import read_manifest
    from simbench.pattern import pattern_from_options
    from simbench.rig import load_rig

    from simbench.io import check_encoding, load_image

    encoding = check_encoding(request.encoding)
    asked = _decoder_params(request)  # bad values fail before any file is read (on the decoder they will change)
    # --decoder mode= and z0_m= say what --mode and --z0 say: the same checks, and a pair that disagrees is refused
    named = _decoder_names(request)
    decoder_mode = asked.mode if "mode" in named else None
    if request.mode and decoder_mode and request.mode != decoder_mode:
        raise ValueError(f"--mode {request.mode} and --decoder mode={decoder_mode} disagree: give one")
    if request.z0_m is not None and "z0_m" in named and request.z0_m != asked.z0_m:
        raise ValueError(f"--z0 {request.z0_m} and --decoder z0_m={asked.z0_m} disagree: give one")
    if not request.near_m < request.far_m:
        raise ValueError(f"--near {request.near_m:g} must be less than --far {request.far_m:g} (metres)")
    if "depth_range_m" in named and (request.near_m, request.far_m) != WORKING_RANGE_M:
        if tuple(asked.depth_range_m) != (request.near_m, request.far_m):
            raise ValueError(
                f"--near {request.near_m:g} --far {request.far_m:g} and --decoder depth_range_m="
                f"{list(asked.depth_range_m)} disagree: give one"
            )
    z0_asked, z0_option = _asked_z0(request, asked)
    overrides = []  # explicit options that replace what a recording holds, announced with the result
    capture_path, rig_path, reference_path = request.capture, request.rig, request.reference
    if Path(request.capture).is_dir():
        folder = Path(request.capture)
        read_manifest(folder / RENDER_MANIFEST)  # the whole folder as recorded: every file's SHA-256
        capture_path = str(folder / "capture.png")
        if rig_path is not None:
            overrides.append(f"rig {rig_path} instead of the recorded rig.toml")
        if reference_path is not None:
            overrides.append(f"reference {reference_path} instead of the recorded reference.png")
        rig_path = rig_path or str(folder / "rig.toml")
        reference_path = reference_path or str(folder / "reference.png")
    if rig_path is None:
        if not Path(capture_path).exists():
            raise FileNotFoundError(f"{capture_path} not found")
        raise ValueError("--rig is required when CAPTURE is an image (or give a folder written by `simbench render`)")
    check_outputs(request, inputs=[capture_path, reference_path, rig_path, request.calibration])
    rig = load_rig(rig_path)
    manifests = {
        p: recording_manifest_of(p) for p in (capture_path, reference_path, rig_path) if p and Path(p).is_file()
    }
    _check_same_recording_rig(capture_path, reference_path, manifests)
    capture = _camera_image(capture_path, rig, request)
    mode = request.mode or decoder_mode or "reference"
    reference = None
    z0 = z0_asked if z0_asked is not None else 1.0
    if mode == "reference":
        if reference_path is None:
            raise ValueError("--reference is required in reference mode (or use --mode calibrated)")
        reference = _camera_image(reference_path, rig, request)
        z0 = _z0_for(Path(reference_path), z0_asked, option=z0_option)
    recorded = manifests.get(capture_path)
    if recorded is not None and recorded["files"].get("capture") != Path(capture_path).name:
        recorded = None  # an image beside a recording, not its capture: decoded as any image
    if recorded is not None:
        _check_recorded_rig(rig, rig_path, capture_path, recorded)
        pattern = _recorded_pattern(
            request, recorded_pattern(recorded, where=str(Path(capture_path).parent / "meta.json"))
        )
        if pattern.size_hw != rig.projector.size_hw:
            raise ValueError(
                f"the recording's pattern is {pattern.size_hw[1]}x{pattern.size_hw[0]}, the rig's projector "
                f"{rig.projector.width_px}x{rig.projector.height_px}: --rig {rig_path} is not this recording's rig"
            )
    else:
        pattern = pattern_from_options(
            rig.projector.size_hw,
            period_px=request.period_px,
            order=request.order,
            sequence=request.sequence,
            channels=request.channels,
        )
    base = DecoderParams(pattern=pattern, mode=mode, z0_m=z0, depth_range_m=(request.near_m, request.far_m))
    params = _decoder_params(request, base)
    # an image records no pattern: with no pattern option the default is taken, which the reference
    # plane checks but nothing else does (a pattern designer's audit, 2026-11-30: a period-30 or
    # order-4 capture triangulated alone decoded 66-96 % of its pixels 87-298 mm off, exit 0, told only
    # that nothing checked the rig)
    pattern_named = any(n == "pattern" or n.startswith("pattern.") for n in named)  # (--decoder pattern=...)
    pattern_assumed = (
        recorded is None
        and all(x is None for x in (request.period_px, request.order, request.sequence, request.channels))
        and not pattern_named
    )
    if pattern_named and not params.pattern.projects_as(pattern):
        # (a fourth audit: --decoder pattern= won over --period without a word, and over a recording's
        # pattern too, whose decode then failed as if the reference were at fault)
        if recorded is not None:
            raise ValueError(
                f"--decoder pattern= ({describe_pattern(params.pattern)}) contradicts the recording, made with the "
                f"pattern {describe_pattern(pattern)} (meta.json) - they differ in "
                f"{pattern_differences(params.pattern, pattern)}; leave it out to decode it as recorded"
            )
        if any(x is not None for x in (request.period_px, request.order, request.sequence, request.channels)):
            raise ValueError(
                f"the pattern options (--period, --order, --sequence, --channels: {describe_pattern(pattern)}) and "
                f"--decoder pattern= ({describe_pattern(params.pattern)}) disagree: give one"
            )
    if request.min_confidence is not None:
        if "min_confidence" in named and params.min_confidence != request.min_confidence:
            raise ValueError(
                f"--min-confidence {request.min_confidence:g} and --decoder min_confidence={params.min_confidence:g} "
                "disagree: give one"
            )
        params = dataclasses.replace(params, min_confidence=request.min_confidence)
    _check_reference_pattern(reference_path, params.pattern, manifests)
    from simbench.decode.pipeline import capture_warnings, reference_warnings

    for told in capture_warnings(capture, rig=rig, params=params, encoding=encoding):
        logging.getLogger("simbench").warning("%s: %s", capture_path, told)
    if isinstance(reference, np.ndarray):
        for told in reference_warnings(reference, rig=rig, params=params, encoding=encoding):
            logging.getLogger("simbench").warning("%s: %s", reference_path, told)
    if request.calibration is not None and not params.unmix:
        raise ValueError(
            f"--calibration {request.calibration}: those frames are for the colour-robust decoder's unmixing; add "
            "--robust (or --decoder unmix=true), or leave --calibration out"
        )
    # a bare reference (no recording) with no Z0 given is taken at 1 m: said so wherever Z0 is named
    z0_assumed = (
        z0_asked is None
        and reference_path is not None
        and Path(reference_path).is_file()
        and recording_manifest_of(reference_path) is None
    )
    # where Z0 came from, for the reference check's advice: a recording's Z0 cannot be the error
    recorded_ref = reference_path is not None and Path(reference_path).is_file() and not z0_assumed
    z0_kind = {
        "z0_assumed": z0_assumed,
        "recorded_z0": recorded_ref and recording_manifest_of(reference_path) is not None,
    }
    pattern_kind = {"pattern_assumed": _short_pattern(params.pattern) if pattern_assumed else ""}
    cache = RenderCache(request.cache_dir)
    store_reference = lambda: None  # noqa: E731
    if params.unmix:
        reference, store_reference = _calibrated_reference(
            request, rig, params, reference, reference_path=reference_path, cache=cache
        )
    elif reference is not None:
        reference, store_reference = lookup_decoded_reference(reference, rig=rig, params=params, cache=cache)
    # a recording's capture given alone: its folder's reference plane checks the rig as the
    # folder form's does (a docs audit, 2026-11-30: the step recording's capture with a rig whose
    # principal point was 51 px off decoded 95 % at 318 mm MAE, exit 0; the folder refused it)
    check_path = reference_path
    if check_path is None and recorded is not None and isinstance(recorded["files"].get("reference"), str):
        check_path = str(Path(capture_path).parent / recorded["files"]["reference"])
        z0_kind = {"z0_assumed": False, "recorded_z0": True}
    if reference is not None:
        check_reference_plane(
            reference,
            rig,
            reference_path=reference_path,
            rig_path=rig_path,
            mode=params.mode,
            **z0_kind,
            **pattern_kind,
        )
    elif request.rig is not None and check_path is not None and Path(check_path).is_file():
        # calibrated mode with a rig given: the recording's reference plane, decoded, must lie at
        # its Z0 by that rig too (a rig of another baseline decoded 95 % at 77 mm MAE without a
        # word; the check costs a decode of the reference, cached, where a rig is given)
        ref_z0 = _z0_for(Path(check_path), z0_asked, option=z0_option)  # (an image's: as --z0 says, or 1 m)
        ref_params = dataclasses.replace(params, mode="reference", z0_m=ref_z0)
        plane, store_plane = lookup_decoded_reference(
            _camera_image(check_path, rig, request), rig=rig, params=ref_params, cache=cache
        )
        check_reference_plane(
            plane, rig, reference_path=check_path, rig_path=rig_path, mode=params.mode, **z0_kind, **pattern_kind
        )
        store_plane()
    elif params.mode == "calibrated" and request.rig is not None:
        # a lone capture triangulated with a rig nothing checks (a lab user's audit, 2026-11-30: a
        # rig converted from OpenCV's stereo calibration with T's sign flipped, R inverted, its
        # rotation left out or cx and cy swapped each decoded 92-96 % of the pixels 57-360 mm off,
        # exit 0; given a reference plane, each was refused)
        assumed = (
            f" nor the pattern, taken as the default ({_short_pattern(params.pattern)}: an image does not record "
            "which pattern lit it; --period/--order/--sequence/--channels give yours)"
            if pattern_assumed
            else ""
        )
        logging.getLogger("simbench").warning(
            "%s: calibrated mode with no reference plane: nothing checks the rig %s against this capture%s - a rig "
            "converted wrongly (the translation's sign or units, the rotation's direction, a principal point)%s "
            "decodes most pixels at wrong depths without a word. Give --reference with a capture of a flat board "
            "at a known distance (--z0) to check it (docs/lab.md)",
            capture_path,
            rig_path,
            assumed,
            " or a pattern other than the one decoded with" if pattern_assumed else "",
        )
    t0 = time.perf_counter()
    result = decode(capture, rig=rig, params=params, reference=reference)
    dt = time.perf_counter() - t0
    # a mirrored or red/green-swapped capture decodes half its stripes to wrong columns, each
    # confirmed by a neighbour: none of it is written (code_order_doubt)
    doubt = code_order_doubt(result.window_succession)
    if doubt:
        result = without_depth(result)
    else:
        told = registration_warning(capture, result, rig=rig, params=params, reference=reference)
        if told:
            logging.getLogger("simbench").warning("%s: %s", capture_path, told)
        # stripes in order but not the pattern's windows: another pattern, or colours that defeat the code
        told = code_succession_doubt(result.window_succession, pattern_known=recorded is not None)
        if told:
            logging.getLogger("simbench").warning("%s: %s", capture_path, told)
    # in calibrated mode the reference serves the colour unmixing only (its coupling matrix)
    role = " (for its colour unmixing)" if params.mode == "calibrated" else ""
    ref_note = (
        ""
        if reference is None
        else (
            f", reference map{role} from the cache"
            if cache.hits
            else f", reference decoded{role}" + ("" if cache.root is None else " and cached")
        )
    )
    over = "; overriding the recording: " + ", ".join(overrides) if overrides else ""
    rig_named = any(o.startswith("rig ") for o in overrides)
    # the point cloud's colours: an 8-bit capture's values as stored (an encoded one's too, not its
    # linearised light, which would show dark)
    shown = capture if encoding == "linear" else load_image(capture_path, expected_size_hw=rig.camera.size_hw)
    threshold = (
        f"holes below {params.min_confidence:g}" if params.min_confidence > 0 else "no threshold: every decoded pixel"
    )
    snr = "fringe SNR (the better of the wide and the narrow window's)" if params.narrow_snr else "fringe SNR"
    caps = [
        c
        for c, on in (
            ("the phase stability", params.phase_stability),
            ("the crease bias", params.crease_doubt),
            ("the bend beside depth edges", params.edge_doubt),
            ("the colour registration", params.registration_doubt),
        )
        if on
    ]
    contested = ", 0 on a contested stripe order" if params.position_doubt else ""
    contested += ", 0 on a stripe order read from too few pixels' codes" if params.code_doubt else ""
    contested += ", 0 beside a shadow" if params.shadow_doubt else ""
    noise = (
        f"the column's random noise at fringe SNR s ~{params.column_noise_px(rig):.2f}/s projector px (1 sigma) with "
        f"{'this rig' if params.camera_period_px is None else '--decoder camera_period_px'}'s "
        f"{params.camera_period(rig):.1f}-px camera period, the decoder's systematic errors besides"
    )
    meaning = f"{snr}{', capped by ' + ' and '.join(caps) if caps else ''}{contested}; {threshold}; {noise}"
    # the decoder's stage images stay lazy (made only for --debug-dir: stacking the bands' took ~90 ms);
    # a stage of the same name wins, as when they were unpacked over these
    final = {"column": result.column_px, "valid": result.valid, "confidence": result.confidence}
    # a refused decode's own column and confidence stages would hold what was refused: the blank
    # ones win there (the other stages stay, to see why)
    stages = ChainMap(final, result.stages) if doubt else ChainMap(result.stages, final)
    z0_note = (  # (none used: no Z0)
        f", Z0 = {float(reference.z0_m)} m{' (assumed: no --z0 given)' if z0_assumed else ''}"
        if reference is not None
        else ""
    )
    return FileDecode(
        depth_m=result.depth_m,
        valid=result.valid,
        confidence=result.confidence,
        camera=rig.camera,
        # the rig the depth was triangulated with, always (an audit: named only when --rig overrode it)
        summary=f"{params.mode} mode{z0_note}{ref_note}{'' if rig_named else f', rig {rig_path}'}{over}"
        + (f", pattern {_short_pattern(params.pattern)} (assumed: no pattern option given)" if pattern_assumed else ""),
        confidence_meaning=meaning,
        elapsed_s=dt,
        # on the ideal pinhole grid the points are on (an audit: the raw capture's colours sat up to
        # 4 px off them at the corners under the paper camera's lens)
        colours=undistort_image(shown, rig.camera) if shown.dtype == np.uint8 else None,
        stages=stages,
        capture_file=capture_path,
        commit=store_reference,
        cause=doubt,
        settings={
            "decoder": dataclasses.asdict(params),
            "rig": rig_path,
            "reference": reference_path if reference is not None else None,
            "calibration_frames": request.calibration,
            "bits": request.bits,
            "encoding": encoding,
            "pattern_assumed": pattern_assumed,
        },
    )


def check_reference_plane(
    reference: ReferenceMap,
    rig: Rig,
    *,
    reference_path: str | Path,
    rig_path: str | Path,
    z0_assumed: bool = False,
    recorded_z0: bool = False,
    mode: str = "calibrated",
    rig_option: str = "--rig",
    pattern_assumed: str = "",
    tell: Callable[[str], None] | None = None,
) -> None:
    """The decoded reference must triangulate, with the rig, to a plane at its Z0: a reference
    of another rig (or a wrong Z0) decoded 100 % at hundreds of mm of error before.  Within the
    tolerance but over :data:`simbench.decode.REFERENCE_Z0_WARNING` it warns: reference-mode
    depths carry that error (a Z0 2 % off gave 20 mm MAE on a plane, exit 0, without a word).
    ``pattern_assumed``: the pattern taken for a bare image (none given), named in a refusal as
    a cause (a capture of period 24 decoded at 21 lies 3.6 % off Z0, blamed on the rig alone).
    ``tell``: what takes a warning's text (None: the ``simbench`` logger; the Python API passes
    one that gives it as a :class:`simbench.SimbenchWarning`, which a script can make an error)."""
    from simbench.decode import REFERENCE_Z0_TOLERANCE, REFERENCE_Z0_WARNING, reference_plane_extent
    from simbench.rig import check_stripe_baseline

    # a baseline not along x first: its plane lies anywhere, and the words below would blame the
    # reference or Z0 (an audit, 2026-12-05: position_m = [0.005, 0.093, 0] in reference mode)
    check_stripe_baseline(rig)
    low, offset, high = reference_plane_extent(reference, rig)
    if np.isnan(offset):
        return
    tilt = dict(reference_path=reference_path, rig_path=rig_path, mode=mode, pattern_assumed=pattern_assumed, tell=tell)
    if abs(offset) <= REFERENCE_Z0_WARNING:
        _check_reference_tilt(reference, low, offset, high, **tilt)
        return
    if np.isinf(offset):
        raise ValueError(
            f"the reference plane {reference_path} does not triangulate with the rig {rig_path}: most of its decoded "
            "pixels' rays meet their projector columns behind the camera - was it captured with this rig (its "
            "projector on this side)?"
        )
    z = reference.z0_m * (1 + offset)
    where = (
        f"the reference plane {reference_path} triangulates with the rig {rig_path} to Z = {z:.4f} m, not its Z0 = "
        f"{reference.z0_m:g} m{' (assumed: no --z0 given)' if z0_assumed else ''} ({100 * offset:+.2f} %"
    )
    if abs(offset) > REFERENCE_Z0_TOLERANCE:
        raise ValueError(
            f"{where}, more than {100 * REFERENCE_Z0_TOLERANCE:.0f} %): was it captured with this rig, and at this Z0?"
            + _pattern_question(pattern_assumed)
        )
    advice = (
        f"the rig given ({rig_option}) is not the one it was recorded with, or not calibrated closely enough"
        if recorded_z0
        else f"give --z0 {z:.4f} if the board stood there, or check the rig"
    ) + ("." + _pattern_question(pattern_assumed) if pattern_assumed else "")
    # which depths carry it depends on what is off (an audit, 2026-11-30: the one text named reference
    # mode to a calibrated-mode user whose rig's baseline was 2.7 % long - 26.6 mm MAE in calibrated
    # mode, 2.4 mm in reference mode)
    error_mm = 1000 * abs(z - reference.z0_m)
    carried = (
        f"calibrated-mode depths carry that error (~{error_mm:.0f} mm at Z0) if the rig is off, reference-mode ones "
        "if the board's Z0 is"
        if mode == "calibrated"
        else f"reference-mode depths carry that error (~{error_mm:.0f} mm at Z0) if the board's Z0 is off; if the rig "
        "is, calibrated-mode ones carry it and reference-mode ones far less (they match columns against the "
        "reference, Eq. 14)"
    )
    tell_or_log(tell, f"{where}, more than {100 * REFERENCE_Z0_WARNING:.1f} %): {carried}; {advice}")
    _check_reference_tilt(reference, low, offset, high, **tilt)


def _pattern_question(pattern_assumed: str) -> str:
    if not pattern_assumed:
        return ""
    return (
        f" Or lit by another pattern than the one assumed ({pattern_assumed}: an image does not record its pattern; "
        "--period/--order/--sequence/--channels give yours)?"
    )


def _check_reference_tilt(
    reference,
    low,
    median,
    high,
    *,
    reference_path,
    rig_path,
    mode: str = "calibrated",
    pattern_assumed: str = "",
    tell: Callable[[str], None] | None = None,
) -> None:
    """The reference plane must be flat and square across the image too, not only at its Z0 in
    the median: its depth's 2nd and 98th percentiles against the median
    (:func:`simbench.decode.reference_plane_extent`), within the same tolerances.  A camera focal
    length or distortion off tilts and bends the plane about its centre, and the depths carry that
    (a focal length 3.8 % off: 54 mm MAE without a word)."""
    from simbench.decode import REFERENCE_EXTENT_PERCENTILES, REFERENCE_Z0_TOLERANCE, REFERENCE_Z0_WARNING

    worst = max(abs(low - median), abs(high - median))
    if worst <= REFERENCE_Z0_WARNING:
        return
    z0 = reference.z0_m
    p_lo, p_hi = REFERENCE_EXTENT_PERCENTILES
    where = (
        f"the reference plane {reference_path} triangulates with the rig {rig_path} to Z = {z0 * (1 + low):.4f} - "
        f"{z0 * (1 + high):.4f} m across the image ({_ordinal(p_lo)} - {_ordinal(p_hi)} percentile, "
        f"{100 * (low - median):+.2f} / "
        f"{100 * (high - median):+.2f} % about its median): tilted or bent"
    )
    if worst > REFERENCE_Z0_TOLERANCE:
        raise ValueError(
            f"{where} more than {100 * REFERENCE_Z0_TOLERANCE:.0f} %: the rig's camera (focal length, principal point "
            "or distortion) is not the one it was captured with - was it captured with this rig?"
            + _pattern_question(pattern_assumed)
        )
    # (a new user's audit, 2026-11-30: the same words in reference mode overstated its error 30-fold -
    # matching against the reference takes the camera's geometry from the reference itself)
    carried = (
        f"calibrated-mode depths carry that error (~{1000 * worst * z0:.0f} mm at the image's edges)"
        if mode == "calibrated"
        else "reference-mode depths carry far less of it (they match columns against the reference, Eq. 14), "
        f"calibrated-mode ones all of it (~{1000 * worst * z0:.0f} mm at the image's edges)"
    )
    tell_or_log(
        tell,
        f"{where} more than {100 * REFERENCE_Z0_WARNING:.1f} %: {carried}; check the rig's camera (focal length, "
        "principal point, distortion), or that the board stood square to the camera",
    )


def _ordinal(x: float) -> str:
    n = int(x)
    if x != n:
        return f"{x:g}th"
    return f"{n}{'th' if 10 <= n % 100 <= 20 else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')}"


def _check_same_recording_rig(capture_path, reference_path, manifests: dict, *, what: str = "reference") -> None:
    """A reference from another recording folder must have been recorded with the capture's rig
    (their manifests' rig.toml digests): a reference of another baseline decodes to wrong
    depths everywhere without a word.  So too the colour-robust decoder's calibration frames,
    against the reference (``what="calibration frame"``: a new user's audit, 2026-11-29, gave
    ``--calibration`` another rig's folder unchallenged)."""
    cap, ref = manifests.get(capture_path), manifests.get(reference_path)
    if cap is None or ref is None or cap is ref:
        return
    a, b = cap["sha256"].get("rig"), ref["sha256"].get("rig")
    if a is not None and b is not None and a != b:
        if what != "reference":
            raise ValueError(
                f"the {what} {reference_path} was recorded with another rig than the reference {capture_path} (their "
                "folders' rig.toml differ): calibration frames belong to the rig and plane they were captured with"
            )
        raise ValueError(
            f"--reference {reference_path} was recorded with another rig than {capture_path} (their folders' rig.toml "
            "differ): a reference plane belongs to the rig it was captured with"
        )


def _check_reference_pattern(reference_path, pattern: PatternSpec, manifests: dict) -> None:
    """A reference plane from a recording folder must have been captured with the pattern the
    capture is decoded with (its manifest records it): a new user's audit (2026-11-30) gave the
    reference of a recording made with a 24-px period to a 21-px capture, and only the plane's Z0
    check happened to refuse it (3.6 % off: a little nearer, and it would have decoded with a
    warning)."""
    if reference_path is None:
        return
    meta = manifests.get(reference_path)
    if meta is None or meta["files"].get("reference") != Path(reference_path).name:
        return  # a bare image (or one that is not its folder's reference): nothing recorded
    where = str(Path(reference_path).parent / RENDER_MANIFEST)
    recorded = recorded_pattern(meta, where=where)
    if not recorded.projects_as(pattern):
        raise ValueError(
            f"--reference {reference_path} was captured with the pattern {describe_pattern(recorded)} ({where}), the "
            f"capture is decoded with {describe_pattern(pattern)}: a reference plane must be captured with the "
            "capture's pattern"
        )


def _check_recorded_rig(rig, rig_path, capture_path, recorded: dict) -> None:
    """A recording's capture decodes with its own rig or a calibration of it: a ``--rig`` that
    describes another device (:func:`simbench.rig.rig_differences` against the rig.toml recorded
    beside the capture) is refused.  In calibrated mode nothing else would notice: a new user's
    audit (2026-11-29) decoded a capture recorded with a 150 mm baseline with the paper rig's 93 mm,
    exit 0, 268 mm MAE.  To decode an image with another rig on purpose, copy it out of its
    recording folder (an image without a recording is decoded as any image)."""
    from simbench.manifest import file_sha256
    from simbench.rig import load_rig

    name = recorded["files"].get("rig")
    if name is None:
        return
    path = Path(capture_path).parent / name
    if not path.is_file() or Path(rig_path).resolve() == path.resolve():
        return
    if file_sha256(path) != recorded["sha256"].get("rig"):
        raise ValueError(f"{path} does not match its folder's manifest (SHA-256 differs): the folder mixes files")
    refuse_another_rig(
        rig,
        load_rig(path),
        rig_path=rig_path,
        capture=capture_path,
        hint=f" ({path}; to decode with this rig on purpose, copy the image out of its recording folder)",
    )


# the calibration frames' file types, as a capture's (a lab's camera writes TIFF as often as PNG)
CALIBRATION_FRAME_SUFFIXES = (".png", ".tif", ".tiff", ".npy")


def _calibration_frame(folder: Path, kind: str) -> Path | None:
    """``folder``'s ``calibration_<kind>`` frame in one of :data:`CALIBRATION_FRAME_SUFFIXES`, None
    if there is none; two of them are refused (which one was meant?)."""
    found = [folder / f"calibration_{kind}{s}" for s in CALIBRATION_FRAME_SUFFIXES]
    found = [p for p in found if p.is_file()]
    if len(found) > 1:
        raise ValueError(
            f"{folder}/ holds {len(found)} calibration_{kind} frames ({', '.join(p.name for p in found)}): keep one"
        )
    return found[0] if found else None


def _calibrated_reference(request, rig, params, reference, *, reference_path, cache=None):
    """The decoded reference with its coupling matrix (the colour-robust decoder's unmixing):
    the reference capture (``reference``, or read from ``reference_path`` in calibrated mode) and
    the calibration frames beside it (or in ``request.calibration``); with the function that
    caches it (:func:`simbench.decode.persist.lookup_decoded_reference`)."""
    from simbench.decode.persist import lookup_decoded_reference
    from simbench.pattern import CALIBRATION_FRAMES

    if reference_path is None:
        raise ValueError(
            "the colour-robust decoder (unmix) calibrates on the reference plane: give --reference (and its "
            "calibration frames)"
        )
    folder = Path(request.calibration) if request.calibration is not None else Path(reference_path).parent
    paths = {k: _calibration_frame(folder, k) for k in CALIBRATION_FRAMES}
    missing = [f"calibration_{k}.png" for k, p in paths.items() if p is None]
    if missing:
        raise ValueError(
            f"the colour-robust decoder needs the calibration frames {missing} (or .tif, .tiff, .npy) in {folder}/ "
            "(render with `simbench render --calibration-frames`, or give --calibration FOLDER)"
        )
    ref_manifest = recording_manifest_of(reference_path) if Path(reference_path).is_file() else None
    for p in paths.values():
        # a frame inside a recording folder must be one of its files (a new user's audit, 2026-11-30:
        # another recording's frames dropped into a folder rendered without them were used, no word)
        own = recording_manifest_of(p)
        if own is not None and p.name not in own["files"].values():
            raise ValueError(
                f"{p} lies in a recording folder whose manifest does not list it ({folder}/{RENDER_MANIFEST}): it is "
                "not part of that recording. Calibration frames belong to the rig and reference plane they were "
                "captured with: render them with `simbench render --calibration-frames`, or give the folder they "
                "were recorded in with --calibration FOLDER"
            )
        _check_same_recording_rig(
            str(reference_path),
            str(p),
            {reference_path: ref_manifest, str(p): recording_manifest_of(p)},
            what="calibration frame",
        )
    frames = {k: _camera_image(p, rig, request, hint=False) for k, p in paths.items()}
    if reference is None:
        # calibrated mode: read here only (reference mode's was read, and warned of, with the capture)
        from simbench.decode.pipeline import reference_warnings
        from simbench.io import check_encoding

        reference = _camera_image(reference_path, rig, request)
        for told in reference_warnings(reference, rig=rig, params=params, encoding=check_encoding(request.encoding)):
            logging.getLogger("simbench").warning("%s: %s", reference_path, told)
    z0_asked, z0_option = _asked_z0(request, params)
    z0 = _z0_for(Path(reference_path), z0_asked, option=z0_option)
    ref_params = dataclasses.replace(params, mode="reference", z0_m=z0)
    from simbench.decode.color import CalibrationFrameError

    try:
        return lookup_decoded_reference(
            reference,
            rig=rig,
            params=ref_params,
            primaries=[frames[k] for k in CALIBRATION_FRAMES[1:]],
            dark=frames["dark"],
            cache=cache,
        )
    except CalibrationFrameError as exc:
        # (a new user's audit, 2026-11-30: these errors named no file)
        names = ", ".join(p.name for p in paths.values())
        raise CalibrationFrameError(f"the calibration frames in {folder}/ ({names}): {exc}") from None


def pattern_record(pattern: PatternSpec) -> dict:
    """The pattern as a render folder's manifest records it (:func:`recorded_pattern` reads it)."""
    return {
        "size_hw": list(pattern.size_hw),
        "period_px": pattern.period_px,
        "order": pattern.order,
        "sequence": pattern.codes().tolist(),
        "dc": pattern.dc,
        "amplitude": pattern.amplitude,
        "channels": pattern.channels,
    }


def recorded_pattern(meta: dict, *, where: str) -> PatternSpec:
    """The pattern a render folder's manifest (``meta.json``) records it was captured with.

    Raises
    ------
    ValueError
        No pattern recorded, or one that is not a valid pattern.
    """
    from simbench.pattern import PatternSpec, de_bruijn

    p = meta.get("pattern")
    if not isinstance(p, dict):
        raise ValueError(f"{where}: records no pattern, so it cannot be decoded as recorded")
    try:
        order = p["order"]
        codes = p.get("sequence")
        default = de_bruijn(order).tolist() if isinstance(order, int) and 2 <= order <= 16 else None
        sequence = None if codes is None or (default is not None and list(codes) == list(default)) else tuple(codes)
        return PatternSpec(
            size_hw=tuple(p["size_hw"]),
            period_px=p["period_px"],
            order=order,
            sequence=sequence,
            dc=p.get("dc", 0.5),
            amplitude=p.get("amplitude", 0.5),
            channels=p.get("channels", "rgb"),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{where}: its pattern is not valid ({exc})") from None


def recorded_z0(meta: dict, *, where: str) -> float:
    """The reference plane's depth a render folder's manifest records (Z0, m)."""
    from simbench import validate

    if "reference_depth_m" not in meta:
        raise ValueError(f"{where}: records no reference_depth_m (Z0)")
    # the bounds of a scene file's reference_depth_m (simbench.sim.scene)
    return validate.number(meta["reference_depth_m"], f"{where}: reference_depth_m", lo=0.0, lo_open=True, hi=100.0)


def recorded_adc_bits(meta: dict, *, where: str) -> int | None:
    """The bits of the camera's ADC a render folder's manifest records (its sensor's camera), or
    None where it records no sensor (the images' dtype's range then)."""
    from simbench import validate
    from simbench.io import ADC_BITS

    camera = meta.get("sensor", {}).get("camera") if isinstance(meta.get("sensor"), dict) else None
    if not isinstance(camera, dict) or "bits" not in camera:
        return None
    return validate.choice(validate.integer(camera["bits"], f"{where}: sensor.camera.bits"), "bits", ADC_BITS)


def _short_pattern(p: PatternSpec) -> str:
    # the pattern options' own terms (simbench pattern --help)
    return f"period {p.period_px} px, order {p.order}, sequence {''.join(map(str, p.codes()))}, channels {p.channels}"


def pattern_differences(given: PatternSpec, recorded: PatternSpec) -> str:
    """What tells ``given`` from ``recorded`` apart, field by field (a new user's audit: a pattern
    table giving only the period took the default size, and the message listed both patterns
    whole, the period alike in each)."""
    fields = (
        ("period", lambda p: f"{p.period_px} px"),
        ("order", lambda p: str(p.order)),
        ("codes", lambda p: "".join(map(str, p.codes()))),
        ("channels", lambda p: p.channels),
        ("dc", lambda p: f"{p.dc:g}"),
        ("amplitude", lambda p: f"{p.amplitude:g}"),
        ("size", lambda p: f"{p.size_hw[1]}x{p.size_hw[0]}"),
    )
    out = [f"{name} ({f(given)} against {f(recorded)} recorded)" for name, f in fields if f(given) != f(recorded)]
    hint = " - a pattern table's fields left out take PatternSpec's defaults, not the recording's" if out else ""
    return (", ".join(out) or "nothing shown here") + hint


def describe_pattern(p: PatternSpec) -> str:
    """One line naming what tells two patterns apart."""
    seq = "".join(map(str, p.codes()))
    return (
        f"period {p.period_px} px, order {p.order}, codes {seq}, channels {p.channels}, dc {p.dc:g}, amplitude "
        f"{p.amplitude:g}, {p.size_hw[1]}x{p.size_hw[0]}"
    )
