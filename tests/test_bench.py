"""Decoder speed, for pytest-benchmark (`pytest tests/test_bench.py --benchmark-enable`).

By default benchmarks are disabled (pyproject addopts) and this runs once as a plain test, so
the suite never depends on timing; `simbench bench` is the command-line equivalent.
"""

import numpy as np
import pytest

from simbench.decode import decode
from simbench.experiments.bench import SHADOW, benchmark_inputs


def test_decode_speed(benchmark):
    capture, ref, rig, params = benchmark_inputs()
    result = benchmark(decode, capture, rig=rig, params=params, reference=ref)
    assert result.valid.mean() > 0.99
    assert abs(np.nanmedian(result.depth_m) - 1.1) < 1e-3  # the benchmark plane is at 1.1 m


def test_decode_speed_with_shadow(benchmark):
    """The path real scenes take: part of the image unlit, so certainty moments per capture."""
    capture, ref, rig, params = benchmark_inputs(scene="shadow")
    result = benchmark(decode, capture, rig=rig, params=params, reference=ref)
    shadow = np.zeros(result.valid.shape, bool)
    shadow[SHADOW] = True
    assert not result.valid[shadow].any()
    assert result.valid[~shadow].mean() > 0.97
    assert abs(np.nanmedian(result.depth_m) - 1.1) < 1e-3
    with pytest.raises(ValueError, match="unknown benchmark scene"):
        benchmark_inputs(scene="cube")


@pytest.mark.parametrize("device", ["kinect", "tof"])
def test_competitor_decode_speed(benchmark, device):
    """The competitors' decoders at native resolution (issue: <= 100 ms; `simbench bench
    --system kinect|tof` on the command line)."""
    from simbench.systems import get_system

    system = get_system(device)
    raw, cal, scene = system.bench_inputs()
    result = benchmark(system.decode, raw, cal, scene=scene)
    assert result.valid.mean() > 0.8
    assert np.nanmedian(result.depth_m) == pytest.approx(1.1, abs=0.005)


def test_stage_times_cover_the_decode_without_changing_it():
    """The per-stage profile (simbench bench's table) sees every stage in every row-band thread
    and leaves the decode's output bit-identical; with no collector nothing is recorded."""
    import dataclasses

    from simbench.decode.profile import stage, stage_times
    from simbench.experiments.bench import run_decode_benchmark, stage_table

    capture, ref, rig, params = benchmark_inputs()
    params = dataclasses.replace(params, threads=2)
    plain = decode(capture, rig=rig, params=params, reference=ref)
    with stage_times() as times:
        profiled = decode(capture, rig=rig, params=params, reference=ref)
    for a, b in (
        (plain.depth_m, profiled.depth_m),
        (plain.column_px, profiled.column_px),
        (plain.valid, profiled.valid),
    ):
        assert np.array_equal(a, b, equal_nan=True)
    for name in (
        "phase (gabor, Eq. 10-11)",
        "stripe segmentation and voting",
        "De Bruijn windows and neighbour correction",
        "column, depth, output (Eq. 14-15, reference matching)",
    ):
        assert times.calls[name] == 2 and times.seconds[name] > 0, name  # once per band thread
    assert times.calls["input check and undistortion"] == 1
    with stage("outside"):
        pass
    assert "outside" not in times.seconds
    res = run_decode_benchmark(repeats=1, warmup=0)
    assert set(res["stages_ms"]) == set(times.seconds)
    assert res["mode"] == "reference"  # the mode it ran in, the decoder's default (was null)
    table = stage_table(res["stages_ms"])
    assert "phase (gabor" in table and table.splitlines()[-1].startswith("sum over threads")
    assert run_decode_benchmark(repeats=1, warmup=0, device="kinect")["stages_ms"] == {}


def test_benchmark_with_another_rig_and_mode():
    """`simbench bench --rig RIG --mode calibrated`: the capture decoded with a rig whose lenses
    distort (undistortion and triangulation through the projector's lens in the timed decode)."""
    import dataclasses

    from simbench.experiments.bench import run_decode_benchmark
    from simbench.rig import paper_rig, scale_camera

    rig = paper_rig()
    rig = dataclasses.replace(
        rig,
        name="calibrated-like",
        position_m=(rig.position_m[0], 0.002, -0.001),
        rotation_deg=(0.2, -0.5, 0.1),
        camera=dataclasses.replace(rig.camera, distortion=(-0.05, 0.02, 0.0, 0.0, 0.0)),
        projector=dataclasses.replace(rig.projector, distortion=(0.03, 0.0, 0.0, 0.0, 0.0)),
    )
    res = run_decode_benchmark(repeats=1, warmup=0, rig=rig, mode="calibrated")
    assert res["rig"] == "calibrated-like" and res["mode"] == "calibrated"
    assert res["stages_ms"]["column, depth, output (Eq. 14-15, triangulation)"] > 0
    assert res["stages_ms"]["input check and undistortion"] > 0
    with pytest.raises(ValueError, match="camera is 640x480"):
        run_decode_benchmark(repeats=1, rig=scale_camera(rig, 0.5))
    with pytest.raises(ValueError, match="proposed decoder"):
        run_decode_benchmark(repeats=1, device="tof", mode="calibrated")


@pytest.mark.parametrize(
    ("device", "size_wh"),
    [("proposed", [1280, 960]), ("kinect", [640, 480]), ("tof", [176, 144]), ("phase_shift", [1280, 960])],
)
def test_benchmark_reports_each_systems_image_size(device, size_wh):
    """An image, an image of taps and a multi-shot stack of frames (K, H, W) alike."""
    from simbench.experiments.bench import run_decode_benchmark

    assert run_decode_benchmark(repeats=1, warmup=0, device=device)["size_wh"] == size_wh


def test_benchmark_of_the_colour_robust_decoder():
    """`simbench bench --robust`: the inputs come with the calibration frames its unmixing needs,
    and the timed decode runs its stages (unmixing and normalisation, the phase-stability fit);
    the plane decodes as well as with the paper's decoder."""
    from simbench.experiments.bench import run_decode_benchmark
    from simbench.systems import get_system
    from simbench.decode import robust_params

    res = run_decode_benchmark(repeats=1, warmup=0, robust=True)
    assert res["decoder"] == "robust" and "ratio" not in res  # no baseline unless asked
    assert res["stages_ms"]["colour unmixing and normalisation"] > 0
    assert any(k.startswith("phase stability") for k in res["stages_ms"])
    system = get_system("proposed")
    raw, cal, spec = system.bench_inputs(frames=True)
    assert set(cal.frames) == {"dark", "red", "green", "blue"}
    r = system.decode(raw, cal, scene=spec, params=robust_params(system.decoder)).detail
    assert r.valid.mean() > 0.95 and abs(np.nanmedian(r.depth_m) - 1.1) < 1e-3
    with pytest.raises(ValueError, match="--robust"):
        run_decode_benchmark(repeats=1, device="kinect", robust=True)


def test_a_decoder_variant_is_timed_as_assigned():
    """``bench --decoder NAME=VALUE`` (a decoder developer's audit, 2026-11-30: a variant could not
    be timed): the assignments go on top of the timed decoder's settings - the paper's, or with
    --robust the colour-robust one's - and the result says which; a competitor takes none."""
    from simbench.experiments.bench import run_decode_benchmark

    res = run_decode_benchmark(repeats=1, warmup=0, decoder=["phase_method=ftp"])
    assert res["decoder_assignments"] == ["phase_method=ftp"] and res["decoder"] == "paper"
    assert any(k.startswith("phase (ftp") for k in res["stages_ms"]), res["stages_ms"]
    robust = run_decode_benchmark(repeats=1, warmup=0, robust=True, decoder=["crease_doubt=false"])
    assert "crease doubt" not in robust["stages_ms"] and "edge bend" in robust["stages_ms"], robust["stages_ms"]
    with pytest.raises(ValueError, match="--decoder apply to the proposed decoder, not to 'tof'"):
        run_decode_benchmark(repeats=1, device="tof", decoder=["voting=false"])


def test_the_colour_robust_benchmark_times_the_paper_decoder_alongside(capsys):
    """`simbench bench --robust --max-ratio R`: the paper decoder timed on the same capture after
    each colour-robust run; the ratio of the medians is reported and guarded (CI's machines differ
    in speed by 2-3x, which moves both medians alike), the stage table stays the robust decoder's,
    and the option without --robust is an error."""
    from simbench.cli import main
    from simbench.experiments.bench import run_decode_benchmark

    res = run_decode_benchmark(repeats=2, warmup=0, robust=True, baseline=True)
    assert res["baseline_median_ms"] > 0 and res["ratio"] == pytest.approx(res["median_ms"] / res["baseline_median_ms"])
    assert "colour unmixing and normalisation" in res["stages_ms"]
    assert "front end (float, lit/clipped, Eq. 9, Eq. 13)" not in res["stages_ms"]  # the paper decoder's stage
    with pytest.raises(ValueError, match="baseline"):
        run_decode_benchmark(repeats=1, baseline=True)
    assert main(["bench", "--repeats", "1", "--max-ratio", "10"]) == 2  # refused before any decode
    assert "--max-ratio applies to --robust" in capsys.readouterr().err
    # a failed guard is a failed check (exit 1, as reproduce --check's), not bad input (2)
    assert main(["bench", "--robust", "--repeats", "1", "--max-ratio", "0.01"]) == 1
    out = capsys.readouterr()
    assert (
        "x the paper decoder's median" in out.out and "regression: " in out.err and "over --max-ratio 0.01" in out.err
    )
    assert main(["bench", "--repeats", "1", "--max-ms", "0.001"]) == 1
    assert "regression: decode median" in capsys.readouterr().err
