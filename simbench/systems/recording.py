"""Competitor recordings as files: the device's raw frames, ground truth and ``device.json``
(every device parameter, the calibration's numbers, the run's metadata and the list of files),
the folder written whole or not at all (:func:`simbench.io.output_directory`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from simbench.manifest import read_manifest, seal_manifest

__all__ = ["DEVICE_MANIFEST", "write_device_recording", "read_device_info"]

DEVICE_MANIFEST = "device.json"


def write_device_recording(
    out_dir: str | Path,
    name: str,
    model: object,
    writers: dict[str, Callable[[Path], Path]],
    *,
    gt: object,
    info: dict,
    overwrite: bool = False,
) -> dict[str, Path]:
    """Write ``writers`` (key -> function writing one file into the folder it is given and
    returning its path), the ground truth ``gt`` (:class:`simbench.sim.truth.GroundTruth` at the
    device's pixels: ``gt_depth.npy``/``.exr``, z-depth in m, ``gt_lit.npy`` and
    ``gt_object_id.npy``, the region and the objects ``simbench score`` reads beside it, and of a
    moving scene ``gt_motion.npy``, as in the proposed sensor's folder) and ``device.json``
    (``{"device": name, **model's parameters, **info}``, sealed with every file's SHA-256:
    :func:`simbench.manifest.seal_manifest`)."""
    from simbench.io import output_directory, save_exr, save_json, save_npy
    from simbench.systems import RECORDING_MANIFESTS

    out = Path(out_dir)
    names = {}
    with output_directory(out, manifest=RECORDING_MANIFESTS, overwrite=overwrite) as tmp:
        for key, write in writers.items():
            names[key] = write(tmp).name
        depth_m = np.asarray(gt.depth_m, np.float32)
        names["gt_depth"] = save_npy(tmp / "gt_depth.npy", depth_m).name
        names["gt_depth_exr"] = save_exr(tmp / "gt_depth.exr", depth_m).name
        # (without them `score` scored every pixel with a depth, shadows too, and the API only the
        # lit ones: a third audit found the two 0.46 and 0.27 mm apart on one folder)
        names["gt_lit"] = save_npy(tmp / "gt_lit.npy", np.asarray(gt.lit, bool)).name
        names["gt_object_id"] = save_npy(tmp / "gt_object_id.npy", gt.object_id).name
        if getattr(gt, "motion_px", None) is not None:  # a moving scene: each pixel's image motion, as
            names["gt_motion"] = save_npy(tmp / "gt_motion.npy", gt.motion_px).name  # the proposed folder's
        manifest = seal_manifest(tmp, {"device": name, **asdict(model), **info}, names)
        save_json(tmp / DEVICE_MANIFEST, manifest)
    return {**{k: out / n for k, n in names.items()}, "device": out / DEVICE_MANIFEST}


def read_device_info(in_dir: str | Path, name: str, model_cls: type) -> tuple[object, dict]:
    """(the device model, the rest of ``device.json``) of a folder written by
    :func:`write_device_recording` for the device ``name``; its manifest and every file it
    lists checked against their recorded SHA-256 (:func:`simbench.manifest.read_manifest`)."""
    path = Path(in_dir) / DEVICE_MANIFEST
    if not path.is_file():
        raise FileNotFoundError(f"{path} not found: not a competitor recording folder")
    info = read_manifest(path)  # sealed, every file as recorded
    device = info.pop("device", None)
    if not isinstance(device, str):
        raise ValueError(f"{path}: not a valid device file (no device name)")
    if device != name:
        raise ValueError(f"{path}: a {device!r} recording, not {name!r}")
    fields = model_cls.__dataclass_fields__
    params = {k: tuple(v) if isinstance(v, list) else v for k, v in info.items() if k in fields}
    try:
        model = model_cls(**params)
    except TypeError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return model, info
