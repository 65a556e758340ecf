"""The runnable examples in the docstrings of the public entry points `solve_manhattan` and
`run_source` run and print what they say (`Mekf`'s is run by tests/backends/test_mekf.py)."""

import doctest

import pytest

from uareme_fusion.pipeline.session import run_source
from uareme_fusion.solver.manhattan import solve_manhattan


@pytest.mark.parametrize("entry", [solve_manhattan, run_source], ids=lambda f: f.__name__)
def test_docstring_example_runs(entry):
    tests = [t for t in doctest.DocTestFinder().find(entry, entry.__name__, globs={entry.__name__: entry})
             if t.examples]
    assert tests, f"{entry.__name__} has no runnable example"
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    for test in tests:
        runner.run(test)
    assert runner.summarize(verbose=False).failed == 0
