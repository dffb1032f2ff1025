"""A result at the end of a notebook cell shows its readable account, not a one-line repr.

API audit C7: no result type defined ``_repr_html_``, so Jupyter showed ``FitResult(...)``
on one line where ``print(fit.summary())`` gives the table.  Each is checked against the
text its own ``summary()`` (or ``str``) gives, escaped by the standard library.
"""

from __future__ import annotations

import html
from pathlib import Path

from bayespilot.campaign import CampaignSummary
from bayespilot.compare import Comparison, Evidence, PooledComparison, pool
from bayespilot.diagnose import DiagnosisResult
from bayespilot.diagnose.pooled import PooledDiagnosisResult
from bayespilot.fit.result import FitResult
from bayespilot.model import paper_model
from bayespilot.sample import Posterior


def _as_html(text: str) -> str:
    return "<pre>" + html.escape(text, quote=True) + "</pre>"


def test_results_show_their_summary_escaped():
    fit = FitResult({"K_v": 1.5, "delta_abs": 0.01}, -100.0, 90.0, "fast", 0, True, {}, {},
                    1.0, "runs/<s1> & co", {"K_v": (0.0, 10.0), "delta_abs": (0.0, 0.1)},
                    {"K_v": "-", "delta_abs": "IPUT"})
    shown = fit._repr_html_()
    assert shown == _as_html(fit.summary())
    assert "runs/&lt;s1&gt; &amp; co" in shown and "<s1>" not in shown
    model = paper_model()
    assert model._repr_html_() == _as_html(model.summary())
    assert "vestibular: theta_ddot_m -&gt; FixedFilter -&gt; DeadZone" in model._repr_html_()
    ev = Evidence(0.0, 0.1, 0.0, 0.0, {}, {}, (), 0, 0, 0.0, {"nlive": 40})
    ic = {"neg_log_lik_threshold": 1.0, "neg_log_lik_none": 2.0, "delta_aic": 0.0,
          "delta_bic": 0.0}
    c = Comparison(3.0, 0.5, "threshold", ev, ev, None, ic, {"likelihood": "eq4"},
                   source="fd0")
    assert c._repr_html_() == _as_html(c.summary())
    pooled = pool([c, {"log_bayes_factor": 1.0}])
    assert isinstance(pooled, PooledComparison)
    assert pooled._repr_html_() == _as_html(pooled.summary())
    done = CampaignSummary(3, 2, 1, 0, {}, Path("out"), 4.0)
    assert done._repr_html_() == _as_html(str(done))


def test_every_result_type_has_the_notebook_display():
    """(The posterior's and a campaign's readable account is their str: a posterior's
    summary() is a dict by parameter.)"""
    for cls in (FitResult, Comparison, PooledComparison, DiagnosisResult,
                PooledDiagnosisResult, Posterior, CampaignSummary):
        assert callable(getattr(cls, "_repr_html_", None)), cls.__name__
    assert Posterior._html_text == CampaignSummary._html_text == "__str__"
    assert DiagnosisResult._html_text == FitResult._html_text == "summary"
