"""A lab porting its own task to ``diagnose`` (port audit, findings 3, 7, 8 and 12).

Pooling compares the task each run describes (plant, rate, control gain, forcing), a
sidecar's forcing is checked against the f_t/f_d columns and for shared lines, the report
carries the evidence notes, and a forcing on one side of OMEGA_SPLIT says which motion
evidence is missing.  Every recording is simulated small (20 s at 50 or 100 Hz) with the
public API.
"""

from __future__ import annotations

import html
import json
import warnings

import numpy as np
import pytest

from bayespilot.diagnose import diagnose, diagnose_pooled
from bayespilot.diagnose import locate as L
from bayespilot.diagnose import pooled as P
from bayespilot.diagnose.batch import diagnose_batch, plan_batch
from bayespilot.recording import _signals_digest
from bayespilot.forcing import Multisine
from bayespilot.io import write_recording
from bayespilot.model import paper_model
from bayespilot.recording import Recording
from bayespilot.simulate import TrackingTask, simulate

#: The pilot the lab's runs are simulated with (the port audit's mk.TRUTH).
TRUTH = dict(K_v=0.6, T_vl=0.5, tau_v=0.22, K_m=0.35, tau_m=0.18, omega_nm=10.0,
             zeta_nm=0.3, delta_abs=0.006)
T = 20.0
W0 = 2 * np.pi / T
DINT = ([2.0], [1.0, 0.0, 0.0])  # 2/s^2
S2 = ([8.0], [1.0, 2.0, 0.0])  # 8/(s(s+2))


def _forcing(nt=(1, 3, 7, 13, 22), nd=(2, 5, 10, 17, 25), target=1.0, phase=0.0):
    """The lab's forcing: 5 target and 5 disturbance lines of the 20-s record (or the first
    amplitudes and phases for fewer), the target's amplitudes times ``target`` and its phases
    moved by ``phase``."""
    ft = Multisine(W0, list(nt), [target * a for a in (0.04, 0.03, 0.015, 0.006, 0.003)][:len(nt)],
                   [phase + p for p in (0.1, 1.2, 2.3, 3.4, 4.5)][:len(nt)])
    fd = Multisine(W0, list(nd), [0.003, 0.006, 0.012, 0.02, 0.03][:len(nd)],
                   [0.5, 1.5, 2.5, 3.5, 4.5][:len(nd)])
    return ft, fd


def _run(plant=DINT, rate=50.0, gain=1.0, seed=5, subject="S1", **forcing):
    """One 20-s run of the lab's task (task "other", K_theta 0.5), its subject in the sidecar."""
    ft, fd = _forcing(**forcing)
    task = TrackingTask(ft, fd, motion_gain=0.5, controlled_element=plant, control_gain=gain,
                        sample_rate_hz=rate, duration=T, run_in=T / 2)
    rec = simulate(params=TRUTH, task=task, remnant_fraction=0.15, seed=seed).recording
    return Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task,
                     {**rec.metadata, "subject": subject}, rec.source)


@pytest.fixture(scope="module")
def runs():
    """Two runs of one task, and one each with another plant, rate, control gain, target
    amplitude, target phases."""
    return {"a": _run(seed=5), "b": _run(seed=6), "plant": _run(plant=S2, seed=7),
            "rate": _run(rate=100.0, seed=8), "gain": _run(gain=0.5, seed=9),
            "amp": _run(target=0.5, seed=10), "phase": _run(phase=1.0, seed=11)}


# --- finding 3: pooling compares the task ---------------------------------------------------
def test_pooling_disagreements_compares_the_task_as_read(runs):
    """Runs of another plant, rate, control gain or forcing are said, as subject/K_theta are;
    runs of one task (another remnant seed, or another realisation of the phases) are not."""
    dis = P.pooling_disagreements
    assert dis([runs["a"], runs["b"]]) is None
    assert dis([runs["a"], runs["phase"]]) is None  # phases are not compared
    assert dis([runs["a"], runs["plant"]]) == "controlled_element 2/s^2, 8/(s^2 + 2 s)"
    assert dis([runs["rate"], runs["a"]]) == "sample_rate_hz 50, 100"
    assert dis([runs["a"], runs["gain"]]) == "control_gain 0.5, 1"
    # the target's rms, sqrt(sum a^2 / 2), at full and at half amplitude
    a = np.array([0.04, 0.03, 0.015, 0.006, 0.003])
    full, half = np.sqrt(np.sum(a ** 2) / 2), np.sqrt(np.sum((a / 2) ** 2) / 2)
    dist = f"disturbance 5 lines {2 * W0:.3g}-{25 * W0:.3g} rad/s rms " \
           f"{np.sqrt(np.sum(np.array([0.003, 0.006, 0.012, 0.02, 0.03]) ** 2) / 2):.3g}"
    target = f"target 5 lines {W0:.3g}-{22 * W0:.3g} rad/s rms "
    assert dis([runs["a"], runs["amp"]], names=["a.csv", "amp.csv"]) == (
        f"forcing {target}{half:.3g} + {dist} (amp.csv), {target}{full:.3g} + {dist} (a.csv)")
    # named runs: each value with the runs that give it
    assert dis([runs["a"], runs["plant"], runs["rate"]], names=["a", "p", "r"]) == (
        "sample_rate_hz 50 (a, p), 100 (r); controlled_element 2/s^2 (a, r), "
        "8/(s^2 + 2 s) (p)")


def test_pooling_disagreements_reads_defaults_and_normalises_the_plant(runs):
    """A control_gain or plant left out is the format's default, as the diagnosis reads it
    (0.69 and 4/s^2), and 8/(2 s^2) is the plant 4/s^2."""
    a = runs["a"]
    meta = {k: v for k, v in a.metadata.items()
            if k not in ("control_gain", "controlled_element", "controlled_element_gain")}

    def relabel(**extra):
        return Recording(a.signals, a.sample_rate_hz, a.motion_gain, a.task, {**meta, **extra})

    given = relabel(control_gain=0.69, controlled_element={"num": [8.0], "den": [2.0, 0.0, 0.0]})
    assert P.pooling_disagreements([relabel(), given]) is None
    assert P.pooling_disagreements([relabel(), relabel(controlled_element_gain=2.0)]) == \
        "controlled_element 2/s^2, 4/s^2"


def test_pooling_disagreements_skips_columns_cut_mid_period(runs):
    """A run whose forcing is read from f_t/f_d columns that are not whole periods (their DFT
    smears each forcing over many lines) is not compared on its forcing; columns of whole
    periods are, as the sidecar's forcing (alike, or at half the target's amplitude not)."""
    a = runs["a"]
    meta = {k: v for k, v in a.metadata.items() if k != "forcing"}
    cut = Recording({k: v[:733] for k, v in a.signals.items()}, 50.0, 0.5, "other", meta)
    assert not L.forcing_of(cut).periodic
    assert P.pooling_disagreements([a, cut]) is None
    cols = Recording(a.signals, 50.0, 0.5, "other", meta)  # whole periods: compared, alike
    assert L.forcing_of(cols).periodic and P.pooling_disagreements([a, cols]) is None
    half = Recording(dict(a.signals, f_t=0.5 * a["f_t"]), 50.0, 0.5, "other", meta)
    assert P.pooling_disagreements([a, half]).startswith("forcing target 5 lines")


def test_diagnose_pooled_warns_for_another_plant(runs, monkeypatch):
    """diagnose_pooled pools runs of two plants with a PoolingWarning (as for subjects), and
    runs of one task without one."""
    class Stop(Exception):
        pass

    def stop(rec, **kw):
        raise Stop

    monkeypatch.setattr(P, "_prepare", stop)
    with pytest.warns(P.PoolingWarning, match=r"\(controlled_element 2/s\^2, 8/\(s\^2 \+ 2 s\)\)"):
        with pytest.raises(Stop):
            diagnose_pooled([runs["a"], runs["plant"]])
    with warnings.catch_warnings():
        warnings.simplefilter("error", P.PoolingWarning)
        with pytest.raises(Stop):
            diagnose_pooled([runs["a"], runs["b"]])


def test_batch_refuses_a_pooled_group_of_two_tasks(runs, tmp_path):
    """diagnose-batch --pool groups by subject, task and K_theta as before (the key of a
    group of one task is unchanged), and refuses a group whose runs are of two plants or
    rates, naming the runs and what differs, before any work (nothing written)."""
    paths = ["x/a.csv", "x/b.csv"]
    tasks = plan_batch(paths, [runs["a"], runs["b"]], pool=True)
    # (a pooled condition's runs in the order of their content, not of their names)
    by_content = tuple(p for _, p in sorted(zip([_signals_digest(runs["a"]),
                                                 _signals_digest(runs["b"])], paths)))
    assert [(t.key, t.paths) for t in tasks] == [("S1_other_k0.5", by_content)]
    with pytest.raises(ValueError) as err:
        plan_batch(["x/a.csv", "x/p.csv", "x/r.csv"], [runs["a"], runs["plant"], runs["rate"]],
                   pool=True)
    assert ("in 1 group(s) the runs differ in the task the diagnosis reads: S1/other/K_theta "
            "0.5 (3 runs): sample_rate_hz 50 (x/a.csv, x/p.csv), 100 (x/r.csv); "
            "controlled_element 2/s^2 (x/a.csv, x/r.csv), 8/(s^2 + 2 s) (x/p.csv)"
            ) in str(err.value)
    # another subject is another group: no refusal, one task per run
    other = Recording(runs["plant"].signals, 50.0, 0.5, "other",
                      {**runs["plant"].metadata, "subject": "S2"})
    assert [t.key for t in plan_batch(["x/a.csv", "x/p.csv"], [runs["a"], other],
                                      pool=True)] == ["S1_other_k0.5", "S2_other_k0.5"]
    # through diagnose_batch: refused before the cluster starts or the folder is made
    for name in ("a", "plant"):
        write_recording(runs[name], tmp_path / name)
    out = tmp_path / "out"
    with pytest.raises(ValueError, match=r"controlled_element 2/s\^2 \(.*a\.csv\)"):
        diagnose_batch([tmp_path / "a.csv", tmp_path / "plant.csv"], out, pool=True,
                       n_bootstrap=0, workers=1, progress=False, warm_cache=False)
    assert not out.exists()


def test_batch_keeps_the_paper_task_keys():
    """Two runs of the paper's FD task (the sidecar of simulate) pool under the key they had."""
    recs = [simulate(task="FD", motion_gain=1.0, seed=s, duration=10.0).recording for s in (1, 2)]
    recs = [Recording(r.signals, r.sample_rate_hz, r.motion_gain, r.task,
                      {**r.metadata, "subject": "p1"}) for r in recs]
    assert P.pooling_disagreements(recs) is None
    assert [t.key for t in plan_batch(["r1.csv", "r2.csv"], recs, pool=True)] == ["p1_FD_k1"]


# --- finding 7: the sidecar's forcing against the columns, and shared lines -----------------
def _with_forcing(rec: Recording, ft: Multisine, fd: Multisine) -> Recording:
    meta = dict(rec.metadata, forcing={"base_frequency": ft.base_frequency,
                                       "target": {"n": ft.n.tolist(),
                                                  "amplitude": ft.amplitude.tolist(),
                                                  "phase": ft.phase.tolist()},
                                       "disturbance": {"n": fd.n.tolist(),
                                                       "amplitude": fd.amplitude.tolist(),
                                                       "phase": fd.phase.tolist()}})
    return Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta,
                     rec.source)


def test_sidecar_forcing_checked_against_the_columns(runs):
    """A sidecar whose target has c times the f_t column's amplitudes differs from it by
    1 - c of its RMS: 50 % and 10 % are noted, naming the target and the size; 2 % is
    within FORCING_MISMATCH (5 %), and the package's own simulated recordings (TrackingTask
    and the paper's FD at 100 Hz) are not noted."""
    a = runs["a"]
    side = a.metadata["forcing"]
    ft = Multisine.from_dict(side["base_frequency"], side["target"])
    fd = Multisine.from_dict(side["base_frequency"], side["disturbance"])
    assert L.forcing_of(a).notes == ()
    for c, said in ((0.5, "50 %"), (0.9, "10 %")):
        scaled = Multisine(ft.base_frequency, ft.n, c * ft.amplitude, ft.phase)
        notes = L.forcing_of(_with_forcing(a, scaled, fd)).notes
        assert len(notes) == 1
        assert (f"the target differs from the f_t column by {said} RMS (its RMS {c:g} times "
                f"the column's)") in notes[0] and "disturbance" not in notes[0].split(":")[1]
    near = Multisine(ft.base_frequency, ft.n, 0.98 * ft.amplitude, ft.phase)
    assert L.forcing_of(_with_forcing(a, near, fd)).notes == ()
    # phases wrong by 1 rad on every disturbance line: |1 - e^{i}| = 2 sin(1/2) = 95.9 %
    moved = Multisine(fd.base_frequency, fd.n, fd.amplitude, fd.phase + 1.0)
    notes = L.forcing_of(_with_forcing(a, ft, moved)).notes
    assert len(notes) == 1 and (f"the disturbance differs from the f_d column by "
                                f"{100 * 2 * np.sin(0.5):.3g} % RMS") in notes[0]
    paper = simulate(task="FD", motion_gain=1.0, seed=3).recording
    assert "forcing" in paper.metadata and "f_t" in paper
    assert L.forcing_of(paper).notes == ()


def test_sidecar_forcing_with_shared_lines_gives_no_bins(runs):
    """Target and disturbance sharing lines n = 2 and 10 in the sidecar: refused as the
    columns' path refuses shared lines (no bins, no frequency evidence, a note naming 2
    lines); a shared line of zero amplitude is not in the signal and does not count."""
    shared = _run(nt=(2, 3, 7, 10, 22), seed=12)  # (its sidecar and columns agree)
    ft, fd = _forcing(nt=(2, 3, 7, 10, 22))
    f = L.forcing_of(shared)
    assert not f.periodic and f.k_target is None
    assert len(f.notes) == 1 and "share 2 DFT line(s)" in f.notes[0]
    assert f"{2 * W0:.4g}, {10 * W0:.4g} rad/s" in f.notes[0]
    values = L.statistics(shared, paper_model(), TRUTH, f)["values"]
    assert all(np.isnan(values[k]) for k in L.EVIDENCE if k.startswith("frequency."))
    # the columns' path refuses the same signals' lines
    cols = Recording(shared.signals, 50.0, 0.5, "other",
                     {k: v for k, v in shared.metadata.items() if k != "forcing"})
    assert not L.forcing_of(cols).periodic and "share 2 DFT line(s)" in L.forcing_of(cols).notes[0]
    # a shared line listed with zero amplitude is not in the signal: not shared
    ft0 = Multisine(W0, ft.n, np.where(np.isin(ft.n, (2, 10)), 0.0, ft.amplitude), ft.phase)
    task = TrackingTask(ft0, fd, motion_gain=0.5, controlled_element=DINT, control_gain=1.0,
                        sample_rate_hz=50.0, duration=T, run_in=T / 2)
    silent = simulate(params=TRUTH, task=task, remnant_fraction=0.15, seed=12).recording
    f = L.forcing_of(silent)
    assert f.periodic and f.notes == ()


# --- finding 12: a forcing on one side of OMEGA_SPLIT ------------------------------------------
@pytest.mark.parametrize("nt, nd, gone, kept", [
    ((7, 9, 13, 17, 22), (8, 10, 15, 19, 25), "motion_low", "motion_high"),  # 2.2-7.9 rad/s
    ((1, 3, 5), (2, 4, 6), "motion_high", "motion_low"),  # 0.31-1.9 rad/s
])
def test_forcing_on_one_side_of_the_motion_split_is_noted(nt, nd, gone, kept):
    """Every line above (below) 2 rad/s: frequency.motion_low (motion_high) is missing and a
    note says which and why; the other is computed over every line, without a numpy warning
    for the empty side."""
    rec = _run(nt=nt, nd=nd, seed=13)
    w = np.array(nt + nd) * W0
    assert np.all(w >= L.OMEGA_SPLIT) if gone == "motion_low" else np.all(w < L.OMEGA_SPLIT)
    f = L.forcing_of(rec)
    assert f.two_input and len(f.notes) == 1
    assert f.notes[0].startswith(f"frequency.{gone} is missing: every forcing line is ")
    assert f"({w.min():.3g} to {w.max():.3g} rad/s)" in f.notes[0]
    assert f"frequency.{kept} covers the motion channel at every line" in f.notes[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        values = L.statistics(rec, paper_model(), TRUTH, f)["values"]
    assert np.isnan(values[f"frequency.{gone}"]) and np.isfinite(values[f"frequency.{kept}"])
    # a forcing on both sides: no note
    assert L.forcing_of(_run(seed=13)).notes == ()


# --- finding 8: the report carries the evidence notes -------------------------------------------
def test_report_shows_the_evidence_notes(tmp_path):
    """A disturbance-only run: the note that the target is zero (and which evidence that
    removes) is in report.html, as it is in the JSON's settings.evidence_notes."""
    rec = _run(target=0.0, seed=14)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", L.EvidenceWarning)
        res = diagnose(rec, n_bootstrap=0, n_calibrate=0, candidates=["motion-washout"],
                       seed=0)
    notes = res.settings["evidence_notes"]
    zero = [n for n in notes if "(disturbance only)" in n]
    assert len(zero) == 1
    paths = res.report(tmp_path / "rep")
    page = paths["html"].read_text(encoding="utf-8")
    stored = json.loads(paths["json"].read_text())["settings"]["evidence_notes"]
    assert stored == notes
    assert "<h2>Notes on the evidence</h2>" in page
    for n in notes:
        assert f"<li>{html.escape(n)}</li>" in page


def test_pooled_report_shows_each_runs_notes(tmp_path):
    """A pooled diagnosis's report names each run's notes with the run."""
    a, b = _run(target=0.0, seed=15), _run(target=0.0, seed=16)
    a = Recording(a.signals, 50.0, 0.5, "other", a.metadata, "run_a.csv")
    b = Recording(b.signals, 50.0, 0.5, "other", b.metadata, "run_b.csv")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", L.EvidenceWarning)
        res = diagnose_pooled([a, b], n_bootstrap=0, n_calibrate=0,
                              candidates=["motion-washout"], seed=0)
    page = res.report(tmp_path / "rep")["html"].read_text(encoding="utf-8")
    assert "<h2>Notes on the evidence</h2>" in page
    for run in res.runs:
        zero = [n for n in run["evidence_notes"] if "(disturbance only)" in n]
        assert len(zero) == 1
        assert f"<li><b>{run['source']}</b>: {html.escape(zero[0])}</li>" in page
