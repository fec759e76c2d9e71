"""``simbench decode`` and ``simbench score``: a capture or recording to depth, and depth scored against
ground truth."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from simbench import api
from simbench.io import ADC_BITS
from simbench.cli.options import (
    add_cache_options,
    add_pattern_options,
    encoding,
    float_in,
    int_in,
)


def _cmd_decode(args) -> int:
    from simbench.systems.files import DecodeRequest, decode_files

    request = DecodeRequest(
        capture=args.capture,
        out=args.out,
        confidence=args.confidence,
        ply=args.ply,
        debug_dir=args.debug_dir,
        rig=args.rig,
        min_confidence=args.min_confidence,
        cache_dir=None if args.no_cache else args.cache,
        reference=args.reference,
        calibration=args.calibration,
        mode=args.mode,
        z0_m=args.z0,
        near_m=args.near,
        far_m=args.far,
        period_px=args.period,
        order=args.order,
        sequence=args.sequence,
        channels=args.channels,
        robust=args.robust,
        decoder=tuple(args.decoder or ()),
        bits=args.bits,
        encoding=args.encoding,
    )
    print(decode_files(request))
    return 0


def _cmd_score(args) -> int:
    from simbench.io import load_depth_map, load_npy
    from simbench.systems.files import recording_manifest_of
    from simbench.metrics import MOVING_TRUTH_NOTE, confidence_curve, depth_errors, edge_band, every_decoded_pixel
    from simbench.metrics import image_motion_px
    from simbench.metrics import implausible_columns, implausible_depth

    if args.period is not None and args.period <= 2:
        raise ValueError(f"--period must be > 2 projector px, got {args.period}")
    _refuse_another_recorded_file(Path(args.gt))
    gt = _depth_map(load_depth_map(args.gt), args.gt, what="ground truth")
    if not np.isfinite(gt).any():
        raise ValueError(f"{args.gt}: the ground truth has no finite depth: nothing to score against")
    if not (gt[np.isfinite(gt)] > 0).any():
        raise ValueError(f"{args.gt}: the ground truth has no depth > 0 m: is it a depth map in metres?")
    depth = _depth_map(load_depth_map(args.depth, expected_shape=gt.shape), args.depth, what="depth map")
    if (args.zero_is_hole or args.min_confidence is not None) and depth.dtype.kind != "f":
        depth = depth.astype(np.float64)  # (holes are NaN: an integer map has none)
    if args.zero_is_hole:
        depth = np.where(depth > 0, depth, depth.dtype.type(np.nan))
    confidence = None
    if args.min_confidence is not None and not args.confidence:
        raise ValueError("--min-confidence needs --confidence (the map it thresholds)")
    if args.confidence:
        confidence = load_npy(args.confidence, expected_shape=depth.shape)
        if confidence.dtype.kind not in "fiu":
            raise ValueError(f"--confidence {args.confidence}: a map of numbers, got {confidence.dtype}")
        confidence = confidence.astype(np.float64)
        if args.min_confidence is not None:  # (NaN confidence: not sure of anything)
            with np.errstate(invalid="ignore"):
                unsure = ~(confidence >= args.min_confidence)
            depth = np.where(unsure, depth.dtype.type(np.nan), depth)
    gt_dir = Path(args.gt).parent
    if args.lit and not Path(args.lit).is_file():  # (it fell back to every finite truth without a word)
        raise FileNotFoundError(f"--lit {args.lit}: no such file")
    lit_path = Path(args.lit) if args.lit else gt_dir / "gt_lit.npy"
    col_gt_path = Path(args.gt_column) if args.gt_column else gt_dir / "gt_column.npy"
    recorded = None
    for p in (Path(args.gt), lit_path, col_gt_path):  # inside a recording folder: as recorded
        if p.is_file():
            meta = recording_manifest_of(p)
            recorded = meta if p == Path(args.gt) else recorded
    period = _score_period(args.period, recorded)
    if not args.lit:
        _refuse_missing(lit_path, recorded, "the region would be all finite ground truth instead")
    region = _mask(load_npy(lit_path, expected_shape=gt.shape), lit_path) if lit_path.is_file() else np.isfinite(gt)
    region_is = str(lit_path) if lit_path.is_file() else "finite ground truth"
    if not lit_path.is_file() and not args.json:
        # (an audit: a ground truth copied out of its recording scored its shadows too, without a word)
        print(
            f"simbench: note: no {lit_path.name} beside --gt: the region is every pixel with a finite ground truth, "
            "shadows and pixels the projector does not reach included; give --lit for the lit pixels",
            file=sys.stderr,
        )
    other = _not_the_recordings_truth(Path(args.depth), Path(args.gt))
    if other:
        print(f"simbench: warning: {args.depth}: {other}", file=sys.stderr)
    exclude = None
    if args.edge_band < 0:
        raise ValueError(f"--edge-band must be >= 0, got {args.edge_band}")
    if args.edge_band > 0:
        obj_path = gt_dir / "gt_object_id.npy"
        _refuse_missing(obj_path, recorded, "the edge band would miss the object boundaries")
        if obj_path.is_file():  # inside a recording folder: as recorded, as the files above
            recording_manifest_of(obj_path)
        obj = load_npy(obj_path, expected_shape=gt.shape) if obj_path.is_file() else None
        exclude = edge_band(gt, object_id=obj, band_px=args.edge_band)
    kw = {}
    if args.column:
        kw = {
            "column_px": load_npy(args.column, expected_shape=gt.shape),
            "gt_column_px": load_npy(col_gt_path, expected_shape=gt.shape),
            "period_px": period,
        }
    if kw:
        for warning in implausible_columns(kw["column_px"], kw["gt_column_px"]):
            print(f"simbench: warning: {args.column}: {warning}", file=sys.stderr)
    m = depth_errors(depth, gt, region=region, exclude=exclude, **kw)
    m.update(every_decoded_pixel(depth, gt, region))
    m["region"] = region_is
    if confidence is not None:
        m["confidence_curve"] = confidence_curve(
            depth, confidence, gt, region, thresholds=_curve_thresholds(confidence[np.isfinite(depth)])
        )
    if not m["n_region"]:
        raise ValueError(
            f"no pixel to score: the region ({lit_path.name if lit_path.is_file() else 'finite ground truth'}) "
            "holds no pixel with a finite ground truth off the edge band"
        )
    for warning in implausible_depth(depth, gt, region):
        print(f"simbench: warning: {args.depth}: {warning}", file=sys.stderr)
    motion_name = (recorded or {}).get("files", {}).get("gt_motion")
    if motion_name:  # a moving recording: its truth is one instant (as simbench.score says)
        motion_path = gt_dir / motion_name
        _refuse_missing(motion_path, recorded, "a moving recording would be scored as a still one")
        recording_manifest_of(motion_path)
        m["image_motion_px"] = image_motion_px(load_npy(motion_path, expected_shape=(*gt.shape, 2)))
    if args.json:  # strict JSON: a metric with nothing to measure is null, not NaN

        def strict(v):
            if isinstance(v, list):
                return [{k: strict(x) for k, x in row.items()} for row in v]
            return None if isinstance(v, float) and not np.isfinite(v) else v

        clean = {k: strict(v) for k, v in m.items()}
        print(json.dumps(clean, indent=2, sort_keys=True, allow_nan=False))
    else:
        band = ""
        if exclude is not None:
            left = int(np.count_nonzero(exclude & region & np.isfinite(gt)))
            band = (
                f" (errors off a {args.edge_band}-px band at depth edges and object boundaries: {left} pixels left out)"
            )
        print(
            f"MAE {m['mae_mm']:.4f} mm  RMSE {m['rmse_mm']:.4f} mm  median {m['median_mm']:.4f} mm  p95 "
            f"{m['p95_mm']:.4f} mm{band}"
        )
        print(
            f"completeness {100 * m['completeness']:.2f} % of the {m['n_region']} pixels of the region "
            f"({lit_path.name if lit_path.is_file() else 'finite ground truth'}), outliers (> 5 mm) "
            f"{100 * m['outlier_share']:.3f} %"
        )
        print(
            f"every decoded pixel: {m['n_decoded']} ({m['n_decoded_outside']} outside the region), "
            f"{100 * m['wrong_share_all']:.3f} % of them > 5 mm wrong (depth edges, shadows and unlit pixels "
            "included; a depth where the truth has none counts wrong)"
        )
        if "stripe_order_errors" in m:
            print(
                f"stripe-order errors {m['stripe_order_errors']} ({100 * m['stripe_order_error_rate']:.4f} % of valid "
                f"pixels)"
            )
        if "image_motion_px" in m:
            print(f"note: {MOVING_TRUTH_NOTE.format(px=m['image_motion_px'])}")
        if "confidence_curve" in m:
            print(
                "kept at confidence >=   completeness   > 5 mm wrong: of the region's kept, of every kept pixel "
                "(decoded pixels left out: 0 / 1 / 2 / 5 / 10 / 20 / 30 / 50 %)"
            )
            for row in m["confidence_curve"]:
                print(
                    f"  {row['threshold']:>20.6g}   {100 * row['completeness']:10.2f} %   "
                    f"{100 * row['wrong_share']:.3f} %, {100 * row['wrong_share_all']:.3f} %"
                )
    return 0


# the shares of the decoded pixels the confidence curve's thresholds leave out (a user's decoder's
# confidence has a scale of its own: its thresholds are quantiles of it)
CURVE_LEFT_OUT = (0.0, 0.01, 0.02, 0.05, 0.1, 0.2, 0.3, 0.5)


def _curve_thresholds(confidence: np.ndarray) -> list[float]:
    """The confidence values below which :data:`CURVE_LEFT_OUT` of the decoded pixels' finite
    ``confidence`` lie (the first, the least: every decoded pixel kept; its NaN never are)."""
    c = confidence[np.isfinite(confidence)]
    if not c.size:
        return [0.0]
    return [float(np.min(c)) if q == 0 else float(np.quantile(c, q, method="higher")) for q in CURVE_LEFT_OUT]


def _refuse_another_recorded_file(gt_path: Path) -> None:
    """A ValueError when ``--gt`` is a file its recording lists as something other than the
    ground-truth depth (an audit, 2026-12-05: gt_column.npy as --gt scored 701570 mm MAE with a
    warning that blamed the depth map; gt_object_id.npy crashed)."""
    from simbench.systems.files import GROUND_TRUTH_DEPTH_KEYS, recording_manifest_of

    if not gt_path.is_file():
        return
    meta = recording_manifest_of(gt_path)
    files = (meta or {}).get("files", {})
    key = next((k for k, name in files.items() if name == gt_path.name), None)
    if key is not None and key not in GROUND_TRUTH_DEPTH_KEYS:
        depth = files.get("gt_depth")
        raise ValueError(
            f"--gt {gt_path} is the recording's {key}, not its ground-truth depth"
            + (f": give {gt_path.parent / depth}" if depth else "")
        )


def _refuse_missing(path: Path, recorded: dict | None, instead: str) -> None:
    """A ValueError when ``path``, a file ``score`` reads by default beside the ground truth, is
    missing though the recording's manifest lists it: scoring would silently use other pixels (a
    user's audit, 2026-11-30: without gt_lit.npy the region became every finite pixel, 95.23 % of
    1228800 instead of 98.54 % of 1187520, exit 0)."""
    if recorded is not None and not path.is_file() and path.name in recorded["files"].values():
        raise ValueError(f"{path} is missing: the recording's manifest lists it ({instead}); render it again")


def _mask(a: np.ndarray, path) -> np.ndarray:
    """A boolean mask (``gt_lit.npy``), or integers that are all 0 or 1; anything else is refused
    (a float map cast to bool counts NaN and every non-zero value as lit)."""
    if a.dtype == bool:
        return a
    if a.dtype.kind in "iu" and a.size and np.isin(a, (0, 1)).all():
        return a.astype(bool)
    finite = a[np.isfinite(a)] if a.dtype.kind == "f" else a
    span = f" in [{finite.min():g}, {finite.max():g}]" if finite.size else ""
    raise ValueError(
        f"{path}: --lit must be a boolean mask (as gt_lit.npy), got {a.dtype} values{span}: a depth or id map?"
    )


def _not_the_recordings_truth(depth_path: Path, gt_path: Path) -> str:
    """A warning when the depth map lies in a recording folder whose ground truth ``gt_path`` is
    not (another scene's ground truth scored without a word gave 174 mm MAE); "" otherwise, or
    where the depth map lies outside any recording (nothing to compare with)."""
    from simbench.manifest import file_sha256
    from simbench.systems.files import GROUND_TRUTH_DEPTH_KEYS, recording_manifest_of

    from simbench.manifest import ManifestError

    if not depth_path.is_file() or not gt_path.is_file():
        return ""
    # the decode's record beside the map says whose depth it is, wherever it was written (a depth
    # decoded from one recording into another's folder was taken for the folder's: an audit)
    record = _decode_record(depth_path)
    if record is not None and record["truth"] is not None:
        truth = record["truth"]
        if file_sha256(gt_path) in set(truth["sha256"].values()):
            return ""
        return (
            f"its decode record ({depth_path.stem}_decode.json) says it is the depth of the recording "
            f"{truth['recording']}, whose ground truth is not {gt_path} (another SHA-256): scored against another "
            "recording's truth?"
        )
    try:  # a folder with a meta.json of the user's own (no recording) tells nothing
        meta = recording_manifest_of(depth_path)
    except (ManifestError, ValueError, OSError):
        return ""
    if record is not None:  # decoded from a capture outside any recording, into this folder or not
        own_truth = {(meta or {}).get("sha256", {}).get(k) for k in GROUND_TRUTH_DEPTH_KEYS} - {None}
        if file_sha256(gt_path) not in own_truth:
            return ""
        return (
            f"it lies in the recording {depth_path.parent}, but its decode record ({depth_path.stem}_decode.json) "
            f"says it was decoded from {record['capture']}, a capture outside any recording: is it this recording's "
            "depth?"
        )
    if meta is None or "gt_depth" not in meta.get("sha256", {}):
        return ""
    if file_sha256(gt_path) in {meta["sha256"].get(k) for k in ("gt_depth", "gt_depth_exr")}:  # .npy or .exr
        return ""
    own = depth_path.parent / meta["files"]["gt_depth"]
    return (
        f"it lies in the recording {depth_path.parent}, whose ground truth is not {gt_path} (another SHA-256): "
        f"scored against another recording's truth? (that recording's is {own})"
    )


def _decode_record(depth_path: Path) -> dict | None:
    """What the decode record beside ``depth_path`` (NAME_decode.json, format 2 or later) says of
    it: {"truth": {"recording": folder, "sha256": {key: hex}} or None (a capture outside any
    recording), "capture": the capture decoded}; None where there is no such record, it is of
    another file, the map is not the one it wrote (written over since: its SHA-256 differs), or
    it cannot be read (edited by hand: anything unexpected in it)."""
    from simbench.manifest import file_sha256

    record = depth_path.with_name(f"{depth_path.stem}_decode.json")
    try:
        info = json.loads(record.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(info, dict) or not isinstance(info.get("format"), int) or info["format"] < 2:
        return None
    depth = info.get("depth")
    if not isinstance(depth, dict) or depth.get("file") != depth_path.name or not isinstance(depth.get("sha256"), str):
        return None
    if file_sha256(depth_path) != depth["sha256"]:
        return None
    truth = info.get("ground_truth")
    if truth is not None:
        sha = truth.get("sha256") if isinstance(truth, dict) else None
        if not (
            isinstance(truth.get("recording") if isinstance(truth, dict) else None, str)
            and isinstance(sha, dict)
            and sha
            and all(isinstance(v, str) for v in sha.values())
        ):
            return None
    return {"truth": truth, "capture": str(info.get("capture", "?"))}


def _score_period(given: float | None, recorded: dict | None) -> float:
    """The fringe period stripe-order errors are counted in: ``--period``, else the pattern the
    ground truth's recording was made with, else the paper's (an audit: a period-30 recording's
    columns were counted against 21 px)."""
    from simbench.pattern import PatternSpec

    recorded = recorded or {}
    pattern = recorded.get("pattern")
    # the proposed sensor's pattern, or a device's own period (the phase-shift system's device.json)
    own = pattern.get("period_px") if isinstance(pattern, dict) else recorded.get("period_px")
    own = float(own) if isinstance(own, (int, float)) and not isinstance(own, bool) else None
    if given is None:
        return own if own is not None else PatternSpec().period_px
    if own is not None and given != own:
        print(
            f"simbench: warning: --period {given:g}, but the recording was made with a period of {own:g} px",
            file=sys.stderr,
        )
    return given


def _depth_map(a: np.ndarray, path, *, what: str) -> np.ndarray:
    """``a`` if it is a 2-D map of real numbers (metres), else a one-line error naming the file."""
    if a.ndim != 2:
        raise ValueError(f"{path}: {what} must be a 2-D depth map, got shape {a.shape}")
    if a.dtype.kind not in "fiu":
        raise ValueError(f"{path}: {what} must hold real numbers (metres), got dtype {a.dtype}")
    return a


def add_parsers(sub, kw: dict) -> None:
    """Add this module's commands to the command line's subparsers."""
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
        help="confidence map to write (.npy, float32, the system's own unit: the colour-fringe sensor's is the fringe "
        "SNR; default: NAME_confidence.npy beside --out)",
    )
    s.add_argument(
        "--min-confidence",
        type=float_in(lo=api.MIN_CONFIDENCE_RANGE[0], hi=api.MIN_CONFIDENCE_RANGE[1]),
        default=None,
        help="the operating point: decoded pixels whose confidence is below it become holes (the colour-fringe "
        "sensor's fringe SNR is at most 1e4; default: the decoder's "
        "own: for the colour-robust decoder simbench.decode.ROBUST_MIN_CONFIDENCE, none for the paper's decoder, each "
        "competitor's validity threshold; a competitor's own threshold always applies, so a lower value changes "
        "nothing there - the decode's line says so)",
    )
    s.add_argument(
        "--ply", help="also write the point cloud as PLY (x, y, z in metres, the camera's frame: OpenCV axes; RGB)"
    )
    s.add_argument("--debug-dir", help="write every decoder stage here")
    s.add_argument(
        "--mode",
        choices=("reference", "calibrated"),
        default=None,
        help="reference (the default): match against the reference plane (paper Sec. 5.4); calibrated: triangulate "
        "with the rig",
    )
    s.add_argument(
        "--bits",
        type=int,
        choices=ADC_BITS,
        default=None,
        help="the bits of the camera's ADC, for images that do not record them: a 10-, 12- or 14-bit camera's 16-bit "
        "image holds its digital numbers, 0 to 2^bits - 1 (default: a recording's camera, else the image's "
        "dtype: 8-bit / 255, 16-bit / 65535)",
    )
    s.add_argument(
        "--encoding",
        type=encoding,
        default="linear",
        metavar="{linear,srgb,gamma=G}",
        help="how the images' values encode light (the capture's, the reference's, the calibration frames'): linear "
        "(the default: a machine-vision camera's raw digital numbers, a simbench recording's), srgb (IEC 61966-2-1, "
        "most consumer cameras' 8-bit output) or gamma=G (value = light^(1/G), G from 1 to 4); encoded images are "
        "linearised first",
    )
    s.add_argument(
        "--z0",
        type=float_in(lo=0.0, hi=100.0, lo_open=True),
        default=None,
        help="reference depth, m (default: meta.json beside the reference, else 1.0)",
    )
    s.add_argument(
        "--near", type=float_in(lo=0.0, hi=100.0, lo_open=True), default=0.75, help="working range near end, m"
    )
    s.add_argument(
        "--far", type=float_in(lo=0.0, hi=100.0, lo_open=True), default=1.75, help="working range far end, m"
    )
    add_pattern_options(s)
    s.add_argument(
        "--robust",
        action="store_true",
        help="our colour-robust decoder (unmixing, colour normalisation, weighted intensity) instead of the paper's; "
        "needs the calibration frames",
    )
    s.add_argument(
        "--calibration",
        default=None,
        help="folder holding calibration_{dark,red,green,blue}.png, .tif, .tiff or .npy (the reference plane under "
        "black and each primary at full drive: `simbench render --calibration-frames`, or a lab's own; default: the "
        "--reference folder)",
    )
    s.add_argument(
        "--decoder",
        nargs="*",
        metavar="NAME=VALUE",
        help="other decoder parameters, e.g. phase_method=ftp voting=false",
    )
    add_cache_options(
        s,
        "cache folder for decoded reference planes (keyed by the reference's bytes, rig, decoder settings and "
        "decoder code)",
        "decode the reference plane every time, store nothing",
    )
    s.set_defaults(fn=_cmd_decode)

    s = sub.add_parser("score", help="score a depth map against ground truth", **kw)
    s.add_argument(
        "depth", help="depth map .npy, one-channel .exr or floating-point .tif (z-depth in metres, NaN = not decoded)"
    )
    s.add_argument(
        "--gt", required=True, help="ground-truth depth .npy or .exr (gt_lit.npy beside it defines the region)"
    )
    s.add_argument(
        "--zero-is-hole",
        action="store_true",
        help="read depths <= 0 as pixels not decoded (a decoder that marks holes with 0 or -1; without it they are "
        "scored as decoded depths, and wrong)",
    )
    s.add_argument("--lit", help="region mask .npy (default: gt_lit.npy beside --gt, else all finite GT)")
    s.add_argument("--column", help="decoded projector columns .npy, for stripe-order errors")
    s.add_argument("--gt-column", help="true columns .npy (default: gt_column.npy beside --gt)")
    s.add_argument(
        "--period",
        type=float_in(lo=2.0, hi=16384.0, lo_open=True),
        default=None,
        help="fringe period, projector px (a column off by more than half of it is a stripe-order error; default: that "
        "of the recording --gt lies in - its pattern's, or a phase-shift folder's - else 21)",
    )
    s.add_argument(
        "--edge-band",
        type=int_in(*api.EDGE_BAND_RANGE_PX),
        default=0,
        help="leave the pixels this close to a depth edge or an object's boundary (px) out of the error statistics "
        "(they still count for completeness)",
    )
    s.add_argument(
        "--confidence",
        help="the depth map's confidence map .npy (float, the depth's shape, higher = surer; e.g. the "
        "NAME_confidence.npy `decode` writes, or your decoder's): adds the completeness against the wrong shares "
        "when only the decoded pixels at or above each of a range of its values are kept",
    )
    s.add_argument(
        "--min-confidence",
        type=float_in(lo=-1e30, hi=1e30),
        default=None,
        help="with --confidence: score the decoded pixels whose confidence reaches this only (the others holes)",
    )
    s.add_argument("--json", action="store_true", help="print the scores as JSON")
    s.set_defaults(fn=_cmd_score)
