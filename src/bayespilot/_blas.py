"""One BLAS thread inside the fits, samplers and diagnosis.

Their dense algebra is small: ``scipy.optimize.least_squares`` factors an
N x p Jacobian (N ~ 8192, p ~ 7-12) per iteration, the AR fits solve
N x p least-squares problems.  OpenBLAS spreads that over its threads, which
gains nothing at these sizes (one fast fit: 2.06 s with two threads, 2.04 s
with one, on an idle 2-core machine) and loses badly when the cores are busy:
with a campaign's two workers on both cores each SVD took 29 ms instead of
0.4 ms and one fast fit 25 s instead of 2.3 s, its BLAS threads waiting on
each other.  threadpoolctl (the well-kept tool for this) limits BLAS to one
thread for the duration of a call and restores the caller's setting after,
so a user's own linear algebra elsewhere keeps its threads.  Only the
outermost decorated call sets the limit: the fits call each other (a fast
fit runs dozens of Gauss-Newton refinements), and entering the limit costs
about 0.3 ms each time, to find the BLAS libraries again.
"""

from __future__ import annotations

import functools
import threading
from typing import Callable, TypeVar

from threadpoolctl import threadpool_limits

F = TypeVar("F", bound=Callable)
#: Per thread: True while a decorated call holds the limit.
_held = threading.local()


def one_blas_thread(func: F) -> F:
    """Decorate ``func`` so that it runs with BLAS limited to one thread."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        if getattr(_held, "limit", False):  # an outer decorated call holds it already
            return func(*args, **kwargs)
        with threadpool_limits(limits=1, user_api="blas"):
            _held.limit = True
            try:
                return func(*args, **kwargs)
            finally:
                _held.limit = False

    return wrapper  # type: ignore[return-value]
