"""The worked example: a small simulated study, fitted, sampled, compared and reported.

:func:`run_example` is what ``bayespilot demo`` runs (the README's first
command).  It walks the package's whole data flow on a few recordings, in a
few minutes on a laptop:

1. simulate one run per motion gain K_theta (Table 3 pilot of the paper,
   delta_abs = 0.0075 IPUT, remnant fraction F_n) and write each as a
   recording (CSV + JSON sidecar, with the truth under ``"simulation"`` as
   ``bayespilot simulate`` writes it), then read it back as a user's file;
2. fit each with the fast maximum-likelihood estimator, with and without
   threshold (:func:`bayespilot.fit.fast.fit_fast`), by default as
   prediction-error fits that share one AR model of the output error;
3. sample the posterior from the fit with emcee (:func:`bayespilot.sample.sample`,
   by default the coloured likelihood, whose intervals are calibrated in
   ``docs/posteriors.md``) and save it as netCDF;
4. compare the models with and without threshold by nested sampling
   (:func:`bayespilot.compare.compare`), per run and pooled;
5. write ``report.md`` with a table and the figures (traces, delta_abs
   marginals, a pair plot).

Everything is seeded: the same seed gives the same numbers, figures and files
(the report's line with the time it took aside).
"""

from __future__ import annotations

import contextlib
import math
import time
import warnings
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from . import presets
from ._files import dumps, write_text_atomic

__all__ = ["run_example"]


def _save(fig, path: Path, *, formats: Sequence[str] = ("png",), dpi: int | None = None) -> None:
    """``fig`` written as ``path`` with each of ``formats``' suffixes (at ``dpi``, default
    the resolution of every figure written), then closed."""
    import matplotlib.pyplot as plt

    from ._figstyle import PLOT_DPI, save_figure

    try:
        for fmt in formats:
            save_figure(fig, path.with_suffix(f".{fmt}"), PLOT_DPI if dpi is None else dpi)
    finally:
        plt.close(fig)


def _shown(formats: Sequence[str]) -> str:
    """The format report.md shows its figures in: PNG if written, else SVG (both shown by a
    Markdown viewer), else the first (a PDF: a link)."""
    return next((f for f in ("png", "svg") if f in formats), formats[0])


class LabRecordingThere(ValueError):
    """``run_example``'s ``out/recordings/`` holds, at a run's name, a recording no demo
    wrote (the command line says it of ``--out``)."""


#: The first line of the demo's report.md (:func:`_report`): a folder with it is the demo's.
REPORT_HEADING = "# bayespilot worked example"


def _refuse_a_lab_recording(out: Path, stems: Sequence[Path]) -> None:
    """Refuse (:class:`LabRecordingThere`) to simulate onto a recording at one of ``stems``
    that is not the demo's own: a lab's measurement cannot be made again.  The demo's own
    has a sidecar with the ``"simulation"`` block, or (written before it kept that block)
    lies in a folder with the demo's ``report.md`` (its first line the demo's heading)."""
    from .io import _pair_on_disk

    try:
        with open(out / "report.md", encoding="utf-8") as fh:
            if fh.readline().rstrip("\n") == REPORT_HEADING:
                return
    except (OSError, UnicodeDecodeError):
        pass
    for stem in stems:
        there, _, simulated = _pair_on_disk(stem)
        if there and not simulated:
            raise LabRecordingThere(f"{' and '.join(str(p) for p in there)} "
                                    f"{'are' if len(there) > 1 else 'is'} not a recording the "
                                    "demo wrote (no \"simulation\" in a sidecar, no report.md "
                                    f"in {out}): the demo would replace it; give another folder")


def run_example(out: str | Path = "bayespilot-demo", *, seed: int | None = 0,
                motion_gains: Sequence[float] = (0.5, 1.0), task: str = "FD",
                remnant_fraction: float = 0.15, duration: float | None = None,
                max_steps: int = 6000, nlive: int = 150, likelihood: str = "coloured",
                formats: Sequence[str] = ("png",), dpi: int | None = None, title: bool = True,
                progress: bool = True, say: Callable[[str], None] = print) -> Path:
    """Run the worked example and write its report.

    Parameters
    ----------
    out : path
        Output folder (created): ``recordings/``, ``fits/``, ``posteriors/``,
        ``comparisons/``, ``figures/`` and ``report.md``.
    seed : int or None
        Seeds the remnant of each run, the fits, the samplers and the nested
        sampler (run i uses ``seed + i``); None draws one from fresh entropy.
        The report states it.
    motion_gains : sequence of float
        K_theta of the runs, one run each.
    task : {"FD", "FT"}
    remnant_fraction : float
        F_n of the simulated pilot.
    duration : float, optional
        Measurement time, s (default the paper's 81.92 s).
    max_steps : int
        Cap on the emcee chain length per run.
    nlive : int
        Live points of the nested sampler.
    likelihood : {"coloured", "eq4"}
        The likelihood of the fits, posteriors and comparisons: the
        prediction-error one (an AR model of the output error, estimated once
        per run and shared by all three; default) or the paper's Eq. 4.
    formats : sequence of str
        The formats of the figures, ``figures/<name>.<format>`` each: ``"png"``
        (default), ``"pdf"``, ``"svg"`` (vector, for a paper); ``report.md``
        shows the PNGs if written, else the SVGs, else links the PDFs.
    dpi : int, optional
        Resolution of a PNG (default
        :data:`~bayespilot._figstyle.PLOT_DPI`); a PDF or SVG uses it only
        for the pair plot's rasterized point clouds.
    title : bool
        True (default): each figure with its title (the run, its draws,
        likelihood and convergence); False: none, for a paper whose captions
        say it (a chain that has not converged is still said, by the warning
        below).
    progress : bool
        Progress bars of the sampler.
    say : callable
        Receives one line per stage (``print`` by default).

    Returns
    -------
    pathlib.Path
        The report, ``out/report.md``.

    Warns
    -----
    ConvergenceWarning
        Once, at the end, naming the runs whose emcee chain reached
        ``max_steps`` before the autocorrelation criterion held (their
        posteriors are rough estimates; raise ``max_steps``).

    Raises
    ------
    ValueError
        A ``task``, ``likelihood``, ``motion_gains`` or ``seed`` out of range,
        or ``formats`` empty or naming one not in ``("png", "pdf", "svg")``;
        or ``out/recordings/`` holds a file at a run's name that no demo
        wrote (a lab's recording: its sidecar has no ``"simulation"`` and
        ``out`` has no ``report.md``); nothing is written.
    TypeError
        ``title`` is not True or False; nothing is written.

    Examples
    --------
    A tiny run (short records, short chains; the real example takes a few minutes):

    >>> import tempfile, warnings
    >>> with tempfile.TemporaryDirectory() as d, warnings.catch_warnings():
    ...     warnings.simplefilter("ignore")
    ...     report = run_example(d, motion_gains=(1.0,), duration=20.0, max_steps=300,
    ...                          nlive=30, progress=False, say=lambda s: None)
    ...     report.name
    'report.md'
    """
    from ._labels import symbol
    from .compare import compare, pool
    from .fit.fast import fit_fast
    from .io import read_recording
    from .plots import _pyplot, _run_note, _wrap, plot_marginal, plot_pair, plot_traces
    from .sample import sample
    from .simulate import simulate

    from .noise import ARNoise
    from .likelihood import coloured_discard
    from .sample import ConvergenceWarning

    from ._figstyle import figure_options
    from ._seeds import resolve_seed

    seed = resolve_seed(seed)  # (checked before a folder is made; None: a fresh one)
    if task not in ("FD", "FT"):
        raise ValueError(f"task must be 'FD' or 'FT', got {task!r}")
    if likelihood not in ("coloured", "eq4"):
        raise ValueError(f"likelihood must be 'coloured' or 'eq4', got {likelihood!r}")
    # (checked before a folder is made or a run simulated: a bad dpi failed after the first)
    figure = figure_options(title, formats, dpi)
    title = figure.pop("title")
    gains = [float(k) for k in motion_gains]
    if not gains or any(not (k > 0) for k in gains):
        raise ValueError(f"motion_gains must be positive numbers, got {motion_gains!r}")
    out = Path(out)
    dirs = {k: out / k for k in ("recordings", "fits", "posteriors", "comparisons", "figures")}
    _refuse_a_lab_recording(out, [dirs["recordings"] / f"{task}_k{kt:g}" for kt in gains])
    for d in dirs.values():
        d.mkdir(parents=True, exist_ok=True)
    plt = _pyplot()
    truth = presets.paper_parameters(task)
    t_start = time.perf_counter()
    rows, comparisons, posteriors = [], [], []
    unconverged: list[tuple[str, float]] = []  # (run, last max tau) of chains not converged
    for i, kt in enumerate(gains):
        name = f"{task}_k{kt:g}"
        s = seed + i
        say(f"[{i + 1}/{len(gains)}] {name}: simulating (F_n = {remnant_fraction:g}, seed {s}) ...")
        sim = simulate(task=task, motion_gain=kt, remnant_fraction=remnant_fraction, seed=s,
                       duration=duration)
        # with its truth (the sidecar's "simulation": true parameters, seed, release), as
        # `bayespilot simulate` writes it, so that the posterior file has true_* attributes
        csv, _ = sim.write(dirs["recordings"] / f"{name}.csv")
        rec = read_recording(csv)
        if i == 0:
            _save(plot_traces(rec, canal=sim.channels["vestibular"]["pre"],
                              delta_abs=truth["delta_abs"], title=title),
                  dirs["figures"] / "traces.png", **figure)
        say(f"[{i + 1}/{len(gains)}] {name}: fitting with and without threshold ...")
        opts: dict = {}
        if likelihood == "coloured":
            # one AR noise model (from a prediction-error fit) for both fits, the posterior
            # and the comparison, so that all are judged by the same likelihood
            # (the default lead-in of noise="ar", min(2 s, a quarter of the record), given
            # explicitly so that the white-noise fits with this AR model leave it out too)
            lead_in = coloured_discard(rec)
            pem = fit_fast(rec, threshold=True, seed=s, noise="ar", discard=lead_in)
            opts = {"noise": ARNoise.from_dict(pem.settings["noise"]), "discard": lead_in}
        fit = fit_fast(rec, threshold=True, seed=s, **opts)
        fit0 = fit_fast(rec, threshold=False, seed=s, **opts)
        fit.to_json(dirs["fits"] / f"{name}_threshold.json")
        fit0.to_json(dirs["fits"] / f"{name}_none.json")
        say(f"[{i + 1}/{len(gains)}] {name}: sampling the posterior (emcee) ...")
        # ar="fixed": the posterior under the comparison's likelihood (fit's AR model)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", ConvergenceWarning)
            post = sample(rec, likelihood=likelihood, ar="fixed", init=fit, seed=s,
                          max_steps=max_steps,
                          min_steps=min(1000, max_steps), check_every=min(500, max_steps),
                          progress=progress)
        for w in caught:  # sample's advice names a backend, which the demo has none of
            if issubclass(w.category, ConvergenceWarning):
                tau = w.message.tau
                finite = [] if tau is None else [t for t in np.ravel(tau) if np.isfinite(t)]
                unconverged.append((name, max(finite) if finite else math.nan))
            else:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        post.to_netcdf(dirs["posteriors"] / f"{name}.nc")
        posteriors.append(post)
        say(f"[{i + 1}/{len(gains)}] {name}: comparing threshold against none (dynesty) ...")
        cmp_ = compare(rec, likelihood=likelihood, seed=s, nlive=nlive, posterior=post,
                       progress=progress)
        cmp_.to_json(dirs["comparisons"] / f"{name}.json")
        comparisons.append(cmp_)
        d = post.draws("delta_abs")
        lo, hi = post.credible_interval("delta_abs", 0.9)
        true_d = truth["delta_abs"]
        rows.append({"run": name, "K_theta": kt, "F_n": sim.remnant_fraction,
                     "delta_ml": fit.params["delta_abs"], "delta_median": float(np.median(d)),
                     "hdi90": (lo, hi),
                     "p50": float(np.mean(np.abs(d - true_d) <= 0.5 * true_d)),
                     "nll": fit.neg_log_lik, "nll0": fit0.neg_log_lik, "vaf": fit.vaf,
                     "log_bf": cmp_.log_bayes_factor, "log_bf_err": cmp_.log_bayes_factor_err,
                     "decision": cmp_.decision, "converged": post.converged})
        with _untitled(title):
            fig = plot_marginal(post, "delta_abs", truth=true_d, title=title)
        if title:
            text = (f"{task}, $K_\\theta$ = {kt:g}: posterior of {symbol('delta_abs')}, "
                    f"{_run_note(post, d.size)}")  # (draws, likelihood, convergence)
            fig.axes[0].set_title(_wrap(text, fig.get_figwidth() - 0.3, 10.0),
                                  fontsize="medium")
        _save(fig, dirs["figures"] / f"delta_abs_{name}.png", **figure)
    with _untitled(title):
        fig = plot_pair(posteriors[-1], truth=truth, title=title)
    _save(fig, dirs["figures"] / "pair.png", **figure)
    pooled = pool(comparisons, label=f"{task}, K_theta {', '.join(f'{k:g}' for k in gains)}")
    write_text_atomic(out / "pooled_comparison.json", dumps(pooled.to_dict()))
    elapsed = time.perf_counter() - t_start
    report = out / "report.md"
    # (atomic: on a full disk it was left empty, the earlier report lost)
    write_text_atomic(report, _report(rows, pooled, truth, task, gains, elapsed, likelihood,
                                      seed, coloured_discard(rec),  # (one duration for all)
                                      _shown(figure["formats"])))
    say(f"wrote {report} ({elapsed:.0f} s)")
    plt.close("all")
    if unconverged:
        _warn_unconverged(unconverged, max_steps)
    return report


def _warn_unconverged(runs: Sequence[tuple[str, float]], max_steps: int) -> None:
    """One ConvergenceWarning for the demo's chains that reached ``max_steps`` (run, max tau),
    with the demo's advice (it has no backend to resume)."""
    from ._caller import warn_at_caller
    from .sample import ConvergenceWarning

    names = ", ".join(n for n, _ in runs)
    taus = [t for _, t in runs if math.isfinite(t)]
    tau = f" (max tau = {max(taus):.0f} steps)" if taus else ""
    one = len(runs) == 1
    rough = ("its posterior is a rough estimate" if one else
             "their posteriors are rough estimates")
    warn_at_caller(ConvergenceWarning(
        f"the emcee chain{'' if one else 's'} of {names} reached max_steps = {max_steps} before "
        f"{'it was' if one else 'they were'} long enough for the autocorrelation criterion"
        f"{tau}: {rough} (the report's intervals too); to run longer, raise max_steps "
        "(bayespilot demo --max-steps)", None, max_steps))


@contextlib.contextmanager
def _untitled(title: bool):
    """Around a posterior figure drawn without its title (``title`` False): its
    ConvergenceWarning (the title said "not converged") ignored; the demo says it once, at
    the end, for every run (:func:`_warn_unconverged`)."""
    from .sample import ConvergenceWarning

    with warnings.catch_warnings():
        if not title:
            warnings.simplefilter("ignore", ConvergenceWarning)
        yield


def _report(rows, pooled, truth, task, gains, elapsed, likelihood, seed,
            lead_in: float, ext: str = "png") -> str:
    from . import __version__
    from .compare import DECISION_LEVEL, DECISION_Z

    true_d = truth["delta_abs"]
    lines = [
        REPORT_HEADING,
        "",
        f"{len(rows)} simulated runs of the {task} task of Pool et al. (2012), one per motion gain "
        f"K_theta ({', '.join(f'{k:g}' for k in gains)}), with the Table 3 pilot "
        f"(true delta_abs = {true_d} IPUT). Each was fitted by maximum likelihood (fast "
        "estimator) with and without threshold, sampled with emcee from that fit (uniform priors "
        "on the Table 1 bounds), and the two models were compared by nested sampling (dynesty), "
        + ("all with the coloured (prediction-error) likelihood: the output error whitened by "
           f"one AR model per run, estimated from a prediction-error fit, the first {lead_in:g} s "
           "left out. " if likelihood == "coloured" else "all with the paper's Eq. 4 likelihood. ")
        + f"Made in {elapsed:.0f} s by `bayespilot demo` (bayespilot {__version__}) with seed "
        f"{seed} (run i seeded {seed} + i).",
        "",
        "| run | K_theta | F_n | delta_abs ML | posterior median | 90 % HDI | P(within +-50 %) "
        "| -ln L with | -ln L without | ln BF | decision |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        conv = "" if r["converged"] else " (chain not converged)"
        lines.append(
            f"| {r['run']} | {r['K_theta']:g} | {r['F_n']:.2f} | {r['delta_ml']:.4f} | "
            f"{r['delta_median']:.4f}{conv} | [{r['hdi90'][0]:.4f}, {r['hdi90'][1]:.4f}] | "
            f"{r['p50']:.2f} | {r['nll']:.1f} | {r['nll0']:.1f} | "
            f"{r['log_bf']:+.1f} +- {r['log_bf_err']:.1f} | {r['decision']} |")
    pd = pooled.to_dict()
    lines += [
        "",
        f"Pooled over the runs: ln BF = {pd.get('log_bayes_factor', float('nan')):+.1f}, "
        f"decision **{pd.get('decision', '?')}**.",
        "",
        f"ln BF is ln Z(threshold) - ln Z(none), with its standard error from dynesty. A "
        f"decision needs |ln BF| above {DECISION_LEVEL:.2f} (Bayes factor 10, Jeffreys' "
        f"'strong') by {DECISION_Z:g} standard errors; otherwise the data cannot tell "
        "('inconclusive'; see the docs' model-comparison page). "
        "P(within +-50 %) is the posterior probability that delta_abs lies within +-50 % of the "
        "true value, the single-recording counterpart of the paper's N50%.",
        "",
        "## Figures",
        "",
        "The first run's signals (tracking error e, control u, motion theta_ddot_m and the canal "
        "output i with the +-delta_abs band):",
        "",
        f"![traces](figures/traces.{ext})",
        "",
    ]
    for r in rows:
        lines += [f"Posterior of delta_abs, {r['run']} (dashed: the true value):", "",
                  f"![delta_abs {r['run']}](figures/delta_abs_{r['run']}.{ext})", ""]
    lines += ["Pair plot of K_m, tau_m and delta_abs for the last run:", "",
              f"![pair](figures/pair.{ext})", "",
              "Files: `recordings/` (the simulated runs in the recording format), `fits/` "
              "(maximum-likelihood fits, JSON), `posteriors/` (arviz netCDF), `comparisons/` "
              "(JSON), `pooled_comparison.json`.", ""]
    return "\n".join(lines)
