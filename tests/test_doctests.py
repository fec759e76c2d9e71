"""The Examples sections of the public functions' docstrings run as written (doctest)."""

from __future__ import annotations

import doctest
import importlib

import numpy as np
import pytest

# the modules whose docstrings carry Examples (an Example that renders is marked +SKIP)
NUMPY_PRINT_DEFAULTS = {
    "precision": 8,
    "threshold": 1000,
    "edgeitems": 3,
    "linewidth": 75,
    "suppress": False,
    "sign": "-",
    "floatmode": "maxprec",
    "legacy": False,
}
MODULES = (
    "simbench.pattern",
    "simbench.sim.scene",
    "simbench.sim.spectral",
    "simbench.decode.params",
    "simbench.api",
)


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    report: list[str] = []
    # numpy's own default print options: another library in the process may have changed them
    with np.printoptions(**NUMPY_PRINT_DEFAULTS):
        for test in doctest.DocTestFinder().find(module, extraglobs={"np": np}):
            runner.run(test, out=report.append)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, "".join(report)


def test_some_examples_exist():
    finder = doctest.DocTestFinder()
    examples = sum(len(t.examples) for n in MODULES for t in finder.find(importlib.import_module(n)))
    assert examples >= 10
