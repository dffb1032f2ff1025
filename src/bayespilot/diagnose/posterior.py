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
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..recording import Recording
from .catalogue import get_extension

__all__ = ["sample_chosen"]


def _checked_chosen(result: Any, recording: Recording):
    """The chosen GLS candidate of a single-run ``result`` of ``recording``, or a clear error."""
    if not isinstance(recording, Recording):
        raise TypeError(f"recording must be a Recording, got {type(recording).__name__}")
    if getattr(result, "runs", None) is not None:
        raise ValueError("sample_chosen takes a single-run diagnosis; the posterior of a "
                         "pooled diagnosis (parameters shared over runs) is not built")
    chosen = getattr(result, "chosen", None)
    if chosen is None:
        raise ValueError(f"the diagnosis chose no extension (physics = "
                         f"{getattr(result, 'physics', 'none')!r}): there is no extended model "
                         "to sample")
    ext = get_extension(chosen.physics)
    if ext.likelihood != "gls" or getattr(chosen, "model", None) is None:
        raise ValueError(f"{chosen.physics!r} is decided by its flat tops and a censored "
                         "likelihood; its limits are read from the data, not sampled")
    check_same_recording(result, recording)
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
                  seed: int | None = 0, progress: bool = False, **options: Any):
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
