"""The ``Examples`` of the model, synthesis, sensors and estimation layers' docstrings run,
and hold.

Every module of ``fahv.model``, ``fahv.synthesis``, ``fahv.sensors`` and
``fahv.estimation`` is imported (``pkgutil``) and its docstrings' examples are run by
the standard library's ``doctest``. The examples are small, with numbers checked
against a closed form or the design point's trim, and print nothing that depends on
NumPy's print options.
"""

import doctest
import importlib
import io
import pkgutil

import fahv.estimation
import fahv.model
import fahv.sensors
import fahv.synthesis

PACKAGES = (fahv.model, fahv.synthesis, fahv.sensors, fahv.estimation)
#: Examples (``>>>`` statements) the two layers hold: a module that stops being found,
#: or examples that stop being collected, fail the test rather than pass it unnoticed.
MIN_EXAMPLES = 215


def _modules():
    for package in PACKAGES:
        yield package
        for info in pkgutil.walk_packages(package.__path__, package.__name__ + "."):
            yield importlib.import_module(info.name)


def test_docstring_examples_run_and_hold():
    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.NORMALIZE_WHITESPACE)
    report = io.StringIO()
    for module in _modules():
        for test in finder.find(module):
            runner.run(test, out=report.write)
    results = runner.summarize(verbose=False)
    assert results.failed == 0, report.getvalue()
    assert results.attempted >= MIN_EXAMPLES, f"only {results.attempted} examples ran"
