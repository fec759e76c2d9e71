"""Decoder speed benchmark: ``simbench bench``.

Decodes one 1280x960 capture of a plane at 1.1 m against a decoded reference at 1.0 m
(reference decoding happens once per calibration, so it is outside the timed call).  The
captures are analytic (numpy, :mod:`simbench.sim.synthetic`) with the minimal camera's noise, so
the benchmark needs no renderer and measures only the decoder.

Two scenes (``--scene``): ``plane``, fully lit, where the Gabor stage takes every certainty
window sum from the all-ones table; and ``shadow``, the same plane with a 400x300-px projector
shadow, which makes the decoder take the path every real scene with shadows or clipped pixels
takes (the certainty's window sums computed for the pixels whose window reaches the shadow).
"""

from __future__ import annotations

from collections.abc import Sequence

import dataclasses
import os
import statistics
import time

import cv2
import numpy as np

from simbench.decode import DecoderParams
from simbench.decode.params import MODES
from simbench.decode.profile import stage_times
from simbench.rig import Rig
from simbench.systems import get_system, system_names
from simbench.systems.proposed import BENCH_SCENES
from simbench.systems.proposed import BENCH_SHADOW as SHADOW

__all__ = [
    "benchmark_inputs",
    "run_decode_benchmark",
    "run_stage_benchmark",
    "stage_table",
    "competitor_inputs",
    "BENCH_SCENES",
    "SHADOW",
]


def benchmark_inputs(*, seed: int = 0, scene: str = "plane") -> tuple:
    """(capture, reference map, rig, params) of the proposed decoder's benchmark; deterministic
    for a seed (:meth:`simbench.systems.proposed.ColourFringeSystem.bench_inputs`)."""
    capture, cal, spec = get_system("proposed").bench_inputs(scene=scene, seed=seed)
    params = DecoderParams()
    return capture, cal.reference_map(params), spec.rig, params


def competitor_inputs(device: str, *, seed: int = 0, model: object = None) -> tuple:
    """(model, raw frame, calibration) of competitor ``device`` looking at a plane at 1.1 m,
    made in numpy without the renderer (its system's ``bench_inputs``); ``model`` overrides
    the default device."""
    system = get_system(device)
    if model is not None:
        system = type(system)(model=model)
    raw, cal, _ = system.bench_inputs(seed=seed)
    return system.model, raw, cal


def run_decode_benchmark(
    *,
    repeats: int = 20,
    warmup: int = 2,
    device: str = "proposed",
    scene: str = "plane",
    rig: Rig | None = None,
    mode: str | None = None,
    robust: bool = False,
    baseline: bool = False,
    decoder: Sequence[str] = (),
) -> dict:
    """Time one decode by the depth system ``device`` (any registered name,
    :mod:`simbench.systems`) of its benchmark inputs (``bench_inputs``) at its native
    resolution; returns median/min/max in ms and the set-up, and ``stages_ms``: each profiled
    stage's mean time per decode, summed over the row-band threads that ran it
    (:mod:`simbench.decode.profile`; the proposed decoder's stages).  ``scene``: see the
    module doc (the competitors have only the plane).

    The proposed decoder only: ``rig`` decodes the capture (made with the paper's rig) with
    another rig of the same camera size, e.g. one from ``simbench calibrate`` (its lens
    distortion then costs what it costs: the capture is undistorted, columns triangulated
    through the projector's lens); ``mode`` (``reference`` or ``calibrated``) overrides the
    decoder's mode; ``robust`` times our colour-robust decoder
    (:func:`simbench.decode.robust_params`: its calibration frames come with the inputs) instead
    of the paper's; ``decoder``: ``NAME=VALUE`` assignments (:func:`simbench.decode.with_assignments`)
    on top of the timed decoder's settings, to time a variant.  The reference map is decoded once,
    before the timed runs.

    ``baseline`` (with ``robust``): the paper's decoder timed too, each of its runs right after one
    of the colour-robust decoder's on the same capture, so that both see the machine in the same
    state; ``baseline_median_ms`` and ``ratio`` (the two medians' ratio: the issue-35 measure, and a
    regression guard that a slower or busier machine does not move, as it moves both)."""
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if device not in system_names():
        raise ValueError(f"unknown benchmark device {device!r}; valid: {system_names()}")
    if device != "proposed" and (rig is not None or mode is not None or robust or decoder):
        raise ValueError(
            f"a rig, a decoder mode, --robust and --decoder apply to the proposed decoder, not to {device!r}"
        )
    if mode is not None and mode not in MODES:
        raise ValueError(f"unknown decoder mode {mode!r}; valid: {list(MODES)}")
    if baseline and not robust:
        raise ValueError("a baseline (the paper decoder timed alongside) applies to the colour-robust decoder")
    system = get_system(device)
    raw, cal, spec = system.bench_inputs(scene=scene, **({"frames": True} if robust else {}))
    # an image (H, W), (H, W, channels or taps), or a multi-shot stack of frames (K, H, W)
    h, w = raw.shape[1:3] if raw.ndim == 3 and raw.shape[2] > 4 else raw.shape[:2]
    if rig is not None:
        if rig.camera.size_hw != (h, w):
            raise ValueError(
                f"the rig's camera is {rig.camera.size_hw[1]}x{rig.camera.size_hw[0]}; the benchmark capture is "
                f"{w}x{h} (the paper's camera)"
            )
        spec = dataclasses.replace(spec, rig=rig)

    extra = {"mode": mode} if mode is not None else {}
    if robust or decoder:
        from simbench.decode import robust_params, with_assignments

        timed = robust_params(system.decoder) if robust else system.decoder
        extra["params"] = with_assignments(timed, list(decoder)) if decoder else timed

    def run():
        system.decode(raw, cal, scene=spec, **extra)

    # the paper's decoder on the same capture: its calibration without the frames it does not take
    paper_cal = dataclasses.replace(cal, frames={}, _maps={}) if baseline else None

    def run_paper():
        system.decode(raw, paper_cal, scene=spec, **{k: v for k, v in extra.items() if k != "params"})

    for _ in range(warmup):
        run()
        if baseline:
            run_paper()
    times, paper_times = [], []
    with stage_times() as stages:
        for _ in range(repeats):
            t0 = time.perf_counter()
            run()
            times.append((time.perf_counter() - t0) * 1000.0)
            if baseline:
                # outside the stage collector's view: its table is the colour-robust decoder's
                with stage_times():
                    t0 = time.perf_counter()
                    run_paper()
                    paper_times.append((time.perf_counter() - t0) * 1000.0)
    extra_out = {}
    if baseline:
        paper_median = statistics.median(paper_times)
        extra_out = {"baseline_median_ms": paper_median, "ratio": statistics.median(times) / paper_median}
    return {
        "device": device,
        "scene": scene,
        "rig": spec.rig.name if spec is not None else None,
        # the mode the decoder ran in (its own default where none was asked for; None: the system has no modes)
        "mode": mode if mode is not None else getattr(getattr(system, "decoder", None), "mode", None),
        "decoder": "robust" if robust else ("paper" if device == "proposed" else None),
        "decoder_assignments": list(decoder),
        "size_wh": [w, h],
        "repeats": repeats,
        "median_ms": statistics.median(times),
        "min_ms": min(times),
        "max_ms": max(times),
        "threads": cv2.getNumThreads(),
        "cpus": os.cpu_count(),
        "stages_ms": {k: v / repeats for k, v in stages.ms.items()},
        **extra_out,
    }


def run_stage_benchmark(*, repeats: int = 10, warmup: int = 1, scene: str = "plane", device: str = "proposed") -> dict:
    """Time the colour-robust decoder whole and with each stage of
    :data:`simbench.experiments.robust_stages.VARIANTS` off (the variants that study scores, in
    its mode: triangulation), and the paper's decoder, on the proposed decoder's benchmark
    capture (``scene``: see the module doc; a stage that works only where something happens - a
    printed step, a broken link, a failed fit - costs little on the plane, so time ``shadow``
    too).  The decoders take turns, one decode each per round, the order rotated every round, so
    that a busy moment or the allocator's state slows a round rather than one variant; the
    ``warmup`` rounds (at least one) decode each variant's reference map before any is timed.

    Returns the set-up and ``rows``: ``stage_off`` (``none`` = the whole decoder, ``paper`` = the
    paper's), ``median_ms``, and ``saved_ms`` with ``saved_iqr_ms``: the median and the
    interquartile range over the rounds of the whole decoder's time less this one's in the same
    round."""
    from simbench.decode import robust_params
    from simbench.experiments.robust_stages import VARIANTS, without_stage

    if device != "proposed":
        raise ValueError(f"the colour-robust decoder's stages are the proposed decoder's, not {device!r}'s")
    if repeats < 1:
        raise ValueError(f"repeats must be >= 1, got {repeats}")
    if warmup < 1:
        raise ValueError(f"warmup must be >= 1 (the reference maps are decoded there), got {warmup}")
    system = get_system("proposed")
    raw, cal, spec = system.bench_inputs(scene=scene, frames=True)
    paper = dataclasses.replace(system.decoder, mode="calibrated")
    robust = robust_params(paper)
    params = {"none": robust, **{name: without_stage(robust, paper, name) for name in VARIANTS}, "paper": paper}
    # the paper's decoder with its own calibration (the frames it does not take left out), as run_decode_benchmark's
    cals = {name: cal for name in params}
    cals["paper"] = dataclasses.replace(cal, frames={}, _maps={})
    names = list(params)
    times: dict[str, list[float]] = {name: [] for name in names}
    for r in range(warmup + repeats):
        k = r % len(names)
        for name in names[k:] + names[:k]:
            t0 = time.perf_counter()
            system.decode(raw, cals[name], scene=spec, params=params[name])
            if r >= warmup:
                times[name].append((time.perf_counter() - t0) * 1000.0)
    rows = []
    for name in names:
        saved = np.subtract(times["none"], times[name])
        q1, q3 = np.percentile(saved, [25, 75])
        rows.append(
            {
                "stage_off": name,
                "median_ms": statistics.median(times[name]),
                "saved_ms": float(np.median(saved)),
                "saved_iqr_ms": [float(q1), float(q3)],
            }
        )
    h, w = raw.shape[:2]
    return {
        "scene": scene,
        "mode": "calibrated",
        "size_wh": [w, h],
        "repeats": repeats,
        "threads": cv2.getNumThreads(),
        "cpus": os.cpu_count(),
        "rows": rows,
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
