"""The worked example (``bayespilot demo``, the README's main job), on a tiny study.

The report's table must carry the numbers of the files written beside it:
the fits (JSON), the posteriors (netCDF) and the comparisons (JSON).
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import bayespilot
from bayespilot.cli import main
from bayespilot.compare import Comparison, decide
from bayespilot.fit.result import FitResult
from bayespilot.io import read_recording
from bayespilot.sample import Posterior


#: The titles of the figures the demo saved, by file name (filled by the ``demo`` fixture).
TITLES: dict[str, list[str]] = {}


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    from bayespilot import example

    out = tmp_path_factory.mktemp("demo")
    save = example._save

    def keep_titles(fig, path, **figure):
        TITLES[path.name] = [ax.get_title() for ax in fig.axes]
        save(fig, path, **figure)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(example, "_save", keep_titles)
        code = main(["-q", "demo", "--out", str(out), "--motion-gains", "1", "--duration", "20",
                     "--max-steps", "400", "--nlive", "30", "--seed", "3"])
    return code, out


def test_demo_figure_titles_are_in_the_papers_notation(demo):
    """Audit 3: the marginal's title read "FD_k1: posterior of delta_abs" (a file stem and a
    code identifier), without the run's convergence; the traces' title began with a path."""
    assert demo[0] == 0
    (title,) = TITLES["delta_abs_FD_k1.png"]
    flat = title.replace("\n", " ")
    assert flat.startswith(r"FD, $K_\theta$ = 1: posterior of $\delta_\mathrm{abs}$")
    assert "delta_abs" not in flat.replace(r"\delta_\mathrm{abs}", "") and "FD_k1" not in flat
    assert "converged" in flat and "likelihood" in flat
    assert not any("recordings" in t for t in TITLES["traces.png"])


def test_demo_writes_the_report_and_its_files(demo):
    code, out = demo
    assert code == 0
    report = (out / "report.md").read_text()
    assert "with seed 3 (run i seeded 3 + i)" in report  # (a reader can repeat it)
    assert f"`bayespilot demo` (bayespilot {bayespilot.__version__})" in report  # (with what)
    rows = [line for line in report.splitlines() if line.startswith("| FD_k1 |")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    fit = FitResult.from_json(out / "fits" / "FD_k1_threshold.json")
    fit0 = FitResult.from_json(out / "fits" / "FD_k1_none.json")
    assert float(cells[3]) == pytest.approx(fit.params["delta_abs"], abs=5e-5)
    assert float(cells[7]) == pytest.approx(fit.neg_log_lik, abs=0.05)
    assert float(cells[8]) == pytest.approx(fit0.neg_log_lik, abs=0.05)
    # the model with threshold contains the one without: the fast fit must not be worse
    assert fit.neg_log_lik <= fit0.neg_log_lik + 1e-6
    post = Posterior.from_netcdf(out / "posteriors" / "FD_k1.nc")
    median = float(re.match(r"[0-9.]+", cells[4]).group(0))
    assert median == pytest.approx(np.median(post.draws("delta_abs")), abs=5e-5)
    cmp_ = Comparison.from_json(out / "comparisons" / "FD_k1.json")
    assert cells[10] == cmp_.decision
    raw = decide(cmp_.log_bayes_factor, cmp_.log_bayes_factor_err)
    if cmp_.settings.get("decision_note"):
        # one of compare's two guards (lost main mode, plateau) made the verdict inconclusive
        assert cmp_.decision == "inconclusive" != raw
    else:
        assert cmp_.decision == raw
    pooled = json.loads((out / "pooled_comparison.json").read_text())
    assert pooled["n"] == 1 and pooled["log_bayes_factor"] == pytest.approx(cmp_.log_bayes_factor)
    for png in re.findall(r"\]\((figures/[^)]+\.png)\)", report):
        assert (out / png).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    rec = read_recording(out / "recordings" / "FD_k1")
    assert (rec.task, rec.motion_gain, rec.n_samples) == ("FD", 1.0, 2000)


def test_no_seed_draws_one_and_says_it(tmp_path, monkeypatch):
    """seed=None (it raised TypeError, None + 0): a seed is drawn, and run i simulates with
    it + i, said on the first line (the report states it too, test above)."""
    import bayespilot.simulate
    from bayespilot.example import run_example

    class Stop(Exception):
        pass

    def first_simulation(**kw):  # (the first run's simulation: its seed, then stop)
        raise Stop(kw["seed"])

    monkeypatch.setattr(bayespilot.simulate, "simulate", first_simulation)
    said = []
    with pytest.raises(Stop) as stop:
        run_example(tmp_path / "out", seed=None, progress=False, say=said.append)
    drawn = stop.value.args[0]
    assert isinstance(drawn, int) and 0 <= drawn < 2 ** 31 and f"seed {drawn})" in said[0]


@pytest.mark.parametrize("seed", [-1, 1.5, "3", True])
def test_a_bad_seed_is_refused_before_any_folder_is_made(tmp_path, seed):
    """run_example(seed=None) raised a TypeError (None + 0) after making five empty folders;
    None now draws a seed (stated in the report) and a bad one is refused first."""
    from bayespilot.example import run_example

    with pytest.raises(ValueError, match="seed must be an integer >= 0 or None"):
        run_example(tmp_path / "out", seed=seed, progress=False, say=lambda s: None)
    assert not (tmp_path / "out").exists()
