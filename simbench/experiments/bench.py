"""Decoder speed benchmark: ``simbench bench``.

Decodes one 1280x960 capture of a plane at 1.1 m against a decoded reference at 1.0 m
(reference decoding happens once per calibration, so it is outside the timed call).  The
captures are analytic (numpy, :mod:`simbench.synthetic`) with the minimal camera's noise, so
the benchmark needs no renderer and measures only the decoder.

Two scenes (``--scene``): ``plane``, fully lit, where the Gabor stage reuses the rig's cached
window moments; and ``shadow``, the same plane with a 400x300-px projector shadow, which makes
the decoder take the path every real scene with shadows or clipped pixels takes (certainty
moments convolved per capture: 5 more convolutions per band).
"""

from __future__ import annotations

import os
import statistics
import time

import cv2
import numpy as np

from simbench.decode import DecoderParams, decode, decode_reference
from simbench.decode.profile import stage_times
from simbench.pattern import PatternSpec, fringe_pattern, quantize
from simbench.rig import paper_rig
from simbench.device import get_sensor
from simbench.projector import transfer_curve
from simbench.sensor import LIGHT_M_S, simple_camera
from simbench.synthetic import synthetic_plane_capture

__all__ = ["benchmark_inputs", "run_decode_benchmark", "stage_table", "competitor_inputs", "BENCH_DEVICES", "BENCH_SCENES", "SHADOW"]

BENCH_DEVICES = ("proposed", "kinect", "tof")
BENCH_SCENES = ("plane", "shadow")
# the ``shadow`` scene's region without projector light (rows, columns)
SHADOW = (slice(330, 630), slice(440, 840))


def benchmark_inputs(*, seed: int = 0, scene: str = "plane"):
    """(capture, reference map, rig, params) for the benchmark; deterministic for a seed.

    ``scene``: ``plane`` (fully lit) or ``shadow`` (:data:`SHADOW` gets no projector light).
    """
    if scene not in BENCH_SCENES:
        raise ValueError(f"unknown benchmark scene {scene!r}; valid: {list(BENCH_SCENES)}")
    rig = paper_rig()
    drive = transfer_curve(quantize(fringe_pattern(PatternSpec(size_hw=rig.projector.size_hw))), transfer="linear")
    cam = get_sensor("minimal").camera
    rad, _, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.1), supersample=2)
    ref_rad, _, _ = synthetic_plane_capture(drive, rig, point_m=(0, 0, 1.0), supersample=2)
    if scene == "shadow":
        rad = rad.copy()
        rad[SHADOW] = 0.0
    rng = np.random.default_rng(seed)
    capture = simple_camera(rad / 1.21, camera=cam, rng=rng)
    reference = simple_camera(ref_rad, camera=cam, rng=rng)
    params = DecoderParams()
    return capture, decode_reference(reference, rig=rig, params=params), rig, params


def competitor_inputs(device: str, *, seed: int = 0, model=None):
    """(model, raw frame, calibration) of a competitor looking at a plane at 1.1 m, made in
    numpy without the renderer (deterministic for a seed).

    Kinect: the dot texture box-resampled onto the camera grid (the reference at its depth,
    the capture shifted by the plane's disparity), with speckle and detector noise.  ToF: the
    four samples of a plane's phasor with shot noise.  ``model`` overrides the default device.
    """
    from simbench import baselines
    from simbench.baselines import kinect, tof

    model = baselines.get_device(device) if model is None else model
    rng = np.random.default_rng(seed)
    if device == "kinect":
        tex = kinect.dot_pattern(model)
        cam = model.camera
        scale = model.texels_per_dot / model.dot_pitch_px  # texels per camera pixel
        cu, cv = (tex.shape[1] - 1) / 2, (tex.shape[0] - 1) / 2
        blurred = cv2.GaussianBlur(tex, (0, 0), scale / 2)

        def view(shift_px: float) -> np.ndarray:
            # x_tex = scale * (x - cx - shift) + cu: the pattern displaced by shift_px
            xs = (np.arange(cam.width_px) - cam.cx_px - shift_px) * scale + cu
            ys = (np.arange(cam.height_px) - cam.cy_px) * scale + cv
            mx, my = np.meshgrid(xs.astype(np.float32), ys.astype(np.float32))
            return cv2.remap(blurred, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

        d = model.fb_px_m * (1 / 1.1 - 1 / model.reference_depth_m)
        ref_view = view(0.0)
        k = model.exposure_fraction * model.full_well_e / float(np.percentile(ref_view, 99.9))
        ref = kinect.record_ir(ref_view, model=model, electrons_per_radiance=k, speckle_rng=rng, rng=rng)
        cap = kinect.record_ir(view(d), model=model, electrons_per_radiance=k, speckle_rng=rng, rng=rng)
        return model, cap, kinect.KinectCalibration(reference=ref, electrons_per_radiance=k)
    if device == "tof":
        cam = model.camera
        yy, xx = np.indices(cam.size_hw)
        ray = np.sqrt(((xx - cam.cx_px) / cam.focal_px) ** 2 + ((yy - cam.cy_px) / cam.focal_px) ** 2 + 1)
        path = 2 * 1.1 * ray
        phasor = np.exp(1j * 2 * np.pi * model.modulation_hz * path / LIGHT_M_S)
        amplitude = np.full(cam.size_hw, 0.8 / 1.1**2)
        return model, tof.record_taps(amplitude, phasor, model=model, rng=rng), None
    raise ValueError(f"unknown benchmark device {device!r}; valid: {list(BENCH_DEVICES)}")


def run_decode_benchmark(*, repeats: int = 20, warmup: int = 2, device: str = "proposed", scene: str = "plane") -> dict:
    """Time one decode (the paper's :func:`simbench.decode.decode`, or a competitor's
    :func:`simbench.baselines.decode_raw`) at the device's native resolution; returns
    median/min/max in ms and the set-up, and for the proposed decoder ``stages_ms``: each
    stage's mean time per decode, summed over the row-band threads that ran it
    (:mod:`simbench.decode.profile`).  ``scene`` (proposed only): see the module doc."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if device not in BENCH_DEVICES:
        raise ValueError(f"unknown benchmark device {device!r}; valid: {list(BENCH_DEVICES)}")
    if device != "proposed" and scene != "plane":
        raise ValueError(f"--scene {scene} is for the proposed decoder; the {device} benchmark has only the plane")
    if device == "proposed":
        capture, ref, rig, params = benchmark_inputs(scene=scene)
        size_wh = [rig.camera.width_px, rig.camera.height_px]

        def run():
            decode(capture, rig=rig, params=params, reference=ref)
    else:
        from simbench.baselines import decode_raw

        model, raw, cal = competitor_inputs(device)
        size_wh = [model.width_px, model.height_px]

        def run():
            decode_raw(model, raw, cal)
    for _ in range(warmup):
        run()
    times = []
    with stage_times() as stages:
        for _ in range(repeats):
            t0 = time.perf_counter()
            run()
            times.append((time.perf_counter() - t0) * 1000.0)
    return {
        "device": device,
        "scene": scene,
        "size_wh": size_wh,
        "repeats": repeats,
        "median_ms": statistics.median(times),
        "min_ms": min(times),
        "max_ms": max(times),
        "threads": cv2.getNumThreads(),
        "cpus": os.cpu_count(),
        "stages_ms": {k: v / repeats for k, v in stages.ms.items()},
    }


def stage_table(stages_ms: dict[str, float]) -> str:
    """The per-stage times as a plain-text table: ms per decode and share of their sum."""
    total = sum(stages_ms.values())
    width = max([len(k) for k in stages_ms] + [5])
    lines = [f"{'stage':<{width}}  {'ms':>7}  {'share':>6}"]
    for k, v in sorted(stages_ms.items(), key=lambda kv: -kv[1]):
        lines.append(f"{k:<{width}}  {v:7.2f}  {100 * v / total if total else 0:5.1f} %")
    lines.append(f"{'sum over threads':<{width}}  {total:7.2f}")
    return "\n".join(lines)
