"""bayespilot: motion-perception thresholds and pilot-model parameters from tracking recordings.

Implements and extends the time-domain identification method of Pool et al.
(2012), J. Guidance, Control, and Dynamics 35(3), 749-763.
"""

from importlib import metadata as _metadata

try:
    __version__ = _metadata.version("bayespilot")
except _metadata.PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

#: The public names: the two entry points, imported on first use (see
#: :func:`__getattr__`); ``__version__`` besides.
__all__ = ["sample", "compare"]

#: The public submodules, each imported on first use as an attribute
#: (``bayespilot.diagnose``), so that ``import bayespilot`` imports none of them.
_LAZY = ("sample", "compare", "io", "recording", "model", "simulate", "likelihood", "fit",
         "diagnose", "plots", "campaign", "presets", "forcing", "noise")


def __getattr__(name: str):
    """The public submodules (:data:`_LAZY`) without importing them up front.

    A submodule is imported on first use (keeping ``import bayespilot``
    cheap), e.g. ``bayespilot.diagnose.diagnose(...)``.  ``sample`` and
    ``compare`` are also callable, so ``bayespilot.sample(recording)`` runs
    :func:`bayespilot.sample.sample` and ``bayespilot.compare(recording)``
    runs :func:`bayespilot.compare.compare`.
    """
    if name in _LAZY:
        from importlib import import_module

        return import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    """The module's names with the lazily imported submodules, for tab completion."""
    return sorted(set(globals()) | set(_LAZY))
