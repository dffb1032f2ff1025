"""Every public function (in a module's ``__all__``) carries a numpydoc docstring and type hints.

The numba kernels are private (``bayespilot.kernels``) and left out; their wrappers are
the public functions checked here.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import bayespilot


def _public_functions():
    out = []
    for info in pkgutil.walk_packages(bayespilot.__path__, "bayespilot."):
        if ".kernels" in info.name:
            continue
        mod = importlib.import_module(info.name)
        for name in getattr(mod, "__all__", ()):
            obj = getattr(mod, name, None)
            if inspect.isfunction(obj) and obj.__module__ == mod.__name__:
                out.append(pytest.param(obj, id=f"{mod.__name__}.{name}"))
    return out


FUNCTIONS = _public_functions()


def test_the_walk_finds_the_public_api():
    ids = {p.id for p in FUNCTIONS}
    assert len(ids) > 80
    for name in ("bayespilot.diagnose.diagnose", "bayespilot.sample.sample",
                 "bayespilot.simulate.simulate", "bayespilot.compare.compare"):
        assert name in ids, name


@pytest.mark.parametrize("func", FUNCTIONS)
def test_public_function_has_numpydoc_and_hints(func):
    doc = inspect.getdoc(func) or ""
    sig = inspect.signature(func)
    assert doc.strip(), "no docstring"
    if sig.parameters:
        assert "Parameters\n----------" in doc, "no numpydoc Parameters section"
        # every named parameter is described (``*args``/``**kwargs`` by their bare names too)
        section = doc.split("Parameters\n----------", 1)[1]
        for name, p in sig.parameters.items():
            assert name in section, f"parameter {name!r} not described"
    if sig.return_annotation not in (None, "None", inspect.Signature.empty):
        assert ("Returns\n-------" in doc or "Yields\n------" in doc), "no Returns section"
    missing = [n for n, p in sig.parameters.items() if p.annotation is inspect.Parameter.empty]
    assert not missing, f"no type hints for {missing}"
    assert sig.return_annotation is not inspect.Signature.empty, "no return annotation"


def _modules_with_examples():
    import doctest

    finder = doctest.DocTestFinder()
    out = []
    for info in pkgutil.walk_packages(bayespilot.__path__, "bayespilot."):
        mod = importlib.import_module(info.name)
        if any(not ex.options.get(doctest.SKIP) for t in finder.find(mod) for ex in t.examples):
            out.append(pytest.param(mod, id=info.name))
    return out


@pytest.mark.parametrize("module", _modules_with_examples())
def test_docstring_examples_run(module):
    """Every Examples section runs and prints what it shows."""
    import doctest
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # e.g. the examples' deliberately short records
        result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                                 report=False)
    assert result.attempted > 0
    assert result.failed == 0
