"""The posterior of the chosen extension (issue 5, "Model": maximum likelihood, then optionally
the posterior).

:func:`diagnose` reports the chosen extension's maximum-likelihood fit with
standard errors from the decision likelihood's curvature.
:func:`sample_chosen` goes one step further: it samples the posterior of
the *extended* model (the pilot parameters and the extension's new ones)
with :func:`bayespilot.sample.sample`, started at that fit, under the
package's posterior likelihood (``"coloured"``: the output error whitened by
an AR model re-estimated at every parameter vector, whose credible intervals
the calibration study checks, see ``docs/posteriors.md``).  It is a separate
step because it costs more than the diagnosis (tens of seconds) and only
makes sense once an extension is chosen.

The decision likelihood of :func:`diagnose` (low-passed at 25 rad/s and
decimated) is not the posterior's (the whole band), so the two can differ:
the posterior uses more of the record.

:func:`shared_posterior` does the same for a pooled diagnosis
(:func:`~bayespilot.diagnose.diagnose_pooled`), whose model has every run's
pilot parameters and the extension's shared ones (about 30 dimensions for
four runs): the shared parameters' marginal posterior on a grid, each run's
pilot parameters refitted and integrated out by Laplace's method, under the
decision likelihood the pooled fit and test use (each run's noise model of
the test), with each run's delta_abs held at the fit reported after the test
rather than at the base model's.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
from scipy.integrate import trapezoid
from scipy.interpolate import CubicSpline

from .._files import WrongKind, number, numbers, require_keys
from ..recording import Recording
from . import _JSONSummary
from .catalogue import get_extension
from .decide import json_number

if TYPE_CHECKING:
    from ..sample import Posterior

__all__ = ["sample_chosen", "shared_posterior", "SharedPosterior"]


def _checked_chosen(result: Any, recording: Recording):
    """The chosen GLS candidate of a single-run ``result`` of ``recording``, or a clear error."""
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    if getattr(result, "runs", None) is not None:
        raise ValueError("sample_chosen takes a single-run diagnosis; for a pooled one use "
                         "shared_posterior (the shared parameters' posterior on a grid)")
    chosen = _gls_chosen(result, "there is no extended model to sample")
    check_same_recording(result, recording)
    return chosen


def _gls_chosen(result: Any, nothing: str):
    """``result.chosen`` if it is an extension fitted by the GLS likelihood, else a clear
    error (``nothing``: what is missing when no extension was chosen)."""
    chosen = getattr(result, "chosen", None)
    if chosen is None:
        raise ValueError(f"the diagnosis chose no extension (physics = "
                         f"{getattr(result, 'physics', 'none')!r}): {nothing}")
    if get_extension(chosen.physics).likelihood == "gls" and getattr(chosen, "model", None) is None:
        raise ValueError(f"this diagnosis does not carry {chosen.physics!r}'s fitted model (read "
                         "back from JSON?); diagnose the recording again")
    if get_extension(chosen.physics).likelihood != "gls":
        raise ValueError(f"{chosen.physics!r} is decided by its flat tops and a censored "
                         "likelihood; its limits are read from the data, not sampled")
    return chosen


def check_same_recording(result: Any, recording: Recording) -> None:
    """Raise ValueError unless ``recording`` has the sample interval and length that
    ``result`` (a single-run diagnosis) was made on."""
    dt = result.settings.get("dt")
    n = np.size(result.arrays.get("residual", ()))
    if (dt is not None and not math.isclose(dt, recording.dt, rel_tol=1e-9)) or \
            (n and n != recording.n_samples):
        raise ValueError(f"this is not the recording that was diagnosed ({result.source}: "
                         f"dt {dt}, {n} samples; given: dt {recording.dt}, "
                         f"{recording.n_samples} samples)")


def sample_chosen(result: Any, recording: Recording, *, likelihood: str = "coloured",
                  seed: int | None = 0, progress: bool = False, **options: Any) -> "Posterior":
    """Sample the posterior of the extended model that :func:`diagnose` chose.

    Parameters
    ----------
    result : DiagnosisResult
        A single-run diagnosis of ``recording`` whose decision is a catalogue
        extension fitted by the GLS likelihood (not ``"none"``, not
        ``control-saturation``, whose limits are read from the flat tops).
    recording : Recording
        The recording that was diagnosed.
    likelihood : {"coloured", "eq4"}
        Passed to :func:`bayespilot.sample.sample`.  ``"coloured"`` (default)
        is the one whose intervals hold on coloured remnant; Eq. 4 treats the
        samples as independent and gives intervals far too narrow.
    seed : int or None
        Seeds the sampler (the same seed gives the same chain).
    progress : bool
        Show emcee's progress bar.
    **options
        Further keywords of :func:`bayespilot.sample.sample` (``max_steps``,
        ``n_walkers``, ``prior``, ``backend``, ...).

    Returns
    -------
    Posterior
        Also stored as ``result.posterior``, so that ``result.to_json()``,
        ``result.summary()`` and ``result.report()`` include it.

    Raises
    ------
    ValueError
        No extension was chosen, the chosen one has no posterior here
        (``control-saturation``), the result is a pooled diagnosis, or the
        recording is not the one diagnosed (another sample interval or length).
    TypeError
        ``recording`` is not a Recording.
    """
    from ..sample import sample

    chosen = _checked_chosen(result, recording)
    model = chosen.model
    init = {k: float(v) for k, v in chosen.all_params.items() if k in model.parameter_names}
    post = sample(recording, model, likelihood=likelihood, init=init, seed=seed,
                  progress=progress, **options)
    result.posterior = post
    return post


def posterior_dict(post: Any, names: tuple[str, ...]) -> dict[str, Any]:
    """JSON-ready summary of ``post``: settings and, per parameter, mean, median, sd, 90 % HDI
    (the extension's new parameters ``names`` first)."""
    summ = post.summary()
    order = [n for n in names if n in summ] + [n for n in summ if n not in names]
    params = {}
    for n in order:
        d = dict(summ[n])
        d["sd"] = float(np.std(post.draws(n)))
        params[n] = d
    return {"likelihood": post.settings.get("likelihood"), "converged": bool(post.converged),
            "seed": post.seed, "elapsed_seconds": post.settings.get("elapsed_seconds"),
            "new_parameters": [n for n in names if n in summ],
            "params": params}


# --- the posterior of a pooled diagnosis's shared parameters --------------------------------------

def _nested(f, x):
    """``f`` applied to every number of the nested lists ``x`` (a grid's values)."""
    return [_nested(f, v) for v in x] if isinstance(x, list) else f(x)


#: Grid points per shared parameter (one parameter; two parameters take ``GRID_2D`` each).
GRID_1D = 41
GRID_2D = 15
#: Half-width of the grid in the pooled fit's standard errors (clipped to the bounds).
GRID_WIDTH = 6.0
#: A grid edge inside the bounds where the log density is within this of its maximum is
#: moved out (the density there is not yet negligible: e^-12 ~ 6e-6) ...
EDGE_DROP = 12.0
#: ... at most this many times, each by the grid's span.
MAX_WIDEN = 3


@dataclass(eq=False)  # by identity: == on its arrays would be ambiguous
class SharedPosterior(_JSONSummary):
    """The marginal posterior of a pooled diagnosis's shared extension parameters.

    Saved and read back by :meth:`to_json` and :meth:`from_json` (or
    :meth:`to_dict` and :meth:`from_dict`); :meth:`from_json` also reads the
    file ``bayespilot diagnose --posterior X.json`` writes for several runs.
    Its repr leaves out the grid, the densities and the settings.

    Attributes
    ----------
    physics : str
        The chosen extension.
    names : tuple of str
        Its new parameters, shared by the runs.
    grid : list of ndarray
        The grid of each parameter.
    log_density : ndarray
        ln of the posterior density on the grid (shape: the grids' lengths),
        normalised.
    marginals : dict
        Per parameter: ``median``, ``mean``, ``sd``, ``interval`` (the central
        90 %), ``mode`` and ``density`` (the marginal density on its grid).
    ml, stderr : dict
        The pooled maximum-likelihood fit of the shared parameters under the
        likelihood the grid is of (the test's noise models, each run's
        delta_abs as ``settings["delta_abs"]`` says) and its standard errors:
        the test's own fit when that likelihood is the test's.
    edge_mass : float
        Posterior mass in the outermost grid cells (large: the grid is too narrow).
    settings : dict
    elapsed : float
        Wall time, s.
    log_bayes_factor : float
        ln BF (extension : base model) by the same Laplace integration, priors
        uniform on the bounds (``settings["bayes_factor"]`` says how); NaN if
        the diagnosis does not carry its base model.
    """

    physics: str
    names: tuple
    # (not in the repr: arrays and the marginals' densities, hundreds of numbers)
    grid: list = field(repr=False)
    log_density: np.ndarray = field(repr=False)
    marginals: dict = field(repr=False)
    ml: dict
    stderr: dict
    edge_mass: float
    settings: dict = field(repr=False)
    elapsed: float
    log_bayes_factor: float = math.nan

    # (from_json: a file without these is another kind of result; from_dict needs them, and
    # the density as log_density or, without it, density: checked by _from_file)
    _file_keys = ("physics", "names", "grid", "marginals")

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the marginals, the grid, its log density (``log_density``; an
        infinity as ``"-inf"``) and density (``density``, which older readers take), the
        Bayes factor, the settings."""
        lbf = self.log_bayes_factor if math.isfinite(self.log_bayes_factor) else None
        log_density = np.asarray(self.log_density, dtype=float)
        return {"physics": self.physics, "names": list(self.names),
                "log_bayes_factor": lbf,
                "marginals": self.marginals, "ml": self.ml, "stderr": self.stderr,
                "grid": [g.tolist() for g in self.grid],
                # the log itself: exp underflows to 0 below about -745, whose log is -inf
                "log_density": _nested(json_number, log_density.tolist()),
                "density": np.exp(log_density).tolist(), "edge_mass": self.edge_mass,
                "settings": self.settings, "elapsed_seconds": self.elapsed}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "SharedPosterior":
        """The posterior a :meth:`to_dict` holds: the log density as written
        (``log_density``), or, in a file written before 2026-11-29, the log of its
        density (-inf where the density underflowed).

        Parameters
        ----------
        d : dict
            A :meth:`to_dict`, as read from JSON (a null number is NaN).

        Returns
        -------
        SharedPosterior

        Raises
        ------
        KeyError
            If ``physics``, ``names``, ``grid``, ``density`` (without
            ``log_density``) or ``marginals`` is missing.
        """
        marginals = {n: {k: ([number(x) for x in v] if isinstance(v, list) else number(v))
                         for k, v in m.items()}
                     for n, m in d["marginals"].items()}
        if d.get("log_density") is not None:
            log_density = np.asarray(_nested(number, d["log_density"]), dtype=float)
        else:
            with np.errstate(divide="ignore"):
                log_density = np.log(np.asarray(d["density"], dtype=float))
        return cls(d["physics"], tuple(d["names"]),
                   [np.asarray(g, dtype=float) for g in d["grid"]], log_density, marginals,
                   numbers(d.get("ml")), numbers(d.get("stderr")), number(d.get("edge_mass")),
                   dict(d.get("settings") or {}), number(d.get("elapsed_seconds", 0.0)),
                   number(d.get("log_bayes_factor")))

    @classmethod
    def _from_file(cls, d: dict[str, Any], source_file: str) -> "SharedPosterior":
        """:meth:`from_dict` of a file's dict; a file without :attr:`_file_keys`, or without
        both ``log_density`` and ``density``, is another kind of result (WrongKind).

        The density is required as :meth:`from_dict` requires it: ``log_density``, or
        ``density`` when that is missing or null (a file of before 2026-11-29).  A file with
        ``log_density`` alone loads here as it does through :meth:`from_dict`.
        """
        require_keys(d, cls._file_keys, cls._kind())
        if d.get("log_density") is None and "density" not in d:
            raise WrongKind(f"not {cls._kind()}: no log_density or density (this one has "
                            f"{', '.join(list(d)[:6]) or 'nothing'})")
        return cls.from_dict(d)

    def summary_lines(self) -> list[str]:
        """Lines for a summary: per parameter the median and central 90 % interval."""
        lines = [f"  posterior of the shared parameters ({self.settings['method']}): "
                 f"median, central 90 %"]
        for n in self.names:
            m = self.marginals[n]
            lines.append(f"  {n:<10} {m['median']:12.5g}  [{m['interval'][0]:.5g}, "
                         f"{m['interval'][1]:.5g}]")
        if self.edge_mass > 0.01:
            lines.append(f"  (posterior mass {self.edge_mass:.2g} at the grid's edge: the "
                         "interval may be cut)")
        if self.settings.get("failed_points"):
            lines.append(f"  ({self.settings['failed_points']} of {self.settings['points']} "
                         "grid points failed to fit; their density is interpolated from the "
                         "neighbours)")
        if math.isfinite(self.log_bayes_factor):
            from ..compare import jeffreys_category

            lbf = self.log_bayes_factor
            lines.append(f"  ln BF ({self.physics} : none) {lbf:+.2f} ({jeffreys_category(lbf)}"
                         f", {'for' if lbf > 0 else 'against'} the extension; Laplace, priors "
                         "uniform on the bounds)")
            bf = self.settings.get("bayes_factor", {})
            if bf.get("volume_driven"):
                lines.append(f"  (above the best gain in ln L, {bf['gain']:.2f}: the extension "
                             "leaves the pilot parameters less determined, and that volume, "
                             "not a better fit, is what the Bayes factor counts)")
        return lines


def _fill_line(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``y`` with its non-finite values interpolated linearly in ``x`` from the finite ones
    (extrapolated linearly from the two nearest at an end); unchanged with fewer than two."""
    good = np.isfinite(y)
    if good.all() or good.sum() < 2:
        return y
    y = y.copy()
    xg, yg = x[good], y[good]
    bad = ~good
    y[bad] = np.interp(x[bad], xg, yg)
    for side, (i0, i1) in ((x < xg[0], (0, 1)), (x > xg[-1], (-1, -2))):
        sel = bad & side
        if np.any(sel):
            slope = (yg[i1] - yg[i0]) / (xg[i1] - xg[i0])
            y[sel] = yg[i0] + slope * (x[sel] - xg[i0])
    return y


def _fill_failed(logp: np.ndarray, grids: list) -> np.ndarray:
    """Grid points where the pooled fit failed (ln p = -inf) get ln p interpolated from their
    finite neighbours along each axis.  Left at -inf, a failed point is a zero of the density
    that the marginal's cubic spline overshoots around (one failed point beside the mode moved
    a median from 0.364 to 0.504) and that the Bayes factor's integral misses."""
    out = np.array(logp, dtype=float)
    for axis in range(out.ndim):
        out = np.apply_along_axis(lambda y, a=axis: _fill_line(grids[a], y), axis, out)
    return out


def _laplace_term(wls, ps, names) -> float:
    """Laplace's ln of each run's integral over its pilot parameters ``names``, summed over
    the runs, less the terms common to every grid point and both models:

        sum_r [ -1/2 ln det H_r + ln P_r(box) ],

    H_r = J_r^T J_r / sigma_r^2 the Gauss-Newton Hessian of run r's GLS -ln L at its
    parameters ``ps[r]``, P_r the mass of the Gaussian N(theta_r, H_r^-1) inside the
    parameters' bounds (the uniform prior's box), taken as the product of its marginals'
    masses.  Without P a parameter at or near a bound (a threshold fitted at 0, as soft
    corners wide enough to imitate it put it) would count Gaussian volume outside the prior
    (-inf if an H_r is singular).
    """
    from scipy import stats

    model = wls[0].model
    lo = np.array([model.parameter(n).lower for n in names])
    hi = np.array([model.parameter(n).upper for n in names])
    total = 0.0
    for wl, q in zip(wls, ps):
        y, J = wl.lik.jacobian(q, names)  # (the response comes with it)
        w = wl.whiten(wl.u - y)
        Jw = wl.whiten(J) / math.sqrt(max(float(np.mean(w * w)), 1e-300))
        H = Jw.T @ Jw
        sign, ld = np.linalg.slogdet(H)
        if sign <= 0:
            return -math.inf
        x = np.array([q[n] for n in names])
        sd = np.sqrt(np.clip(np.diag(np.linalg.inv(H)), 1e-300, None))
        mass = stats.norm.cdf((hi - x) / sd) - stats.norm.cdf((lo - x) / sd)
        total += -0.5 * ld + float(np.sum(np.log(np.maximum(mass, 1e-300))))
    return total


def _log_bayes_factor(result: Any, chosen: Any, recs: list, noise: list, names: tuple,
                      shared: tuple, log_integral: float) -> tuple[float, float, float]:
    """ln BF(extended : base) of a pooled candidate (see :func:`shared_posterior`), the
    base model's Laplace term and its pooled ln L at its fit.  ``log_integral``: ln of the
    integral over the grid of exp(ln p~(s)), the unnormalised log density of the shared
    parameters."""
    from . import decide as D
    from .pooled import _pooled_refine

    model = chosen.model
    base_model = result.arrays.get("base_model")
    if base_model is None:
        return math.nan, math.nan, math.nan
    # the base model refitted in the same parameters as the extended one (delta_abs too for
    # the threshold shape, as its test's reference is), from each run's GLS base fit
    wls = [D.Whitened(base_model, rec, nz) for rec, nz in zip(recs, noise)]
    bases = [D.FitSummary(dict(r["base"]["gls_params"]), math.nan, (), np.zeros((0, 0)))
             for r in result.runs]
    ps, f, _ = _pooled_refine(wls, bases, names, (), {})
    base_term = -f + _laplace_term(wls, ps, names)
    log_w = float(sum(math.log(model.parameter(n).upper - model.parameter(n).lower)
                      for n in shared))
    return float(log_integral - log_w - base_term), float(base_term), float(-f)


def _check_pooled(result: Any, recordings, physics: str | None = None) -> tuple[Any, list, list]:
    """The GLS candidate of a pooled ``result`` to weigh (``physics``, else the chosen one),
    its fit per run, and the recordings; or a clear error."""
    if isinstance(recordings, Recording):
        raise TypeError("recordings must be the sequence of Recordings the diagnosis pooled, "
                        "got one Recording")
    recs = list(recordings)
    if getattr(result, "runs", None) is None:
        raise ValueError("shared_posterior takes a pooled diagnosis (diagnose_pooled); for one "
                         "run use sample_chosen")
    for rec in recs:
        if not isinstance(rec, Recording):
            raise TypeError(f"recordings must be Recordings, got {type(rec).__name__}")
    if len(recs) != len(result.runs):
        raise ValueError(f"the diagnosis pooled {len(result.runs)} runs; {len(recs)} "
                         "recordings given")
    noise = result.arrays.get("noise")
    if not noise:
        raise ValueError("this diagnosis does not carry its runs' noise models and fits "
                         "(read back from JSON?); diagnose the runs again")
    if physics is None:
        chosen = _gls_chosen(result, "there is no shared parameter to weigh (name a "
                                     "candidate with physics=...)")
    else:
        get_extension(physics)  # an unknown name: a clear error
        chosen = next((c for c in result.ranking if c.physics == physics), None)
    # each GLS candidate's pooled fit, the parameters per run (the chosen one's too)
    fits = result.arrays.get("fits", {}).get(getattr(chosen, "physics", None))
    if (chosen is None or get_extension(chosen.physics).likelihood != "gls"
            or not chosen.testable or getattr(chosen, "model", None) is None or not fits):
        raise ValueError(f"{physics!r} has no pooled GLS fit in this diagnosis (not a "
                         "candidate, not testable on these runs, or control-saturation, "
                         "whose limits are read from the flat tops)")
    return chosen, [dict(q) for q in fits], recs


def shared_posterior(result: Any, recordings: Sequence[Recording], *, physics: str | None = None,
                     n_grid: int | None = None, width: float = GRID_WIDTH,
                     progress: bool = False) -> SharedPosterior:
    """The posterior of the shared parameters of the extension a pooled diagnosis chose,
    and its Bayes factor against the base model.

    The pooled model has every run's pilot parameters (R x 7) and the
    extension's shared ones; sampling all of them is costly (about 30
    dimensions for four runs).  Here the shared parameters' marginal posterior
    is computed on a grid: at each grid value the runs' pilot parameters are
    refitted (the pooled fit of :func:`~bayespilot.diagnose.diagnose_pooled`,
    its decision likelihood: each run's noise model of the test) and
    integrated out by Laplace's method,

        ln p(s | data) = const - sum_r [ -ln L_r(theta_r*(s), s)
                                         + 1/2 ln det H_r(s) - ln P_r(s) ],

    with H_r = J_r^T J_r / sigma_r^2 the Gauss-Newton Hessian of run r's GLS
    -ln L in its pilot parameters, P_r the mass of the Gaussian
    N(theta_r*, H_r^-1) inside the pilot parameters' bounds (product of the
    marginals'; near 1 unless a parameter sits near a bound), and a uniform
    prior on the grid.  Laplace's
    method is exact for a likelihood Gaussian in the pilot parameters; the
    shared parameters' own shape (a bound, a skew) is kept exactly.  (A grid
    rather than emcee: the method's cost is R refits per grid point.)

    Each run's delta_abs is held, as in the test, but at the value of the fit
    reported after it (``diagnose_pooled(refit=True)``: each run's own noise
    model, delta_abs scanned again) when that is the chosen extension's;
    the base model's, which the test holds, is biased by what the base model
    misses, and the shared parameters with it (an otolith's head height on
    pooled pairs of runs: ``docs/diagnose-evidence.md``).  The noise models stay the
    test's: in the closed loop they move the posterior's centre a little (a
    platform's by about 0.4 posterior sd on pooled pairs of runs), but the
    reported fit's own, from the extended model's residual, make the
    likelihood sharper than its estimates' spread.  An entry that refines
    delta_abs (``threshold-shape``) refits it at every grid point; a
    candidate not chosen holds the test's.

    The same integral gives the extension's Bayes factor against the base
    model, each run's base fit integrated out the same way: with priors
    uniform on the bounds (the pilot parameters' are the same in both models
    and cancel; the shared parameters' box has volume W),

        ln BF = ln[ (1/W) integral exp(ln p~(s)) ds ]
                - sum_r [ -ln L_r(theta_r*) + 1/2 ln det H_r - ln P_r ]   (base model),

    ln p~ the unnormalised log density above.  The grid spans the posterior,
    not the whole prior box; the likelihood outside it is taken as nil.  When
    ln BF exceeds the best gain in pooled ln L on the grid
    (``settings["bayes_factor"]["volume_driven"]``), what it counts is that
    the extension leaves the pilot parameters less determined (a soft
    threshold's delta_abs), not a better fit.
    Unlike :func:`~bayespilot.diagnose.bayes_factor` (nested sampling, one
    run, the whole band) it is under the decision likelihood and costs no
    more than the grid.

    Parameters
    ----------
    result : PooledDiagnosisResult
        A pooled diagnosis whose decision is a GLS catalogue extension (or
        any whose ranking holds ``physics``).
    recordings : sequence of Recording
        The runs it pooled, in its order.
    physics : str, optional
        The candidate to weigh (a GLS extension the diagnosis fitted).
        Default: the chosen one.  Naming the top-ranked candidate of a
        ``"none"`` decision says how strongly the runs speak against it.
    n_grid : int, optional
        Grid points per parameter (default 41 for one shared parameter, 15
        for two).
    width : float
        Half-width of the grid in the pooled fit's standard errors, clipped to
        the parameter's bounds (the whole bounds if the standard error is not
        finite).  A side where the log density at the grid's edge is within
        :data:`EDGE_DROP` of its maximum is moved out by the grid's span (at
        most to the bound) and the grid evaluated again, up to
        :data:`MAX_WIDEN` times (``settings["widened"]``).
    progress : bool
        A tqdm bar over the grid.

    Returns
    -------
    SharedPosterior
        Also stored as ``result.posterior``, so that ``result.to_json()``,
        ``result.summary()`` and ``result.report()`` include it.

    Raises
    ------
    ValueError
        Not a pooled diagnosis, no GLS extension chosen (and no ``physics``
        named) or ``physics`` not fitted, another number of recordings, or
        recordings that are not the ones diagnosed (their pooled -ln L at the
        fit differs from the diagnosis's).
    TypeError
        A recording is not a Recording.
    """
    from tqdm.auto import tqdm

    from . import decide as D
    from .pooled import _pooled_refine

    chosen, fits, recs = _check_pooled(result, recordings, physics)
    t0 = time.perf_counter()
    ext = get_extension(chosen.physics)
    model = chosen.model
    shared = tuple(ext.new_parameters)
    k = len(shared)
    if k > 2:
        raise ValueError(f"{chosen.physics} shares {k} parameters; the grid takes 1 or 2")
    n_grid = (GRID_1D if k == 1 else GRID_2D) if n_grid is None else n_grid
    if isinstance(n_grid, bool) or not isinstance(n_grid, (int, np.integer)) or n_grid < 5:
        raise ValueError(f"n_grid must be an integer >= 5, got {n_grid!r}")
    if isinstance(width, bool) or not (isinstance(width, (int, float)) and math.isfinite(width)
                                       and width > 0):
        raise ValueError(f"width must be a positive number of standard errors, got {width!r}")
    names = tuple(n for n in model.parameter_names if n not in shared
                  and (ext.refine_threshold or n != "delta_abs"))
    noise = result.arrays["noise"]
    wls = [D.Whitened(model, rec, nz) for rec, nz in zip(recs, noise)]
    f_fit = float(sum(wl.neg_log_lik(q) for wl, q in zip(wls, fits)))
    if chosen.fit is not None and not math.isclose(f_fit, chosen.fit.neg_log_lik,
                                                   rel_tol=1e-9, abs_tol=1e-6):
        raise ValueError(f"these are not the recordings that were diagnosed (pooled -ln L at "
                         f"the fit {f_fit:.6f}, the diagnosis's {chosen.fit.neg_log_lik:.6f})")
    bounds = [(float(model.parameter(n).lower), float(model.parameter(n).upper))
              for n in shared]
    # Each run's delta_abs (why the reported fit's: the docstring).  The pooled fit under
    # this likelihood centres the grid: refitted when delta_abs is the reported fit's, else
    # the test's own (the likelihood is then the test's).
    final = result.arrays.get("final_fits")
    if (final and chosen is result.chosen and not ext.refine_threshold
            and "delta_abs" in model.parameter_names):
        held = "held at the reported fit's"
        fits, f_ml, cov = _pooled_refine(
            wls, [D.FitSummary(dict(q, delta_abs=float(r["delta_abs"])), math.nan, (),
                               np.zeros((0, 0))) for q, r in zip(fits, final)],
            names, shared, {n: fits[0][n] for n in shared})
        at_se = dict(zip(shared, np.sqrt(np.clip(np.diag(cov), 0, None)).tolist()))
    else:
        held = "refitted" if ext.refine_threshold else "held at the test's"
        f_ml, at_se = f_fit, {n: chosen.stderr.get(n, math.nan) for n in shared}
    at = fits[0]
    spans = []
    for n, (lo, hi) in zip(shared, bounds):
        c, se = float(at[n]), float(at_se.get(n, math.nan))
        if math.isfinite(se) and se > 0:
            lo, hi = max(lo, c - width * se), min(hi, c + width * se)
        spans.append([lo, hi])
    centre = np.array([float(at[n]) for n in shared])

    def evaluate(grids):
        mesh = np.stack(np.meshgrid(*grids, indexing="ij"), axis=-1).reshape(-1, k)
        # walk outward from the fit, each point started from its nearest finished neighbour
        scale = np.array([g[-1] - g[0] for g in grids]) / (n_grid - 1)
        order = np.argsort(np.sum(((mesh - centre) / scale) ** 2, axis=1))
        logp = np.full(len(mesh), -np.inf)
        best = -math.inf  # the highest pooled ln L on the grid
        starts: dict[int, list] = {}
        for i in order:
            base = fits
            if starts:
                near = min(starts,
                           key=lambda j: float(np.sum(((mesh[j] - mesh[i]) / scale) ** 2)))
                base = starts[near]
            value = dict(zip(shared, (float(v) for v in mesh[i])))
            try:
                ps, f, _ = _pooled_refine(wls, [D.FitSummary(dict(q, **value), math.nan, (),
                                                             np.zeros((0, 0))) for q in base],
                                          names, (), value)
            except (ValueError, np.linalg.LinAlgError):
                bar.update(1)
                continue
            lap = _laplace_term(wls, ps, names)
            if math.isfinite(f) and math.isfinite(lap):
                logp[i] = -f + lap
                best = max(best, -f)
                starts[i] = ps
            bar.update(1)
        return logp.reshape(tuple(len(g) for g in grids)), best

    bar = tqdm(total=n_grid ** k, desc="shared posterior", unit="point", disable=not progress)
    try:
        grids = [np.linspace(lo, hi, n_grid) for lo, hi in spans]
        logp, best = evaluate(grids)
        # the pooled fit's standard error is a local curvature; where the density has not fallen
        # off at an edge of the grid inside the bounds (a ridge, a skew), that side is moved out
        # by the grid's span (at most to the bound) and the grid evaluated again
        widened = []
        for _ in range(MAX_WIDEN):
            if not np.any(np.isfinite(logp)):
                break
            top, moved = float(np.max(logp)), False
            for a in range(k):
                span = spans[a][1] - spans[a][0]
                for side, j, sign in ((0, 0, -1.0), (1, -1, 1.0)):
                    if spans[a][side] != bounds[a][side] and \
                            np.max(np.take(logp, j, axis=a)) > top - EDGE_DROP:
                        edge = spans[a][side] + sign * span
                        spans[a][side] = max(edge, bounds[a][0]) if side == 0 else \
                            min(edge, bounds[a][1])
                        widened.append(f"{shared[a]} {'lower' if side == 0 else 'upper'} to "
                                       f"{spans[a][side]:.6g}")
                        moved = True
            if not moved:
                break
            bar.reset(total=n_grid ** k)
            grids = [np.linspace(lo, hi, n_grid) for lo, hi in spans]
            logp, best = evaluate(grids)
    finally:
        bar.close()
    if not np.any(np.isfinite(logp)):
        raise ValueError("the pooled fit failed at every grid point")
    failed = int(np.sum(~np.isfinite(logp)))
    logp = _fill_failed(logp, grids)
    dens = np.exp(logp - np.max(logp))
    # normalise on the grid (trapezoid over each axis)
    norm = dens
    for axis in reversed(range(k)):
        norm = trapezoid(norm, grids[axis], axis=axis)
    log_density = np.log(np.maximum(dens / norm, 1e-300))
    lbf, base_term, base_log_lik = _log_bayes_factor(result, chosen, recs, noise, names, shared,
                                       float(np.max(logp)) + math.log(norm))
    marginals = {}
    edge = 0.0
    for a, n in enumerate(shared):
        m = dens
        for b in reversed(range(k)):
            if b != a:
                m = trapezoid(m, grids[b], axis=b)
        g = grids[a]
        m = m / trapezoid(m, g)
        # moments and quantiles on a 20x finer grid, ln m interpolated by a cubic spline (a
        # near-Gaussian ln m is near-quadratic): linear interpolation of the coarse CDF would
        # widen the tails by a grid step (the 2-D grids are 0.9 standard errors apart)
        gf = np.linspace(g[0], g[-1], 20 * (g.size - 1) + 1)
        lm = CubicSpline(g, np.log(np.maximum(m, 1e-300)))(gf)
        mf = np.exp(lm - lm.max())
        mf /= trapezoid(mf, gf)
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (mf[1:] + mf[:-1]) * np.diff(gf))])
        cdf /= cdf[-1]
        q = lambda x, cdf=cdf, gf=gf: float(np.interp(x, cdf, gf))  # noqa: E731
        mean = float(trapezoid(gf * mf, gf))
        sd = float(math.sqrt(max(trapezoid((gf - mean) ** 2 * mf, gf), 0.0)))
        marginals[n] = {"median": q(0.5), "mean": mean, "sd": sd,
                        "interval": [q(0.05), q(0.95)], "mode": float(gf[int(np.argmax(mf))]),
                        "density": m.tolist()}
        # mass in the outer cells of a grid cut inside the bounds
        p = model.parameter(n)
        cell = 20  # one coarse cell on the fine grid
        if g[0] > p.lower:
            edge = max(edge, float(cdf[cell]))
        if g[-1] < p.upper:
            edge = max(edge, float(1.0 - cdf[-1 - cell]))
    settings = {"method": "grid; each run's pilot parameters refitted and integrated out by "
                          f"Laplace's method; decision likelihood, each run's delta_abs {held}",
                "delta_abs": {"how": held, "runs": [q.get("delta_abs") for q in fits]},
                "pooled_fit_neg_log_lik": float(f_ml),
                "n_grid": n_grid, "width_stderr": width, "points": int(logp.size),
                "failed_points": failed, "widened": widened,
                "prior": "uniform on the grid", "n_runs": len(recs),
                "bayes_factor": {
                    "method": "Laplace over each run's pilot parameters (Gauss-Newton "
                              "Hessian), the grid over the shared ones; decision likelihood",
                    "prior": {n: [float(model.parameter(n).lower),
                                  float(model.parameter(n).upper)] for n in shared},
                    "log_laplace_base": base_term,
                    "base_log_lik": base_log_lik,
                    # ln BF above the likelihood's own gain: the extension's evidence is the
                    # pilot parameters' wider posterior under it, not a better fit
                    "gain": best - base_log_lik,
                    "volume_driven": bool(lbf > best - base_log_lik),
                    "schwarz": (float(chosen.log_bayes_factor)
                                if math.isfinite(chosen.log_bayes_factor) else None)}}
    post = SharedPosterior(chosen.physics, shared, grids, log_density, marginals,
                           {n: float(at[n]) for n in shared},
                           {n: float(at_se.get(n, math.nan)) for n in shared},
                           edge, settings, time.perf_counter() - t0, lbf)
    result.posterior = post
    return post
