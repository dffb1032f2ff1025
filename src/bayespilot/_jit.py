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
on one machine is never loaded on a CPU it was not built for.  numba checks
only the source file of the function it caches: after editing
``kernels/_simd.py`` (whose intrinsics are compiled into ``_segmented``'s
kernels), delete ``src/bayespilot/kernels/__pycache__`` or touch
``_segmented.py``; the same after editing ``kernels/_oversample.py`` or
``kernels/_blocks.py`` alone (compiled into ``_response``'s and
``_sensitivity``'s kernels: seen to keep a stale callee).
"""

from __future__ import annotations

import os

# numba's OpenMP threading layer spin-waits between parallel regions by
# default; on a shared machine (dask workers, a second process) that made
# Likelihood.batch 3-8x slower per row.  Passive waiting costs nothing when the
# machine is idle.  Set before numba starts its thread pool (lazily, at the
# first parallel call); a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402

JIT_OPTIONS = {"cache": True, "error_model": "numpy", "nogil": True}


def njit(*args, **kwargs):
    """``numba.njit`` with the package defaults; keyword arguments override them."""
    opts = dict(JIT_OPTIONS)
    opts.update(kwargs)
    if args and callable(args[0]):
        return numba.njit(**opts)(args[0])
    return numba.njit(*args, **opts)


def pjit(*args, **kwargs):
    """``njit`` with ``parallel=True``, for kernels that ``prange`` over independent items."""
    kwargs.setdefault("parallel", True)
    return njit(*args, **kwargs)
