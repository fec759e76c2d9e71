from pathlib import Path

import pytest

from simbench.render import MIN_LLVM_MAJOR, _llvm_major_from_path, find_libllvm


@pytest.mark.parametrize(
    "name, major",
    [("libLLVM-19.so", 19), ("libLLVM.so.19.1", 19), ("libLLVM-14.0.6.so.1", 14), ("/usr/lib/llvm-15/lib/libLLVM.so", 15), ("libLLVM-15.so.1", 15)],
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
    from simbench.render import select_variant

    with pytest.raises(ValueError, match="unknown Mitsuba variant"):
        select_variant("no_such_variant")
    select_variant(variant)
