"""Imports and version lookups that another package's stand-in modules cannot break.

colour-science puts a ``MagicMock`` into ``sys.modules["scipy"]`` when SciPy is missing, and any
package imported later that reads SciPy's version then fails on it. These run in fresh
interpreters, where import order is what a user's process has (an in-process test would see
everything already loaded).
"""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

# a meta-path finder that makes SciPy look uninstalled in the child interpreter
_HIDE_SCIPY = textwrap.dedent(
    """
    import sys
    class _NoScipy:
        def find_spec(self, name, path=None, target=None):
            if name == "scipy" or name.startswith("scipy."):
                raise ImportError("No module named 'scipy' (hidden by the test)")
    sys.meta_path.insert(0, _NoScipy())
    """
)


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)


def test_versions_import_nothing_and_survive_a_mocked_scipy():
    code = _HIDE_SCIPY + textwrap.dedent(
        """
        import json, sys
        from unittest import mock
        sys.modules["scipy"] = mock.MagicMock()   # what colour-science leaves behind
        from simbench.sim.keys import versions
        v = versions()
        print(json.dumps({"v": v}))
        """
    )
    res = _run(code)
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout.strip().splitlines()[-1])
    from importlib import metadata

    assert out["v"]["scipy"] == metadata.version("scipy")
    assert out["v"]["c_compiler"].startswith(("GCC:", "clang"))
    assert out["v"]["opencv"] == metadata.version("opencv-python-headless")
    assert out["v"]["python"].count(".") == 2
    assert out["v"]["cpu"] and out["v"]["cpu"] != "unknown"


@pytest.mark.parametrize(
    "flags, want",
    [
        ("fpu sse2 avx avx2 fma avx512f avx512bw", "Test CPU (AVX-512)"),
        ("fpu sse2 avx avx2 fma", "Test CPU (AVX2)"),
        ("fpu sse2 sse4_2 avx", "Test CPU (no AVX2)"),
        (None, "Test CPU"),  # an Arm CPU: "Features", no "flags" line
    ],
)
def test_the_cpu_in_provenance_names_its_widest_vector_instructions(flags, want):
    """Two CPUs of one model name, one with AVX-512 and one without, render and decode other last
    bits (docs/rendering.md): provenance tells them apart."""
    from simbench.sim.keys import cpu_model

    text = "processor\t: 0\nmodel name\t: Test CPU\n" + (
        "Features\t: fp asimd\n" if flags is None else f"flags\t\t: {flags}\n"
    )
    assert cpu_model(text) == want
    assert cpu_model() != "unknown"  # this machine's, whatever it is


def test_colour_without_scipy_is_a_clear_error_and_leaves_no_mock():
    code = _HIDE_SCIPY + textwrap.dedent(
        """
        import sys, types
        from simbench.sim import spectral
        try:
            spectral.camera_sensitivities()
        except ImportError as exc:
            print("ERR", exc)
        loaded = sorted(n for n in sys.modules if "scipy" in n)
        assert not any(n == "scipy" or n.startswith("scipy.") for n in sys.modules), loaded
        try:
            import scipy  # with colour's mock left behind this would "succeed"
        except ImportError as exc:
            assert "hidden by the test" in str(exc), exc
            print("import state ok")
        """
    )
    res = _run(code)
    assert res.returncode == 0, res.stderr
    assert "ERR colour-science could not import SciPy" in res.stdout and "pip install" in res.stdout
    assert "import state ok" in res.stdout


def test_colour_then_the_decoder_in_a_fresh_process():
    """The order `simbench render` takes: colour's crosstalk first, then the decoder's kernels."""
    res = _run(
        "from simbench.sim import spectral; spectral.camera_sensitivities(); from simbench.decode import "
        "_kernels; _kernels._library(); import scipy.ndimage; print('ok')"
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().endswith("ok")
