"""The result of a maximum-likelihood fit: parameters by name, fit quality, how it was found."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._files import dumps, read_result, require_keys, write_text_atomic
from .. import presets

__all__ = ["FitResult"]


@dataclass(frozen=True, eq=False)
class FitResult:
    """A fitted pilot model.

    Attributes
    ----------
    params : dict
        Every parameter of the model by name (fixed ones included, e.g.
        ``delta_abs = 0`` without threshold).
    neg_log_lik : float
        Final -ln L (Eq. 4, output-error variance profiled out).
    vaf : float
        Variance accounted for, percent.
    method : {"paper", "fast"}
    seed : int or None
        The seed used (drawn from fresh entropy when ``seed=None`` was
        given); None in results saved before it was recorded.
    threshold : bool
        Whether delta_abs was estimated.
    settings : dict
        Every setting of the procedure.
    steps : dict
        Step I (the GA repetitions and their histories), Step II (each
        refinement) and Step III (the scan), or the fast method's stages.
    elapsed : float
        Wall time, s.
    source : str or None
        The recording it was fitted to.
    """

    params: dict[str, float]
    neg_log_lik: float
    vaf: float
    method: str
    seed: int | None
    threshold: bool
    settings: dict[str, Any] = field(default_factory=dict)
    steps: dict[str, Any] = field(default_factory=dict)
    elapsed: float = math.nan
    source: str | None = None

    def to_dict(self, *, full: bool = True) -> dict[str, Any]:
        """JSON-ready dict: ``params``, ``neg_log_lik``, ``vaf``, ``method``, ``seed``, ... .

        Parameters
        ----------
        full : bool, default True
            Include ``steps``, the per-step details (the GA histories, each
            refinement, the scan); False leaves them out (a short summary).

        Returns
        -------
        dict
            ``params``, ``neg_log_lik``, ``vaf``, ``method``, ``seed``,
            ``threshold``, ``elapsed_seconds`` (s), ``source``, ``settings``
            and, with ``full``, ``steps``.
        """
        d = {"params": dict(self.params), "neg_log_lik": self.neg_log_lik, "vaf": self.vaf,
             "method": self.method, "seed": self.seed, "threshold": self.threshold,
             "elapsed_seconds": self.elapsed, "source": self.source, "settings": self.settings}
        if full:
            d["steps"] = self.steps
        return d

    def to_json(self, path: str | Path, *, full: bool = True) -> Path:
        """Write :meth:`to_dict` to ``path`` (parent folders created).

        Non-finite numbers are written as null (read back as NaN by
        :meth:`from_json`); an existing file is replaced only once the new one
        is written.

        Parameters
        ----------
        path : str or Path
            The JSON file to write.
        full : bool, default True
            Include the per-step details (see :meth:`to_dict`).

        Returns
        -------
        Path
            ``path``.
        """
        return write_text_atomic(path, dumps(self.to_dict(full=full)))

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "FitResult":
        """The fit a :meth:`to_dict` holds (a null number is NaN).

        Parameters
        ----------
        d : dict
            A :meth:`to_dict` (as read from JSON); ``steps`` may be absent
            (``full=False``), as may the fields after ``method``.

        Returns
        -------
        FitResult

        Raises
        ------
        ValueError
            ``d`` lacks what a fit's dict has (``params``, ``neg_log_lik``,
            ``vaf``, ``method``): another kind of file.
        """
        require_keys(d, ("params", "neg_log_lik", "vaf", "method"), "a fit result")

        def num(v):  # (a non-finite number was written as null, _files.dumps)
            return math.nan if v is None else float(v)

        return cls({k: num(v) for k, v in d["params"].items()}, num(d["neg_log_lik"]),
                   num(d["vaf"]), d["method"], d.get("seed"), bool(d.get("threshold", True)),
                   d.get("settings", {}), d.get("steps", {}), num(d.get("elapsed_seconds")),
                   d.get("source"))

    @classmethod
    def from_json(cls, path: str | Path) -> "FitResult":
        """The fit a :meth:`to_json` file holds.

        Parameters
        ----------
        path : str or Path
            The JSON file.

        Returns
        -------
        FitResult

        Raises
        ------
        FileNotFoundError
            No file at ``path``.
        ValueError
            The file is not JSON, or not a fit's (the message names it).
        """
        return read_result(path, cls.from_dict, "a FitResult")

    def summary(self) -> str:
        """A readable table of the estimates and the fit."""
        units = presets.PARAMETER_UNITS
        lines = [f"bayespilot fit ({self.method} method, "
                 f"{'with' if self.threshold else 'without'} threshold, seed {self.seed})"]
        if self.source:
            lines.append(f"recording: {self.source}")
        lines.append(f"{'parameter':<10} {'estimate':>12}  unit")
        for k, v in self.params.items():
            fixed = "  (fixed)" if (k == "delta_abs" and not self.threshold) else ""
            lines.append(f"{k:<10} {v:>12.6g}  {units.get(k, '')}{fixed}")
        lines.append(f"-ln L = {self.neg_log_lik:.3f}   VAF = {self.vaf:.2f} %   "
                     f"time = {self.elapsed:.1f} s")
        return "\n".join(lines)

    __str__ = summary
