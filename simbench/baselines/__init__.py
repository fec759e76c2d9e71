"""Competitor sensors of the paper's Table 3 and Fig. 9, simulated the way the devices work:
a Kinect-v1-like speckle structured-light sensor (:mod:`simbench.baselines.kinect`) and an
SR4000-like continuous-wave time-of-flight camera (:mod:`simbench.baselines.tof`).

Both look at the same scene files as the main sensor, from the same camera centre with parallel
axes (the paper "adjusts the three systems to have the same depth to the object"), at their
native resolutions, and give depth maps with the main sensor's conventions: float32 z-depth in
metres at their pixel centres, NaN where invalid, scored against ground truth traced at those
pixel centres.  :func:`register_depth` resamples a competitor's map onto another camera's grid.

One interface for both (``model`` = a :class:`~simbench.baselines.kinect.KinectModel` or a
:class:`~simbench.baselines.tof.ToFModel`): :func:`device_scene`, :func:`calibrate` (the
Kinect's factory reference; nothing for the ToF camera), :func:`acquire` (raw frames: IR images
or four-sample tap frames), :func:`decode_raw` (-> :class:`CompetitorDepth`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from simbench.baselines import kinect, tof
from simbench.rig import Intrinsics
from simbench.scene import SceneSpec

__all__ = ["DEVICES", "DEVICE_LABELS", "get_device", "CompetitorDepth", "device_scene", "calibrate", "acquire", "decode_raw", "register_depth", "device_params", "write_recording", "read_recording"]

DEVICES = {"kinect": kinect.KinectModel, "tof": tof.ToFModel}
DEVICE_LABELS = {"kinect": "Kinect v1 (simulated)", "tof": "SR4000 ToF (simulated)"}


def get_device(name: str, **overrides):
    """The device model ``name`` (``kinect`` or ``tof``) with optional parameter overrides."""
    if name not in DEVICES:
        raise ValueError(f"unknown competitor device {name!r}; valid: {list(DEVICES)}")
    cls = DEVICES[name]
    fields = set(cls.__dataclass_fields__)
    bad = sorted(set(overrides) - fields)
    if bad:
        raise ValueError(f"unknown {name} parameter(s) {bad}; valid: {sorted(fields)}")
    return cls(**overrides)


def _kind(model) -> str:
    for name, cls in DEVICES.items():
        if isinstance(model, cls):
            return name
    raise TypeError(f"not a competitor device model: {type(model).__name__}")


def device_params(model) -> dict:
    """The model's parameters as plain data (for provenance)."""
    from dataclasses import asdict

    return {"device": _kind(model), **asdict(model)}


@dataclass(frozen=True)
class CompetitorDepth:
    """depth_m (H, W) float32 z-depth (NaN invalid), valid (H, W) bool, confidence (H, W)
    float32 (Kinect: best correlation; ToF: demodulated amplitude in electrons)."""

    depth_m: np.ndarray
    valid: np.ndarray
    confidence: np.ndarray


def device_scene(model, scene: SceneSpec) -> SceneSpec:
    return kinect.device_scene(scene, model) if _kind(model) == "kinect" else tof.device_scene(scene, model)


def calibrate(model, *, spp: int, seed: int, sampler: str = "independent", cache=None):
    """The device's calibration (Kinect: :class:`~simbench.baselines.kinect.KinectCalibration`;
    ToF: None)."""
    return kinect.calibrate(model, spp=spp, seed=seed, sampler=sampler, cache=cache) if _kind(model) == "kinect" else None


def acquire(model, scene: SceneSpec, calibration, *, spp: int, seed: int, noise_seeds: list[int], sampler: str = "independent", cache=None) -> list[np.ndarray]:
    """Raw frames of ``scene`` (already :func:`device_scene`), one per noise seed."""
    if _kind(model) == "kinect":
        if calibration is None:
            raise ValueError("the Kinect needs its calibration (reference image): call calibrate() first")
        return kinect.capture(scene, model, calibration, spp=spp, seed=seed, noise_seeds=noise_seeds, sampler=sampler, cache=cache)
    return tof.capture(scene, model, spp=spp, seed=seed, noise_seeds=noise_seeds, sampler=sampler, cache=cache)


def decode_raw(model, raw: np.ndarray, calibration=None) -> CompetitorDepth:
    """One raw frame -> depth, the device's own way."""
    if _kind(model) == "kinect":
        if calibration is None:
            raise ValueError("the Kinect needs its reference image to decode")
        ref = calibration.reference if isinstance(calibration, kinect.KinectCalibration) else np.asarray(calibration)
        r = kinect.match(raw, ref, model=model)
        return CompetitorDepth(r.depth_m, r.valid, r.ncc)
    r = tof.decode_taps(raw, model=model)
    return CompetitorDepth(r.depth_m, r.valid, r.amplitude_e)


def register_depth(depth_m: np.ndarray, *, source: Intrinsics, target: Intrinsics) -> np.ndarray:
    """Resample a depth map from camera ``source`` onto camera ``target``'s pixel grid, for two
    cameras sharing their centre and axes (nearest neighbour: depth is not interpolated across
    edges).  Pixels of ``target`` outside ``source``'s view are NaN.

    Returns
    -------
    ndarray, shape target.size_hw, float32
    """
    d = np.asarray(depth_m, dtype=np.float32)
    if d.shape != source.size_hw:
        raise ValueError(f"depth map shape {d.shape} does not match the source camera {source.size_hw}")
    yy, xx = np.indices(target.size_hw, dtype=np.float64)
    xs = np.rint((xx - target.cx_px) * source.focal_px / target.focal_px + source.cx_px).astype(np.int64)
    ys = np.rint((yy - target.cy_px) * source.focal_px / target.focal_px + source.cy_px).astype(np.int64)
    inside = (xs >= 0) & (xs < source.width_px) & (ys >= 0) & (ys < source.height_px)
    out = np.full(target.size_hw, np.nan, np.float32)
    out[inside] = d[ys[inside], xs[inside]]
    return out


def write_recording(out_dir, model, raw: np.ndarray, calibration, *, gt_depth_m: np.ndarray, meta: dict, overwrite: bool = False) -> dict:
    """A competitor recording as files: ``ir.png`` + ``reference.png`` (Kinect, 16-bit grey) or
    ``taps.npy`` (ToF, (H, W, 4) float32 electrons); ``gt_depth.npy``/``.exr`` (z-depth, m);
    ``device.json`` (every device parameter, the calibration's exposure, ``meta`` and the list
    of files).  The folder is written whole or not at all (:func:`simbench.io.output_directory`)."""
    from pathlib import Path

    from simbench.io import output_directory, save_exr, save_json, save_npy, save_png

    out = Path(out_dir)
    info = {**device_params(model), **meta}
    names = {}
    with output_directory(out, manifest="device.json", overwrite=overwrite) as tmp:
        if _kind(model) == "kinect":
            names["ir"] = save_png(tmp / "ir.png", np.asarray(raw, np.uint16)).name
            names["reference"] = save_png(tmp / "reference.png", np.asarray(calibration.reference, np.uint16)).name
            info["electrons_per_radiance"] = calibration.electrons_per_radiance
        else:
            names["taps"] = save_npy(tmp / "taps.npy", np.asarray(raw, np.float32)).name
        names["gt_depth"] = save_npy(tmp / "gt_depth.npy", gt_depth_m.astype(np.float32)).name
        names["gt_depth_exr"] = save_exr(tmp / "gt_depth.exr", gt_depth_m.astype(np.float32)).name
        names["device"] = save_json(tmp / "device.json", {**info, "files": dict(names)}).name
    return {k: out / n for k, n in names.items()}


def read_recording(in_dir):
    """(model, raw, calibration) from a folder written by :func:`write_recording`."""
    import json
    from pathlib import Path

    from simbench.io import load_image, load_npy

    d = Path(in_dir)
    info_path = d / "device.json"
    if not info_path.is_file():
        raise FileNotFoundError(f"{info_path} not found: not a competitor recording folder")
    try:
        info = json.loads(info_path.read_text())
        name = info.pop("device")
    except (ValueError, KeyError, AttributeError):
        raise ValueError(f"{info_path}: not a valid device file") from None
    fields = DEVICES[name].__dataclass_fields__ if name in DEVICES else {}
    params = {k: tuple(v) if isinstance(v, list) else v for k, v in info.items() if k in fields}
    model = get_device(name, **params)
    if name == "kinect":
        frames = [load_image(d / fname, expected_size_hw=model.camera.size_hw, channels=1) for fname in ("ir.png", "reference.png")]
        cal = kinect.KinectCalibration(reference=frames[1], electrons_per_radiance=float(info.get("electrons_per_radiance", 1.0)))
        return model, frames[0], cal
    taps = load_npy(d / "taps.npy", expected_shape=(model.height_px, model.width_px, 4))
    return model, taps, None
