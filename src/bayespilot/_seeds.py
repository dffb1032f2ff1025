"""The seed a stochastic function runs with.

Every stochastic entry point (``simulate``, ``fit_fast``, ``fit_paper``,
``sample``, ``compare``, ``nested_evidence``, ``diagnose``, ``diagnose_pooled``,
``bayes_factor``) takes ``seed``: an integer >= 0
gives the same result bit for bit on the same machine and software (on a CPU
with other vector instructions, or another BLAS, to about 1e-10 relative:
docs/cli.md, "Seeds and reproducibility"), and ``None`` draws a seed from
fresh operating-system entropy.  Either way the function runs with, and its result
records, an integer that repeats the run when given back as ``seed``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["resolve_seed", "spawn_seeds", "stream_seed"]


def resolve_seed(seed: int | None, name: str = "seed") -> int:
    """The integer seed to run with: ``seed`` itself, or a fresh one for None.

    Parameters
    ----------
    seed : int or None
        An integer >= 0, or None for a seed drawn from fresh entropy (31 bits,
        so that it reads back from JSON as the same number everywhere).
    name : str
        The argument's name in the error message.

    Returns
    -------
    int

    Raises
    ------
    ValueError
        If ``seed`` is not None and not an integer >= 0 (a bool, a float or
        a numpy Generator is refused: a Generator would be consumed, and a
        second call with it would not repeat the first).

    Examples
    --------
    >>> resolve_seed(7)
    7
    >>> 0 <= resolve_seed(None) < 2**31
    True
    """
    if seed is None:
        return int(np.random.SeedSequence().generate_state(1)[0] >> 1)
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"{name} must be an integer >= 0 or None, got {seed!r}")
    return int(seed)


def spawn_seeds(seed: int, n: int) -> list[int]:
    """``n`` independent seeds from one (``numpy.random.SeedSequence(seed).spawn``).

    For the runs of one call: ``seed + k`` would make the runs of ``seed``
    and of ``seed + 1`` share all but one stream, so that repeating a call
    with the next seed repeats most of its runs.

    Parameters
    ----------
    seed : int
        The call's seed (>= 0).
    n : int
        How many.

    Returns
    -------
    list of int
        31-bit seeds, as :func:`resolve_seed`'s.

    Examples
    --------
    >>> a, b = spawn_seeds(1, 3), spawn_seeds(2, 3)
    >>> len(set(a) | set(b))
    6
    >>> spawn_seeds(1, 3) == a
    True
    """
    return [stream_seed(seed, k) for k in range(n)]


def stream_seed(seed: int, k: int) -> int:
    """The ``k``-th of :func:`spawn_seeds` (``seed``, n) for any n > ``k``, made alone: for
    runs whose number is not known in advance.

    Parameters
    ----------
    seed : int
        The call's seed (>= 0).
    k : int
        Which stream (>= 0).

    Returns
    -------
    int
        A 31-bit seed.

    Examples
    --------
    >>> stream_seed(1, 2) == spawn_seeds(1, 3)[2]
    True
    """
    return int(np.random.SeedSequence(seed, spawn_key=(k,)).generate_state(1)[0] >> 1)
