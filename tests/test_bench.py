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
    --device kinect|tof` on the command line)."""
    from simbench.baselines import decode_raw
    from simbench.experiments.bench import competitor_inputs

    model, raw, cal = competitor_inputs(device)
    result = benchmark(decode_raw, model, raw, cal)
    assert result.valid.mean() > 0.8
    assert np.nanmedian(result.depth_m) == pytest.approx(1.1, abs=0.005)
