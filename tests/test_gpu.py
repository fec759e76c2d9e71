"""On a CUDA machine (marker ``cuda``; skipped where no GPU is, CI's machines included): the
variant chosen there is ``cuda_ad_rgb``, and a scene renders, records and decodes on the GPU to
the accuracy the CPU variants give (within render noise: the GPU's sampler draws other samples,
so its numbers are its own, never the CPU's bits)."""

from __future__ import annotations

import pytest

from .conftest import SCENES

pytestmark = pytest.mark.cuda

# (MAE mm, completeness) measured with llvm_ad_rgb on the 2-core development machine: white
# plane, 16 spp, the default seed, the paper sensor, the reference-plane protocol, 5-px edge band.
# The GPU's render noise is the CPU's in size, so its MAE may differ by a few per cent; the bounds
# leave 25 % (the quick thresholds' margin) and one point of completeness
CPU = {
    ("proposed", "paper"): (0.0582, 0.99995),
    ("proposed", "robust"): (0.0615, 0.99995),
    ("kinect", ""): (2.044, 0.8700),
}


def test_a_cuda_machine_chooses_the_cuda_variant(variant):
    import drjit as dr

    from simbench.variant import _has_cuda

    if not _has_cuda(dr):
        pytest.skip("no CUDA GPU here")
    assert variant == "cuda_ad_rgb"


@pytest.fixture(scope="module")
def on_gpu(variant):
    if variant != "cuda_ad_rgb":
        pytest.skip(f"no CUDA GPU here: the variant in use is {variant}")
    return variant


@pytest.mark.parametrize("system, decoder", sorted(CPU))
def test_a_scene_renders_and_decodes_on_the_gpu(on_gpu, system, decoder):
    import simbench

    rec = simbench.record(
        SCENES / "white_plane.toml", system=system, spp=16, calibration_frames=decoder == "robust", cache=None
    )
    depth = simbench.depth(rec, **({"decoder": decoder} if decoder else {}))
    score = simbench.score(depth, rec, edge_band_px=5)
    mae_mm, complete = CPU[(system, decoder)]
    print(f"GPU {system} {decoder}: MAE {score['mae_mm']:.4f} mm, completeness {score['completeness']:.4f}")
    assert score["mae_mm"] <= 1.25 * mae_mm + 0.02
    assert score["completeness"] >= complete - 0.01
