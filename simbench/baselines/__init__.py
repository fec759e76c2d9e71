"""Competitor sensors of the paper's Table 3 and Fig. 9, simulated the way the devices work:
a Kinect-v1-like speckle structured-light sensor (:mod:`simbench.baselines.kinect`) and an
SR4000-like continuous-wave time-of-flight camera (:mod:`simbench.baselines.tof`).

Both look at the same scene files as the main sensor, from the same camera centre with parallel
axes (the paper "adjusts the three systems to have the same depth to the object"), at their
native resolutions, and give depth maps with the main sensor's conventions: float32 z-depth in
metres at their pixel centres, NaN where invalid, scored against ground truth traced at those
pixel centres.  :func:`register_depth` resamples a competitor's map onto another camera's grid.

Each is a registered depth system (:mod:`simbench.systems`): :class:`~simbench.baselines.kinect.KinectSystem`
and :class:`~simbench.baselines.tof.ToFSystem`; their recordings are written by
:mod:`simbench.systems.recording`.
"""

from __future__ import annotations

import numpy as np

from simbench.baselines import kinect, tof
from simbench.rig import Intrinsics

__all__ = ["DEVICES", "get_device", "register_depth"]

DEVICES = {"kinect": kinect.KinectModel, "tof": tof.ToFModel}


def get_device(name: str, **overrides: object) -> kinect.KinectModel | tof.ToFModel:
    """The device model ``name`` (``kinect`` or ``tof``) with optional parameter overrides."""
    if name not in DEVICES:
        raise ValueError(f"unknown competitor device {name!r}; valid: {list(DEVICES)}")
    cls = DEVICES[name]
    fields = set(cls.__dataclass_fields__)
    bad = sorted(set(overrides) - fields)
    if bad:
        raise ValueError(f"unknown {name} parameter(s) {bad}; valid: {sorted(fields)}")
    return cls(**overrides)


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
