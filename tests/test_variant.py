from pathlib import Path

import pytest

from simbench.variant import MIN_LLVM_MAJOR, _llvm_major_from_path, find_libllvm


@pytest.mark.parametrize(
    "name, major",
    [
        ("libLLVM-19.so", 19),
        ("libLLVM.so.19.1", 19),
        ("libLLVM-14.0.6.so.1", 14),
        ("/usr/lib/llvm-15/lib/libLLVM.so", 15),
        ("libLLVM-15.so.1", 15),
    ],
)
def test_llvm_version_from_file_names(name, major):
    assert _llvm_major_from_path(Path(name)) == major


def test_find_libllvm_sorted_newest_first():
    found = find_libllvm()
    assert [v for v, _ in found] == sorted((v for v, _ in found), reverse=True)


def test_selected_variant_never_runs_llvm_below_16(variant):
    import drjit as dr

    if variant.startswith("llvm_"):
        assert dr.detail.llvm_version()[0] >= MIN_LLVM_MAJOR


def test_unknown_variant_is_a_clear_error(variant):
    from simbench.variant import select_variant

    with pytest.raises(ValueError, match="unknown Mitsuba variant"):
        select_variant("no_such_variant")
    select_variant(variant)


ALL = ["scalar_rgb", "llvm_ad_rgb", "cuda_ad_rgb"]


@pytest.mark.parametrize(
    "llvm, cuda, expect",
    [
        ((19, 1, 7), False, "llvm_ad_rgb"),
        ((16, 0), False, "llvm_ad_rgb"),
        ((15, 0, 7), False, "scalar_rgb"),
        (None, False, "scalar_rgb"),
        ((15, 0), True, "cuda_ad_rgb"),
    ],
)
def test_choose_variant(llvm, cuda, expect):
    from simbench.variant import choose_variant

    variant, notice = choose_variant(None, available=ALL, llvm_version=llvm, cuda=cuda)
    assert variant == expect
    assert (notice is not None) == (expect == "scalar_rgb")
    if notice:
        assert "scalar_rgb" in notice and "libllvm19" in notice and "\n" not in notice


def test_requested_llvm_with_old_llvm_is_refused():
    from simbench.variant import choose_variant

    with pytest.raises(ValueError, match="needs libLLVM >= 16"):
        choose_variant("llvm_ad_rgb", available=ALL, llvm_version=(15, 0, 7), cuda=False)
    assert choose_variant("scalar_rgb", available=ALL, llvm_version=(15, 0, 7), cuda=False) == ("scalar_rgb", None)


@pytest.mark.slow
def test_scalar_fallback_renders_the_same_scene(variant, tmp_path):
    """The scalar_rgb path (a Python loop for ground truth) agrees with the vectorised one."""
    import subprocess
    import sys

    import numpy as np

    code = """
import json, sys, numpy as np
from simbench.variant import select_variant
from simbench.sim.truth import ground_truth
from simbench.sim.render import render_radiance
v = select_variant(sys.argv[1])
from simbench.sim.scene import scene_from_dict
from simbench.rig import Rig, Intrinsics
import dataclasses
s = scene_from_dict({"object": [{"type": "sphere", "center_m": [0.02, 0, 1.0], "radius_m": 0.05},
                                {"type": "plane", "center_m": [0, 0, 1.2], "size_m": [2, 2]}]})
s = dataclasses.replace(s, rig=Rig(Intrinsics.centred(96, 72, 173.4), Intrinsics.centred(136, 86, 166.1)))
gt = ground_truth(s)
rad = render_radiance(s, np.ones((86, 136, 3), np.float32), spp=64, seed=0)
np.savez(sys.argv[2], depth=gt.depth_m, col=gt.column_px, lit=gt.lit, obj=gt.object_id, rad=rad)
print(v)
"""
    out = {}
    for v in ("scalar_rgb", variant):
        path = tmp_path / f"{v}.npz"
        res = subprocess.run([sys.executable, "-c", code, v, str(path)], capture_output=True, text=True, timeout=300)
        assert res.returncode == 0, res.stderr
        out[v] = np.load(path)
    a, b = out["scalar_rgb"], out[variant]
    assert np.array_equal(a["obj"], b["obj"]) and np.array_equal(a["lit"], b["lit"])
    assert np.allclose(a["depth"], b["depth"], atol=1e-5, equal_nan=True)
    assert np.allclose(a["col"], b["col"], atol=1e-3, equal_nan=True)
    assert abs(a["rad"].mean() - b["rad"].mean()) < 0.01 * b["rad"].mean()  # different samplers, same physics


def test_variants_that_cannot_render_here_are_refused_with_one_line():
    """Issue 33: ``--variant cuda_ad_rgb`` without a GPU and ``scalar_spectral`` (listed as
    available) were an ImportError and a RuntimeError, exit 1."""
    from simbench.variant import choose_variant

    with pytest.raises(ValueError, match="needs a CUDA GPU") as err:
        choose_variant("cuda_ad_rgb", available=ALL, llvm_version=(19, 1, 0), cuda=False)
    # what it lists can run here (a third audit: the CUDA variants were listed as "available")
    assert "cuda_" not in str(err.value).split("usable here:")[1] and "llvm_ad_rgb" in str(err.value)
    assert choose_variant("cuda_ad_rgb", available=ALL, llvm_version=None, cuda=True)[0] == "cuda_ad_rgb"
    with pytest.raises(ValueError, match="RGB variant; usable here: .*scalar_rgb"):
        choose_variant("scalar_spectral", available=[*ALL, "scalar_spectral"], llvm_version=(19, 1, 0), cuda=False)
