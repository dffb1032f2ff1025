"""The one place that sets numba options for every kernel in bayespilot.

``cache=True`` writes compiled kernels next to the source so a new process
(a test run, a dask worker) loads them instead of compiling again.
``error_model="numpy"`` makes 0/0 give NaN instead of raising, which the
kernels turn into +inf costs rather than exceptions.  ``fastmath`` stays off:
the likelihood must be reproducible to the last bit between the scalar and
batch forms.  (Two kernels make documented exceptions: ``_recursion_2`` allows
``contract``, and the segmented SIMD kernel, ``kernels/_segmented.py``, writes
its fused multiply-adds and one AVX-512 instruction explicitly through the
intrinsics of ``kernels/_simd.py``; ``Likelihood`` sends single evaluations
through the same routine as the batch, so single and batch still agree to
the bit.)

The cache is keyed on the CPU features numba compiles for, so a kernel cached
on one machine is never loaded on a CPU it was not built for.  numba itself
checks only the source file of the function it caches, so a kernel kept its
stale callee after ``kernels/_blocks.py``, ``_oversample.py`` or ``_simd.py``
alone was edited (their code is compiled into ``_response``'s,
``_sensitivity``'s and ``_segmented``'s kernels; a lab adding a block edits
exactly those files).  Our cache's source stamp therefore also holds a
digest of every source file in the kernel's folder and of this file
(``_FolderCache``): an edit to any of them recompiles every kernel in the
folder at its first call.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

# numba's OpenMP threading layer spin-waits between parallel regions by
# default; on a shared machine (dask workers, a second process) that made
# Likelihood.batch 3-8x slower per row.  Passive waiting costs nothing when the
# machine is idle.  Set before numba starts its thread pool (lazily, at the
# first parallel call); a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
from numba.core.caching import FunctionCache  # noqa: E402

JIT_OPTIONS = {"cache": True, "error_model": "numpy", "nogil": True}


@functools.lru_cache(maxsize=None)
def _folder_digest(folder: str) -> str:
    """sha256 of the names and contents of every ``.py`` file in ``folder`` and of this
    file (``JIT_OPTIONS``)."""
    h = hashlib.sha256()
    for path in [*sorted(Path(folder).glob("*.py")), Path(__file__)]:
        h.update(path.name.encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


class _FolderCache(FunctionCache):
    """numba's on-disk cache, its source stamp extended by the digest of the sources beside
    the function's file.  numba invalidates a kernel's cache on its own file only, so a jitted
    callee from another file, compiled into the caller, went stale unseen (written here
    because numba has no option for it; see the module text).  An edit anywhere in the folder
    makes every kernel's index stale, which numba then rewrites."""

    def __init__(self, py_func):
        super().__init__(py_func)
        digest = _folder_digest(str(Path(py_func.__code__.co_filename).resolve().parent))
        cache_file = self._cache_file
        cache_file._source_stamp = (cache_file._source_stamp, digest)


def _with_folder_cache(dispatcher):
    cache = getattr(dispatcher, "_cache", None)
    if isinstance(cache, FunctionCache):
        try:
            dispatcher._cache = _FolderCache(dispatcher.py_func)
        except AttributeError:  # numba's private cache layout changed: its own cache then
            import warnings

            warnings.warn("bayespilot: numba's cache internals changed; after editing a file in "
                          "bayespilot/kernels, delete its __pycache__ folder", RuntimeWarning)
    return dispatcher


def njit(*args, **kwargs):
    """``numba.njit`` with the package defaults; keyword arguments override them.

    No signature: numba would compile it at once, with its own cache, before
    ``_FolderCache`` is attached."""
    opts = dict(JIT_OPTIONS)
    opts.update(kwargs)
    if args and callable(args[0]):
        return _with_folder_cache(numba.njit(**opts)(args[0]))
    if args:
        raise TypeError("bayespilot's njit takes no signature (kernels compile lazily, so that "
                        "their disk cache is keyed on the kernels' sources)")
    return lambda func: _with_folder_cache(numba.njit(**opts)(func))


def pjit(*args, **kwargs):
    """``njit`` with ``parallel=True``, for kernels that ``prange`` over independent items."""
    kwargs.setdefault("parallel", True)
    return njit(*args, **kwargs)
