"""Decoder speed benchmark: ``simbench bench``.

Decodes one 1280x960 capture of a plane at 1.1 m against a decoded reference at 1.0 m
(reference decoding happens once per calibration, so it is outside the timed call).  The
captures are analytic (numpy, :mod:`simbench.synthetic`) with the minimal camera's noise, so
the benchmark needs no renderer and measures only the decoder.
"""

from __future__ import annotations

import os
import statistics
import time

import cv2
import numpy as np

from simbench.decode import DecoderParams, decode, decode_reference
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.rig import paper_rig
from simbench.device import get_sensor
from simbench.projector import transfer_curve
from simbench.sensor import simple_camera
from simbench.synthetic import synthetic_plane_capture

__all__ = ["benchmark_inputs", "run_decode_benchmark"]


def benchmark_inputs(*, seed: int = 0):
    """(capture, reference map, rig, params) for the benchmark; deterministic for a seed."""
    rig = paper_rig()
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec(size_hw=rig.projector.size_hw))), transfer="linear")
    cam = get_sensor("minimal").camera
    rad, _, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.1), supersample=2)
    ref_rad, _, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.0), supersample=2)
    rng = np.random.default_rng(seed)
    capture = simple_camera(rad / 1.21, camera=cam, rng=rng)
    reference = simple_camera(ref_rad, camera=cam, rng=rng)
    params = DecoderParams()
    return capture, decode_reference(reference, rig=rig, params=params), rig, params


def run_decode_benchmark(*, repeats: int = 20, warmup: int = 2) -> dict:
    """Time :func:`simbench.decode.decode`; returns median/min/max in ms and the set-up."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    capture, ref, rig, params = benchmark_inputs()
    for _ in range(warmup):
        decode(capture, rig=rig, params=params, reference=ref)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        decode(capture, rig=rig, params=params, reference=ref)
        times.append((time.perf_counter() - t0) * 1000.0)
    return {
        "size_wh": [rig.camera.width_px, rig.camera.height_px],
        "repeats": repeats,
        "median_ms": statistics.median(times),
        "min_ms": min(times),
        "max_ms": max(times),
        "threads": cv2.getNumThreads(),
        "cpus": os.cpu_count(),
    }
