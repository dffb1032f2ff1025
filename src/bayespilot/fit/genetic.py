"""Step I of Pool et al. (2012): a binary-encoded genetic algorithm, run as the paper ran it.

Section III.A of the paper fixes: every free parameter encoded in 20 bits
within the Table 1 bounds, a population of 160 (20 x the 8 parameters),
100 generations ("iterations"), crossover probability 0.7 and mutation
probability 0.01; 20 repetitions per data set, and the Step I threshold
estimate is the mean of delta_abs over the 5 repetitions with the lowest
-ln L.  :func:`genetic_algorithm` is one run, :func:`step_one` the 20.

Encoding
--------
Parameter j occupies ``bits`` consecutive genes of the chromosome, most
significant bit first, as a plain (not Gray-coded) unsigned integer k:

    x_j = lower_j + (upper_j - lower_j) * k / (2**bits - 1),

so all-zero genes give ``lower_j``, all-one genes give ``upper_j`` (exactly)
and the resolution is ``(upper_j - lower_j) / (2**bits - 1)`` (1e-5 for K_v,
1e-7 for delta_abs with 20 bits, as the paper says).  A chromosome is the
concatenation of the parameters in ``model.parameter_names`` order; the
population is one boolean array of shape (population, n_params * bits).

What the paper does not say, and what is chosen here
----------------------------------------------------
The paper (and its Ref. 12) gives only the numbers above; the operators are
the classical simple GA (Goldberg 1989), for which 0.7 and 0.01 are the
"typical values" the paper cites:

* **Selection: binary tournament** (size 2, with replacement) on -ln L.
  It uses only the ranking of -ln L, so it needs no fitness transform of a
  cost that is negative and whose scale changes with the record length
  (roulette-wheel selection would), it keeps a constant, moderate selection
  pressure over the run, and a non-finite -ln L (an unstable closed loop,
  ``+inf`` from :meth:`~bayespilot.likelihood.Likelihood.batch`, or NaN)
  simply loses every tournament: non-finite values rank worst.  Ties go to
  the first contestant drawn.
* **Crossover: single-point on the whole chromosome.**  The selected parents
  are paired in the order drawn; each pair is crossed with probability
  ``p_crossover`` at one cut point, uniform over the n*bits - 1 gaps, and
  the tails are swapped (a cut may fall inside a parameter's bits).
  Otherwise the pair is copied.
* **Mutation: independent bit flips** with probability ``p_mutation`` per
  bit (about 1.6 flips per 160-bit chromosome per generation).
* **Elitism: the best ``elitism`` individuals (default 1)** of each
  generation are carried unchanged into the next, in place of the first
  children.  The paper's Fig. 7 shows the best -ln L settling, not
  oscillating, which a GA without elitism would not guarantee; with it the
  population best never gets worse for a deterministic objective.  Elites
  are re-evaluated with the rest so that each generation costs exactly one
  objective call on the whole population.

Cost and reproducibility
------------------------
Everything is vectorised NumPy; the only per-generation work of any size is
ONE call ``objective(x)`` with ``x`` of shape (population, n_params), i.e.
:meth:`Likelihood.batch`, which is parallel over rows.  A run makes
``generations + 1`` calls (generation 0 is the initial population).  All
random numbers come from one ``numpy.random.Generator`` seeded by
``np.random.SeedSequence(seed)`` and are drawn in a fixed order and amount
per generation, so the same seed gives the same result bit for bit (given
an objective that is itself deterministic).
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Sequence

import numpy as np

if TYPE_CHECKING:  # pragma: no cover
    from ..likelihood import Likelihood

__all__ = ["GAResult", "StepOneResult", "genetic_algorithm", "step_one", "decode", "encode",
           "resolution", "PAPER_SETTINGS"]

#: Section III.A of the paper (the fitters' signatures restate these defaults so that help()
#: shows them; a test holds the two equal).
PAPER_SETTINGS = {"population": 160, "generations": 100, "p_crossover": 0.7,
                  "p_mutation": 0.01, "bits": 20, "repetitions": 20, "n_best": 5}

MAX_BITS = 52  # k / (2**bits - 1) is exact in float64 up to here

SeedLike = int | Sequence[int] | np.random.SeedSequence | None


# --- validation --------------------------------------------------------------------
def _int(name: str, value: Any, low: int, high: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    value = int(value)
    if value < low or (high is not None and value > high):
        rng = f">= {low}" if high is None else f"in {low}..{high}"
        raise ValueError(f"{name} must be {rng}, got {value}")
    return value


def _probability(name: str, value: Any) -> float:
    try:
        p = float(value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a number in [0, 1], got {value!r}") from None
    if not 0.0 <= p <= 1.0:  # also rejects NaN
        raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
    return p


def _bounds(lower: Any, upper: Any) -> tuple[np.ndarray, np.ndarray]:
    lo = np.array(lower, dtype=float, ndmin=1)
    hi = np.array(upper, dtype=float, ndmin=1)
    if lo.ndim != 1 or hi.shape != lo.shape or lo.size == 0:
        raise ValueError(f"lower and upper must be 1-D arrays of the same length >= 1, "
                         f"got shapes {lo.shape} and {hi.shape}")
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError("lower and upper bounds must be finite")
    bad = np.flatnonzero(~(lo < hi))
    if bad.size:
        j = int(bad[0])
        raise ValueError(f"need lower < upper for every parameter; parameter {j} has "
                         f"lower={lo[j]!r} >= upper={hi[j]!r}")
    return lo, hi


def _seed_sequence(seed: SeedLike) -> np.random.SeedSequence:
    """A fresh SeedSequence for ``seed`` (a copy, never the caller's object)."""
    if isinstance(seed, np.random.SeedSequence):
        return np.random.SeedSequence(seed.entropy, spawn_key=seed.spawn_key,
                                      pool_size=seed.pool_size)
    try:
        return np.random.SeedSequence(seed)
    except (TypeError, ValueError) as err:
        raise TypeError(f"seed must be None, a non-negative int, a sequence of them or a "
                        f"numpy SeedSequence, got {seed!r} ({err})") from None


def _seed_dict(ss: np.random.SeedSequence) -> dict[str, Any]:
    ent = ss.entropy
    ent = [int(e) for e in ent] if isinstance(ent, (list, tuple, np.ndarray)) else int(ent)
    return {"entropy": ent, "spawn_key": [int(k) for k in ss.spawn_key]}


# --- encoding -----------------------------------------------------------------------
def _decode(genes: np.ndarray, lo: np.ndarray, hi: np.ndarray, bits: int) -> np.ndarray:
    n = lo.size
    weights = 2.0 ** np.arange(bits - 1, -1, -1, dtype=float)  # exact: sums stay < 2**53
    k = genes.reshape(genes.shape[:-1] + (n, bits)).astype(float) @ weights
    top = float(2**bits - 1)
    x = lo + (hi - lo) * (k / top)
    x = np.where(k == top, hi, np.minimum(x, hi))
    return x


def _encode(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, bits: int) -> np.ndarray:
    top = 2**bits - 1
    k = np.rint((x - lo) / (hi - lo) * top)
    k = np.clip(k, 0, top).astype(np.uint64)
    shifts = np.arange(bits - 1, -1, -1, dtype=np.uint64)
    genes = ((k[..., None] >> shifts) & np.uint64(1)).astype(bool)
    return genes.reshape(x.shape[:-1] + (lo.size * bits,))


def decode(genes: np.ndarray, lower: Sequence[float], upper: Sequence[float],
           bits: int = 20) -> np.ndarray:
    """Parameter vectors from binary chromosomes.

    Parameters
    ----------
    genes : array_like of bool or {0, 1}, shape (..., n * bits)
        Chromosomes; parameter j is genes ``j*bits:(j+1)*bits``, most
        significant bit first.
    lower, upper : array_like, shape (n,)
        Finite bounds, ``lower < upper``.
    bits : int
        Bits per parameter, 2..52.

    Returns
    -------
    ndarray, shape (..., n)
        ``lower + (upper - lower) * k / (2**bits - 1)`` with k the unsigned
        integer of each parameter's bits (``upper`` exactly when all bits are 1).

    Examples
    --------
    >>> decode([0, 0, 1, 1], [0.0, -1.0], [3.0, 2.0], bits=2)
    array([0., 2.])
    """
    lo, hi = _bounds(lower, upper)
    bits = _int("bits", bits, 2, MAX_BITS)
    g = np.asarray(genes)
    if g.ndim < 1 or g.shape[-1] != lo.size * bits:
        raise ValueError(f"genes must have last dimension n * bits = {lo.size * bits}, "
                         f"got shape {g.shape}")
    if not np.all((g == 0) | (g == 1)):
        raise ValueError("genes must be 0/1 or boolean")
    return _decode(g.astype(bool), lo, hi, bits)


def encode(x: np.ndarray, lower: Sequence[float], upper: Sequence[float],
           bits: int = 20) -> np.ndarray:
    """Binary chromosomes of the grid points nearest to parameter vectors ``x``.

    The inverse of :func:`decode` up to the resolution (see :func:`resolution`).

    Parameters
    ----------
    x : array_like, shape (..., n)
        Finite vectors inside ``[lower, upper]``.
    lower, upper : array_like, shape (n,)
    bits : int

    Returns
    -------
    ndarray of bool, shape (..., n * bits)
    """
    lo, hi = _bounds(lower, upper)
    bits = _int("bits", bits, 2, MAX_BITS)
    x = np.array(x, dtype=float, ndmin=1)
    if x.shape[-1] != lo.size:
        raise ValueError(f"x must have last dimension {lo.size}, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("x must be finite")
    if np.any(x < lo) or np.any(x > hi):
        raise ValueError("x must lie inside [lower, upper]")
    return _encode(x, lo, hi, bits)


def resolution(lower: Sequence[float], upper: Sequence[float], bits: int = 20) -> np.ndarray:
    """Grid step of each parameter, ``(upper - lower) / (2**bits - 1)``.

    Parameters
    ----------
    lower, upper : array_like, shape (n,)
        Finite bounds, ``lower < upper``.
    bits : int, default 20
        Bits per parameter, 2..52 (the paper: 20).

    Returns
    -------
    ndarray, shape (n,)
        The step between neighbouring values :func:`decode` can give, in
        the units of each parameter.

    Raises
    ------
    ValueError
        If the bounds are not 1-D of one length >= 1, not finite, or not
        ``lower < upper``, or ``bits`` is outside 2..52.
    TypeError
        If ``bits`` is not an integer.
    """
    lo, hi = _bounds(lower, upper)
    bits = _int("bits", bits, 2, MAX_BITS)
    return (hi - lo) / (2**bits - 1)


# --- results --------------------------------------------------------------------------
def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class GAResult:
    """One run of :func:`genetic_algorithm`.

    Attributes
    ----------
    x : ndarray, shape (n,)
        The best parameter vector found (decoded).
    fun : float
        Its objective value (-ln L); ``inf`` if no individual was ever finite.
    history_best_x : ndarray, shape (generations + 1, n)
        Best-so-far vector after each generation; row 0 is the initial population.
    history_best_fun : ndarray, shape (generations + 1,)
        Best-so-far objective value (non-increasing).
    history_mean_fun : ndarray, shape (generations + 1,)
        Mean of the finite objective values of each generation (NaN if none).
    n_evaluations : int
        Objective values computed: ``(generations + 1) * population``.
    seed : numpy.random.SeedSequence
        The seed sequence of the run; passing it as ``seed`` repeats the run
        (also when the run was started with ``seed=None``).
    settings : dict
        population, generations, p_crossover, p_mutation, bits, elitism.
    """

    x: np.ndarray
    fun: float
    history_best_x: np.ndarray
    history_best_fun: np.ndarray
    history_mean_fun: np.ndarray
    n_evaluations: int
    seed: np.random.SeedSequence
    settings: dict = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """Plain lists and numbers for JSON (non-finite values stay float inf/nan).

        ``seed`` becomes ``{"entropy", "spawn_key"}``; rebuild it with
        ``np.random.SeedSequence(entropy, spawn_key=tuple(spawn_key))``.
        """
        return {
            "x": self.x.tolist(),
            "fun": float(self.fun),
            "history_best_x": self.history_best_x.tolist(),
            "history_best_fun": self.history_best_fun.tolist(),
            "history_mean_fun": self.history_mean_fun.tolist(),
            "n_evaluations": int(self.n_evaluations),
            "seed": _seed_dict(self.seed),
            "settings": dict(self.settings),
        }


@dataclass(frozen=True, eq=False)
class StepOneResult:
    """Step I: repeated genetic-algorithm runs on one likelihood (:func:`step_one`).

    Attributes
    ----------
    runs : tuple of GAResult
        One per repetition, in repetition order.
    order : ndarray of int
        Indices into ``runs`` sorted by ``fun`` ascending (stable; ties keep
        repetition order).
    delta_abs : float or None
        The Step I threshold: mean ``delta_abs`` of the ``n_best`` runs with the
        lowest -ln L; None if the model has no free ``delta_abs``.
    parameter_names : tuple of str
        Names of the entries of each run's ``x``.
    n_best : int
    seed : numpy.random.SeedSequence
        Root sequence; run i used ``seed.spawn_key + (i,)``.
    """

    runs: tuple[GAResult, ...]
    order: np.ndarray
    delta_abs: float | None
    parameter_names: tuple[str, ...]
    n_best: int
    seed: np.random.SeedSequence

    @property
    def best(self) -> GAResult:
        """The run with the lowest -ln L."""
        return self.runs[int(self.order[0])]

    @property
    def funs(self) -> np.ndarray:
        """-ln L of every run, in repetition order."""
        return np.array([r.fun for r in self.runs])

    def best_params(self) -> dict[str, float]:
        """The best run's vector by parameter name."""
        return {n: float(v) for n, v in zip(self.parameter_names, self.best.x)}

    def to_dict(self) -> dict[str, Any]:
        """Plain lists and numbers for JSON."""
        return {
            "parameter_names": list(self.parameter_names),
            "delta_abs": None if self.delta_abs is None else float(self.delta_abs),
            "n_best": int(self.n_best),
            "order": [int(i) for i in self.order],
            "seed": _seed_dict(self.seed),
            "runs": [r.to_dict() for r in self.runs],
        }


# --- the algorithm ---------------------------------------------------------------------
def _evaluate(objective: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    f = np.asarray(objective(x), dtype=float)
    if f.shape != (x.shape[0],):
        raise ValueError(f"objective must return an array of shape ({x.shape[0]},) for an "
                         f"input of shape {x.shape}, got shape {f.shape}")
    return np.where(np.isfinite(f), f, np.inf)  # non-finite ranks worst (NaN included)


def _finite_mean(f: np.ndarray) -> float:
    ok = np.isfinite(f)
    return float(np.mean(f[ok])) if np.any(ok) else float("nan")


def genetic_algorithm(objective: Callable[[np.ndarray], np.ndarray],
                      lower: Sequence[float] | np.ndarray, upper: Sequence[float] | np.ndarray,
                      *, population: int = 160, generations: int = 100,
                      p_crossover: float = 0.7, p_mutation: float = 0.01, bits: int = 20,
                      elitism: int = 1, seed: SeedLike = None,
                      initial: np.ndarray | None = None) -> GAResult:
    """Minimise ``objective`` over a box with a binary-encoded genetic algorithm.

    Parameters
    ----------
    objective : callable
        ``objective(x)`` with ``x`` of shape (population, n) returns the
        (population,) costs, e.g. :meth:`bayespilot.likelihood.Likelihood.batch`.
        Non-finite values rank worst.  Called exactly ``generations + 1`` times.
    lower, upper : array_like, shape (n,)
        Finite bounds with ``lower < upper`` (e.g. ``model.bounds``).
    population : int, default 160
        Even, >= 2.
    generations : int, default 100
        Generations after the initial one (>= 0).
    p_crossover : float, default 0.7
        Probability that a parent pair is crossed (single point).
    p_mutation : float, default 0.01
        Probability that a bit flips.
    bits : int, default 20
        Bits per parameter, 2..52.
    elitism : int, default 1
        Best individuals carried unchanged into the next generation,
        ``0 <= elitism < population``.
    seed : int, sequence of int, SeedSequence or None
        Seeds ``np.random.default_rng(np.random.SeedSequence(seed))``.
    initial : array_like, shape (k, n) or (n,), optional
        Vectors inside the bounds placed (snapped to the bit grid) in the
        first k slots of the initial population (k <= population); the rest
        are uniformly random bits.

    Returns
    -------
    GAResult

    Raises
    ------
    ValueError
        On an odd or too small population, a probability outside [0, 1],
        ``bits`` outside 2..52, non-finite bounds or ``lower >= upper``, a
        bad ``initial``, or an objective that returns the wrong shape.
    TypeError
        If ``objective`` is not callable or an integer argument is not an int.

    Examples
    --------
    >>> res = genetic_algorithm(lambda x: np.sum((x - 0.3) ** 2, axis=1), [0, 0], [1, 1],
    ...                         population=40, generations=30, seed=1)
    >>> bool(np.all(np.abs(res.x - 0.3) < 0.05))
    True
    """
    if not callable(objective):
        raise TypeError(f"objective must be callable (e.g. Likelihood.batch), got "
                        f"{type(objective).__name__}")
    lo, hi = _bounds(lower, upper)
    population = _int("population", population, 2)
    if population % 2:
        raise ValueError(f"population must be even (parents are paired), got {population}")
    generations = _int("generations", generations, 0)
    p_crossover = _probability("p_crossover", p_crossover)
    p_mutation = _probability("p_mutation", p_mutation)
    bits = _int("bits", bits, 2, MAX_BITS)
    elitism = _int("elitism", elitism, 0, population - 1)
    ss = _seed_sequence(seed)
    n = lo.size
    length = n * bits
    rng = np.random.default_rng(ss)

    genes = rng.integers(0, 2, size=(population, length), dtype=np.uint8).astype(bool)
    if initial is not None:
        init = np.array(initial, dtype=float, ndmin=2)
        if init.ndim != 2 or init.shape[1] != n or not 1 <= init.shape[0] <= population:
            raise ValueError(f"initial must have shape (k, {n}) with 1 <= k <= population "
                             f"= {population}, got {np.shape(initial)}")
        if not np.all(np.isfinite(init)) or np.any(init < lo) or np.any(init > hi):
            raise ValueError("initial vectors must be finite and inside [lower, upper]")
        genes[:init.shape[0]] = _encode(init, lo, hi, bits)

    hist_x = np.empty((generations + 1, n))
    hist_f = np.empty(generations + 1)
    hist_mean = np.empty(generations + 1)

    x = _decode(genes, lo, hi, bits)
    f = _evaluate(objective, x)
    i = int(np.argmin(f))
    best_x, best_f = x[i].copy(), float(f[i])
    hist_x[0], hist_f[0], hist_mean[0] = best_x, best_f, _finite_mean(f)

    half = population // 2
    positions = np.arange(length)
    children = np.empty_like(genes)
    for g in range(1, generations + 1):
        elite = np.argsort(f, kind="stable")[:elitism]
        # Binary tournaments, with replacement: the lower cost wins, ties go to the first.
        a, b = rng.integers(0, population, size=(2, population))
        winners = np.where(f[b] < f[a], b, a)
        p1, p2 = genes[winners[0::2]], genes[winners[1::2]]
        # Single-point crossover of each pair with probability p_crossover.
        cross = rng.random(half) < p_crossover
        cut = rng.integers(1, length, size=half)
        tail = (positions >= cut[:, None]) & cross[:, None]
        children[0::2] = np.where(tail, p2, p1)
        children[1::2] = np.where(tail, p1, p2)
        # Bit-flip mutation.
        children ^= rng.random((population, length)) < p_mutation
        # Elitism: the best of the last generation replace the first children.
        children[:elitism] = genes[elite]
        genes, children = children, genes

        x = _decode(genes, lo, hi, bits)
        f = _evaluate(objective, x)
        i = int(np.argmin(f))
        if f[i] < best_f:
            best_x, best_f = x[i].copy(), float(f[i])
        hist_x[g], hist_f[g], hist_mean[g] = best_x, best_f, _finite_mean(f)

    settings = {"population": population, "generations": generations,
                "p_crossover": p_crossover, "p_mutation": p_mutation, "bits": bits,
                "elitism": elitism}
    return GAResult(_frozen(best_x), best_f, _frozen(hist_x), _frozen(hist_f),
                    _frozen(hist_mean), (generations + 1) * population, ss, settings)


def step_one(likelihood: "Likelihood", *, repetitions: int = 20, n_best: int = 5,
             seed: SeedLike = None, progress: bool = False, threshold: str = "delta_abs",
             **ga_kwargs: Any) -> StepOneResult:
    """Step I of the paper: the genetic algorithm ``repetitions`` times, and the threshold.

    Each repetition minimises ``likelihood.batch`` within ``likelihood.model.bounds``.
    Repetition i is seeded with the i-th child of
    ``np.random.SeedSequence(seed).spawn(repetitions)`` (spawn key
    ``(..., i)``), so the runs are independent streams, one seed fixes all of
    them, and run i can be repeated alone with ``genetic_algorithm(...,
    seed=result.runs[i].seed)``.

    Parameters
    ----------
    likelihood : Likelihood
        Any object with ``.model`` (a PilotModel) and ``.batch(free)``.
    repetitions : int, default 20
    n_best : int, default 5
        Runs averaged for the Step I threshold, 1..repetitions.
    seed : int, sequence of int, SeedSequence or None
        Root seed (a SeedSequence passed in is copied, not spawned from, so the
        same object gives the same result twice).
    progress : bool, default False
        Show a tqdm bar over the repetitions.
    threshold : str, default "delta_abs"
        Name of the threshold parameter averaged over the best runs.
    **ga_kwargs
        Passed to :func:`genetic_algorithm` (population, generations,
        p_crossover, p_mutation, bits, elitism, initial).

    Returns
    -------
    StepOneResult
        ``delta_abs`` is None if ``threshold`` is not a free parameter of the model.
    """
    for key in ("objective", "lower", "upper", "seed"):
        if key in ga_kwargs:
            raise TypeError(f"step_one sets {key!r} itself; do not pass it in ga_kwargs")
    if not (hasattr(likelihood, "model") and callable(getattr(likelihood, "batch", None))):
        raise TypeError(f"likelihood must be a Likelihood (with .model and .batch), got "
                        f"{type(likelihood).__name__}")
    repetitions = _int("repetitions", repetitions, 1)
    n_best = _int("n_best", n_best, 1, repetitions)
    model = likelihood.model
    names = tuple(model.parameter_names)
    lower, upper = model.bounds
    root = _seed_sequence(seed)
    seeds = root.spawn(repetitions)

    bar = None
    if progress:
        from tqdm.auto import tqdm  # a widget in a notebook, text on a terminal
        bar = tqdm(total=repetitions, desc="Step I (GA)", unit="run")
    runs = []
    try:
        for ss in seeds:
            runs.append(genetic_algorithm(likelihood.batch, lower, upper, seed=ss, **ga_kwargs))
            if bar is not None:
                bar.update(1)
                bar.set_postfix(best=min(r.fun for r in runs))
    finally:
        if bar is not None:
            bar.close()

    order = np.argsort(np.array([r.fun for r in runs]), kind="stable")
    delta = None
    if threshold in names:
        j = names.index(threshold)
        delta = float(np.mean([runs[k].x[j] for k in order[:n_best]]))
    return StepOneResult(tuple(runs), _frozen(order), delta, names, n_best, root)
