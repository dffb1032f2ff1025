"""Tests of ``bayespilot diagnose`` (the command of issue 5), in-process through ``main``."""

from __future__ import annotations

import errno
import json

import numpy as np
import pytest

import bayespilot
from bayespilot.cli import main
from bayespilot.diagnose import NAMES
from bayespilot.io import write_recording
from bayespilot.recording import Recording
from bayespilot.simulate import simulate


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def rec_stem(tmp_path_factory):
    """A short simulated run written as a lab would: the generator's truth is not in it."""
    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=31, duration=30.0).recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta)
    stem = tmp_path_factory.mktemp("diag") / "run"
    write_recording(rec, stem)
    return stem


def test_diagnose_json_and_report(rec_stem, tmp_path, capsys):
    out = tmp_path / "d.json"
    rep = tmp_path / "report"
    post = tmp_path / "post.nc"
    code, stdout, err = _run(capsys, "diagnose", rec_stem, "--json", out, "--report", rep,
                             "--bootstrap", "0", "--seed", "1", "--posterior", post,
                             "--report-format", "pdf")
    assert code == 0, err
    pdf = (rep / "candidates.pdf").read_bytes()  # (a vector copy for a paper)
    assert pdf[:5] == b"%PDF-" and b"/Type3" not in pdf and not (rep / "candidates.svg").exists()
    assert "decision:" in stdout
    # nothing chosen, nothing to sample: said, and no file
    assert "no extended model to sample" in err and not post.exists()
    d = json.loads(out.read_text())
    assert isinstance(d["mismatch"], bool)
    assert d["physics"] in (*NAMES, "none")
    assert d["physics"] == "none"  # a correct-model run
    assert [r["physics"] for r in d["ranking"]] and len(d["ranking"]) == len(NAMES)
    for r in d["ranking"]:
        assert {"physics", "delta_neg_log_lik", "p_value", "params"} <= set(r)
    assert "time.nonstationarity" in d["where"]
    html = (rep / "report.html").read_text()
    assert "data:image/png;base64," in html and "<img" in html
    assert html.endswith(f"<p>Report written by bayespilot {bayespilot.__version__}.</p>\n"
                         "</body></html>\n")
    for name in ("residuals.png", "candidates.png", "diagnosis.json"):
        assert (rep / name).stat().st_size > 0
    # a 30-s run is not whole forcing periods (no describing function) and --bootstrap 0
    # gives no located p-values: their figures would be empty, so they are not written,
    # and the page says why
    assert not (rep / "frequency_response.png").exists() and not (rep / "evidence.png").exists()
    assert "so there is no figure of them" in html


def test_diagnose_report_format_needs_a_report(rec_stem, capsys):
    code, out, err = _run(capsys, "diagnose", rec_stem, "--report-format", "pdf")
    assert code == 2 and "--report-format: needs --report" in err and out == ""
    code, out, err = _run(capsys, "diagnose", rec_stem, "--report", "x", "--report-format", "eps")
    assert code == 2 and "invalid choice" in err


def test_diagnose_missing_recording_is_a_usage_error(tmp_path, capsys):
    code, out, err = _run(capsys, "diagnose", tmp_path / "nothing")
    assert code == 2
    assert err.startswith("bayespilot: error:") and err.count("\n") == 1
    assert "Traceback" not in err


def test_diagnose_bad_option_is_a_usage_error(rec_stem, capsys):
    code, out, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "-3")
    assert code == 2 and "bootstrap" in err
    code, out, err = _run(capsys, "diagnose", rec_stem, "--calibrate", "-1")
    assert code == 2 and "--calibrate" in err and out == ""
    code, out, err = _run(capsys, "diagnose", rec_stem, "--noise-passes", "0")
    assert code == 2 and "--noise-passes" in err and out == ""
    code, out, err = _run(capsys, "diagnose", rec_stem, "--noise-passes", "6")
    assert code == 2 and "noise_passes" in err and "Traceback" not in err


def test_diagnose_unwritable_json_is_a_failure(rec_stem, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, out, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "0",
                          "--json", blocker / "sub" / "d.json")
    # (the 30-s record is not whole periods: a warning line says the frequency evidence is
    # missing, before the error)
    assert code == 1 and err.splitlines()[-1].startswith("bayespilot: error:")
    assert "cannot write" in err.splitlines()[-1]


def test_diagnose_several_runs_pools_them(rec_stem, tmp_path, capsys):
    rec = simulate(task="FT", motion_gain=1.0, remnant_gain=0.06, seed=32, duration=30.0).recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    stem2 = tmp_path / "run2"
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    stem2)
    out = tmp_path / "pooled.json"
    code, stdout, err = _run(capsys, "diagnose", rec_stem, stem2, "--json", out,
                             "--bootstrap", "0", "--report", tmp_path / "rep")
    assert code == 0, err
    assert "2 runs pooled" in stdout
    d = json.loads(out.read_text())
    assert d["pooled"] is True and d["n_runs"] == 2 and d["physics"] == "none"
    assert len(d["runs"]) == 2 and len(d["ranking"]) == len(NAMES)
    assert (tmp_path / "rep" / "runs.png").stat().st_size > 0
    # one subject and condition: no pooling warning (the 30-s records are not whole periods,
    # which each run's one line says)
    assert "not of one subject" not in err
    warned = [ln for ln in err.splitlines() if "warning" in ln]
    assert len(warned) == 2 and all("frequency evidence (frequency.*) is missing" in ln
                                    for ln in warned)


def test_diagnose_warns_before_pooling_runs_that_differ(rec_stem, tmp_path, capsys):
    """Runs of another K_theta are said at once, in one line (here the run then stops on a
    bad setting, so that the test does not pay for the pooled diagnosis)."""
    rec = simulate(task="FT", motion_gain=0.75, remnant_gain=0.06, seed=33, duration=30.0).recording
    stem2 = tmp_path / "other"
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, {}),
                    stem2)
    code, _, err = _run(capsys, "diagnose", rec_stem, stem2, "--noise-passes", "9")
    lines = err.strip().splitlines()
    assert code == 2 and len(lines) == 2, err
    assert lines[0] == ("bayespilot: warning: the runs are not of one subject and condition "
                        "(K_theta 0.75, 1); pooling assumes the physics left out is the same "
                        "in every run")
    assert lines[1].startswith("bayespilot: error: noise_passes")


def test_diagnose_posterior_file_name_says_what_it_holds(rec_stem, tmp_path, capsys):
    """One recording: draws as netCDF (.nc); several: the shared parameters' grid (.json)."""
    code, out, err = _run(capsys, "diagnose", rec_stem, rec_stem, "--posterior",
                          tmp_path / "p.nc")
    assert code == 2 and "must end in .json" in err and err.count("\n") == 1
    code, out, err = _run(capsys, "diagnose", rec_stem, "--posterior", tmp_path / "p.txt")
    assert code == 2 and "must end in .nc" in err
    assert not list(tmp_path.iterdir())


def test_diagnose_pooled_posterior_writes_the_shared_parameters_json(tmp_path, capsys,
                                                                    monkeypatch):
    """Two runs with a washout: --posterior POST.json holds the shared omega_w's grid
    posterior, which the summary and --json also carry (grid shortened here)."""
    import bayespilot.diagnose as dg
    from bayespilot import presets
    from bayespilot.diagnose import get_extension
    from bayespilot.model import paper_model

    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    stems = []
    for seed in (22, 23):
        rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=seed,
                       duration=40.96).recording
        meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
        stems.append(tmp_path / f"wash{seed}")
        write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                                  meta), stems[-1])
    real = dg.shared_posterior
    monkeypatch.setattr(dg, "shared_posterior", lambda res, r, **kw: real(res, r, n_grid=7,
                                                                         **kw))
    post, out = tmp_path / "post.json", tmp_path / "d.json"
    code, stdout, err = _run(capsys, "diagnose", *stems, "--bootstrap", "0", "--posterior",
                             post, "--json", out)
    assert code == 0, err
    assert "decision: motion-washout" in stdout
    assert "posterior of the shared parameters" in stdout
    got = json.loads(post.read_text())
    assert got["names"] == ["omega_w"] and len(got["grid"][0]) == 7
    lo, hi = got["marginals"]["omega_w"]["interval"]
    assert lo < 0.8 < hi
    assert json.loads(out.read_text())["posterior"]["marginals"] == got["marginals"]


@pytest.mark.filterwarnings("ignore::bayespilot.sample.ConvergenceWarning")
def test_diagnose_posterior_writes_the_extended_models_netcdf(tmp_path, capsys, monkeypatch):
    """--posterior on a run with a strong washout: the chosen model's posterior as netCDF
    (readable by Posterior.from_netcdf), its summary in the JSON and the stdout summary.
    (The chain is shortened here; the command's own is sample()'s default.)"""
    import bayespilot.diagnose as dg
    from bayespilot import presets
    from bayespilot.diagnose import get_extension
    from bayespilot.model import paper_model
    from bayespilot.sample import Posterior

    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=22,
                   duration=40.96).recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    stem = tmp_path / "wash"
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    stem)
    real = dg.sample_chosen
    monkeypatch.setattr(dg, "sample_chosen", lambda res, r, **kw: real(
        res, r, n_walkers=20, max_steps=600, min_steps=200, check_every=200, **kw))
    made = []  # (the diagnosis, kept for the failures below)
    real_diagnose = dg.diagnose
    monkeypatch.setattr(dg, "diagnose", lambda *a, **k: made.append(real_diagnose(*a, **k))
                        or made[-1])
    post, out = tmp_path / "post.nc", tmp_path / "d.json"
    code, stdout, err = _run(capsys, "diagnose", stem, "--bootstrap", "0", "--posterior", post,
                             "--json", out, "--calibrate", "3")
    assert code == 0, err
    assert "decision: motion-washout" in stdout and "posterior (coloured likelihood" in stdout
    assert "calibrated by 3 replicates" in stdout
    back = Posterior.from_netcdf(post)
    assert "omega_w" in back.parameter_names
    d = json.loads(out.read_text())["chosen"]["posterior"]
    assert d["params"]["omega_w"]["median"] == pytest.approx(
        float(np.median(back.draws("omega_w"))))

    # a posterior that cannot be written (a full disk) fails the command at the end: the
    # diagnosis is still printed and its --json written (both were lost with it); the
    # diagnosis is the one above, and the chain a stub
    class Unwritable:
        def to_netcdf(self, path):
            raise OSError(errno.ENOSPC, "No space left on device", str(path))

    (done,) = made
    monkeypatch.setattr(dg, "diagnose", lambda *a, **k: done)
    monkeypatch.setattr(dg, "sample_chosen", lambda *a, **k: Unwritable())
    out2 = tmp_path / "d2.json"
    code, stdout, err = _run(capsys, "diagnose", stem, "--bootstrap", "0", "--posterior",
                             tmp_path / "full.nc", "--json", out2)
    assert code == 1
    assert "decision: motion-washout" in stdout
    assert err.splitlines()[-1] == (f"bayespilot: error: {tmp_path / 'full.nc'}: cannot write "
                                    f"the posterior (No space left on device); the diagnosis "
                                    f"above was printed and its other files written")
    assert json.loads(out2.read_text())["physics"] == "motion-washout"
    assert not (tmp_path / "full.nc").exists()

    # --json inside the --report folder (allowed: the same content), the report failing
    # part-way (its second figure): the --json the command wrote is kept, not removed with
    # the incomplete report's files
    from test_disk_full import _fail_at

    _fail_at(monkeypatch, 2)
    rep = tmp_path / "rep"
    code, stdout, err = _run(capsys, "diagnose", stem, "--bootstrap", "0", "--json",
                             rep / "diagnosis.json", "--report", rep)
    assert code == 1 and "the report in" in err and "is incomplete" in err
    assert json.loads((rep / "diagnosis.json").read_text())["physics"] == "motion-washout"
    assert not (rep / "report.html").exists()


def test_diagnose_bayes_factor_option(rec_stem, tmp_path, capsys, monkeypatch):
    """--bayes-factor weighs the decision's candidate (nested sampling stubbed: its numbers
    are tests/test_diagnose.py's) and puts ln BF in the summary and JSON; with two
    recordings it is a usage error, and what cannot be weighed is a warning."""
    import bayespilot.diagnose as dg

    code, _, err = _run(capsys, "diagnose", rec_stem, rec_stem, "--bayes-factor")
    assert code == 2 and "--bayes-factor: takes one recording" in err

    class Stub:
        physics = "threshold-shape"
        elapsed = 12.5  # (the nested sampling's seconds, which the summary's time line adds)

        def summary_line(self):
            return "Bayes factor (threshold-shape : base, nested sampling): ln BF = -1.50"

        def to_dict(self):
            return {"physics": self.physics, "log_bayes_factor": -1.5}

    seen = {}

    def stub(res, rec, **kw):
        seen.update(kw, physics=res.physics, n=rec.n_samples)
        res.bayes_factor = Stub()
        return res.bayes_factor

    monkeypatch.setattr(dg, "bayes_factor", stub)
    out = tmp_path / "d.json"
    code, stdout, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "0", "--seed", "4",
                             "--bayes-factor", "--json", out)
    assert code == 0, err
    assert seen["seed"] == 4 and seen["physics"] == "none" and seen["n"] == 3000
    assert stdout.count("ln BF = -1.50") == 2  # said when computed, and in the summary
    assert "(and 12.5 s for the Bayes factor's nested sampling)" in stdout
    assert json.loads(out.read_text())["bayes_factor"]["log_bayes_factor"] == -1.5

    def refuse(res, rec, **kw):
        raise ValueError("no candidate of this diagnosis has a GLS fit to weigh")

    monkeypatch.setattr(dg, "bayes_factor", refuse)
    code, stdout, err = _run(capsys, "diagnose", rec_stem, "--bootstrap", "0", "--bayes-factor")
    assert code == 0 and "warning: no Bayes factor: no candidate" in err


def test_report_bolds_the_justified_row(tmp_path):
    """report.html writes a justified candidate's row as <tr style="font-weight:bold"> (valid
    CSS; it was escaped to style=&quot;...&quot;, which no browser reads as a style)."""
    from bayespilot import presets
    from bayespilot.diagnose import diagnose, get_extension
    from bayespilot.model import paper_model

    model = get_extension("motion-washout").build(paper_model())
    p = dict(presets.paper_parameters("FD"), omega_w=0.8)
    rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=22,
                   duration=40.96).recording
    res = diagnose(rec, seed=0, n_bootstrap=0, candidates=["motion-washout"])
    assert res.physics == "motion-washout"
    assert [c.physics for c in res.ranking if c.justified] == ["motion-washout"]
    html = (res.report(tmp_path)["html"]).read_text(encoding="utf-8")
    assert '<tr style="font-weight:bold"><td>motion-washout</td>' in html
    assert html.count('style="font-weight:bold"') == 1 and "&quot;" not in html
