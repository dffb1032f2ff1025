"""Every public function (in a module's ``__all__``) carries a numpydoc docstring and type hints.

The numba kernels are private (``bayespilot.kernels``) and left out; their wrappers are
the public functions checked here.

:func:`test_parameters_sections_match_the_signatures` goes further, over what the API
reference (``docs/api.md``) renders: functions, classes' constructors, public methods and
properties; each numpydoc Parameters section must list exactly the signature's parameters,
in its order (all offenders are listed in one failure).
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

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


# --- the Parameters sections match the signatures ---------------------------------------------
# The objects mkdocstrings renders: the public names (``__all__``) of every module that
# ``docs/api.md`` lists, their public methods (including class- and staticmethods) and
# properties, and the classes' constructors (documented, as mkdocstrings' ``merge_init_into_class``
# shows them, in the class docstring's Parameters section, in ``__init__``'s, or, for a
# dataclass, in its Attributes section).

ROOT = Path(__file__).resolve().parents[1]
API_MODULES = re.findall(r"^::: (\S+)", (ROOT / "docs" / "api.md").read_text(), re.M)


# A section header: a line, then a line of (at least three) dashes.
_SECTION = re.compile(r"^([^\n]+)\n-{3,}[ \t]*$", re.M)


def _section(doc: str, title: str) -> str | None:
    """The body of the numpydoc section ``title`` of a cleaned docstring, or None."""
    heads = list(_SECTION.finditer(doc))
    for i, m in enumerate(heads):
        if m.group(1).strip() == title:
            end = heads[i + 1].start() if i + 1 < len(heads) else len(doc)
            return doc[m.end():end]
    return None


def documented_names(doc: str, title: str = "Parameters") -> list[str] | None:
    """The names a numpydoc section lists, in order, or None if the docstring has no such section.

    An entry is a line at the section's indentation (the shallowest of its non-blank lines),
    ``name : type``, ``name1, name2 : type`` or a bare ``name``; ``*args``/``**kwargs`` keep
    their stars.  Deeper lines are descriptions.
    """
    body = _section(doc, title)
    if body is None:
        return None
    lines = [ln for ln in body.splitlines() if ln.strip()]
    if not lines:
        return []
    indent = min(len(ln) - len(ln.lstrip()) for ln in lines)
    names = []
    for ln in lines:
        if len(ln) - len(ln.lstrip()) == indent:
            head = ln.strip().split(" : ", 1)[0].rstrip(":").strip()
            names += [n.strip() for n in head.split(",") if n.strip()]
    return names


def test_documented_names_parser():
    doc = inspect.cleandoc("""Summary.

        Parameters
        ----------
        a, b : float
            Two numbers : with a colon.

            A second paragraph.
        c
            No type.
        *args : float
        **options : Any
            More.

        Returns
        -------
        float
        """)
    assert documented_names(doc) == ["a", "b", "c", "*args", "**options"]
    assert documented_names(doc, "Returns") == ["float"]
    assert documented_names(doc, "Attributes") is None
    assert documented_names("Summary only.") is None


def _signature_names(func, drop_first: bool) -> list[str]:
    """The parameters of ``func`` as a docstring names them (``*args``, ``**kwargs``)."""
    out = []
    for i, (name, p) in enumerate(inspect.signature(func).parameters.items()):
        if i == 0 and drop_first and name in ("self", "cls"):
            continue
        stars = {p.VAR_POSITIONAL: "*", p.VAR_KEYWORD: "**"}.get(p.kind, "")
        out.append(stars + name)
    return out


def _compare(documented: list[str], signature: list[str], extra_ok=lambda name: False) -> list[str]:
    """What is wrong with a documented list of parameter names, as messages."""
    bare = {n.lstrip("*"): n for n in signature}
    # ``*args`` may be written with or without its stars; a name must not be written twice
    doc = [bare.get(n.lstrip("*"), n) for n in documented]
    problems = []
    missing = [n for n in signature if n not in doc]
    if missing:
        problems.append(f"not documented: {missing}")
    unknown = [n for n in doc if n not in signature and not extra_ok(n)]
    if unknown:
        problems.append(f"documented but not in the signature: {unknown}")
    dup = sorted({n for n in doc if doc.count(n) > 1})
    if dup:
        problems.append(f"documented twice: {dup}")
    in_doc = [n for n in doc if n in signature]
    if not missing and not dup and in_doc != signature:
        problems.append(f"order {in_doc} is not the signature's {signature}")
    return problems


def _check_function(func, drop_first: bool) -> list[str]:
    doc = inspect.getdoc(func) or ""
    if not doc.strip():
        return ["no docstring"]
    signature = _signature_names(func, drop_first)
    params = list(inspect.signature(func).parameters.values())
    params = params[len(params) - len(signature):]  # less self/cls
    unhinted = [p.name for p in params if p.annotation is inspect.Parameter.empty]
    problems = [f"no type hints for {unhinted}"] if unhinted else []
    documented = documented_names(doc)
    if documented is None:
        return problems + ([f"no Parameters section (parameters {signature})"] if signature else [])
    return problems + _compare(documented, signature)


def _check_class(cls) -> list[str]:
    doc = inspect.getdoc(cls) if cls.__doc__ else ""
    if not (doc or "").strip():
        return ["no docstring"]
    if "__init__" not in vars(cls):  # the constructor is inherited (an exception's, a base's)
        return []
    signature = _signature_names(cls, drop_first=False)
    documented = documented_names(doc)
    if documented is not None:
        return _compare(documented, signature)
    init_doc = cls.__init__.__doc__ and inspect.getdoc(cls.__init__)
    if init_doc and documented_names(init_doc) is not None:
        return _compare(documented_names(init_doc), signature)
    attributes = documented_names(doc, "Attributes")
    if dataclasses.is_dataclass(cls) and attributes is not None:
        fields = {f.name for f in dataclasses.fields(cls)}
        # an Attributes section may also list fields set after construction and properties
        return _compare(attributes, signature, lambda n: n in fields or hasattr(cls, n))
    if signature:
        return [f"constructor parameters {signature} not documented (no Parameters section in the "
                f"class or __init__ docstring{', no Attributes section' if dataclasses.is_dataclass(cls) else ''})"]
    return []


# Dunder methods checked like public ones (the constructor is checked with its class; the
# others -- __repr__, __str__, __post_init__, ... -- are trivial and exempt).
_CHECKED_DUNDERS = {"__call__"}


def _api_objects():
    """(qualified name, what, object) of every object the API reference renders, once each."""
    seen, out = set(), []
    for modname in API_MODULES:
        mod = importlib.import_module(modname)
        for name in mod.__all__:
            obj = getattr(mod, name)
            if not (inspect.isfunction(obj) or inspect.isclass(obj)) or id(obj) in seen:
                continue
            if not obj.__module__.startswith("bayespilot"):
                continue
            seen.add(id(obj))
            qual = f"{obj.__module__}.{obj.__qualname__}"
            if inspect.isfunction(obj):
                out.append((qual, "function", obj))
                continue
            out.append((qual, "class", obj))
            for mname, member in vars(obj).items():
                if mname.startswith("_") and mname not in _CHECKED_DUNDERS:
                    continue
                if isinstance(member, property):
                    out.append((f"{qual}.{mname}", "property", member))
                elif isinstance(member, (classmethod, staticmethod)):
                    out.append((f"{qual}.{mname}", type(member).__name__, member.__func__))
                elif inspect.isfunction(member):
                    out.append((f"{qual}.{mname}", "method", member))
    return out


API_OBJECTS = _api_objects()


def _api_doc_problems() -> dict[str, list[str]]:
    problems = {}
    for qual, what, obj in API_OBJECTS:
        if what == "function":
            found = _check_function(obj, drop_first=False)
        elif what == "class":
            found = _check_class(obj)
        elif what == "property":
            found = [] if (obj.__doc__ or "").strip() else ["no docstring"]
        else:  # method, classmethod: drop self/cls; staticmethod: keep every parameter
            found = _check_function(obj, drop_first=what != "staticmethod")
        if found:
            problems[qual] = found
    return problems


def test_the_api_walk_finds_classes_methods_and_properties():
    names = {qual for qual, _, _ in API_OBJECTS}
    assert len(names) > 250
    for name in ("bayespilot.likelihood.Likelihood", "bayespilot.likelihood.Likelihood.neg_log_lik",
                 "bayespilot.model.PilotModel.fix", "bayespilot.sample.Posterior.from_netcdf",
                 "bayespilot.model.PilotModel.n_free", "bayespilot.campaign.Job",
                 "bayespilot.diagnose.pooled.diagnose_pooled"):
        assert name in names, name


def test_parameters_sections_match_the_signatures():
    """Every parameter documented, nothing documented that is not one, in the signature's order.

    For every public function, class (its constructor) and public method of the modules
    ``docs/api.md`` renders; ``self``/``cls`` and trivial dunders are exempt, as is a method
    with no other parameter; every public property has a docstring.
    """
    offenders = _api_doc_problems()
    assert not offenders, f"{len(offenders)} docstrings do not match their signatures:\n" + "\n".join(
        f"  {q}: {'; '.join(p)}" for q, p in sorted(offenders.items()))


def test_public_submodules_load_on_attribute_access_and_not_before():
    """Audit: ``import bayespilot; bayespilot.diagnose`` raised AttributeError (only sample
    and compare were loaded on use).  Every public submodule is an attribute, imported on
    first use, listed by dir(); ``import bayespilot`` imports none of them, and
    ``bayespilot.sample`` / ``bayespilot.compare`` are still the callable modules."""
    import subprocess
    import sys

    public = ("io", "recording", "model", "simulate", "likelihood", "fit", "sample", "compare",
              "diagnose", "plots", "campaign", "presets", "forcing", "noise")
    code = ("import sys, bayespilot\n"
            "print(sorted(m for m in sys.modules if m.startswith('bayespilot')))\n"
            "print(bayespilot.diagnose.__name__, 'bayespilot.plots' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.splitlines()
    assert out == ["['bayespilot']", "bayespilot.diagnose False"]
    for name in public:
        mod = getattr(bayespilot, name)
        assert mod is importlib.import_module(f"bayespilot.{name}")
        assert name in dir(bayespilot)
    assert callable(bayespilot.sample) and callable(bayespilot.compare)
    assert bayespilot.sample.sample.__module__ == "bayespilot.sample"
    assert set(bayespilot.__all__) == {"sample", "compare"}
    with pytest.raises(AttributeError, match="module 'bayespilot' has no attribute 'kernelz'"):
        bayespilot.kernelz  # noqa: B018
