"""bayespilot: motion-perception thresholds and pilot-model parameters from tracking recordings.

Implements and extends the time-domain identification method of Pool et al.
(2012), J. Guidance, Control, and Dynamics 35(3), 749-763.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bayespilot")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"


def __getattr__(name: str):
    """``bayespilot.sample(...)`` and ``bayespilot.compare(...)`` without importing them up front.

    The submodules are imported on first use (keeping ``import bayespilot``
    cheap); each is also callable, so ``bayespilot.sample(recording)`` runs
    :func:`bayespilot.sample.sample` and ``bayespilot.compare(recording)``
    runs :func:`bayespilot.compare.compare`.
    """
    if name in ("sample", "compare"):
        from importlib import import_module

        return import_module(f".{name}", __name__)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
