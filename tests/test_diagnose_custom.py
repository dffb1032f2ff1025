"""Catalogue entries of one's own: ``register_extension`` and its use everywhere a name is.

One entry throughout, a first-order lag on the visual channel (not in the
built-in catalogue), on short simulated records that have one, tested with
few candidates and no bootstrap, as the other diagnose tests keep their cost
down.  The registry is emptied around every test.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings

import cloudpickle
import pytest

from bayespilot.diagnose import (NAMES, DiagnosisResult, Extension, candidate_names, diagnose,
                                 diagnose_pooled, get_extension, register_extension,
                                 registered_extensions, unregister_extension)
from bayespilot.model import FirstOrderLag, Parameter, paper_model
from bayespilot.presets import paper_parameters
from bayespilot.simulate import simulate


def _lag(model):
    return model.add_stage("visual", FirstOrderLag("T_vis"),
                           [Parameter("T_vis", 1e-3, 0.5, 0.05, "s", "visual lag")])


LAG = Extension("visual-lag", "A first-order lag on the visual channel.",
                "The visual describing function loses phase at high frequencies.",
                ("frequency.visual",), _lag, ("T_vis",), ({"T_vis": 0.05}, {"T_vis": 0.15}),
                boundary_null=True)


@pytest.fixture(autouse=True)
def empty_registry():
    """No entry of one's own before or after a test (the registry is process-wide)."""
    for e in registered_extensions():
        unregister_extension(e.name)
    yield
    for e in registered_extensions():
        unregister_extension(e.name)


def _lagged(seed: int, duration: float):
    """A run of task FD whose pilot has a 0.15-s visual lag (a low remnant: the paper's
    visual lead, K_v (1 + T_vl s), absorbs much of a lag)."""
    truth = dict(paper_parameters("FD"), T_vis=0.15)
    return simulate(_lag(paper_model()), truth, task="FD", remnant_gain=0.03, seed=seed,
                    duration=duration).recording


@pytest.fixture(scope="module")
def lagged():
    return _lagged(2, 30.0)


def test_register_list_replace_and_remove():
    assert registered_extensions() == () and candidate_names() == NAMES
    got = register_extension(dataclasses.replace(LAG, new_parameters=["T_vis"]))
    assert got.new_parameters == ("T_vis",) and got == LAG  # lists stored as tuples
    assert get_extension("visual-lag") is got and registered_extensions() == (got,)
    assert candidate_names() == NAMES + ("visual-lag",)
    # the same name again replaces it, in its place
    other = register_extension(dataclasses.replace(LAG, physics="A display lag."))
    assert get_extension("visual-lag") is other and registered_extensions() == (other,)
    assert unregister_extension("visual-lag") is other
    assert candidate_names() == NAMES
    with pytest.raises(ValueError, match="unknown extension 'visual-lag'.*register_extension"):
        get_extension("visual-lag")
    with pytest.raises(ValueError, match="no registered extension 'visual-lag'"):
        unregister_extension("visual-lag")
    with pytest.raises(ValueError, match="built-in catalogue entry, which cannot be removed"):
        unregister_extension("motion-washout")


@pytest.mark.parametrize("change,match", [
    (dict(name="motion-washout"), "name of a built-in catalogue entry"),
    (dict(name="none"), "'none' is the decision's word"),
    (dict(name=" visual-lag"), "non-empty str without surrounding spaces"),
    (dict(build=42), "build must be a function"),
    (dict(build=lambda m: m.add_stage("visul", FirstOrderLag("T_vis"), [])),
     r"build\(paper_model\(\)\) raised"),
    (dict(build=lambda m: "a model"), "returned a str, not a PilotModel"),
    (dict(build=lambda m: _lag(m).fix(tau_v=0.2)), "leaves the base model's tau_v fixed"),
    (dict(new_parameters=("T_lag",)), r"adds the free parameters \['T_vis'\].*\['T_lag'\]"),
    (dict(new_parameters=()), "new_parameters is empty"),
    (dict(new_parameters="T_vis"), "got the string 'T_vis'"),
    (dict(likelihood="censored"), "wired to that entry"),
    (dict(likelihood="ols"), "likelihood must be one of 'gls', 'censored'"),
    (dict(signature_keys=("frequency.visual_high",)), "not keys of the located evidence"),
    (dict(starts=({"K_v": 1.0},)), r"\['K_v'\], which are not among its new_parameters"),
    (dict(starts=({"T_vis": 2.0},)), r"within T_vis's bounds \[0.001, 0.5\]"),
    (dict(boundary_null="yes"), "boundary_null must be True or False"),
])
def test_register_refuses_a_bad_entry_saying_why(change, match):
    with pytest.raises(ValueError, match=match):
        register_extension(dataclasses.replace(LAG, **change))
    assert registered_extensions() == ()
    with pytest.raises(TypeError, match="an Extension"):
        register_extension("visual-lag")


def test_an_entry_built_by_a_local_function_or_lambda_pickles():
    """What diagnose_batch sends its workers: dask pickles with cloudpickle."""
    def local(model):
        return _lag(model)

    for build in (local, lambda m: _lag(m)):
        back = cloudpickle.loads(cloudpickle.dumps(dataclasses.replace(LAG, build=build)))
        assert register_extension(back).build(paper_model()).parameter_names[-1] == "T_vis"


def test_candidates_take_names_and_entries(lagged):
    from bayespilot.diagnose import _check

    assert _check(lagged, 0.01, 0, 5.0, None) == NAMES  # the default, as it always was
    with pytest.raises(ValueError, match="got the Extension 'visual-lag' alone"):
        _check(lagged, 0.01, 0, 5.0, LAG)
    with pytest.raises(ValueError, match="name of a built-in"):
        _check(lagged, 0.01, 0, 5.0, [dataclasses.replace(LAG, name="motion-washout")])
    # a built-in entry itself stands for its name and registers nothing
    assert _check(lagged, 0.01, 0, 5.0, [get_extension("motion-washout")]) == ("motion-washout",)
    assert registered_extensions() == ()
    assert _check(lagged, 0.01, 0, 5.0, [LAG, "motion-washout"]) == ("visual-lag",
                                                                      "motion-washout")
    assert registered_extensions() == (LAG,)
    assert _check(lagged, 0.01, 0, 5.0, None) == NAMES + ("visual-lag",)
    with pytest.raises(ValueError, match="names an entry twice"):
        _check(lagged, 0.01, 0, 5.0, [LAG, "visual-lag"])


def test_diagnose_tests_reports_and_round_trips_an_entry(lagged, tmp_path):
    import matplotlib.pyplot as plt

    from bayespilot.diagnose.report import plot_candidates

    res = diagnose(lagged, seed=0, n_bootstrap=0, candidates=[LAG, "motion-washout"])
    assert get_extension("visual-lag") == LAG  # registered by the call
    assert res.settings["candidates"] == ["visual-lag", "motion-washout"]
    lag = next(c for c in res.ranking if c.physics == "visual-lag")
    assert lag.testable and "boundary null" in lag.reason and set(lag.params) == {"T_vis"}
    assert res.physics == "visual-lag" and lag.p_value < 1e-4
    assert lag.params["T_vis"] == pytest.approx(0.15, abs=0.05)
    assert lag.interval["T_vis"].lower < 0.15 < lag.interval["T_vis"].upper
    paths = res.report(tmp_path / "report")
    assert {"candidates", "profile", "html", "json"} <= set(paths)
    assert "visual-lag" in paths["html"].read_text()
    # read back where the entry is not registered: the numbers, the summary, the figure
    unregister_extension("visual-lag")
    back = DiagnosisResult.from_json(paths["json"])
    assert back.physics == "visual-lag" and back.chosen.params == pytest.approx(lag.params)
    assert "visual-lag" in back.summary()
    assert json.loads(back.to_json()) == json.loads(res.to_json())
    fig = plot_candidates(back)
    assert "visual-lag" in [t.get_text() for t in fig.axes[0].get_yticklabels()]
    plt.close(fig)


def test_diagnose_pooled_takes_an_entry(tmp_path):
    from bayespilot.diagnose import PooledDiagnosisResult

    runs = [_lagged(s, 20.0) for s in (2, 3)]
    res = diagnose_pooled(runs, seed=0, n_bootstrap=0, candidates=[LAG])
    assert res.settings["candidates"] == ["visual-lag"]
    (lag,) = res.ranking
    assert lag.physics == "visual-lag" and lag.testable and lag.df == 1
    assert math.isfinite(lag.p_value) and set(lag.params) == {"T_vis"}
    # its result file, read where the entry is not registered: loaded, and its report written
    res.to_json(tmp_path / "pooled.json")
    unregister_extension("visual-lag")
    back = PooledDiagnosisResult.from_json(tmp_path / "pooled.json")
    assert back.ranking[0].physics == "visual-lag" and "visual-lag" in back.summary()
    assert "visual-lag" in back.report(tmp_path / "report")["html"].read_text()


def test_plot_batch_draws_an_entry_of_ones_own():
    import matplotlib.pyplot as plt

    from bayespilot.diagnose.report import plot_batch

    level = {"level_per_candidate": 0.005}
    d1 = {"physics": "visual-lag", "settings": level,
          "ranking": [{"physics": "visual-lag", "p_value": 1e-5, "testable": True},
                      {"physics": "motion-washout", "p_value": 0.3, "testable": True}]}
    d2 = {"physics": "none", "settings": level,
          "ranking": [{"physics": "motion-washout", "p_value": 0.01, "testable": True}]}
    fig = plot_batch([("a", d1), ("b", d2)])  # not registered here: from the results alone
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels == list(NAMES) + ["visual-lag"]
    z = ax.images[0].get_array()
    assert z[0, len(NAMES)] == pytest.approx(5.0) and z.mask[1, len(NAMES)]
    assert len(ax.patches) == 1  # the chosen entry's box
    plt.close(fig)
    fig = plot_batch([("b", d2)])  # only built-in entries: the columns as always
    assert [t.get_text() for t in fig.axes[0].get_xticklabels()] == list(NAMES)
    plt.close(fig)


def test_batch_sends_the_entry_to_its_workers(lagged, tmp_path):
    """The worker (another process, on a one-worker LocalCluster) has only what the batch
    sends it: an entry built by a local function, registered here."""
    from bayespilot.diagnose.batch import diagnose_batch
    from bayespilot.io import write_recording

    stem = tmp_path / "recs" / "lag-run1"
    stem.parent.mkdir()
    write_recording(lagged, stem)

    def build(model):
        return model.add_stage("visual", FirstOrderLag("T_vis"),
                               [Parameter("T_vis", 1e-3, 0.5, 0.05, "s", "visual lag")])

    entry = dataclasses.replace(LAG, build=build)
    out = tmp_path / "out"
    with warnings.catch_warnings():  # (a short record's warnings: not what is tested)
        warnings.simplefilter("ignore")
        s = diagnose_batch([stem], out, seed=0, n_bootstrap=0, candidates=[entry],
                           workers=1, progress=False, warm_cache=False)
    assert (s.completed, s.failed) == (1, 0), s.errors
    got = json.loads((out / "lag-run1.json").read_text())
    assert got["settings"]["candidates"] == ["visual-lag"]
    (lag,) = got["diagnosis"]["ranking"]
    assert lag["physics"] == "visual-lag" and lag["testable"] and lag["p_value"] < 1e-4
    assert got["diagnosis"]["physics"] == "visual-lag" and (out / "summary.png").is_file()
    # again by its name, registered here by the first call: done, not redone
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = diagnose_batch([stem], out, seed=0, n_bootstrap=0, candidates=["visual-lag"],
                           workers=1, progress=False, warm_cache=False)
    assert (s.completed, s.skipped) == (0, 1)


# --- from the command line: --extension FILE.py:NAME ------------------------------------------
ENTRY_FILE = '''
from bayespilot.diagnose import Extension
from bayespilot.model import FirstOrderLag, Parameter


def lag(model):
    return model.add_stage("visual", FirstOrderLag("T_vis"),
                           [Parameter("T_vis", 1e-3, 0.5, 0.05, "s", "visual lag")])


LAG = Extension("visual-lag", "A first-order lag on the visual channel.",
                "The visual describing function loses phase at high frequencies.",
                ("frequency.visual",), lag, ("T_vis",), ({"T_vis": 0.05}, {"T_vis": 0.15}),
                boundary_null=True)
NOT_AN_ENTRY = 3
WRONG = Extension("visual-lag", "", "", ("frequency.visual",), lag, ("T_other",))
'''


@pytest.fixture
def entry_file(tmp_path):
    path = tmp_path / "mylab_entries.py"
    path.write_text(ENTRY_FILE, encoding="utf-8")
    return path


@pytest.mark.parametrize("spec, match", [
    ("{f}", "give FILE.py:NAME or package.module:NAME"),
    ("{d}/nowhere.py:LAG", "no file .*nowhere.py"),
    ("{f}:MISSING", "defines no 'MISSING'"),
    ("{f}:NOT_AN_ENTRY", "NOT_AN_ENTRY is int, not an Extension"),
    ("{f}:WRONG", "T_other"),
    ("no_such_module_xyz:LAG", "no_such_module_xyz failed to load \\(ModuleNotFoundError"),
])
def test_cli_extension_refuses_what_it_cannot_use_before_reading(entry_file, tmp_path, capsys,
                                                                  spec, match):
    """Said in one line with exit code 2, before the recording is read (it does not exist
    here) and before any computation."""
    import re

    from bayespilot.cli import main

    arg = spec.format(f=entry_file, d=tmp_path)
    assert main(["diagnose", str(tmp_path / "absent"), "--extension", arg]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"bayespilot: error: argument --extension: {arg}: ") and "\n" not in err
    assert re.search(match, err), err
    assert registered_extensions() == () or match == "T_other"


def test_cli_diagnose_tests_an_entry_from_a_file(lagged, entry_file, tmp_path, capsys):
    """The entry is tested after the six built-in ones and named, as from Python."""
    from bayespilot.cli import main
    from bayespilot.io import write_recording

    stem = tmp_path / "lag-run1"
    write_recording(lagged, stem)
    out = tmp_path / "d.json"
    assert main(["diagnose", str(stem), "--extension", f"{entry_file}:LAG", "--bootstrap", "0",
                 "--json", str(out)]) == 0
    got = json.loads(out.read_text())
    assert got["physics"] == "visual-lag"
    assert [r["physics"] for r in got["ranking"]][0] == "visual-lag"
    assert sorted(r["physics"] for r in got["ranking"]) == sorted(NAMES + ("visual-lag",))
    assert got["chosen"]["params"]["T_vis"] == pytest.approx(0.15, abs=0.08)
    assert "7 catalogue extensions" in capsys.readouterr().out


def test_cli_batch_sends_an_entry_from_a_file_to_its_workers(lagged, entry_file, tmp_path):
    """The worker has never seen the file: its build function travels by value (the file is
    loaded as a module outside sys.modules)."""
    from bayespilot.cli import main
    from bayespilot.io import write_recording

    recs = tmp_path / "recs"
    recs.mkdir()
    write_recording(lagged, recs / "lag-run1")
    out = tmp_path / "out"
    assert main(["diagnose-batch", str(recs), "--out", str(out), "--extension",
                 f"{entry_file}:LAG", "--bootstrap", "0", "--workers", "1", "-q"]) == 0
    got = json.loads((out / "lag-run1.json").read_text())
    assert got["diagnosis"]["physics"] == "visual-lag"
    assert "visual-lag" in got["settings"]["candidates"]
