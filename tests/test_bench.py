"""Decoder speed, for pytest-benchmark (`pytest tests/test_bench.py --benchmark-enable`).

By default benchmarks are disabled (pyproject addopts) and this runs once as a plain test, so
the suite never depends on timing; `simbench bench` is the command-line equivalent.
"""

import numpy as np

from simbench.decode import decode
from simbench.experiments.bench import benchmark_inputs


def test_decode_speed(benchmark):
    capture, ref, rig, params = benchmark_inputs()
    result = benchmark(decode, capture, rig=rig, params=params, reference=ref)
    assert result.valid.mean() > 0.99
    assert abs(np.nanmedian(result.depth_m) - 1.1) < 1e-3  # the benchmark plane is at 1.1 m
