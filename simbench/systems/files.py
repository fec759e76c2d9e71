"""Decoding from files to files: a capture image or a recording folder in, a depth map, its
confidence map (and optionally a point cloud and the decoder's stage images) out - what
``simbench decode`` does, for every system.

A recording folder (``simbench render --out``) names the system that wrote it
(:func:`simbench.systems.system_of_recording`) and decodes that system's way, with what it
recorded; an image file is a capture of :data:`simbench.systems.DEFAULT_SYSTEM` (the paper's
sensor), decoded with a rig file.  A system that decodes its files itself (options of its own, a
reference plane, images) has a ``decode_files(request)`` method returning a :class:`FileDecode`;
any other system's folder is read with its ``read_recording`` and decoded with its ``decode``,
and the options it cannot use are refused, never ignored.

Every output is checked writable before anything is read, an output that would overwrite one of
the inputs (or a recording's own file) is refused, and the outputs are written together or not at
all (:func:`simbench.io.write_files`).
"""

from __future__ import annotations

import contextlib

import dataclasses
import hashlib
import json
import logging
import re
import shlex
import sys
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from simbench.rig import Rig

__all__ = [
    "DecodeRequest",
    "FileDecode",
    "decode_files",
    "recording_manifest_of",
    "confidence_path",
    "refuse_another_rig",
    "check_rig_on_a_plane",
    "tell_or_log",
]


# the command line's working range (--near, --far), metres: the paper's rig's ~0.9-1.4 m with margin
WORKING_RANGE_M = (0.75, 1.75)


@dataclass(frozen=True)
class DecodeRequest:
    """What to decode, how, and where the results go (paths as given by the user).

    capture : an image file (PNG/TIFF/NPY) or a recording folder
    out : the depth map to write (.npy, float32 metres, NaN invalid)
    confidence : the confidence map to write (default: NAME_confidence.npy beside ``out``)
    ply, debug_dir : the point cloud (.ply) and the folder of decoder stages, optional
    rig : a rig TOML (required for an image; for a folder, it replaces the recorded rig)
    min_confidence : the operating point; None = the decoder's own

    The other fields are options of the colour-fringe (proposed) sensor's decoder: a reference
    plane capture, its calibration frames' folder, the decoding ``mode``, Z0, the working range,
    the pattern (None = as recorded, or the default), the colour-robust decoder and other
    decoder settings as ``name=value`` items, the bits of the camera's ADC for images that
    do not record them (a 10-, 12- or 14-bit camera's uint16 digital numbers), and how the images'
    values encode light (:data:`simbench.io.ENCODINGS`: linear, or linearised first).  None or
    empty = not given.
    """

    capture: str
    out: str
    confidence: str | None = None
    ply: str | None = None
    debug_dir: str | None = None
    rig: str | None = None
    min_confidence: float | None = None
    cache_dir: str | None = None
    reference: str | None = None
    calibration: str | None = None
    mode: str | None = None
    z0_m: float | None = None
    near_m: float = WORKING_RANGE_M[0]
    far_m: float = WORKING_RANGE_M[1]
    period_px: int | None = None
    order: int | None = None
    sequence: str | None = None
    channels: str | None = None
    robust: bool = False
    decoder: tuple[str, ...] = ()
    bits: int | None = None
    encoding: str = "linear"


# how the command line names each option of a request, for messages that tell a user what to change
FLAGS = {
    "reference": "--reference",
    "calibration": "--calibration",
    "mode": "--mode",
    "z0_m": "--z0",
    "period_px": "--period",
    "order": "--order",
    "sequence": "--sequence",
    "channels": "--channels",
    "robust": "--robust",
    "decoder": "--decoder",
    "near_m": "--near",
    "far_m": "--far",
    "bits": "--bits",
    "encoding": "--encoding",
}
# the options every system takes (the rest are the colour-fringe decoder's)
COMMON_FIELDS = frozenset({"capture", "out", "confidence", "ply", "debug_dir", "rig", "min_confidence", "cache_dir"})


@dataclass
class FileDecode:
    """A system's decode of a request, before anything is written.

    depth_m, valid, confidence : (H, W) float32 metres (NaN invalid), bool, float32 (confidence
        None: the system gives none, and no confidence file is written)
    camera : the :class:`simbench.rig.Intrinsics` the depth map is on (for the point cloud)
    colours : (H, W, 3) uint8 per pixel for the point cloud, or None
    summary : what was done, for the one-line report (mode, Z0, reference, overrides)
    confidence_meaning : what the confidence is and the operating point applied
    stages : name -> array of the decoder's stages (``--debug-dir``), or None when it has none
    elapsed_s : the decode's own time
    capture_file : the image decoded (a folder's capture), as the stage folder records it
    commit : called after the decode succeeded, before the outputs are written (a cache entry)
    thresholded : (H, W) bool, the decoded pixels ``--min-confidence`` made holes, where the
        system knows them apart from pixels it never decoded (None: told by a positive
        confidence under the threshold)
    cause : why nothing was decoded where the system knows it (the warning names it)
    settings : what the decode was made with (the decoder's parameters, the files it read), for
        the decode's record (:func:`record_path`) and ``--debug-dir``'s stages.json
    """

    depth_m: np.ndarray
    valid: np.ndarray
    confidence: np.ndarray | None
    camera: Any
    summary: str
    confidence_meaning: str
    elapsed_s: float
    colours: np.ndarray | None = None
    stages: Mapping[str, np.ndarray] | None = None
    capture_file: str = ""
    commit: Callable[[], None] = field(default=lambda: None)
    thresholded: np.ndarray | None = None
    cause: str = ""
    settings: dict = field(default_factory=dict)


def confidence_path(request: DecodeRequest) -> Path:
    """Where the confidence map goes: ``request.confidence``, else NAME_confidence.npy beside
    ``request.out``."""
    if request.confidence:
        return Path(request.confidence)
    out = Path(request.out)
    return out.with_name(f"{out.stem}_confidence.npy")


def record_path(request: DecodeRequest) -> Path:
    """Where the decode's record goes: NAME_decode.json beside ``request.out`` (what the depth map
    and the confidence are, in which units, and what made them)."""
    out = Path(request.out)
    return out.with_name(f"{out.stem}_decode.json")


# the decode record's format (record_path); 2 (2026-12-05): ``ground_truth``, the decoded
# recording's ground truth (capture_ground_truth; null for a capture outside any recording), and
# ``depth.sha256``, the depth map's: `simbench score` checks a --gt against the first where the
# map is still the one the decode wrote
RECORD_FORMAT = 2
# what every system's depth map is (simbench.systems.SystemDepth, the ground truth's convention)
DEPTH_MEANING = (
    "z-depth in metres along the camera's optical axis (OpenCV axes: x right, y down, z forward), float32, "
    "one value per pixel of the ideal pinhole image (lens distortion undone); NaN where nothing was decoded"
)


def capture_ground_truth(capture: str | Path) -> dict | None:
    """The ground truth of the recording a capture belongs to (``capture`` a recording folder or
    a file in one): ``{"recording": its folder (absolute), "sha256": {"gt_depth": ..., ...}}``
    (the SHA-256 its sealed manifest records of each ground-truth depth file), or None for a
    capture outside any recording, or a recording without ground truth.  The decode record keeps
    it, so that `simbench score` knows whose depth a map is wherever it was written."""
    from simbench.manifest import read_manifest
    from simbench.systems import RECORDING_MANIFESTS

    capture = Path(capture)
    folder = capture if capture.is_dir() else capture.parent
    for name in reversed(RECORDING_MANIFESTS):  # meta.json first, as recording_manifest_of
        if (folder / name).is_file() and not _not_a_manifest(folder / name):
            sha = read_manifest(folder / name, verify_files=False)["sha256"]
            truth = {k: sha[k] for k in GROUND_TRUTH_DEPTH_KEYS if k in sha}
            return {"recording": str(folder.resolve()), "sha256": truth} if truth else None
    return None


# a recording's ground-truth depth files, as its manifest names them (.npy, and the same as EXR)
GROUND_TRUTH_DEPTH_KEYS = ("gt_depth", "gt_depth_exr")


def _not_a_manifest(path: Path) -> bool:
    """Whether the JSON file ``path`` is plainly no simbench manifest: an object with neither a
    ``manifest_format`` nor ``files`` (a lab's own ``meta.json`` beside its ground truth was
    refused as "a manifest of format None": an audit, 2026-12-05).  One with either, edited or
    of an older simbench, is still a recording's, and checked as one."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and "manifest_format" not in data and "files" not in data


def recording_manifest_of(path: str | Path) -> dict | None:
    """The sealed manifest (``meta.json``, or a competitor's ``device.json``) of the recording
    folder holding ``path`` (checked: the manifest's own seal, and ``path``'s recorded SHA-256
    when it lists it), or None when there is none.  A folder mixing the files of two renders,
    or whose manifest was edited, is refused."""
    from simbench.manifest import ManifestError, file_sha256, read_manifest
    from simbench.systems import RECORDING_MANIFESTS

    path = Path(path)
    for name in reversed(RECORDING_MANIFESTS):  # meta.json first
        meta = path.parent / name
        if not meta.exists():
            continue
        if _not_a_manifest(meta):  # a lab's own meta.json beside its files: no recording
            continue
        data = read_manifest(meta, verify_files=False)
        for key, listed in data["files"].items():
            if listed == path.name and file_sha256(path) != data["sha256"][key]:
                raise ManifestError(
                    f"{path} does not match {meta} (SHA-256 differs): the folder mixes files of two renders"
                )
        return data
    return None


def refuse_another_rig(
    rig: Rig,
    recorded: Rig,
    *,
    rig_path: str | Path | None,
    capture: str | Path,
    hint: str = "",
    label: str | None = None,
) -> None:
    """A ValueError when ``rig`` (given as ``--rig rig_path``; ``label`` names it otherwise)
    describes another device than the rig ``capture`` was recorded with
    (:func:`simbench.rig.rig_differences`): a recording decodes with its own rig or a calibration
    of it, never silently with another's (a new user's audit, 2026-11-29: a 150 mm baseline's
    capture decoded with a 93 mm rig, exit 0, 268 mm MAE).  ``hint``: what the caller adds to the
    line."""
    from simbench.rig import rig_differences

    far = rig_differences(rig, recorded)
    if far:
        raise ValueError(
            f"{label or f'--rig {rig_path}'} is another rig than {capture} was recorded with{hint}: {'; '.join(far)} - "
            "decode with the recorded rig or a calibration of it"
        )


def check_request_paths(request: DecodeRequest) -> None:
    """The output paths' kinds, before anything else: a depth map is .npy, a point cloud .ply,
    the stage folder a folder."""
    if Path(request.out).suffix != ".npy":
        raise ValueError(f"--out must name a .npy file, got {request.out}")
    if request.ply and Path(request.ply).suffix.lower() != ".ply":
        raise ValueError(f"--ply must name a .ply file, got {request.ply}")
    if confidence_path(request).suffix != ".npy":  # (an audit: NumPy bytes were written as c.png)
        raise ValueError(f"--confidence must name a .npy file, got {request.confidence}")
    if request.debug_dir and Path(request.debug_dir).exists() and not Path(request.debug_dir).is_dir():
        raise ValueError(f"--debug-dir {request.debug_dir} exists and is not a folder")


def check_outputs(request: DecodeRequest, *, inputs: list[str | None]) -> None:
    """Every output writable before the decode starts (a folder in the way, a file above one, no
    permission; the reference cache too), and none of them one of the ``inputs`` or a file of a
    recording among them (``--out FOLDER/gt_depth.npy`` replaced the ground truth)."""
    from simbench.cache import CACHE_HINT, check_cache_location
    from simbench.io import check_output_file, check_own_folder
    from simbench.manifest import listed_files
    from simbench.systems import RECORDING_MANIFESTS

    protected: set[Path] = set()
    folders: set[Path] = set()  # recording folders among the inputs'
    for p in inputs:
        if p:
            protected.add(Path(p).resolve())
            folder = Path(p) if Path(p).is_dir() else Path(p).parent
            listed = set().union(*(listed_files(folder / m) for m in RECORDING_MANIFESTS))
            protected |= listed
            folders |= {f.parent for f in listed}
    outputs = [Path(request.out), confidence_path(request), record_path(request)]
    outputs += [Path(request.ply)] if request.ply else []
    if request.debug_dir and Path(request.debug_dir).resolve() in folders:
        raise ValueError(f"--debug-dir {request.debug_dir} is a recording's folder: its stage images would mix with it")
    for out in outputs:
        if out.resolve() in protected:
            raise ValueError(
                f"{out} is a file of the recording being decoded (or an input): choose another output path"
            )
    check_output_file(request.out, what="--out")
    check_output_file(confidence_path(request), what="--confidence")
    check_output_file(record_path(request), what="the decode's record (NAME_decode.json beside --out)")
    if Path(request.out).resolve() == confidence_path(request).resolve():
        raise ValueError(f"--confidence {confidence_path(request)} is --out: give another path")
    if request.ply:
        check_output_file(request.ply, what="--ply")
    if request.debug_dir:
        check_own_folder(request.debug_dir, marker="stages.json", written_by="simbench decode", what="--debug-dir")
        debug, out = Path(request.debug_dir).resolve(), Path(request.out).resolve()
        if debug == out or out in debug.parents:
            raise ValueError(f"--debug-dir {request.debug_dir} is --out {request.out} or under it: give another folder")
        others = {p.resolve() for p in outputs}
        if debug in others or others & set(debug.parents):
            # (a new user's audit, 2026-11-30: --debug-dir named as the decode's record wrote the depth
            # and the confidence, then failed on the record with a raw errno)
            raise ValueError(
                f"--debug-dir {request.debug_dir} is another output's path or under it: give another folder"
            )
    if request.cache_dir is not None:
        check_cache_location(request.cache_dir, what="--cache", hint=CACHE_HINT)


def _is_confidence_of(path: Path, depth: np.ndarray) -> bool:
    """Whether ``path`` holds a confidence map (float32 .npy) of ``depth``'s shape."""
    if not path.is_file():
        return False
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError):
        return False
    return arr.dtype == np.float32 and arr.shape == depth.shape


@contextlib.contextmanager
def _warnings_told():
    """The messages of the warnings the ``simbench`` logger gives inside the block, as a list
    (filled as they come; they are still logged as before)."""
    told: list[str] = []

    class _Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            told.append(record.getMessage())

    handler = _Keep(logging.WARNING)
    logger = logging.getLogger("simbench")
    logger.addHandler(handler)
    try:
        yield told
    finally:
        logger.removeHandler(handler)


def decode_files(request: DecodeRequest) -> str:
    """Decode ``request.capture`` with the system it belongs to and write the outputs; the
    one-line report of what was decoded and where it went."""
    from simbench.io import json_bytes, npy_bytes, ply_bytes, png_bytes, write_files
    from simbench.metrics import points_from_depth
    from simbench.systems import DEFAULT_SYSTEM, get_system, system_of_recording

    t0 = time.perf_counter()
    check_request_paths(request)
    name = system_of_recording(request.capture) if Path(request.capture).is_dir() else DEFAULT_SYSTEM
    system = get_system(name)
    hook = getattr(system, "decode_files", None)
    with _warnings_told() as told:
        try:
            res = hook(request) if hook is not None else _decode_folder(system, request)
        except ValueError as exc:
            # a 16-bit image of fewer bits' digital numbers, warned of, then failing a check that
            # blames something else (an audit, 2026-12-05: a 12-bit pair without --bits was asked
            # whether its reference was the reference-plane capture): the error names the warning
            hint = next((m.group(0) for t in told if (m := re.search(r"give --bits \d+", t))), None)
            if hint is None or "--bits" in str(exc):
                raise
            raise ValueError(
                f"{exc} - or, as warned above, the images hold fewer bits than their type: {hint}"
            ) from None
    truth = capture_ground_truth(request.capture)
    elsewhere = _another_recordings_folder(Path(request.out), truth)
    if elsewhere:
        logging.getLogger("simbench").warning("--out %s: %s", request.out, elsewhere)
        told.append(f"--out {request.out}: {elsewhere}")
    files = {Path(request.out): npy_bytes(res.depth_m)}
    if res.confidence is not None:
        files[confidence_path(request)] = npy_bytes(res.confidence)
        confidence_note = f"confidence ({res.confidence_meaning}) -> {confidence_path(request)}"
    elif request.confidence:
        raise ValueError(f"--confidence {request.confidence}: the {name} system gives no confidence map")
    else:
        confidence_note = f"no confidence map (the {name} system gives none)"
    # an earlier decode's confidence beside --out would read as this depth's (a system without
    # one decoding into the folder where another wrote NAME_confidence.npy): removed with the write
    stale_confidence = None
    if res.confidence is None and not request.confidence and _is_confidence_of(confidence_path(request), res.depth_m):
        from simbench.io import check_not_protected

        stale_confidence = confidence_path(request)
        check_not_protected(stale_confidence)  # (a recording's listed file is never removed)
        confidence_note += f"; removed {stale_confidence}, an earlier decode's"
    msg = (
        f"decoded {res.valid.mean() * 100:.2f} % of the image's pixels in {res.elapsed_s * 1000:.0f} ms "
        # the decode alone; a user timing the command sees the files read and checked too (an audit)
        f"({time.perf_counter() - t0:.2f} s with reading the files; {res.summary}) -> {request.out}, "
        f"{confidence_note}"
    )
    if request.ply:
        pts = points_from_depth(res.depth_m, res.camera)
        files[Path(request.ply)] = ply_bytes(pts[res.valid], None if res.colours is None else res.colours[res.valid])
        msg += f", {request.ply}"
    if request.debug_dir:
        if res.stages is None:
            raise ValueError(f"--debug-dir: the {name} system's decoder has no stage images to write")
        d = Path(request.debug_dir)
        stage_files = {f"{key}.npy": npy_bytes(arr) for key, arr in res.stages.items()}
        if "wrapped_phase" in res.stages:
            stage_files["wrapped_phase.png"] = png_bytes(_to_u8(res.stages["wrapped_phase"], -np.pi, np.pi))
        if "intensity" in res.stages:
            stage_files["intensity.png"] = png_bytes(_to_u8(res.stages["intensity"], 0.0, 1.0))
        stage_files["depth.png"] = png_bytes(_to_u8(res.depth_m, *_finite_range(res.depth_m)))
        # the stage files only: --out, its confidence or --ply may lie in the folder too, and are
        # neither listed nor ever removed as a stage
        outputs = {p.resolve() for p in files}
        stages = sorted(n for n in stage_files if (d / n).resolve() not in outputs)
        files.update({d / n: stage_files[n] for n in stages})
        # a folder an earlier decode wrote keeps none of its stage files this decode has not
        # (the colour-robust decoder's crease_bias.npy beside the paper decoder's stages)
        here = {p.name for p in outputs if p.parent == d.resolve()}  # (an --out named like a stage stays)
        stale = sorted(set(_listed_stages(d)) - set(stages) - here - {"stages.json"})
        files[d / "stages.json"] = json_bytes(
            {
                "command": _command_line(),
                "format": STAGES_FORMAT,
                "capture": res.capture_file or request.capture,
                "system": name,
                "decoded": res.summary,
                "confidence": res.confidence_meaning if res.confidence is not None else "none",
                # (a fourth audit: docs/usage.md said it names the decode's settings; it named none)
                "settings": res.settings,
                "files": stages,
            }
        )
        msg += f", stages in {d}/"
    # what the files are and what made them, beside the depth map (a new user's audit, 2026-11-30:
    # the .npy files said nothing of their units, decoder or threshold; only stdout did)
    files[record_path(request)] = json_bytes(
        {
            "format": RECORD_FORMAT,
            "command": _command_line(),
            "simbench": _version(),
            "capture": res.capture_file or request.capture,
            "system": name,
            "decoded": res.summary,
            # whose depth this is, wherever it is written: `simbench score` checks its --gt against it
            "ground_truth": truth,
            "depth": {
                "file": Path(request.out).name,
                "meaning": DEPTH_MEANING,
                "valid_share": float(res.valid.mean()),
                # (what `simbench score` checks before it believes the record: a map written over
                # since is not this decode's)
                "sha256": hashlib.sha256(files[Path(request.out)]).hexdigest(),
            },
            "confidence": (
                None
                if res.confidence is None
                else {"file": confidence_path(request).name, "meaning": res.confidence_meaning}
            ),
            # the operating point in force: the decoder's (the proposed sensor's), or the one given; a
            # competitor's own validity rule is in confidence.meaning and settings.device
            "min_confidence": res.settings.get("decoder", {}).get("min_confidence", request.min_confidence),
            "point_cloud": Path(request.ply).name if request.ply else None,
            "settings": res.settings,
            # what the decode warned of, kept with the depth (a lab user's audit, 2026-11-30: "nothing
            # checks the rig" went to the terminal only, not to the files a batch run keeps)
            "warnings": told,
        }
    )
    msg += f", record -> {record_path(request)}"
    if len({p.resolve() for p in files}) != len(files):
        raise ValueError(
            "--out, --confidence, --ply, the decode's record (NAME_decode.json) and the --debug-dir files must be "
            "different paths"
        )
    # only now, the decode done: a failed decode leaves nothing behind, not even a cache entry; and
    # before the outputs, so that a cache that cannot take the entry fails with no output written
    res.commit()
    stale_records = _stale_records(files, request)
    write_files(files)
    if stale_confidence is not None and stale_confidence.resolve() not in {p.resolve() for p in files}:
        stale_confidence.unlink(missing_ok=True)
    for path in stale_records:
        path.unlink(missing_ok=True)
    if request.debug_dir:
        for name in stale:
            (Path(request.debug_dir) / name).unlink(missing_ok=True)
    hint = nothing_decoded_hint(
        res.valid,
        res.colours,
        working_range_m=(request.near_m, request.far_m),
        confidence=res.confidence,
        min_confidence=request.min_confidence,
        thresholded=res.thresholded,
        cause=res.cause,
    )
    if hint:
        logging.getLogger("simbench").warning("%s: %s", request.capture, hint)
    return msg


def _another_recordings_folder(out: Path, truth: dict | None) -> str:
    """Why writing the depth map ``out`` may mislead, where it lies in a recording folder other
    than the decoded capture's (``truth``: :func:`capture_ground_truth` of the capture): a user
    reading that folder, or a script pairing each folder's depth with its ground truth, would
    take it for that recording's (an audit, 2026-12-05).  "" otherwise."""
    from simbench.manifest import ManifestError

    try:  # a folder with a meta.json of the user's own, or an edited recording's: no recording to mistake
        there = capture_ground_truth(out.parent) if out.parent.is_dir() else None
    except (ManifestError, ValueError, OSError):
        return ""
    if there is None or (truth is not None and there["recording"] == truth["recording"]):
        return ""
    whose = f"the recording {truth['recording']}" if truth else "a capture outside any recording"
    return (
        f"written into the recording {out.parent}, but it is the depth of {whose}; `simbench score` tells "
        "them apart by the decode's record beside it, other readers may not"
    )


def _stale_records(files: dict, request: DecodeRequest) -> list[Path]:
    """The decode records that describe, as their depth map, a file this decode overwrites with
    something else (``--confidence c/x.npy`` over an earlier ``--out c/x.npy``: its x_decode.json
    would still call it the depth in metres - a new user's audit, 2026-11-30); removed with the write."""
    from simbench.io import check_not_protected

    written = {p.resolve() for p in files}
    stale = []
    for path in files:
        if path.resolve() == Path(request.out).resolve() or path.suffix != ".npy":
            continue
        record = path.with_name(f"{path.stem}_decode.json")
        if not record.is_file() or record.resolve() in written:
            continue
        try:
            described = json.loads(record.read_text()).get("depth", {}).get("file")
        except (OSError, ValueError, AttributeError):
            continue
        if described == path.name:
            check_not_protected(record)
            stale.append(record)
    return stale


def _command_line() -> str:
    """The command as typed where it is one (the marker's "simbench decode" prefix either way)."""
    argv = sys.argv[1:]
    at = argv.index("decode") + 1 if "decode" in argv[:2] else None  # (after a leading --debug too)
    return "simbench decode" + ("" if at is None else " " + shlex.join(argv[at:]))


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("simbench")
    except PackageNotFoundError:
        return "unknown"


# stages.json's format: 2 lists the stage files alone (format 1, unmarked, listed --out and the
# other outputs that lay in the folder too: its list is never used to remove anything)
STAGES_FORMAT = 2


def _listed_stages(folder: Path) -> list[str]:
    """The stage files an earlier ``simbench decode --debug-dir`` listed in ``folder``'s
    stages.json (plain names only: nothing outside the folder), or none."""
    try:
        info = json.loads((folder / "stages.json").read_text(encoding="utf-8"))
        listed = info.get("files", []) if info.get("format") == STAGES_FORMAT else []
    except (OSError, ValueError, AttributeError):
        return []
    return [n for n in listed if isinstance(n, str) and n == Path(n).name and n not in ("", ".", "..")]


# under this share of decoded pixels a decode is reported as (nearly) empty
NOTHING_DECODED_SHARE = 0.01


def nothing_decoded_hint(
    valid: np.ndarray,
    capture_u8: np.ndarray | None = None,
    *,
    working_range_m: tuple[float, float] | None = None,
    confidence: np.ndarray | None = None,
    min_confidence: float | None = None,
    thresholded: np.ndarray | None = None,
    cause: str = "",
) -> str:
    """A warning for a decode that found (almost) nothing - under :data:`NOTHING_DECODED_SHARE`
    of the pixels - naming the likely cause where the 8-bit capture shows it (dark, saturated)
    or a working range other than the default was asked for, or the system's own ``cause``; ""
    otherwise.  The decode itself
    stands (NaN where nothing decoded): a dark frame is a legal image, but a user who passed the
    wrong file should hear of it."""
    share = float(np.mean(valid)) if np.size(valid) else 0.0
    if share >= NOTHING_DECODED_SHARE:
        return ""
    why = "is the capture lit by this pattern, in focus, and taken with this rig and reference?"
    if working_range_m is not None and tuple(working_range_m) != WORKING_RANGE_M:
        near, far = working_range_m
        why = f"is the scene within the working range asked for, {near:g}-{far:g} m (--near, --far)?"
    if capture_u8 is not None and capture_u8.size:
        top = int(capture_u8.max())
        full = capture_u8 >= 255
        clipped = float(full.all(axis=-1).mean()) if capture_u8.ndim == 3 else float(full.mean())
        # one channel clipped is enough to lose the fringe (a capture three times too bright:
        # blue, the fringe, at 255 over most of it while red and green were not)
        per_channel = full.reshape(-1, capture_u8.shape[-1]).mean(axis=0) if capture_u8.ndim == 3 else []
        if top <= 16:
            why = f"the capture is dark (its brightest value {top} of 255)"
        elif clipped >= 0.5:
            why = f"{100 * clipped:.0f} % of the capture's pixels are saturated in every channel"
        elif len(per_channel) == 3 and max(per_channel) >= 0.5:
            names = " and ".join(f"{c} on {100 * v:.0f} %" for c, v in zip("RGB", per_channel) if v >= 0.5)
            why = f"the capture is saturated: {names} of its pixels (at 255) - expose it shorter"
    if min_confidence is not None and confidence is not None:
        conf = np.asarray(confidence, np.float32)
        under = np.isfinite(conf) & (conf > 0) & (conf < np.float32(min_confidence))
        if thresholded is not None:
            # (phase shifting's modulation is positive at pixels it never decoded: a dark
            # capture's holes are not the threshold's)
            under &= np.asarray(thresholded, bool)
        if under.any():  # (a hole's confidence is kept: the threshold, not the decode, made it)
            why = (
                f"--min-confidence {min_confidence:g} made holes of {100 * float(np.mean(under)):.1f} % of the pixels "
                f"(the most confident has {float(np.max(conf[under])):.4g})"
            )
    if cause:
        why = cause
    what = "no pixel" if share == 0 else f"only {100 * share:.2f} % of the pixels"
    return f"{what} decoded: {why}"


def _decode_folder(system: Any, request: DecodeRequest) -> FileDecode:
    """A recording folder of a system without a ``decode_files`` of its own: read with its
    ``read_recording``, decoded with its ``decode`` and what it recorded; a ``rig`` replaces the
    recorded one (e.g. the rig ``simbench calibrate`` estimated)."""
    from simbench.decode.pipeline import apply_min_confidence

    name = system.name
    defaults = DecodeRequest(capture=request.capture, out=request.out)
    stray = [
        FLAGS[f.name]
        for f in dataclasses.fields(request)
        if f.name not in COMMON_FIELDS and getattr(request, f.name) != getattr(defaults, f.name)
    ]
    if stray:
        verb = "applies" if len(stray) == 1 else "apply"
        raise ValueError(
            f"{request.capture} is a {name} recording: {', '.join(stray)} {verb} to the proposed sensor's folders only "
            f"(a {name} folder decodes the {name} way, with what it recorded)"
        )
    if request.debug_dir:
        raise ValueError(f"--debug-dir: the {name} system's decoder has no stage images to write")
    if request.rig is not None and not system.info().uses_scene_rig:
        # (its decode keeps the device's factory calibration: a rig would change only the point
        # cloud's rays - a new user's audit found a Kinect cloud twice as wide, the depth unchanged)
        raise ValueError(
            f"--rig applies to systems decoding with the scene's rig; the {name} system keeps its device's factory "
            "calibration: leave --rig out"
        )
    check_outputs(request, inputs=[request.capture, request.rig])
    raw, cal, scene = system.read_recording(Path(request.capture))
    if request.rig is not None:
        from simbench.rig import load_rig

        rig = load_rig(request.rig)
        if rig.camera.size_hw != scene.rig.camera.size_hw:
            raise ValueError(
                f"--rig {request.rig}: camera {rig.camera.width_px}x{rig.camera.height_px}, but the recording's is "
                f"{scene.rig.camera.width_px}x{scene.rig.camera.height_px}"
            )
        refuse_another_rig(rig, scene.rig, rig_path=request.rig, capture=request.capture)
        check_rig_on_a_plane(rig, scene.rig, rig_path=request.rig, capture=request.capture)
        scene = dataclasses.replace(scene, rig=rig)
    t0 = time.perf_counter()
    res = system.decode(raw, cal, scene=scene)
    dt = time.perf_counter() - t0
    info = system.info()
    if request.min_confidence is not None:
        if res.confidence is None:
            raise ValueError(f"--min-confidence: the {name} system gives no confidence map")
        before = res.valid
        res = apply_min_confidence(res, request.min_confidence)
        thresholded = before & ~res.valid
        if before.any() and not (before & ~res.valid).any():
            # (the audit's ToF decode at 0.9: 100 % decoded, nothing said of its 200 e- floor)
            lowest = float(np.min(np.asarray(res.confidence)[before]))
            over_floor = f", which removed no pixel (the least confident decoded one has {lowest:.4g})"
        else:
            over_floor = ""
    else:
        thresholded = None
    over = f"; overriding the recording: rig {request.rig} instead of the recorded one" if request.rig else ""
    if info.uses_scene_rig and not request.rig:  # the rig its depth was triangulated with, always
        over = f", rig {Path(request.capture) / 'rig.toml'}"
    meaning = info.confidence + (
        f"; and, by --min-confidence, below {request.min_confidence:g}{over_floor}"
        if request.min_confidence is not None
        else ""
    )
    return FileDecode(
        depth_m=res.depth_m,
        valid=res.valid,
        # (a fourth audit: an all-zero map was written, read as "zero confidence everywhere")
        confidence=res.confidence,
        camera=scene.rig.camera,
        summary=info.label + over,
        confidence_meaning=meaning,
        elapsed_s=dt,
        thresholded=thresholded,
        settings={"rig": request.rig, "min_confidence": request.min_confidence, "device": _device_parameters(system)},
    )


# the plane a competitor's --rig is tried on (m): the middle of the working range
RIG_CHECK_DEPTH_M = 1.0


def check_rig_on_a_plane(
    rig: Rig,
    recorded: Rig,
    *,
    rig_path: str | Path | None,
    capture: str | Path,
    label: str | None = None,
    tell: Callable[[str], None] | None = None,
) -> None:
    """A ``--rig`` (``label`` names it otherwise) for a recording decoded by triangulation with
    no reference plane (phase shifting): a fronto-parallel plane at :data:`RIG_CHECK_DEPTH_M`,
    seen through the recorded rig (each ideal pixel's projector column), triangulated with
    ``rig`` must lie there across the image within the proposed sensor's reference-plane
    tolerances (2nd-98th percentile within :data:`simbench.decode.REFERENCE_Z0_TOLERANCE`, a
    warning over ..._WARNING).  A new user's audit (2026-11-30): phase shifting decoded with a
    camera focal length 4 % off - inside :func:`simbench.rig.rig_differences`' 5 % - triangulated
    60 mm wrong with only "overriding the recording" said.  (Lens distortion is not compared: the
    plane is on the ideal pixel grid.)  ``tell``: what takes the warning's text (None: the
    ``simbench`` logger)."""
    from simbench.decode import REFERENCE_Z0_TOLERANCE, REFERENCE_Z0_WARNING, ReferenceMap, reference_plane_extent
    from simbench.rig import projector_column_at_depth

    # the plane as the recorded rig's reference would map it, read as the reference check reads one
    col = projector_column_at_depth(RIG_CHECK_DEPTH_M, recorded).astype(np.float32)
    plane = ReferenceMap(column_px=col, expected_px=col, inverse=np.zeros((1, 1), np.float32), z0_m=RIG_CHECK_DEPTH_M)
    label = label or f"--rig {rig_path}"
    lo, _, hi = reference_plane_extent(plane, rig)
    if np.isinf(lo):
        raise ValueError(f"{label} triangulates no plane in front of the camera from {capture}'s recorded rig")
    worst = max(abs(lo), abs(hi))
    if worst <= REFERENCE_Z0_WARNING:
        return
    where = (
        f"{label} puts a plane the recorded rig sees at {RIG_CHECK_DEPTH_M:g} m at "
        f"{RIG_CHECK_DEPTH_M * (1 + lo):.4f} - {RIG_CHECK_DEPTH_M * (1 + hi):.4f} m across the image"
    )
    if worst > REFERENCE_Z0_TOLERANCE:
        raise ValueError(
            f"{where}, more than {100 * REFERENCE_Z0_TOLERANCE:.0f} % off: it is not a calibration of the rig "
            f"{capture} was recorded with"
        )
    tell_or_log(
        tell,
        f"{where} (more than {100 * REFERENCE_Z0_WARNING:.1f} % off): depths by triangulation carry that "
        f"(~{1000 * worst * RIG_CHECK_DEPTH_M:.0f} mm at 1 m)",
    )


def tell_or_log(tell: Callable[[str], None] | None, message: str) -> None:
    """A check's warning ``message`` to ``tell`` (the Python API's, which gives it as a
    :class:`simbench.SimbenchWarning`), or logged (logger ``simbench``) where it is None."""
    if tell is None:
        logging.getLogger("simbench").warning("%s", message)
    else:
        tell(message)


def _device_parameters(system) -> dict | None:
    """A competitor's parameters as its recording holds them (its sequence or device model), for
    the decode's record: its own validity rule among them (e.g. phase shifting's ``min_snr``)."""
    for name in ("spec", "model"):
        value = getattr(system, name, None)
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return dataclasses.asdict(value)
    return None


def _finite_range(a: np.ndarray) -> tuple[float, float]:
    f = a[np.isfinite(a)]
    return (float(f.min()), float(f.max())) if f.size else (0.0, 1.0)


def _to_u8(a: np.ndarray, lo: float, hi: float) -> np.ndarray:
    x = (np.nan_to_num(np.asarray(a, dtype=np.float64), nan=lo) - lo) / max(hi - lo, 1e-12)
    return np.rint(np.clip(x, 0, 1) * 255).astype(np.uint8)
