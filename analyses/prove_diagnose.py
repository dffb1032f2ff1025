"""Prove ``bayespilot diagnose`` on concealed physics (issue 5, item 6).

For every catalogue entry the simulator generates recordings with that
physics at several effect sizes, in both tasks (FD, FT), at K_theta 0.75 and
1 and remnant levels F_n 0.1 and 0.25 (K_n from Table 4), plus controls with
the paper's model and no extra physics.  ``diagnose`` then runs blind on each
recording (it reads the recording only; the truth stays in this script's
result files).  Each case is one JSON in ``analyses/results/diagnose/``, so
the script resumes where it stopped and can run in chunks.

A case is "concealed" when the base model's fit looks ordinary: its VAF and
its residual RMS lie within 3 standard deviations of those of the controls of
the same task and remnant level.

``--pooled R`` runs the same cases as R runs each (new seeds, the same
condition and effect) through ``diagnose_pooled``, which shares the
extension's parameters over the runs; a pooled case is concealed when every
one of its runs is, judged against the pooled controls' runs.

Run (from the repository root):

    nice -n 10 python analyses/prove_diagnose.py --chunk 20     # next 20 cases
    python analyses/prove_diagnose.py --summarize              # table + figures
    python analyses/prove_diagnose.py --profile-noise --shard 0/2   # the same study with
    python analyses/prove_diagnose.py --profile-noise --shard 1/2   # profile_noise=True, 2 cores
    python analyses/prove_diagnose.py --width-profile 177,181,215   # soft-threshold -ln L by width
    python analyses/prove_diagnose.py --pooled 4 --shard 0/2   # four runs per case, pooled
    python analyses/prove_diagnose.py --pooled 4 --shard 1/2   # (diagnose_pooled), 2 cores
    python analyses/prove_diagnose.py --example-pooled         # the docs' pooled walk-through
    python analyses/prove_diagnose.py --posterior-check 8      # s.e. and posterior vs spread
    python analyses/prove_diagnose.py --locate-null           # located p-values on controls
    python analyses/prove_diagnose.py --pooled 8 --shard 0/2   # eight runs per case, pooled
    python analyses/prove_diagnose.py --pooled 16 --misses-of 8 --shard 0/2   # sixteen runs,
                                          # first the cases eight runs got wrong (and 1/2)
    python analyses/prove_diagnose.py --pooled 8 --open-loop --entry threshold-shape \
        --shard 0/2                       # open-loop twins of the soft thresholds (and 1/2)
    python analyses/prove_diagnose.py --compare-runs           # 1, 4 and 8 runs, same cases
    python analyses/prove_diagnose.py --pooled-null 100        # pooled vs one-run null tests
    python analyses/prove_diagnose.py --pooled-null 100 --rebase   # the same, tests against the
                                                                   # base's best fit (as diagnose)
    python analyses/prove_diagnose.py --bayes-factor-check 12 --shard 0/2   # nested-sampling
                                          # Bayes factors on 12 controls, 12 effects (and 1/2)
    python analyses/prove_diagnose.py --bayes-factor-repeat 28,42 --shard 0/2   # 4 more
                                          # seeds each: scatter vs stated error (and 1/2)
    python analyses/prove_diagnose.py --shared-posterior-check 40 --shard 0/2   # pooled
                                          # posterior's intervals vs the truth (and 1/2)
    python analyses/prove_diagnose.py --shared-posterior-check 40 --entry \
        motion-system-dynamics --shard 0/2  # the same for a platform (or time-varying-gains)
    python analyses/prove_diagnose.py --final-fit-check 40 --entry motion-system-dynamics \
        --shard 0/2                       # the reported fit's spread and s.e. against the test's
    python analyses/prove_diagnose.py --pooled-bayes-factor 12 # the pooled Laplace Bayes
                                          # factor on 12 controls, 12 effects of four runs
    python analyses/prove_diagnose.py --platform-band          # the platform's gain by band on
                                          # the controls the Bayes factor weighed it on

The case list is ordered round-robin over the entries and the controls (with
the conditions shuffled by a fixed seed), so any prefix of it is a balanced
subset.  The summary prints the confusion matrix (truth x decision) and, per
entry, the rate of correct naming against the effect size; it writes
``analyses/results/diagnose/summary.json``, ``docs/figures/diagnose_detection.png``
and ``docs/figures/diagnose_confusion.png``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import re
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: The default study's results; ``--profile-noise`` writes beside them.
DEFAULT_OUT = ROOT / "analyses" / "results" / "diagnose"
OUT = DEFAULT_OUT
FIG = ROOT / "docs" / "figures"
#: Appended to the figure names (``--profile-noise`` writes its own).
FIG_SUFFIX = ""
#: diagnose(profile_noise=...) of the study (``--profile-noise`` sets it).
PROFILE_NOISE = False
#: Runs per case of the pooled study (``--pooled R`` sets it; 0: one run, ``diagnose``).
POOLED = 0
#: ``--open-loop``: each pooled run's u replaced by an open-loop twin's (see
#: :func:`pooled_recordings`).
OPEN_LOOP = False
#: --pooled-null: test against the base model's best fit found (decide.null_refit), as diagnose.
REBASE = False
#: Cut-off of the decision likelihood's low-pass, rad/s (``--omega-c`` sets it; None:
#: the package default; inf: the whole band).
OMEGA_C = None
#: The likelihood's vestibular channel oversampling (``--oversample`` sets it; 1: the paper's).
OVERSAMPLE = 1
#: Replicates of the bootstrap calibration of the chosen candidate's test (``--calibrate B``;
#: 0: the asymptotic test alone, as the stored studies without the suffix _cal<B> were run).
N_CALIBRATE = 0
#: Passes of the noise model's estimation (``--noise-passes P``; 1: from the Eq. 4 fit's residual,
#: as the stored studies without the suffix _np<P> were run).
NOISE_PASSES = 1

#: Effect sizes per entry, smallest effect first: (label, parameters).
EFFECTS = {
    # (the platform's damping is 0.7, the value the catalogue entry fixes)
    "motion-system-dynamics": [("omega_ms=16", {"omega_ms": 16.0}),
                               ("omega_ms=10", {"omega_ms": 10.0}),
                               ("omega_ms=6", {"omega_ms": 6.0})],
    "motion-washout": [("omega_w=0.15", {"omega_w": 0.15}), ("omega_w=0.3", {"omega_w": 0.3}),
                       ("omega_w=0.6", {"omega_w": 0.6})],
    "otolith-channel": [("K_ot=0.01", {"K_ot": 0.01, "h_head": 1.0}),
                        ("K_ot=0.02", {"K_ot": 0.02, "h_head": 1.0}),
                        ("K_ot=0.04", {"K_ot": 0.04, "h_head": 1.0})],
    "threshold-shape": [("w_soft=0.004", {"w_soft": 0.004}), ("w_soft=0.01", {"w_soft": 0.01}),
                        ("w_soft=0.02", {"w_soft": 0.02})],
    "time-varying-gains": [("drift=0.3", {"drift_v": 0.3, "drift_m": 0.3}),
                           ("drift=0.6", {"drift_v": 0.6, "drift_m": 0.6}),
                           ("drift=1.0", {"drift_v": 1.0, "drift_m": 1.0})],
    # the limit clips this fraction of the samples of the same run without a limit
    "control-saturation": [("clip=0.3%", {"clip": 0.003}), ("clip=1%", {"clip": 0.01}),
                           ("clip=3%", {"clip": 0.03})],
}
#: Sizes added in a second round (their cases come after the first round's, so the
#: first round keeps its ids and seeds): the threshold shape was not yet found at
#: the widths above, so the curve continues to wider corners; saturation and drift
#: were found at their smallest size, so the curve continues below it.
MORE_EFFECTS = {
    "threshold-shape": [("w_soft=0.03", {"w_soft": 0.03}), ("w_soft=0.045", {"w_soft": 0.045})],
    "time-varying-gains": [("drift=0.15", {"drift_v": 0.15, "drift_m": 0.15})],
    "control-saturation": [("clip=0.1%", {"clip": 0.001})],
}
CONDITIONS = list(itertools.product(("FD", "FT"), (0.75, 1.0), (0.1, 0.25)))
#: Bootstrap replicates per diagnosis here (the decision does not depend on them).
N_BOOTSTRAP = 9
#: Control replicates per condition in each round (8 conditions: 24 + 24 controls).
CONTROL_ROUNDS = (3, 3)


def _strength(entry: str, extra: dict) -> float:
    """A number that grows with the effect (to order an entry's sizes)."""
    if entry == "motion-system-dynamics":
        return 1.0 / extra["omega_ms"]
    if entry == "time-varying-gains":
        return extra["drift_v"]
    return float(next(iter(extra.values())))


#: Every size of an entry, smallest effect first (the detection curves' x axis).
ALL_EFFECTS = {e: sorted(EFFECTS[e] + MORE_EFFECTS.get(e, []),
                         key=lambda s, e=e: _strength(e, s[1])) for e in EFFECTS}


def _round(effects: dict, n_controls: int, seed: int) -> list[dict]:
    """One round of cases, round-robin over entries and controls, conditions shuffled."""
    rng = np.random.default_rng(seed)
    per: dict[str, list[dict]] = {}
    for entry, sizes in effects.items():
        lst = [{"truth": entry, "effect": lab, "extra": ex, "task": t, "K_theta": k, "F_n": f}
               for (lab, ex) in sizes for (t, k, f) in CONDITIONS]
        per[entry] = [lst[i] for i in rng.permutation(len(lst))]
    ctl = [{"truth": "none", "effect": "control", "extra": {}, "task": t, "K_theta": k, "F_n": f}
           for r in range(n_controls) for (t, k, f) in CONDITIONS]
    per["none"] = [ctl[i] for i in rng.permutation(len(ctl))]
    order = []
    for i in range(max(len(v) for v in per.values())):
        for key in ("none", *effects):
            if i < len(per[key]):
                order.append(per[key][i])
    return order


def cases() -> list[dict]:
    """Every case: the first round, then the second (ids and seeds run on), seeded."""
    order = (_round(EFFECTS, CONTROL_ROUNDS[0], 20240605)
             + _round(MORE_EFFECTS, CONTROL_ROUNDS[1], 20261125))
    for j, c in enumerate(order):
        c["id"] = j
        c["seed"] = 1000 + j
    return order


def case_key(c: dict) -> str:
    return (f"{c['id']:04d}_{c['truth']}_{c['effect'].replace('=', '').replace('%', 'pc')}_"
            f"{c['task']}_k{c['K_theta']:g}_fn{c['F_n']:g}")


def simulate_case(c: dict):
    from bayespilot import presets
    from bayespilot.diagnose import get_extension
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    task, k, fn = c["task"], c["K_theta"], c["F_n"]
    kn = presets.TABLE4_K_N[(task, fn)][presets.MOTION_GAINS.index(k)]
    params = presets.paper_parameters(task)
    model = paper_model()
    extra = dict(c["extra"])
    if c["truth"] == "control-saturation":
        free = simulate(model, params, task=task, motion_gain=k, remnant_gain=kn, seed=c["seed"])
        extra = {"u_max": float(np.quantile(np.abs(free.recording.u), 1.0 - extra["clip"]))}
    if c["truth"] != "none":
        model = get_extension(c["truth"]).build(model)
        params.update(extra)
    sim = simulate(model, params, task=task, motion_gain=k, remnant_gain=kn, seed=c["seed"])
    return sim, extra


def pooled_seed(c: dict, j: int) -> int:
    """Seed of run ``j`` of a pooled case (apart from every single-run case's seed)."""
    return 500000 + 10 * c["id"] + j


def pooled_recordings(c: dict, runs: int) -> tuple[list, list, dict]:
    """The ``runs`` blind recordings of a pooled case, their remnant fractions, its extras.

    With ``OPEN_LOOP`` each run is an open-loop twin: its recorded e and theta
    are kept, but u is the true model's noise-free output on them plus the
    remnant of another closed-loop run of the case (seed + OPEN_LOOP_SEED), so
    the remnant no longer feeds back into the pilot's inputs.
    """
    from bayespilot import presets
    from bayespilot.diagnose import get_extension
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot.recording import Recording

    recs, remnant, extra = [], [], {}
    if OPEN_LOOP:
        model = (paper_model() if c["truth"] == "none"
                 else get_extension(c["truth"]).build(paper_model()))
    for j in range(runs):
        sim, extra = simulate_case(dict(c, seed=pooled_seed(c, j)))
        rec = sim.recording
        meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
        u, n = rec.u, sim.remnant
        if OPEN_LOOP:
            truth = dict(presets.paper_parameters(c["task"]), **extra)
            n = simulate_case(dict(c, seed=pooled_seed(c, j) + OPEN_LOOP_SEED))[0].remnant
            u = Likelihood(model, rec).response(truth) + n
        recs.append(Recording(dict(rec.signals, u=u), rec.sample_rate_hz, rec.motion_gain,
                              rec.task, meta, f"run{j + 1}"))
        remnant.append(float(np.var(n) / np.var(u)))
    return recs, remnant, extra


#: Seed offset of the remnant an open-loop twin borrows (``--open-loop``).
OPEN_LOOP_SEED = 777777


def open_loop_table(entry: str) -> None:
    """``entry``'s cases decided by the closed-loop study and by its open-loop twins (same
    runs, same inputs), per effect size, beside the oracle test's expectation."""
    from bayespilot.diagnose import get_extension

    lam = oracle_lambdas()
    twin = {r["case"]["id"]: r for r in load()}
    closed_dir = OUT.with_name(OUT.name.removesuffix("_openloop"))
    closed = {r["case"]["id"]: r for r in load(closed_dir)}
    rows: dict[str, list] = {}
    for i, t in sorted(twin.items()):
        c = t["case"]
        if c["truth"] != entry or i not in closed:
            continue
        v = rows.setdefault(c["effect"], [0, 0, 0, 0.0])
        v[0] += 1
        v[1] += closed[i]["decision"] == entry
        v[2] += t["decision"] == entry
        v[3] += (optimal_power(get_extension(entry), POOLED * lam[i]) if i in lam
                 else math.nan)
    print(f"{entry}, {POOLED} runs pooled: named in closed loop (the study) and in the "
          "open-loop twins, against the oracle test's expectation")
    print(f"{'effect':<16}{'cases':>6}{'closed loop':>13}{'open loop':>11}{'oracle':>9}")
    tot = [0, 0, 0, 0.0]
    for e, v in sorted(rows.items()):
        print(f"{e:<16}{v[0]:>6}{v[1]:>13}{v[2]:>11}{v[3]:>9.1f}")
        tot = [a + b for a, b in zip(tot, v)]
    print(f"{'all':<16}{tot[0]:>6}{tot[1]:>13}{tot[2]:>11}{tot[3]:>9.1f}")


def null_recordings(i: int) -> tuple[dict, list]:
    """Pooled null control ``i`` of :func:`pooled_null`: its case and its four recordings."""
    from bayespilot.recording import Recording

    task, kt, fn = CONDITIONS[i % len(CONDITIONS)]
    c = {"id": 100000 + i, "truth": "none", "effect": "control", "extra": {},
         "task": task, "K_theta": kt, "F_n": fn}
    recs = []
    for j in range(4):
        rec = simulate_case(dict(c, seed=900000 + 10 * i + j))[0].recording
        recs.append(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, {},
                              f"run{j + 1}"))
    return c, recs


def run_pooled_case(c: dict) -> dict:
    """``diagnose_pooled`` on POOLED runs of the case's condition and effect (new seeds)."""
    from bayespilot.diagnose import diagnose_pooled
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model

    recs, remnant, extra = pooled_recordings(c, POOLED)
    t0 = time.perf_counter()
    res = diagnose_pooled(recs, seed=0, n_bootstrap=N_BOOTSTRAP, omega_c=OMEGA_C,
                          oversample=OVERSAMPLE, n_calibrate=N_CALIBRATE,
                          noise_passes=NOISE_PASSES)
    el = time.perf_counter() - t0
    vafs = [r["base"]["vaf"] for r in res.runs]
    rms = []
    for rec, r in zip(recs, res.runs):
        eps = Likelihood(paper_model(oversample=OVERSAMPLE), rec).residual(r["base"]["gls_params"])
        rms.append(float(np.sqrt(np.mean(eps ** 2))))
    return {"case": dict(c), "runs": POOLED, "true_params": extra,
            "remnant_fraction": float(np.mean(remnant)),
            "decision": res.physics, "mismatch": res.mismatch,
            "base_vaf": float(np.mean(vafs)), "residual_rms": float(np.mean(rms)),
            "base_vafs": vafs, "residual_rmss": rms,
            "ranking": [{"physics": r.physics, "delta_neg_log_lik": r.delta_neg_log_lik,
                         "p_value": r.p_value, "params": r.params,
                         "per_run": [x["delta_neg_log_lik"].get(r.physics) for x in res.runs],
                         **_calibration_of(r)}
                        for r in res.ranking],
            "chosen_params": res.chosen.params if res.chosen else None,
            "chosen_stderr": res.chosen.stderr if res.chosen else None,
            "elapsed_seconds": el}


def _calibration_of(r) -> dict:
    """A ranking entry's bootstrap calibration (``--calibrate``), if its test was calibrated."""
    c = r.calibration
    if c is None:
        return {}
    return {"calibration": {"replicates": c.replicates, "scale": c.scale,
                            "p_nominal": c.p_nominal, "p_empirical": c.p_empirical}}


def run_case(c: dict) -> dict:
    from bayespilot.diagnose import diagnose
    from bayespilot.recording import Recording

    if POOLED:
        return run_pooled_case(c)
    sim, extra = simulate_case(c)
    rec = sim.recording
    # blind: only what a lab recording would have (the simulator's notes go too)
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta, "case")
    t0 = time.perf_counter()
    res = diagnose(rec, seed=0, n_bootstrap=N_BOOTSTRAP, profile_noise=PROFILE_NOISE,
                   omega_c=OMEGA_C, oversample=OVERSAMPLE, n_calibrate=N_CALIBRATE,
                   noise_passes=NOISE_PASSES)
    el = time.perf_counter() - t0
    resid = res.arrays["residual"]
    return {"case": {k: v for k, v in c.items()}, "true_params": extra,
            "remnant_fraction": float(np.var(sim.remnant) / np.var(rec.u)),
            "decision": res.physics, "mismatch": res.mismatch,
            "base_vaf": res.base["vaf"], "residual_rms": float(np.sqrt(np.mean(resid ** 2))),
            "ranking": [{"physics": r.physics, "delta_neg_log_lik": r.delta_neg_log_lik,
                         "p_value": r.p_value, "params": r.params, **_calibration_of(r)}
                        for r in res.ranking],
            "chosen_params": res.chosen.params if res.chosen else None,
            "chosen_stderr": res.chosen.stderr if res.chosen else None,
            "elapsed_seconds": el}


def study_folder(runs: int) -> Path:
    """The stored study's results with ``runs`` runs per case (1: one run, ``diagnose``)."""
    return DEFAULT_OUT if runs == 1 else DEFAULT_OUT.with_name(
        "diagnose_pooled" if runs == 4 else f"diagnose_pooled{runs}")


def wrong_ids(runs: int, rs: list[dict] | None = None) -> set[int]:
    """The ids of the cases that the stored study with ``runs`` runs per case (1: one run,
    ``diagnose``; R: ``--pooled R``) decided wrongly: a name other than the truth.
    ``rs``: that study's results, if already loaded."""
    folder = study_folder(runs)
    rs = load(folder) if rs is None else rs
    if len(rs) < len(cases()):
        raise SystemExit(f"--misses-of {runs}: {folder} holds {len(rs)} of {len(cases())} "
                         "cases; that study is not complete")
    return {r["case"]["id"] for r in rs if r["decision"] != r["case"]["truth"]}


def misses_table(runs: int) -> None:
    """The cases the ``runs``-run study decided wrongly, decided again by this study (more
    runs): truth, effect, condition, the oracle test's power with ``runs`` and with this
    study's runs (the oracle's single-run lambda times the runs, from ``--oracle``), and both
    decisions."""
    from bayespilot.diagnose import get_extension

    stored = load(study_folder(runs))
    ids = wrong_ids(runs, stored)
    lam = oracle_lambdas()
    now = {r["case"]["id"]: r for r in load()}
    before = {r["case"]["id"]: r for r in stored}
    now_runs = POOLED or 1
    print(f"The {len(ids)} cases the {runs}-run study got wrong, with {now_runs} runs "
          f"({sum(i in now for i in ids)} done)")
    print("(power R: the oracle test's with R runs; given: with the new runs, given the "
          f"{runs} runs' own statistic, see conditional_power)")
    print(f"{'id':>4}  {'truth / effect / condition':<52}{'power ' + str(runs):>9}"
          f"{'power ' + str(now_runs):>10}{'given':>7}  {str(runs) + ' runs':<24}{now_runs} runs")
    named = expected = given = 0.0
    for i in sorted(ids):
        c = before[i]["case"]
        what = f"{c['truth']} {c['effect']} {c['task']} k{c['K_theta']:g} fn{c['F_n']:g}"
        pw = ["-", "-", "-"]
        if i in lam:
            ext = get_extension(c["truth"])
            stat = 2.0 * next(x["delta_neg_log_lik"] for x in before[i]["ranking"]
                              if x["physics"] == c["truth"])
            pw = [f"{optimal_power(ext, k * lam[i]):.2f}" for k in (runs, now_runs)]
            pw.append(f"{conditional_power(ext, stat, runs, now_runs, lam[i]):.2f}")
        dec = now[i]["decision"] if i in now else "(not run)"
        print(f"{i:>4}  {what:<52}{pw[0]:>9}{pw[1]:>10}{pw[2]:>7}  "
              f"{before[i]['decision']:<24}{dec}")
        if i in now and c["truth"] != "none":
            named += dec == c["truth"]
            expected += float(pw[1]) if i in lam else 1.0
            given += float(pw[2]) if i in lam else 1.0
    print(f"effect cases done: named {named:.0f}, the oracle test with {now_runs} runs expects "
          f"{expected:.1f}, or {given:.1f} given the {runs} runs' own statistics (these cases "
          f"were chosen because those were low)")


def run(chunk: int | None, shard: tuple[int, int] = (0, 1),
        only: set[int] | None = None) -> None:
    import numba

    numba.set_num_threads(1)
    OUT.mkdir(parents=True, exist_ok=True)
    k, n = shard
    # a selection is shared out by rank, not id, so that both shards get half of it
    rank = {i: j for j, i in enumerate(sorted(only))} if only is not None else None
    todo = [c for c in cases()
            if (c["id"] if rank is None else rank.get(c["id"], -1)) % n == k
            and (rank is None or c["id"] in rank)
            and not (OUT / f"{case_key(c)}.json").exists()]
    if chunk is not None:
        todo = todo[:chunk]
    print(f"{len(todo)} case(s) to run", flush=True)
    uncalibrated = OUT.with_name(OUT.name.removesuffix(f"_cal{N_CALIBRATE}"))
    for c in todo:
        path = OUT / f"{case_key(c)}.json"
        before = uncalibrated / f"{case_key(c)}.json"
        r = json.loads(before.read_text()) if N_CALIBRATE and before.exists() else None
        if r is not None and r["decision"] == "none":
            # the calibration only ever raises a p-value: a case the asymptotic test leaves at
            # none (same seeds, same pipeline up to the decision) stays none; not rerun
            r["calibration"] = "none before calibration: not rerun"
            path.write_text(json.dumps(r, indent=1, default=float))
            continue
        try:
            r = run_case(c)
        except Exception as exc:  # keep going; the error is recorded and retried next time
            (OUT / f"{case_key(c)}.error.txt").write_text(f"{type(exc).__name__}: {exc}\n")
            print(f"{case_key(c)}: ERROR {exc}", flush=True)
            continue
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(r, indent=1, default=float))
        tmp.replace(path)
        print(f"{case_key(c)}: {r['decision']} ({r['elapsed_seconds']:.0f} s)", flush=True)


def load(folder: Path | None = None) -> list[dict]:
    """Every case result in ``folder`` (default: this study's ``OUT``)."""
    return [json.loads(p.read_text()) for p in sorted((folder or OUT).glob("[0-9]*.json"))]


def mark_concealed(rs: list[dict]) -> None:
    """Set ``r["concealed"]``: VAF and residual RMS within 3 sd of the controls of the same
    task and remnant level (every run of a pooled case); None with fewer than 2 controls."""
    ctl: dict[tuple, list] = {}
    for r in rs:
        if r["case"]["truth"] == "none":
            ctl.setdefault((r["case"]["task"], r["case"]["F_n"]), []).append(r)
    for r in rs:
        cs = ctl.get((r["case"]["task"], r["case"]["F_n"]), [])
        if len(cs) >= 2:
            ok = True
            for key in ("base_vaf", "residual_rms"):
                # pooled cases: every run against the controls' runs
                many = key + "s"
                if many in r:
                    v = np.concatenate([c[many] for c in cs])
                    mine = np.asarray(r[many])
                else:
                    v = np.array([c[key] for c in cs])
                    mine = np.asarray([r[key]])
                ok &= bool(np.all(np.abs(mine - v.mean()) <= 3 * max(v.std(ddof=1), 1e-12)))
            r["concealed"] = bool(ok)
        else:
            r["concealed"] = None


def summarize() -> dict:
    rs = load()
    if not rs:
        print("no results yet")
        return {}
    mark_concealed(rs)
    labels = ["none", *EFFECTS]
    cols = labels
    conf = {t: {d: 0 for d in cols} for t in labels}
    conf_c = {t: {d: 0 for d in cols} for t in labels}
    for r in rs:
        t, d = r["case"]["truth"], r["decision"]
        conf[t][d] += 1
        if r["concealed"] is not False:
            conf_c[t][d] += 1
    short = {"none": "none", "motion-system-dynamics": "msd", "motion-washout": "wash",
             "otolith-channel": "oto", "threshold-shape": "thr", "time-varying-gains": "tvg",
             "control-saturation": "sat"}

    def table(cf, title):
        lines = [title, f"{'truth / decision':<24}" + "".join(f"{short[c]:>6}" for c in cols)
                 + f"{'n':>6}{'correct':>9}"]
        for t in labels:
            n = sum(cf[t].values())
            if not n:
                continue
            lines.append(f"{t:<24}" + "".join(f"{cf[t][c]:>6}" for c in cols)
                         + f"{n:>6}{cf[t][t] / n:>9.0%}")
        return "\n".join(lines)

    print(table(conf, "Confusion matrix, all cases (rows: truth; columns: decision)"))
    print()
    print(table(conf_c, "Confusion matrix, concealed cases and controls"))
    ent = [r for r in rs if r["case"]["truth"] != "none" and r["concealed"] is not False]
    n_ok = sum(r["decision"] == r["case"]["truth"] for r in ent)
    n_ctl = sum(1 for r in rs if r["case"]["truth"] == "none")
    fa = sum(1 for r in rs if r["case"]["truth"] == "none" and r["decision"] != "none")
    print(f"\nconcealed cases named correctly: {n_ok}/{len(ent)}"
          + (f" = {n_ok / len(ent):.0%}" if ent else ""))
    print(f"false alarms on controls: {fa}/{n_ctl}")
    n_conc = sum(1 for r in rs if r["case"]["truth"] != "none" and r["concealed"])
    n_ent = sum(1 for r in rs if r["case"]["truth"] != "none")
    print(f"cases concealed (VAF and residual RMS within 3 sd of the controls): {n_conc}/{n_ent}")
    curves = {}
    print("\nDetection (correct naming) by effect size, all cases:")
    for e, sizes in ALL_EFFECTS.items():
        row = []
        for lab, _ in sizes:
            sel = [r for r in rs if r["case"]["truth"] == e and r["case"]["effect"] == lab]
            k = sum(r["decision"] == e for r in sel)
            conc = sum(1 for r in sel if r["concealed"])
            row.append((lab, k, len(sel), conc))
        curves[e] = row
        print(f"  {e:<24} " + "   ".join(f"{lab}: {k}/{n} (concealed {c})" for lab, k, n, c in row))
    sweep = alpha_sweep(rs)
    # a calibrated study's copied none cases keep the uncalibrated run's time: left out
    times = [r["elapsed_seconds"] for r in rs if not isinstance(r.get("calibration"), str)]
    rerun = " rerun" if N_CALIBRATE else ""
    print(f"\ndiagnose time per case{rerun}: median {np.median(times):.0f} s, max "
          f"{np.max(times):.0f} s (B = {N_BOOTSTRAP}, one numba thread, shared machine)")
    # figures
    FIG.mkdir(parents=True, exist_ok=True)
    plot_detection(curves, FIG / f"diagnose_detection{FIG_SUFFIX}.png")
    plot_confusion(conf, labels, FIG / f"diagnose_confusion{FIG_SUFFIX}.png")
    summary = {"n_cases": len(rs), "confusion": conf, "confusion_concealed": conf_c,
               "concealed_named_correctly": [n_ok, len(ent)], "false_alarms": [fa, n_ctl],
               "detection_curves": {e: [{"effect": lab, "correct": k, "n": n, "concealed": c}
                                        for lab, k, n, c in row] for e, row in curves.items()},
               "median_seconds": float(np.median(times)), "alpha_sweep": sweep}
    if PROFILE_NOISE or POOLED or OMEGA_C is not None or N_CALIBRATE or NOISE_PASSES != 1:
        summary["paired_with_default"] = paired_with_default(rs)
    if N_CALIBRATE:
        summary["calibration_scales"] = calibration_scales(rs)
    if POOLED and OMEGA_C is None and OVERSAMPLE == 1:
        summary["against_optimal_test"] = pooled_against_oracle(rs)
    (OUT / "summary.json").write_text(json.dumps(summary, indent=1))
    return summary


def plot_confusion(conf: dict, labels: list[str], path: Path) -> None:
    """The confusion matrix ``conf[truth][decision]`` (counts) over ``labels`` (truths and
    decisions alike): each cell shaded by its share of the truth's cases, its count in white
    on the dark half of the colour map; the decisions written out in full, rotated (as
    ``bayespilot.diagnose.report.plot_batch`` writes the candidates)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure

    fig, ax = plt.subplots(figsize=(7.0, 5.6), layout="constrained")
    M = np.array([[conf[t][d] for d in labels] for t in labels], float)
    share = M / np.maximum(M.sum(axis=1, keepdims=True), 1)
    ax.imshow(share, cmap="Blues", vmin=0, vmax=1)
    for i in range(len(labels)):
        for j in range(len(labels)):
            if M[i, j]:  # white on the dark half of Blues, black on the light half
                ax.text(j, i, int(M[i, j]), ha="center", va="center", fontsize="medium",
                        color="white" if share[i, j] > 0.5 else "black")
    ax.set_xticks(range(len(labels)))
    ax.set_xticklabels(labels, rotation=30, ha="right", rotation_mode="anchor",
                       fontsize="small")
    ax.set_yticks(range(len(labels)))
    ax.set_yticklabels(labels, fontsize="small")
    ax.set_xlabel("decision")
    ax.set_ylabel("truth")
    ax.set_title("diagnose: confusion matrix (counts; shade: share of the truth's cases)",
                 fontsize="medium")
    save_figure(fig, path)
    plt.close(fig)


def _effect_axis(entry: str) -> str:
    """The x axis of an entry's detection curve: what its effect size is, with its unit
    (the catalogue's parameter, or how the saturation limit was set), in two lines that
    fit a third of a 7-in page at the "small" size."""
    from bayespilot._labels import label, symbol

    return {
        "motion-system-dynamics": "platform bandwidth\n" + label("omega_ms", "rad/s"),
        "motion-washout": "washout break frequency\n" + label("omega_w", "rad/s"),
        "otolith-channel": "otolith gain " + label("K_ot", "rad/(m/s^2)")
                           + f",\n{symbol('h_head')} = 1 m",
        "threshold-shape": "soft-threshold corner width\n" + label("w_soft", "IPUT"),
        "time-varying-gains": f"relative drift of {symbol('K_v')} and {symbol('K_m')}\n"
                              "over the run",
        "control-saturation": "control samples clipped\nby the limit (%)",
    }.get(entry, entry)


def _wilson_95(k: int, n: int) -> tuple[float, float]:
    """The 95 % Wilson interval of a proportion k/n (scipy.stats.binomtest)."""
    from scipy.stats import binomtest

    ci = binomtest(k, n).proportion_ci(confidence_level=0.95, method="wilson")
    return float(ci.low), float(ci.high)


def plot_detection(curves: dict, path: Path) -> None:
    """The detection curves: per entry, the share of its cases named correctly at each
    effect size (``curves[entry]`` = [(label, correct, n, concealed), ...], smallest effect
    first) as points with 95 % Wilson intervals; an effect size without cases is marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure

    FIG.mkdir(parents=True, exist_ok=True)
    ncols = 3
    nrows = math.ceil(len(curves) / ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(7.0, 2.7 * nrows + 0.5), sharey=True,
                             squeeze=False, layout="constrained")
    for ax, (e, row) in zip(axes.flat, curves.items()):
        x = np.arange(len(row))
        for xi, (_, k, n, _) in zip(x, row):
            if not n:
                ax.text(xi, 0.02, "no cases", rotation=90, ha="center", va="bottom",
                        fontsize=7, color="0.4")
                continue
            rate = k / n
            lo, hi = _wilson_95(k, n)
            # categorical sizes: points with their intervals, not joined
            ax.errorbar(xi, rate, yerr=[[rate - lo], [hi - rate]], fmt="o", ms=4, capsize=2,
                        color="C0", lw=1)
            ax.annotate(f"{k}/{n}", (xi, hi), textcoords="offset points", xytext=(0, 3),
                        ha="center", fontsize=7)
        ax.set_xticks(x, [lab.split("=")[-1].rstrip("%") for lab, *_ in row], fontsize=8)
        ax.set_xlim(-0.5, len(row) - 0.5)
        ax.set_xlabel(_effect_axis(e), fontsize="small")
        ax.set_ylim(-0.03, 1.15)
        ax.set_yticks(np.linspace(0, 1, 6))
        ax.set_title(e, fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    for ax in list(axes.flat)[len(curves):]:
        ax.set_visible(False)
    for ax in axes[:, 0]:
        ax.set_ylabel("share named correctly")
    fig.suptitle("diagnose: detection against effect size, all cases (smallest effect left;\n"
                 "point: share named correctly out of the cases shown; bar: its 95 % Wilson "
                 "interval)", fontsize=9)
    save_figure(fig, path)
    plt.close(fig)


def alpha_sweep(rs: list[dict], alphas=(0.01, 0.02, 0.05)) -> list[dict]:
    """Would a looser family-wise level name more concealed cases, and at what false-alarm cost?

    Re-decides every case from its stored p-values at each level (Bonferroni
    over the six candidates, as ``diagnose`` splits it).  Among several
    justified candidates it picks saturation (flat tops), else the largest
    -ln L improvement less half the BIC penalty of its extra parameters: an
    approximation to ``diagnose``'s rule (which breaks near-ties by the
    located signatures), so the script also counts how many stored decisions
    the rule reproduces at the study's level.
    """
    n_new = {"motion-system-dynamics": 1, "motion-washout": 1, "threshold-shape": 1,
             "otolith-channel": 2, "time-varying-gains": 2, "control-saturation": 0}

    def decide(r, level):
        ok = [x for x in r["ranking"] if x["p_value"] < level]
        if not ok:
            return "none"
        return max(ok, key=lambda x: np.inf if x["physics"] == "control-saturation"
                   else x["delta_neg_log_lik"] - 0.5 * n_new[x["physics"]] * np.log(8192)
                   )["physics"]

    from bayespilot.diagnose import ALPHA

    same = sum(decide(r, ALPHA / 6) == r["decision"] for r in rs)
    print(f"\nAt other family-wise levels (re-decided from the stored p-values; the rule "
          f"reproduces {same} of the {len(rs)} stored decisions at alpha = {ALPHA:g}):")
    ent = [r for r in rs if r["case"]["truth"] != "none" and r["concealed"] is not False]
    ctl = [r for r in rs if r["case"]["truth"] == "none"]
    out = []
    for a in alphas:
        ok = sum(decide(r, a / 6) == r["case"]["truth"] for r in ent)
        fa = sum(decide(r, a / 6) != "none" for r in ctl)
        print(f"  alpha = {a:<5g} concealed named correctly {ok}/{len(ent)}, "
              f"false alarms {fa}/{len(ctl)}")
        out.append({"alpha": a, "concealed_named_correctly": [ok, len(ent)],
                    "false_alarms": [fa, len(ctl)]})
    return out


def paired_with_default(rs: list[dict]) -> dict:
    """Decisions of this (profile-noise, pooled, other-band or calibrated) study beside the
    default study's on the same cases; for a changed decision, the calibrated tests' scale
    and p-values (nominal -> calibrated)."""
    out = {"cases": 0, "same": 0, "gained": [], "lost": [], "changed_wrong": []}
    for r in rs:
        key = case_key(r["case"])
        path = DEFAULT_OUT / f"{key}.json"
        if not path.exists():
            continue
        d = json.loads(path.read_text())
        truth, old, new = r["case"]["truth"], d["decision"], r["decision"]
        out["cases"] += 1
        if old == new:
            out["same"] += 1
        elif new == truth:
            out["gained"].append(key)
        elif old == truth:
            out["lost"].append(key)
        else:
            out["changed_wrong"].append(key)
    print(f"\nPaired with the default study on {out['cases']} cases: same decision "
          f"{out['same']}, newly correct {len(out['gained'])}, newly wrong {len(out['lost'])}, "
          f"wrong either way but different {len(out['changed_wrong'])}")
    cal = {case_key(r["case"]): [x for x in r["ranking"] if x.get("calibration")] for r in rs}
    for k in ("gained", "lost", "changed_wrong"):
        for key in out[k]:
            tests = "; ".join(f"{x['physics']} scale {x['calibration']['scale']:.2f}, p "
                              f"{x['calibration']['p_nominal']:.2g} -> {x['p_value']:.2g}"
                              for x in cal.get(key, []))
            print(f"  {k}: {key}" + (f" ({tests})" if tests else ""))
    return out


def calibration_scales(rs: list[dict]) -> dict:
    """Per tested entry, the scales the calibrated study measured (every calibrated test)."""
    got: dict[str, list[float]] = {}
    for r in rs:
        for x in r["ranking"]:
            if x.get("calibration"):
                got.setdefault(x["physics"], []).append(x["calibration"]["scale"])
    print("\nScales of the calibrated tests (replicates' mean d(-ln L) / the reference's):")
    for e, v in sorted(got.items()):
        print(f"  {e:<24} {len(v):>3} tests: median {np.median(v):.2f}, "
              f"range {min(v):.2f}-{max(v):.2f}, above 1 in {sum(x > 1 for x in v)}")
    return {e: sorted(v) for e, v in got.items()}


def oracle_lambdas() -> dict[int, float]:
    """Each effect case's single-run noncentrality at the default decision likelihood
    (``--oracle``'s stored rows), by case id."""
    lam = {}
    for f in sorted(DEFAULT_OUT.glob("oracle*.jsonl")):
        for line in f.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                lam[row["id"]] = row["lowpass"]["lambda"]
    return lam


def pooled_against_oracle(rs: list[dict]) -> dict:
    """A pooled study's naming beside the oracle test's expectation with as many runs.

    For every pooled case concealed in all its runs (saturation left out) the
    single-run oracle's noncentrality of the same case (``--oracle``, the
    single-run study's recording of it: same condition and effect, another
    seed) times the number of runs gives the power of the oracle test of
    the true extension pooled over that many runs (information adds over
    runs).  Per entry: cases, named by ``diagnose_pooled``, expected for the
    oracle test.
    """
    from bayespilot.diagnose import get_extension

    lam = oracle_lambdas()
    per: dict[str, list] = {}
    for r in rs:
        c = r["case"]
        if c["truth"] in ("none", "control-saturation") or not r["concealed"] \
                or c["id"] not in lam:
            continue
        ext = get_extension(c["truth"])
        v = per.setdefault(c["truth"], [0, 0, 0.0])
        v[0] += 1
        v[1] += r["decision"] == c["truth"]
        v[2] += optimal_power(ext, POOLED * lam[c["id"]])
    print(f"\nAgainst the oracle test with {POOLED} runs (concealed cases, saturation left "
          f"out; lambda from --oracle x {POOLED}):")
    print(f"  {'entry':<24}{'n':>5}{'named':>7}{'oracle':>9}")
    tot = [0, 0, 0.0]
    for e, (n, k, x) in per.items():
        print(f"  {e:<24}{n:>5}{k:>7}{x:>9.1f}")
        tot = [tot[0] + n, tot[1] + k, tot[2] + x]
    print(f"  {'all':<24}{tot[0]:>5}{tot[1]:>7}{tot[2]:>9.1f}")
    return {"runs": POOLED, "per_entry": {e: {"n": v[0], "named": v[1], "optimal": v[2]}
                                          for e, v in per.items()},
            "all": {"n": tot[0], "named": tot[1], "optimal": tot[2]}}


def example() -> None:
    """The walk-through of docs/diagnose.md: a concealed washout, diagnosed blind.

    Writes the recording to analyses/results/diagnose/example/ and the report's
    figures to docs/figures/diagnose_example_*.png.
    """
    import shutil

    from bayespilot.diagnose import diagnose, sample_chosen
    from bayespilot.io import read_recording, write_recording
    from bayespilot.recording import Recording

    c = {"truth": "motion-washout", "effect": "omega_w=0.3", "extra": {"omega_w": 0.3},
         "task": "FD", "K_theta": 1.0, "F_n": 0.1, "seed": 777, "id": -1}
    sim, _ = simulate_case(c)
    rec = sim.recording
    meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
    ex = OUT / "example"
    write_recording(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta),
                    ex / "washout_run")
    rec = read_recording(ex / "washout_run")
    res = diagnose(rec, seed=0)
    if res.chosen is not None and res.physics != "control-saturation":
        # step 4's optional posterior of the chosen extended model (sample()'s default chain)
        sample_chosen(res, rec, seed=0)
    print(res.summary())
    paths = res.report(ex / "report")
    FIG.mkdir(parents=True, exist_ok=True)
    for key in ("frequency_response", "residuals", "evidence", "candidates", "profile",
                "posterior"):
        if key not in paths:
            continue
        shutil.copy(paths[key], FIG / f"diagnose_example_{key}.png")
    (ex / "summary.txt").write_text(res.summary() + "\n")


def compare_runs(runs: tuple[int, ...] = (1, 4, 8)) -> dict:
    """One run, four and eight pooled, on the same cases: those the largest study has done.

    Each study judges concealment its own way (a pooled case: every one of
    its runs within the spread of that study's control runs); per entry the
    table gives the concealed cases and how many of them each study named.
    """
    global OUT
    keep = OUT
    studies = {}
    try:
        for R in runs:
            OUT = DEFAULT_OUT if R == 1 else DEFAULT_OUT.with_name(
                "diagnose_pooled" if R == 4 else f"diagnose_pooled{R}")
            rs = load()
            mark_concealed(rs)
            studies[R] = {r["case"]["id"]: r for r in rs}
    finally:
        OUT = keep
    ids = set.intersection(*(set(v) for v in studies.values()))
    print(f"{len(ids)} cases done by every study ({', '.join(str(R) for R in runs)} runs); "
          "per entry: named / concealed (all cases: named / n)")
    print(f"  {'truth':<24}" + "".join(f"{f'{R} run' + ('s' if R > 1 else ''):>22}"
                                       for R in runs))
    out = {}
    tot = {R: [0, 0, 0, 0] for R in runs}
    for e in ["none", *EFFECTS]:
        row = []
        for R in runs:
            sel = [studies[R][i] for i in ids if studies[R][i]["case"]["truth"] == e]
            conc = [r for r in sel if r["concealed"]]
            k_c = sum(r["decision"] == e for r in conc)
            k = sum(r["decision"] == e for r in sel)
            row.append((k_c, len(conc), k, len(sel)))
            if e != "none":
                tot[R] = [a + b for a, b in zip(tot[R], row[-1])]
        if not row[0][3]:
            continue
        out[e] = {R: dict(zip(("named_concealed", "concealed", "named", "n"), v))
                  for R, v in zip(runs, row)}
        print(f"  {e:<24}" + "".join(f"{f'{a}/{b} ({c}/{d})':>22}" for a, b, c, d in row))
    print(f"  {'all effects':<24}" + "".join(
        f"{f'{a}/{b} ({c}/{d})':>22}" for a, b, c, d in (tot[R] for R in runs)))
    out["all effects"] = {R: dict(zip(("named_concealed", "concealed", "named", "n"), tot[R]))
                          for R in runs}
    # the same effects judged by one run: which of the cases that one run conceals are named
    one = studies[runs[0]]
    sel = sorted(i for i in ids if one[i]["case"]["truth"] != "none" and one[i]["concealed"])
    print(f"\nThe {len(sel)} of these cases whose single run is concealed (the same condition and "
          "effect), named by:")
    out["single_run_concealed"] = {}
    for R in runs:
        k = sum(studies[R][i]["decision"] == studies[R][i]["case"]["truth"] for i in sel)
        out["single_run_concealed"][R] = [k, len(sel)]
        print(f"  {R} run{'s' if R > 1 else ' '}: {k}/{len(sel)}"
              + (f" = {k / len(sel):.0%}" if sel else ""))
    out["identifiable"] = identifiable(studies, sel)
    return out


def identifiable(studies: dict[int, dict[int, dict]], concealed: list[int],
                 powers=(0.5, 0.9, 0.99)) -> dict:
    """Naming among the cases the data can reveal: the oracle test's power at least ``powers``.

    For each study (R runs) and each non-saturation case of ``--oracle``, the
    power the oracle test of the true extension has with R runs (lambda x R,
    the decision's level); among the cases with at least that power, how
    many the study named, of those one run conceals (``concealed``, case ids)
    and of all.  The selection uses the truth (the oracle's lambda), so it is
    an evaluation of ``diagnose`` where the target can be met, not a decision rule.
    """
    from bayespilot.diagnose import get_extension

    path = DEFAULT_OUT / "oracle.jsonl"
    if not path.exists():
        print("\n(no oracle results: run --oracle for the naming among identifiable cases)")
        return {}
    orc = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    conc = set(concealed)
    print("\nAmong the cases the oracle test with as many runs names with at least this "
          "probability (non-saturation; named / those one run conceals, named / all):")
    out = {}
    for R, st in studies.items():
        cases = [(o, st[o["id"]], optimal_power(get_extension(o["truth"]),
                                                o["lowpass"]["lambda"] * R))
                 for o in orc if o["id"] in st]
        row = {}
        for q in powers:
            k = n = k_all = n_all = 0
            for o, r, power in cases:
                if power < q:
                    continue
                hit = r["decision"] == o["truth"]
                n_all, k_all = n_all + 1, k_all + hit
                if o["id"] in conc:
                    n, k = n + 1, k + hit
            row[q] = {"named_concealed": k, "concealed": n, "named": k_all, "n": n_all}
        out[R] = row
        print(f"  {R} run{'s' if R > 1 else ' '}: " + "   ".join(
            f"power >= {q:g}: {v['named_concealed']}/{v['concealed']} ({v['named']}/{v['n']})"
            for q, v in row.items()))
    return out


def locate_null(n_bootstrap: int = 39, shard: tuple[int, int] = (0, 1)) -> None:
    """Are the located evidence's bootstrap p-values calibrated on correct-model data?

    On the study's 48 controls (the paper's model, no extra physics): the base
    stages of ``diagnose`` with ``n_bootstrap`` replicates (what ``diagnose``
    runs by default, 39), and every statistic's p-value.  Under a calibrated
    (or conservative) bootstrap P(p <= a) <= a for every a on the replicates'
    grid.  One JSON line per control in
    ``analyses/results/diagnose/locate_null_refit*.jsonl`` (resumable; each
    replicate refitted, as ``diagnose`` does since 2026-11-27); the summary
    prints per statistic the fraction at p <= 0.05 and 0.10 and the mean p,
    beside the same for the replicates at fixed parameters
    (``locate_null_fixed.jsonl``, made before the refit).
    """
    from tqdm import tqdm

    from bayespilot.diagnose import SKIP_SECONDS, _prepare
    from bayespilot.recording import Recording

    import numba

    numba.set_num_threads(1)
    k, n = shard
    out = DEFAULT_OUT / (f"locate_null_refit_{k}of{n}.jsonl" if n > 1
                         else "locate_null_refit.jsonl")
    files = sorted(DEFAULT_OUT.glob("locate_null_refit*.jsonl"))
    done = {json.loads(line)["id"] for f in files for line in f.read_text().splitlines()
            if line.strip()}
    todo = [c for c in cases() if c["truth"] == "none" and c["id"] % n == k
            and c["id"] not in done]
    for c in tqdm(todo, desc="locate null", unit="control"):
        sim, _ = simulate_case(c)
        rec = sim.recording
        meta = {q: v for q, v in rec.metadata.items() if q != "notes"}
        rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta, "ctl")
        run = _prepare(rec, seed=0, n_bootstrap=n_bootstrap, base_fit=None,
                       skip_seconds=SKIP_SECONDS, omega_c=None, n_starts=4,
                       profile_noise=False, bar=tqdm(disable=True), oversample=1)
        row = {"id": c["id"], "task": c["task"], "F_n": c["F_n"], "K_theta": c["K_theta"],
               "replicates": run.boot_info.get("replicates"),
               "p": {q: e.p_value for q, e in run.where.items()}}
        with open(out, "a") as f:
            f.write(json.dumps(row) + "\n")
    def rows_of(pattern):
        return [json.loads(line) for f in sorted(DEFAULT_OUT.glob(pattern))
                for line in f.read_text().splitlines() if line.strip()]

    rows, fixed = rows_of("locate_null_refit*.jsonl"), rows_of("locate_null_fixed.jsonl")
    if not rows:
        print("no results yet")
        return
    print(f"located evidence on {len(rows)} correct-model runs, B = {n_bootstrap} "
          f"(p = (1 + #replicates >= observed) / (B + 1)); replicates refitted "
          f"(left) and at fixed parameters ({len(fixed)} runs, right):")
    print(f"  {'statistic':<30}{'n':>4}{'p<=0.05':>9}{'p<=0.10':>9}{'mean p':>8}"
          f"  |{'p<=0.05':>9}{'p<=0.10':>9}{'mean p':>8}")

    def cols(rs, key):
        ps = np.array([r["p"].get(key) for r in rs], dtype=float)
        ps = ps[np.isfinite(ps)]
        if not ps.size:
            return ps.size, " " * 26
        return ps.size, f"{np.mean(ps <= 0.05):>9.3f}{np.mean(ps <= 0.10):>9.3f}{ps.mean():>8.3f}"

    for key in rows[0]["p"]:
        m, left = cols(rows, key)
        print(f"  {key:<30}{m:>4}{left}  |{cols(fixed, key)[1]}")

    def anyp(rs):
        return sum(any(v is not None and v <= 0.05 for v in r["p"].values()) for r in rs)

    print(f"  runs with any statistic at p <= 0.05: {anyp(rows)}/{len(rows)}  |  "
          f"{anyp(fixed)}/{len(fixed)}")


#: Starts of the base model's Eq. 4 fit in the checks (``--posterior-check``,
#: ``--shared-posterior-check``, ``--final-fit-check``): diagnose's default.  These checks
#: first ran with 2 to save time (their results kept as ``*_nstarts2*.jsonl``); with 2, about
#: one otolith run in ten had its base fit stopped in a basin of the motion channel (K_m near
#: 0, tau_m near its 1-s bound, delta_abs large) worse by 60-130 in GLS -ln L than the basin 4
#: starts reach, which the extension's fit and the posterior inherited (the otolith's h_head,
#: 4/22 covered).
CHECK_N_STARTS = 4


def posterior_check(n: int = 8) -> None:
    """Are the chosen extension's uncertainties honest?  ``n`` runs (FD, 40.96 s, K_theta = 1,
    K_n = 0.063) with a washout at omega_w = 0.8 rad/s, seeds 100, 101, ...: per run the
    GLS fit of the washout with its standard error and the posterior (``sample_chosen``,
    coloured likelihood, at most 3000 steps) median and sd.  Over the runs, each spread
    should match its reported width.  ``analyses/results/diagnose/posterior_check.jsonl``.
    """
    import warnings

    from bayespilot import presets
    from bayespilot.diagnose import diagnose, get_extension, sample_chosen
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    import numba

    numba.set_num_threads(1)
    model = get_extension("motion-washout").build(paper_model())
    truth = 0.8
    p = dict(presets.paper_parameters("FD"), omega_w=truth)
    out = DEFAULT_OUT / "posterior_check.jsonl"
    rows = []
    if out.exists():
        rows = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
    for seed in range(100 + len(rows), 100 + n):
        rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063, seed=seed,
                       duration=40.96).recording
        res = diagnose(rec, seed=0, n_bootstrap=0, n_starts=CHECK_N_STARTS,
                       candidates=["motion-washout"])
        c = res.ranking[0]
        res.chosen = c  # sampled whether or not the test chose it (it does, at this size)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            post = sample_chosen(res, rec, seed=0, max_steps=3000, min_steps=1000,
                                 check_every=500)
        d = post.draws("omega_w")
        row = {"seed": seed, "decision": res.physics, **_fit_columns(c, "omega_w"),
               "median": float(np.median(d)), "sd": float(d.std()),
               "hdi_90": list(post.credible_interval("omega_w", 0.9)),
               "converged": bool(post.converged)}
        rows.append(row)
        with open(out, "a") as f:
            f.write(json.dumps(row) + "\n")
        print(json.dumps(row), flush=True)
    g = np.array([r["gls"] for r in rows])
    m = np.array([r["median"] for r in rows])
    print(f"{len(rows)} runs, omega_w = {truth} rad/s; named {sum(r['decision'] == 'motion-washout' for r in rows)}")
    print(f"GLS fit:   mean {g.mean():.3f}, sd over runs {g.std(ddof=1):.3f}, mean s.e. "
          f"{np.mean([r['se'] for r in rows]):.3f}")
    print(f"posterior: mean median {m.mean():.3f}, sd over runs {m.std(ddof=1):.3f}, mean "
          f"posterior sd {np.mean([r['sd'] for r in rows]):.3f}; truth in the 90 % HDI "
          f"{sum(r['hdi_90'][0] < truth < r['hdi_90'][1] for r in rows)}/{len(rows)}")


def shared_posterior_check(n: int = 40, runs: int = 2,
                           shard: tuple[int, int] = (0, 1), weak: bool = False) -> None:
    """Are the pooled posterior's intervals honest?  ``n`` sets of ``runs`` runs (FD, 40.96 s,
    K_theta = 1, K_n = 0.063) with a washout at omega_w = 0.8 rad/s shared by the set (set k:
    seeds 200 + runs k, ...): per set the pooled GLS fit with its standard error and
    ``shared_posterior``'s median, sd and central 90 % interval.  Over the sets the truth
    should fall in the interval about 9 times in 10, and the medians' spread match the
    posterior sd.  ``weak``: a weaker washout in longer, noisier runs, the proof study's
    condition (four 81.92-s runs, omega_w = 0.3 rad/s, F_n = 0.25; seeds 300 + 4 k, ...).
    Resumable, ``--shard K/N``;
    ``analyses/results/diagnose_pooled/shared_posterior_check[_weak]*.jsonl``.
    """
    from bayespilot import presets
    from bayespilot.diagnose import diagnose_pooled, get_extension, shared_posterior
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    import numba

    numba.set_num_threads(1)
    model = get_extension("motion-washout").build(paper_model())
    truth, duration, k_n, seed0 = 0.8, 40.96, 0.063, 200
    if weak:
        runs, truth, duration, seed0 = 4, 0.3, 81.92, 300
        k_n = presets.TABLE4_K_N[("FD", 0.25)][presets.MOTION_GAINS.index(1.0)]
    p = dict(presets.paper_parameters("FD"), omega_w=truth)
    out_dir = DEFAULT_OUT.with_name("diagnose_pooled")
    path, every = _shard_files(out_dir, "shared_posterior_check" + ("_weak" if weak else ""),
                               shard)
    done = {json.loads(line)["set"] for f in every() for line in f.read_text().splitlines()
            if line.strip()}
    for k in range(n):
        if k % shard[1] != shard[0] or k in done:
            continue
        recs = [simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=k_n,
                         seed=seed0 + runs * k + j, duration=duration).recording
                for j in range(runs)]
        res = diagnose_pooled(recs, seed=0, n_bootstrap=0, n_starts=CHECK_N_STARTS,
                              candidates=["motion-washout"])
        c = res.ranking[0]
        row = {"set": k, "runs": runs, "decision": res.physics, **_fit_columns(c, "omega_w")}
        if res.chosen is not None:
            post = shared_posterior(res, recs)
            m = post.marginals["omega_w"]
            row.update(median=m["median"], sd=m["sd"], interval=m["interval"],
                       edge_mass=post.edge_mass, seconds=post.elapsed)
        _append_row(path, row)
    rows = _rows(every)
    got = [r for r in rows if "median" in r]
    if not got:
        print("no results yet")
        return
    med = np.array([r["median"] for r in got])
    inside = sum(r["interval"][0] < truth < r["interval"][1] for r in got)
    print(f"{len(rows)} sets of {runs} runs of {duration} s (K_n {k_n:.3f}), omega_w = {truth} "
          f"rad/s; named {len(got)}")
    _print_fit_columns(got, "omega_w", truth)
    print(f"shared posterior: mean median {med.mean():.3f}, sd over sets {med.std(ddof=1):.3f}, "
          f"mean posterior sd {np.mean([r['sd'] for r in got]):.3f}; truth in the central "
          f"90 % interval {inside}/{len(got)} (binomial sd {math.sqrt(len(got) * 0.09):.1f}); "
          f"median time {np.median([r['seconds'] for r in got]):.1f} s")


def _fit_columns(c, m: str) -> dict:
    """A check's columns for parameter ``m`` of candidate ``c``: ``gls``/``se``, the test's
    fit (the decision likelihood, which ``shared_posterior`` is of), and, when the candidate
    was chosen and refitted after the test (its own noise model and delta_abs),
    ``final``/``final_se``, the fit reported."""
    out = {"gls": (c.refit["test_params"] if c.refit else c.params).get(m),
           "se": c.stderr.get(m)}
    if c.refit:
        out.update(final=c.params.get(m), final_se=c.refit["own_stderr"].get(m))
    return out


def _print_fit_columns(cols: list[dict], m: str, truth: float) -> None:
    """Per fit in ``cols`` (:func:`_fit_columns`: the test's, the refit with its own standard
    errors, the reported refit's estimate with the test's): mean, spread over the sets, mean
    standard error and how often +- 1.645 s.e. holds the truth."""
    for key, se, what in (("gls", "se", "test's fit"), ("final", "final_se", "refit, own s.e."),
                          ("final", "se", "reported")):
        have = [q for q in cols if q.get(key) is not None]
        if not have:
            continue
        est = np.array([q[key] for q in have])
        ses = np.array([q[se] for q in have])
        print(f"{m} = {truth}: pooled, {what}: mean {est.mean():.3f}, spread "
              f"{est.std(ddof=1):.3f}, mean s.e. {ses.mean():.3f}; truth within 1.645 s.e. "
              f"{int(np.sum(np.abs(est - truth) < 1.645 * ses))}/{len(have)}")


#: ``--shared-posterior-check --entry``: the truth, runs, run length and first seed per entry
#: (FD, K_theta = 1, K_n = 0.063).
POSTERIOR_CHECK = {
    "motion-system-dynamics": ({"omega_ms": 6.0}, 2, 81.92, 400),
    "time-varying-gains": ({"drift_v": 0.6, "drift_m": 0.3}, 2, 40.96, 500),
    "otolith-channel": ({"K_ot": 0.04, "h_head": 1.0}, 2, 81.92, 600),
}


def shared_posterior_check_entry(entry: str, n: int, shard: tuple[int, int] = (0, 1)) -> None:
    """:func:`shared_posterior_check` for another entry (``POSTERIOR_CHECK``): a platform,
    whose posterior is bounded and skewed (omega_ms up to 100 rad/s is nearly the base model),
    or two shared drifts on a 15 x 15 grid.  Per set and parameter the pooled fit, its
    standard error, and the posterior's median, sd and central 90 % interval; over the sets
    the truth's coverage.  Sets where the extension is not named have no posterior and are
    counted apart.  Resumable, ``--shard K/N``;
    ``analyses/results/diagnose_pooled/shared_posterior_check_<entry>*.jsonl``.
    """
    from bayespilot import presets
    from bayespilot.diagnose import diagnose_pooled, get_extension, shared_posterior
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    import numba

    numba.set_num_threads(1)
    truth, runs, duration, seed0 = POSTERIOR_CHECK[entry]
    model = get_extension(entry).build(paper_model())
    p = dict(presets.paper_parameters("FD"), **truth)
    out_dir = DEFAULT_OUT.with_name("diagnose_pooled")
    path, every = _shard_files(out_dir, f"shared_posterior_check_{entry}", shard)
    done = {json.loads(line)["set"] for f in every() for line in f.read_text().splitlines()
            if line.strip()}
    for k in range(n):
        if k % shard[1] != shard[0] or k in done:
            continue
        recs = [simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063,
                         seed=seed0 + runs * k + j, duration=duration).recording
                for j in range(runs)]
        res = diagnose_pooled(recs, seed=0, n_bootstrap=0, n_starts=CHECK_N_STARTS,
                              candidates=[entry])
        c = res.ranking[0]
        row = {"set": k, "runs": runs, "decision": res.physics,
               "params": {m: _fit_columns(c, m) for m in truth}}
        if res.chosen is not None:
            post = shared_posterior(res, recs)
            for m in truth:
                q = post.marginals[m]
                row["params"][m].update(median=q["median"], sd=q["sd"], interval=q["interval"])
            row.update(edge_mass=post.edge_mass, widened=post.settings["widened"],
                       log_bayes_factor=post.log_bayes_factor, seconds=post.elapsed)
        _append_row(path, row)
    rows = _rows(every)
    got = [r for r in rows if "seconds" in r]
    print(f"{len(rows)} sets of {runs} runs of {duration} s with {entry} at {truth}; named "
          f"{len(got)}")
    if not got:
        return
    for m, v in truth.items():
        med = np.array([r["params"][m]["median"] for r in got])
        inside = sum(r["params"][m]["interval"][0] < v < r["params"][m]["interval"][1]
                     for r in got)
        below = sum(v <= r["params"][m]["interval"][0] for r in got)
        _print_fit_columns([r["params"][m] for r in got], m, v)
        print(f"{m} = {v}: pooled fit mean {np.mean([r['params'][m]['gls'] for r in got]):.3f}, "
              f"mean s.e. {np.mean([r['params'][m]['se'] for r in got]):.3f}; posterior "
              f"median mean {med.mean():.3f}, sd over sets {med.std(ddof=1):.3f}, mean "
              f"posterior sd {np.mean([r['params'][m]['sd'] for r in got]):.3f}; truth in the "
              f"central 90 % interval {inside}/{len(got)} (below it {below}, above "
              f"{len(got) - inside - below}; binomial sd {math.sqrt(len(got) * 0.09):.1f})")
    print(f"median time {np.median([r['seconds'] for r in got]):.1f} s; grids widened in "
          f"{sum(bool(r['widened']) for r in got)}")


#: ``--final-fit-check --entry``: the truth, run length and first seed per entry (single runs,
#: FD, K_theta = 1, K_n = 0.063).
FINAL_FIT_CHECK = {
    "motion-system-dynamics": ({"omega_ms": 6.0}, 81.92, 10_000),
    "motion-washout": ({"omega_w": 0.8}, 40.96, 100),
    "time-varying-gains": ({"drift_v": 0.6, "drift_m": 0.3}, 81.92, 20_000),
    "otolith-channel": ({"K_ot": 0.04, "h_head": 1.0}, 81.92, 30_000),
    "threshold-shape": ({"w_soft": 0.045}, 81.92, 40_000),
}


def final_fit_check(entry: str, n: int, shard: tuple[int, int] = (0, 1)) -> None:
    """The fit made after the test (``decide.final_fit``: its own noise model, delta_abs
    rescanned) against the test's fit (both at the base model's), on ``n`` single closed-loop
    runs with the entry at ``FINAL_FIT_CHECK``'s truth: per parameter the mean, spread over
    the runs, mean standard error and Wald 90 % coverage of the truth of the test's fit, of
    the refit with its own standard errors, and of what is reported (the refit's estimate,
    the test's standard error); and the coverage of the reported profile-likelihood interval
    (``diagnose.profile``; rows made before it have none and are left out of that line).  Runs
    where the test does not choose the entry are refitted the same way
    (``decide.report_final_fit``: coverage is not conditioned on the decision).  Resumable,
    ``--shard K/N``;
    ``analyses/results/diagnose/final_fit_check_<entry>*.jsonl``.
    """
    from bayespilot import presets
    from bayespilot.diagnose import decide as D
    from bayespilot.diagnose import diagnose, get_extension
    from bayespilot.model import paper_model
    from bayespilot.simulate import simulate

    import numba

    numba.set_num_threads(1)
    truth, duration, seed0 = FINAL_FIT_CHECK[entry]
    ext = get_extension(entry)
    model = ext.build(paper_model())
    p = dict(presets.paper_parameters("FD"), **truth)
    path, every = _shard_files(DEFAULT_OUT, f"final_fit_check_{entry}", shard)
    done = {r["set"] for r in _rows(every)}
    for k in range(n):
        if k % shard[1] != shard[0] or k in done:
            continue
        t0 = time.perf_counter()
        rec = simulate(model, p, task="FD", motion_gain=1.0, remnant_gain=0.063,
                       seed=seed0 + k, duration=duration).recording
        res = diagnose(rec, seed=0, n_bootstrap=0, n_starts=CHECK_N_STARTS, candidates=[entry])
        c = res.ranking[0]
        if c.refit is None and c.fit is not None:
            D.report_final_fit(c, res.base_model, rec, res.arrays["noise"])
        row = {"set": k, "decision": res.physics, "truth": truth,
               "test": {m: [c.refit["test_params"][m], c.stderr.get(m)]
                        for m in truth},
               "final": {m: [c.params[m], c.refit["own_stderr"].get(m)] for m in truth},
               "interval": {m: [c.interval[m].lower, c.interval[m].upper] for m in truth},
               "delta_abs": c.refit["delta_abs"], "seconds": time.perf_counter() - t0}
        _append_row(path, row)
    rows = list({r["set"]: r for r in reversed(_rows(every))}.values())  # a set once
    print(f"{len(rows)} runs of {duration} s with {entry} at {truth}; named "
          f"{sum(r['decision'] == entry for r in rows)}")
    for m, v in truth.items():
        # the test's fit; the refit with its own standard errors; the refit's estimate with
        # the test's standard errors (what diagnose reports)
        for label, k_est, k_se in (("test fit:", "test", "test"), ("refit:", "final", "final"),
                                   ("reported:", "final", "test")):
            est = np.array([r[k_est][m][0] for r in rows])
            se = np.array([r[k_se][m][1] for r in rows])
            inside = int(np.sum(np.abs(est - v) < 1.645 * se))
            print(f"  {m} = {v}, {label:<10} mean {est.mean():.3f}, spread "
                  f"{est.std(ddof=1):.3f}, mean s.e. {se.mean():.3f} (median "
                  f"{np.median(se):.3f}); truth within 1.645 s.e. {inside}/{len(rows)}")
        with_iv = [r for r in rows if "interval" in r]
        lo, hi = (np.array([r["interval"][m][i] for r in with_iv]) for i in (0, 1))
        print(f"  {m} = {v}, profile-likelihood 90 % interval: truth inside "
              f"{int(np.sum((lo <= v) & (v <= hi)))}/{len(with_iv)} (below it "
              f"{int(np.sum(hi < v))}, above {int(np.sum(lo > v))}); median width "
              f"{np.median(hi - lo):.3g}")
    d = np.array([r["delta_abs"] for r in rows], float)
    print(f"  delta_abs (truth {p['delta_abs']:g}): test's fit mean {d[:, 0].mean():.4f} sd "
          f"{d[:, 0].std(ddof=1):.4f}; reported fit mean {d[:, 1].mean():.4f} sd "
          f"{d[:, 1].std(ddof=1):.4f}")


def _first_cases(n: int, shard: tuple[int, int], every) -> list[dict]:
    """The first ``n`` controls and the first ``n`` effect cases of the GLS entries (case
    order: round-robin over entries and conditions), this shard's, less those already in
    the study's files (``every``)."""
    all_cases = cases()
    ctl = [c for c in all_cases if c["truth"] == "none"][:n]
    eff = [c for c in all_cases if c["truth"] not in ("none", "control-saturation")][:n]
    done = {r["id"] for r in _rows(every)}
    return [c for i, c in enumerate(ctl + eff) if i % shard[1] == shard[0]
            and c["id"] not in done]


def _rescale_bayes_factors(rows: list[dict]) -> None:
    """Rows made before the Bayes factor's error was scaled by ``nested.ERR_SCALE`` (no
    ``err_scale`` key): scale their error and re-read ``favours`` with it (the scale only
    widens the error, so an ``inconclusive`` - also one from a lost-mode bound - stays)."""
    from bayespilot.compare import decide
    from bayespilot.diagnose.nested import ERR_SCALE

    for r in rows:
        k = ERR_SCALE / r.get("err_scale", 1.0)
        if k == 1.0:
            continue
        r["log_bayes_factor_err"] *= k
        r["err_scale"] = ERR_SCALE
        if r["favours"] != "inconclusive":
            f = decide(r["log_bayes_factor"], r["log_bayes_factor_err"])
            r["favours"] = {"threshold": r["weighed"], "none": "none"}.get(f, "inconclusive")


def bayes_factor_check(n: int, shard: tuple[int, int] = (0, 1)) -> None:
    """How the nested-sampling Bayes factor (``bayes_factor``) reads against the LR decision.

    The first ``n`` controls and the first ``n`` effect cases of the GLS entries (case order:
    round-robin over entries and conditions, so a mix of sizes and of named and missed) of
    the single-run study, each diagnosed blind (no bootstrap: the decision does not use it)
    and then weighed by :func:`bayespilot.diagnose.bayes_factor` with its defaults (200 live
    points, three slice-sampling runs per model): the chosen extension, or on ``none`` the
    top-ranked candidate.  Resumable; ``--shard K/N`` splits the cases.  Writes
    ``analyses/results/diagnose_bayes_factor/bf[_KofN].jsonl`` and prints the table.
    """
    import warnings

    import numba

    from bayespilot.diagnose import bayes_factor, diagnose
    from bayespilot.recording import Recording

    numba.set_num_threads(1)
    out_dir = DEFAULT_OUT.with_name("diagnose_bayes_factor")
    out_dir.mkdir(parents=True, exist_ok=True)
    path, every = _shard_files(out_dir, "bf", shard)
    todo = _first_cases(n, shard, every)
    for c in todo:
        sim, _ = simulate_case(c)
        rec = sim.recording
        meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
        rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta, "case")
        res = diagnose(rec, seed=0, n_bootstrap=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bf = bayes_factor(res, rec, seed=0)
        cand = next(r for r in res.ranking if r.physics == bf.physics)
        row = {"id": c["id"], "truth": c["truth"], "effect": c["effect"], "task": c["task"],
               "K_theta": c["K_theta"], "F_n": c["F_n"], "decision": res.physics,
               "weighed": bf.physics, "lr_statistic": cand.statistic, "p_value": cand.p_value,
               "schwarz": bf.schwarz, "log_bayes_factor": bf.log_bayes_factor,
               "log_bayes_factor_err": bf.log_bayes_factor_err, "favours": bf.favours,
               "err_scale": bf.settings.get("err_scale", 1.0),
               "runs_base": [(r["log_z"], r["max_log_lik"], r["used"])
                             for r in bf.settings["runs_base"]],
               "runs_extended": [(r["log_z"], r["max_log_lik"], r["used"])
                                 for r in bf.settings["runs_extended"]],
               "elapsed_seconds": bf.elapsed}
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")
        print(json.dumps(row), flush=True)
    rows = sorted((json.loads(line) for f in every() for line in f.read_text().splitlines()
                   if line.strip()), key=lambda r: (r["truth"] != "none", r["id"]))
    _rescale_bayes_factors(rows)
    print(f"{'id':>4} {'truth':<24} {'effect':<14} {'decision':<24} {'weighed':<24} "
          f"{'2dlnL':>7} {'Schwarz':>8} {'ln BF':>7} {'+-':>5}  favours")
    for r in rows:
        print(f"{r['id']:4d} {r['truth']:<24} {r['effect']:<14} {r['decision']:<24} "
              f"{r['weighed']:<24} {r['lr_statistic']:7.2f} {r['schwarz']:8.2f} "
              f"{r['log_bayes_factor']:7.2f} {r['log_bayes_factor_err']:5.2f}  {r['favours']}")
    for who, sel in (("controls", [r for r in rows if r["truth"] == "none"]),
                     ("effects", [r for r in rows if r["truth"] != "none"])):
        if not sel:
            continue
        fav = [r["favours"] for r in sel]
        line = (f"{who}: {len(sel)}; ln BF favours an extension in "
                f"{sum(f not in ('none', 'inconclusive') for f in fav)}")
        if who == "effects":
            line += (f" (the truth in {sum(f == r['truth'] for f, r in zip(fav, sel))}, of them "
                     f"{sum(f == r['truth'] != r['decision'] for f, r in zip(fav, sel))} the "
                     f"LR test missed; the truth weighed in "
                     f"{sum(r['weighed'] == r['truth'] for r in sel)})")
        line += (f", 'none' in {fav.count('none')}, inconclusive in "
                 f"{fav.count('inconclusive')}; the LR test's decision right in "
                 f"{sum(r['decision'] == r['truth'] for r in sel)}; mean time "
                 f"{np.mean([r['elapsed_seconds'] for r in sel]):.0f} s")
        print(line)


def pooled_bayes_factor(n: int, runs: int = 4, shard: tuple[int, int] = (0, 1)) -> None:
    """How the pooled Laplace Bayes factor (``shared_posterior``) reads against the LR decision.

    The first ``n`` controls and the first ``n`` effect cases of the GLS entries of the
    ``runs``-run pooled study (the same runs: ``pooled_recordings``), each diagnosed again
    (no bootstrap: the decision does not use it) and then weighed by
    :func:`bayespilot.diagnose.shared_posterior`: the chosen extension, or on ``none`` the
    top-ranked GLS candidate.  Prints per case the LR statistic, the Schwarz and the Laplace
    ln BF, and which way the Bayes factor points at Jeffreys' "strong" level (|ln BF| > ln 10).
    Resumable, ``--shard K/N``;
    ``analyses/results/diagnose_pooled/bayes_factor[_KofN].jsonl``.
    """
    import warnings

    import numba

    from bayespilot.diagnose import diagnose_pooled, get_extension, shared_posterior

    numba.set_num_threads(1)
    out_dir = DEFAULT_OUT.with_name("diagnose_pooled")
    path, every = _shard_files(out_dir, "bayes_factor", shard)
    todo = _first_cases(n, shard, every)
    study = {r["case"]["id"]: r for r in load(study_folder(runs))}
    for c in todo:
        recs = pooled_recordings(c, runs)[0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = diagnose_pooled(recs, seed=0, n_bootstrap=0)
        weigh = res.chosen or next(r for r in res.ranking if r.testable
                                   and get_extension(r.physics).likelihood == "gls")
        t0 = time.perf_counter()
        post = shared_posterior(res, recs, physics=weigh.physics)
        row = {"id": c["id"], "truth": c["truth"], "effect": c["effect"], "task": c["task"],
               "K_theta": c["K_theta"], "F_n": c["F_n"], "runs": runs, "decision": res.physics,
               "study_decision": study.get(c["id"], {}).get("decision"),
               "weighed": weigh.physics, "lr_statistic": weigh.statistic,
               "p_value": weigh.p_value, "schwarz": weigh.log_bayes_factor,
               "log_bayes_factor": post.log_bayes_factor, "edge_mass": post.edge_mass,
               "gain": post.settings["bayes_factor"]["gain"],
               "widened": post.settings["widened"],
               "medians": {k: v["median"] for k, v in post.marginals.items()},
               "seconds_posterior": time.perf_counter() - t0}
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")
        print(json.dumps(row), flush=True)
    rows = sorted((json.loads(line) for f in every() for line in f.read_text().splitlines()
                   if line.strip()), key=lambda r: (r["truth"] != "none", r["id"]))
    level = math.log(10.0)
    fav = {r["id"]: (r["weighed"] if r["log_bayes_factor"] > level else
                     "none" if r["log_bayes_factor"] < -level else "inconclusive")
           for r in rows}
    # ln BF above the likelihood's gain (rows before the gain was kept: the LR statistic / 2,
    # the gain at the pooled fit): the extension's evidence is the pilot parameters' volume
    vol = {r["id"]: r["log_bayes_factor"] > r.get("gain", r["lr_statistic"] / 2) for r in rows}
    print(f"{'id':>4} {'truth':<24} {'effect':<14} {'decision':<24} {'weighed':<24} "
          f"{'2dlnL':>7} {'Schwarz':>8} {'ln BF':>7}  favours")
    for r in rows:
        print(f"{r['id']:4d} {r['truth']:<24} {r['effect']:<14} {r['decision']:<24} "
              f"{r['weighed']:<24} {r['lr_statistic']:7.2f} {r['schwarz']:8.2f} "
              f"{r['log_bayes_factor']:7.2f}{'v' if vol[r['id']] else ' '} {fav[r['id']]}")
    print("(v: ln BF above the gain in ln L, the extension's evidence is the pilot parameters' "
          "wider posterior under it)")
    same = sum(r["decision"] == r["study_decision"] for r in rows)
    print(f"decisions as in the {runs}-run study: {same}/{len(rows)}")
    for who, sel in (("controls", [r for r in rows if r["truth"] == "none"]),
                     ("effects", [r for r in rows if r["truth"] != "none"])):
        if not sel:
            continue
        f = [fav[r["id"]] for r in sel]
        line = (f"{who}: {len(sel)}; ln BF > ln 10 for an extension in "
                f"{sum(x not in ('none', 'inconclusive') for x in f)}")
        if who == "effects":
            line += (f" (the truth in {sum(x == r['truth'] for x, r in zip(f, sel))}, of them "
                     f"{sum(x == r['truth'] != r['decision'] for x, r in zip(f, sel))} the "
                     f"LR test missed)")
        line += (f", < -ln 10 in {f.count('none')}, between in {f.count('inconclusive')}; "
                 f"the LR test right in {sum(r['decision'] == r['truth'] for r in sel)}; "
                 f"Laplace - Schwarz: median "
                 f"{np.median([r['log_bayes_factor'] - r['schwarz'] for r in sel]):+.2f}")
        print(line)


def platform_band() -> None:
    """The platform's gain on the controls the Bayes-factor check weighed it on, by band.

    For each such control of ``--bayes-factor-check`` (its ``bf*.jsonl``):
    the platform candidate's d(-ln L) under the decision's GLS likelihood
    low-passed at 25 rad/s (the default), on the whole band with the model at
    the recording's rate (what the Bayes factor's likelihood sees) and on the
    whole band with the motion channel at 8x; beside the Bayes factor and the
    gain in best ln L over its nested-sampling runs.  Does the model's own
    discretisation error give the platform something to fit on the whole
    band?  ``analyses/results/diagnose_bayes_factor/platform_band.jsonl``.
    """
    import numba

    from bayespilot.diagnose import diagnose
    from bayespilot.recording import Recording

    numba.set_num_threads(1)
    out_dir = DEFAULT_OUT.with_name("diagnose_bayes_factor")
    path = out_dir / "platform_band.jsonl"
    bf = [json.loads(line) for f in sorted(out_dir.glob("bf*.jsonl"))
          for line in f.read_text().splitlines() if line.strip()]
    bf = sorted((r for r in bf if r["truth"] == "none"
                 and r["weighed"] == "motion-system-dynamics"), key=lambda r: r["id"])
    done = {json.loads(line)["id"]: json.loads(line)
            for line in (path.read_text().splitlines() if path.exists() else []) if line.strip()}
    by_id = {c["id"]: c for c in cases()}
    for r in bf:
        if r["id"] in done:
            continue
        sim, _ = simulate_case(by_id[r["id"]])
        rec = sim.recording
        rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, {}, "case")
        row = {"id": r["id"]}
        for key, opts in (("band25", {}), ("whole_1x", {"omega_c": math.inf}),
                          ("whole_8x", {"omega_c": math.inf, "oversample": 8})):
            # every candidate, as the decision sees it: the tests are against the best base
            # fit reached from any extension's fit (alone, the platform reached a better basin
            # of the base model on control 56 at 8x and "gained" 24.7)
            res = diagnose(rec, seed=0, n_bootstrap=0, **opts)
            c = next(x for x in res.ranking if x.physics == "motion-system-dynamics")
            row[key] = [float(c.delta_neg_log_lik), float(c.params.get("omega_ms", math.nan))]
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")
        done[r["id"]] = row
    print("platform on the controls the Bayes factor weighed it on: d(-ln L) (omega_ms, rad/s)")
    print(f"{'id':>4} {'25 rad/s':>14} {'whole, 1x':>14} {'whole, 8x':>14} "
          f"{'nested best-lnL gain':>21} {'ln BF':>12}")
    for r in bf:
        d = done[r["id"]]
        gain = (max(x[1] for x in r["runs_extended"]) - max(x[1] for x in r["runs_base"]))
        print(f"{r['id']:4d} " + " ".join(f"{d[k][0]:7.2f} ({d[k][1]:4.0f})"
                                          for k in ("band25", "whole_1x", "whole_8x"))
              + f" {gain:21.2f} {r['log_bayes_factor']:+6.2f} +- {r['log_bayes_factor_err']:.2f}")


def bayes_factor_repeat(ids: list[int], seeds: int = 4,
                        shard: tuple[int, int] = (0, 1), tag: str = "") -> None:
    """Is the Bayes factor's stated error its scatter?  ``bayes_factor`` on each case of
    ``ids`` again with nested-sampling seeds 1, 2, ... ``seeds`` (the check used 0), same
    diagnosis, same noise model; per case the mean and sd of ln BF over the seeds (the
    check's seed 0 included) beside the mean stated error.  Resumable, ``--shard K/N``
    splits the (case, seed) pairs; ``analyses/results/diagnose_bayes_factor/repeat*.jsonl``.
    With ``--tag SUFFIX`` a new measurement in ``diagnose_bayes_factor<SUFFIX>/`` that runs
    seed 0 too (the stored check's seed 0 and seeds 1-4 were run before 2026-11-28, when
    the nested runs of seed s were seeded s + k and neighbouring seeds shared most runs).
    """
    import warnings

    import numba

    from bayespilot.diagnose import bayes_factor, diagnose
    from bayespilot.recording import Recording

    numba.set_num_threads(1)
    out_dir = DEFAULT_OUT.with_name("diagnose_bayes_factor" + tag)
    path, every = _shard_files(out_dir, "repeat", shard)
    done = {(r["id"], r["seed"]) for f in every() for line in f.read_text().splitlines()
            if line.strip() for r in [json.loads(line)]}
    pairs = [(i, s) for i in ids for s in range(0 if tag else 1, seeds + 1)]
    todo = [p for j, p in enumerate(pairs) if j % shard[1] == shard[0] and p not in done]
    by_id = {c["id"]: c for c in cases()}
    res_of: dict = {}
    for i, s in todo:
        sim, _ = simulate_case(by_id[i])
        rec = sim.recording
        meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
        rec = Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta, "case")
        if i not in res_of:
            res_of[i] = diagnose(rec, seed=0, n_bootstrap=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            bf = bayes_factor(res_of[i], rec, seed=s)
        row = {"id": i, "seed": s, "weighed": bf.physics, "log_bayes_factor": bf.log_bayes_factor,
               "log_bayes_factor_err": bf.log_bayes_factor_err,
               "err_scale": bf.settings.get("err_scale", 1.0),
               "best_gain": max(r["max_log_lik"] for r in bf.settings["runs_extended"])
               - max(r["max_log_lik"] for r in bf.settings["runs_base"]),
               "elapsed_seconds": bf.elapsed}
        _append_row(path, row)
    first = {json.loads(line)["id"]: json.loads(line)
             for f in sorted(out_dir.glob("bf*.jsonl")) for line in f.read_text().splitlines()
             if line.strip()}
    rows = [json.loads(line) for f in every() for line in f.read_text().splitlines()
            if line.strip()]
    from bayespilot.compare import MODE_TOLERANCE

    print(f"{'id':>4} {'weighed':<24} {'ln BF over the seeds':<44} {'mean':>6} {'sd':>5} "
          f"{'mean stated err':>16}")
    pooled_var = []
    for i in ids:
        got = sorted((r for r in rows if r["id"] == i), key=lambda r: r["seed"])
        if i in first:
            got.insert(0, {"seed": 0, "log_bayes_factor": first[i]["log_bayes_factor"],
                           "log_bayes_factor_err": first[i]["log_bayes_factor_err"],
                           "err_scale": first[i].get("err_scale", 1.0),
                           "weighed": first[i]["weighed"]})
        if not got:
            continue
        v = np.array([r["log_bayes_factor"] for r in got])
        # the runs' own (stated) error, whatever scale a row was written with
        e = np.array([r["log_bayes_factor_err"] / r.get("err_scale", 1.0) for r in got])
        # a seed whose extended model never reached the base model's best ln L lost the mode
        # (bayes_factor flags it and reads it as inconclusive): not scatter, left out of sd
        lost = np.array([r.get("best_gain", 0.0) < -MODE_TOLERANCE for r in got])
        keep = v[~lost]
        sd = keep.std(ddof=1) if keep.size > 1 else float("nan")
        print(f"{i:4d} {got[0]['weighed']:<24} "
              f"{' '.join(f'{x:+.2f}' + ('*' if m else '') for x, m in zip(v, lost)):<44} "
              f"{keep.mean():+6.2f} {sd:5.2f} {e.mean():16.2f}")
        if keep.size > 1:
            pooled_var.append((keep.size - 1, keep.var(ddof=1) / e[~lost].mean() ** 2))
    if pooled_var:
        dof = sum(d for d, _ in pooled_var)
        scale = math.sqrt(sum(d * r for d, r in pooled_var) / dof)
        print(f"(* lost the mode: left out.)  sd / stated error pooled over the cases: "
              f"{scale:.2f} ({dof} degrees of freedom)")


def example_pooled() -> None:
    """The pooled walk-through of docs/diagnose.md: a weak washout, one run against four.

    Four runs (FD, K_theta = 1, F_n = 0.25, omega_w = 0.15 rad/s) diagnosed one
    at a time and together, then the shared omega_w's posterior; writes
    docs/figures/diagnose_pooled_runs.png, diagnose_pooled_candidates.png,
    diagnose_pooled_posterior.png and analyses/results/diagnose_pooled/example.txt.
    """
    import shutil

    from bayespilot.diagnose import diagnose, diagnose_pooled, shared_posterior
    from bayespilot.recording import Recording

    recs = []
    for j in range(4):
        c = {"truth": "motion-washout", "effect": "omega_w=0.15", "extra": {"omega_w": 0.15},
             "task": "FD", "K_theta": 1.0, "F_n": 0.25, "seed": 50000 + j, "id": -1}
        rec = simulate_case(c)[0].recording
        meta = {k: v for k, v in rec.metadata.items() if k != "notes"}
        recs.append(Recording(rec.signals, rec.sample_rate_hz, rec.motion_gain, rec.task, meta,
                              f"run{j + 1}"))
    lines = ["one run at a time:"]
    for rec in recs:
        r = diagnose(rec, seed=0, n_bootstrap=9)
        w = next(x for x in r.ranking if x.physics == "motion-washout")
        lines.append(f"  {rec.source}: decision {r.physics}; washout d(-ln L) = "
                     f"{w.delta_neg_log_lik:.2f}, p = {w.p_value:.3g}")
    res = diagnose_pooled(recs, seed=0, n_bootstrap=9)
    if res.physics == "motion-washout":
        # the shared omega_w's posterior (grid; each run's pilot parameters integrated out)
        shared_posterior(res, recs)
    lines += ["", res.summary()]
    text = "\n".join(lines)
    print(text)
    out = ROOT / "analyses" / "results" / "diagnose_pooled"
    out.mkdir(parents=True, exist_ok=True)
    (out / "example.txt").write_text(text + "\n")
    paths = res.report(out / "example_report")
    FIG.mkdir(parents=True, exist_ok=True)
    for key in ("runs", "candidates", "posterior"):
        if key in paths:
            shutil.copy(paths[key], FIG / f"diagnose_pooled_{key}.png")


def threshold_null() -> None:
    """threshold-shape's test on the controls alone: is its statistic chi-bar-squared?

    Runs ``diagnose`` with only that candidate (no bootstrap) on every control
    and prints the mean -ln L improvement (0.25 under 0.5 chi2(0) + 0.5 chi2(1))
    and the share of p-values below 0.05 and 0.01.
    """
    from bayespilot.diagnose import diagnose

    ds, ps = [], []
    for c in cases():
        if c["truth"] != "none":
            continue
        res = diagnose(simulate_case(c)[0].recording, seed=0, n_bootstrap=0,
                       candidates=["threshold-shape"])
        ds.append(res.ranking[0].delta_neg_log_lik)
        ps.append(res.ranking[0].p_value)
    ds, ps = np.array(ds), np.array(ps)
    print(f"threshold-shape on {ds.size} controls: mean d(-ln L) {ds.mean():.3f} (chi-bar-squared "
          f"null: 0.25), median {np.median(ds):.3f}; p < 0.05: {np.sum(ps < 0.05)}, "
          f"p < 0.01: {np.sum(ps < 0.01)}, min p {ps.min():.3g}")


#: The one-parameter boundary-null entries whose null distributions ``--pooled-null`` measures.
NULL_ENTRIES = ("motion-washout", "motion-system-dynamics")
#: The entries whose closed- and open-loop null distributions ``--open-loop-null`` measures.
OPEN_LOOP_ENTRIES = NULL_ENTRIES + ("time-varying-gains",)


def calibration_check(which: list[str], n_calibrate: int = 39) -> None:
    """The bootstrap calibration (``n_calibrate``) on the false alarms and on controls.

    ``which``: ``null<i>`` (pooled null control i of ``--pooled-null``, four runs,
    ``diagnose_pooled``), ``case<i>`` (study case i with eight runs, as ``--pooled 8``), or
    ``controls<N>`` (the chosen-candidate scale of the washout and the platform on N new
    single-run controls, whatever their decision).  One JSON line per item in
    ``analyses/results/diagnose/calibration_check.jsonl``.
    """
    from bayespilot.diagnose import SKIP_SECONDS, _prepare, diagnose_pooled, get_extension
    from bayespilot.diagnose import decide as D
    from bayespilot.diagnose.calibrate import calibrate_candidate
    from tqdm import tqdm

    out = DEFAULT_OUT / "calibration_check.jsonl"
    for item in which:
        t0 = time.perf_counter()
        if item.startswith("controls"):
            rows = []
            for i in range(int(item[len("controls"):])):
                task, kt, fn = CONDITIONS[i % len(CONDITIONS)]
                c = {"id": 0, "truth": "none", "effect": "control", "extra": {}, "task": task,
                     "K_theta": kt, "F_n": fn, "seed": 7770000 + i}
                rec = simulate_case(c)[0].recording
                run = _prepare(rec, seed=0, n_bootstrap=0, base_fit=None,
                               skip_seconds=SKIP_SECONDS, omega_c=D.OMEGA_C, n_starts=4,
                               profile_noise=False, bar=tqdm(disable=True))
                for name in ("motion-washout", "motion-system-dynamics"):
                    ext = get_extension(name)
                    res, _ = D.fit_candidate(ext, run.base_model, rec, run.base, run.noise)
                    cal = calibrate_candidate(ext, [run], [rec], res.delta_neg_log_lik,
                                              n_replicates=n_calibrate, seed=i)
                    rows.append({"control": i, "physics": name, "scale": cal.scale,
                                 "null_mean": cal.null_mean})
                    print(f"control {i} {name}: scale {cal.scale:.2f}", flush=True)
            line = {"item": item, "controls": rows}
        else:
            if item.startswith("null"):
                _, recs = null_recordings(int(item[4:]))
                nb = 0
            else:
                c = next(c for c in cases() if c["id"] == int(item[4:]))
                recs = pooled_recordings(c, 8)[0]
                nb = N_BOOTSTRAP
            res = diagnose_pooled(recs, seed=0, n_bootstrap=nb, n_calibrate=n_calibrate)
            print(res.summary(), flush=True)
            line = {"item": item, "decision": res.physics,
                    "ranking": [{"physics": r.physics, "delta_neg_log_lik": r.delta_neg_log_lik,
                                 "p_value": r.p_value, **_calibration_of(r)}
                                for r in res.ranking]}
        line["elapsed_seconds"] = time.perf_counter() - t0
        with out.open("a") as f:
            f.write(json.dumps(line) + "\n")


def _shard_files(out: Path, stem: str, shard: tuple[int, int]):
    """A resumable study's output: this shard's file ``stem[_KofN].jsonl`` in ``out`` and a
    function listing every shard's file of that stem."""
    k, n = shard
    path = out / (f"{stem}_{k}of{n}.jsonl" if n > 1 else f"{stem}.jsonl")
    mine = re.compile(rf"{stem}(_\d+of\d+)?\.jsonl")
    return path, lambda: sorted(f for f in out.glob("*.jsonl") if mine.fullmatch(f.name))


def _append_row(path: Path, row: dict) -> None:
    """Append ``row`` to a resumable study's JSON-lines file and print it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as f:
        f.write(json.dumps(row) + "\n")
    print(json.dumps(row), flush=True)


def _rows(every) -> list[dict]:
    """Every row of every shard's file (``every`` from :func:`_shard_files`)."""
    return [json.loads(line) for f in every() for line in f.read_text().splitlines()
            if line.strip()]


def _null_line(name: str, label: str, d: np.ndarray, p: np.ndarray, null: float) -> str:
    """One row of a null study: mean -ln L improvement (2 s.e.) against its null mean, and the
    shares of p below 0.05 and 0.01 with their two-binomial-sd bands."""
    m = d.size
    band = lambda q: 2.0 * np.sqrt(q * (1 - q) / m)  # noqa: E731
    return (f"{name:<24} {label:<8} n={m:4d}  mean d(-ln L) {d.mean():.3f} +- "
            f"{2 * d.std(ddof=1) / np.sqrt(m):.3f} (null {null:g})  "
            f"p<0.05: {np.mean(p < 0.05):.3f} (0.05 +- {band(0.05):.3f})  "
            f"p<0.01: {np.mean(p < 0.01):.3f} (0.01 +- {band(0.01):.3f})")


def pooled_null(n_cases: int, shard: tuple[int, int] = (0, 1)) -> None:
    """The pooled tests' null distributions beside one run's, on the same runs.

    ``n_cases`` new pooled controls (the paper's model, no extra physics;
    conditions in turn over CONDITIONS, seeds apart from every other study's),
    four runs each.  Per case: each run's base stages without bootstrap, then
    for each entry of NULL_ENTRIES the pooled test (shared parameter) and the
    one-run test of every run, from the same base fits.  One JSON line per case
    in ``analyses/results/diagnose_pooled/null_study.jsonl`` (resumable; the
    shards append to their own files); prints the mean -ln L improvement
    (0.25 under 0.5 chi2(0) + 0.5 chi2(1)) and the shares of p below 0.05
    and 0.01 with their binomial bands.
    """
    from tqdm import tqdm

    from bayespilot.diagnose import SKIP_SECONDS, _prepare
    from bayespilot.diagnose import decide as D
    from bayespilot.diagnose.catalogue import get_extension
    from bayespilot.diagnose.pooled import _pooled_candidate

    out = ROOT / "analyses" / "results" / "diagnose_pooled"
    out.mkdir(parents=True, exist_ok=True)
    k, n = shard
    one_pass = "null_study_rebase" if REBASE else "null_study"
    stem = one_pass + (f"_np{NOISE_PASSES}" if NOISE_PASSES != 1 else "")
    path, files = _shard_files(out, stem, shard)
    done = {json.loads(line)["id"] for f in files()
            for line in f.read_text().splitlines() if line.strip()}
    todo = [i for i in range(n_cases) if i % n == k and i not in done]
    for i in tqdm(todo, desc="pooled null", unit="case"):
        c, recs = null_recordings(i)
        task, kt, fn = c["task"], c["K_theta"], c["F_n"]
        runs = [_prepare(rec, seed=j, n_bootstrap=0, base_fit=None, skip_seconds=SKIP_SECONDS,
                         omega_c=D.OMEGA_C, n_starts=4, profile_noise=False,
                         bar=tqdm(disable=True), noise_passes=NOISE_PASSES)
                for j, rec in enumerate(recs)]
        row = {"id": i, "task": task, "K_theta": kt, "F_n": fn}
        for name in NULL_ENTRIES:
            ext = get_extension(name)
            pooled, extra = _pooled_candidate(ext, runs, recs)
            single = [D.fit_candidate(ext, r.base_model, rec, r.base, r.noise)[0]
                      for rec, r in zip(recs, runs)]
            if REBASE:
                # the tests against the base model's best fit found, as diagnose does it:
                # each run's base refitted from the candidate's fit (decide.null_refit)
                model = runs[0].base_model
                best = []
                for rec, r, s_, q in zip(recs, runs, single, extra[0] if extra else [None] * 4):
                    refs = [r.base.neg_log_lik]
                    for start in ([q] if q is not None else []) + [s_.fit.params if s_.fit
                                                                   else None]:
                        if start is None:
                            continue
                        got = D.null_refit_from(ext, model, rec, start, r.noise)
                        if got is not None:
                            refs.append(got.neg_log_lik)
                    best.append(min(refs))
                    D.retest(s_, ext, min(refs))
                D.retest(pooled, ext, float(sum(best)))
            row[name] = {"pooled": [pooled.delta_neg_log_lik, pooled.p_value,
                                    pooled.params.get(ext.new_parameters[0])],
                         "single": [[s.delta_neg_log_lik, s.p_value,
                                     s.params.get(ext.new_parameters[0])] for s in single]}
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")
    rows = [json.loads(line) for f in files()
            for line in f.read_text().splitlines() if line.strip()]
    print(f"{len(rows)} pooled controls of 4 runs (and their {4 * len(rows)} runs one at a time)")
    for name in NULL_ENTRIES:
        for label, vals in (("pooled", [r[name]["pooled"] for r in rows]),
                            ("one run", [s for r in rows for s in r[name]["single"]])):
            d = np.array([v[0] for v in vals])
            p = np.array([v[1] for v in vals])
            print(_null_line(name, label, d, p, 0.25) + f"  at the bound: {np.mean(d <= 0.0):.2f}")
    if NOISE_PASSES != 1:
        # the same controls (same ids, same recordings) with one pass of the noise model
        _, one = _shard_files(out, one_pass, (0, 1))
        ref = {r["id"]: r for f in one() for line in f.read_text().splitlines()
               if line.strip() for r in [json.loads(line)]}
        both = [r for r in rows if r["id"] in ref]
        print(f"paired with one noise pass on the same {len(both)} pooled controls:")
        for name in NULL_ENTRIES:
            a = np.array([ref[r["id"]][name]["pooled"][0] for r in both])
            b = np.array([r[name]["pooled"][0] for r in both])
            x = a - b
            print(f"  {name:<24} pooled mean d: one pass {a.mean():.3f}, {NOISE_PASSES} passes "
                  f"{b.mean():.3f}; difference {x.mean():+.3f} +- "
                  f"{2 * x.std() / np.sqrt(max(1, x.size)):.3f}; p < 0.01: "
                  f"{sum(ref[r['id']][name]['pooled'][1] < 0.01 for r in both)} -> "
                  f"{sum(r[name]['pooled'][1] < 0.01 for r in both)}")


def open_loop_null(n_cases: int, shard: tuple[int, int] = (0, 1)) -> None:
    """Is the closed loop what makes the washout's null tail heavy? The same runs with and without
    feedback of the remnant.

    Eq. 4 treats e and theta_ddot_m as inputs, but in the closed loop they
    carry the remnant's past (remnant -> u -> plant -> e, motion), most at
    the low frequencies where the loop gain is high: the washout's only
    freedom.  Per case a control run A (the paper's model, a condition of
    CONDITIONS in turn) and the *open-loop* run u_A - n_A + n_B, its
    deterministic pilot output with the remnant n_B of another run of the
    condition, independent of A's e and motion.  Both get diagnose's base
    stages (no bootstrap) and the one-run tests of OPEN_LOOP_ENTRIES from their
    own base fits.  One JSON line per case in
    ``analyses/results/diagnose/open_loop_null.jsonl`` (resumable; a case
    whose line lacks an entry is done again, and its newer line counts);
    prints per entry and loop the mean -ln L improvement (its null mean: 0.25
    under the chi-bar-squared null, df / 2 under chi2(df)) and the shares of p
    below 0.05 and 0.01 with their binomial bands.
    """
    from tqdm import tqdm

    from bayespilot.diagnose import SKIP_SECONDS, _prepare
    from bayespilot.diagnose import decide as D
    from bayespilot.diagnose.catalogue import get_extension
    from bayespilot.recording import Recording

    DEFAULT_OUT.mkdir(parents=True, exist_ok=True)
    k, n = shard
    path, files = _shard_files(DEFAULT_OUT, "open_loop_null", shard)

    def load():
        rows = {}
        for f in files():
            for line in f.read_text().splitlines():
                if line.strip():
                    r = json.loads(line)
                    if all(e in r for e in OPEN_LOOP_ENTRIES) or r["id"] not in rows:
                        rows[r["id"]] = r
        return rows

    done = {i for i, r in load().items() if all(e in r for e in OPEN_LOOP_ENTRIES)}
    todo = [i for i in range(n_cases) if i % n == k and i not in done]
    for i in tqdm(todo, desc="open-loop null", unit="case"):
        task, kt, fn = CONDITIONS[i % len(CONDITIONS)]
        c = {"id": 200000 + i, "truth": "none", "effect": "control", "extra": {},
             "task": task, "K_theta": kt, "F_n": fn}
        a = simulate_case(dict(c, seed=700000 + 2 * i))[0]
        b = simulate_case(dict(c, seed=700001 + 2 * i))[0]
        ra = a.recording
        closed = Recording(ra.signals, ra.sample_rate_hz, ra.motion_gain, ra.task, {}, "closed")
        opened = closed.with_signals(u=ra.u - a.remnant + b.remnant)
        row = {"id": i, "task": task, "K_theta": kt, "F_n": fn}
        for label, rec in (("closed", closed), ("open", opened)):
            run = _prepare(rec, seed=0, n_bootstrap=0, base_fit=None, skip_seconds=SKIP_SECONDS,
                           omega_c=D.OMEGA_C, n_starts=4, profile_noise=False,
                           bar=tqdm(disable=True))
            for name in OPEN_LOOP_ENTRIES:
                ext = get_extension(name)
                res = D.fit_candidate(ext, run.base_model, rec, run.base, run.noise)[0]
                row.setdefault(name, {})[label] = [res.delta_neg_log_lik, res.p_value,
                                                   res.params.get(ext.new_parameters[0])]
        with open(path, "a") as f:
            f.write(json.dumps(row) + "\n")
    rows = list(load().values())
    print(f"{len(rows)} controls, each closed-loop and with its remnant replaced (open loop)")
    for name in OPEN_LOOP_ENTRIES:
        have = [r for r in rows if name in r]
        null = 0.25 if get_extension(name).boundary_null else get_extension(name).df / 2
        for label in ("closed", "open"):
            d = np.array([r[name][label][0] for r in have])
            p = np.array([r[name][label][1] for r in have])
            print(_null_line(name, label, d, p, null))


def critical_value(ext) -> float:
    """The critical 2 d(-ln L) of extension ``ext``'s test at diagnose's per-candidate level
    (alpha over six candidates; the chi-bar-squared value for a one-parameter boundary null)."""
    from scipy import stats

    from bayespilot.diagnose import ALPHA

    level = ALPHA / 6
    if ext.boundary_null and ext.df == 1:
        return float(stats.chi2.isf(2.0 * level, 1))
    return float(stats.chi2.isf(level, ext.df))


def _mean_square(neg_log_lik: float, m: int) -> float:
    """The whitened residual's mean square of a GLS fit from its -ln L over m samples
    (-ln L = m/2 (ln s2 + 1), the noise level profiled out)."""
    return math.exp(2.0 * neg_log_lik / m - 1.0)


def conditional_power(ext, stat_before: float, runs_before: int, runs: int, lam: float) -> float:
    """Power of the oracle test with ``runs`` runs when ``runs_before`` of them are already
    recorded and gave the statistic ``stat_before`` (2 d(-ln L) of the right extension).

    The cases that a study with fewer runs missed are a selection: their first runs'
    statistics are low, and the unconditional power (``optimal_power`` with ``runs`` x
    lambda) overstates what more runs can do for them.  With the signed root of the
    statistic as the score (Z ~ N(sqrt(R lambda), 1) for R runs), the pooled score is
    Z = sqrt(R0 / R) Z0 + sqrt((R - R0) / R) Z1, Z0 = +sqrt(``stat_before``) (the root's
    sign is lost when the fit ends at the null; taking it positive is optimistic) and
    Z1 ~ N(sqrt((R - R0) lambda), 1) from the new runs; for two parameters the old score
    is taken along the new runs' mean (optimistic too).
    """
    from scipy import stats

    a, b = math.sqrt(runs_before / runs), math.sqrt((runs - runs_before) / runs)
    m = a * math.sqrt(max(stat_before, 0.0)) + b * math.sqrt(max((runs - runs_before) * lam, 0.0))
    crit = critical_value(ext)
    if ext.boundary_null and ext.df == 1:
        return float(stats.norm.sf((math.sqrt(crit) - m) / b))
    return float(stats.ncx2.sf(crit / b ** 2, ext.df, max((m / b) ** 2, 1e-12)))


def optimal_power(ext, lam: float) -> float:
    """Power of the likelihood-ratio test of extension ``ext`` when 2 d(-ln L) is noncentral
    chi2(df, ``lam``), at diagnose's per-candidate level (alpha over six candidates; the
    chi-bar-squared critical value for a one-parameter boundary null)."""
    from scipy import stats

    return float(stats.ncx2.sf(critical_value(ext), ext.df, max(lam, 1e-12)))


#: Starts of delta_abs (IPUT) for the oracle's base fit of the noise-free extended response.
ORACLE_DELTA_STARTS = tuple(0.0025 * k for k in range(9))


def _best_base(wl, fit):
    """The base model's best fit to the noise-free extended response: ``fit`` (delta_abs
    scanned, the others refined) refined in every parameter, and refined again from each
    delta_abs in ``ORACLE_DELTA_STARTS``; the best.

    The noncentrality is the misfit of the base model's *best* approximation.  The scan
    alone overstated it for the soft threshold: its crisp imitation sits at another
    delta_abs with the pilot parameters moved too (a corner of w_soft = 0.045 has the
    offset of a crisp threshold of 0.035 at large |x|), and the crisp dead zone's
    likelihood has several basins in delta_abs (mean lambda of the eight w_soft = 0.045
    cases 3.64 scanned, 2.91 refined, 2.78 from these starts; other entries within 6 %).
    """
    from bayespilot.diagnose import decide as D

    names = wl.model.parameter_names
    best = fit
    for start in (fit.params, *({**fit.params, "delta_abs": d} for d in ORACLE_DELTA_STARTS)):
        got = D._gls_refine(wl, start, names)
        if got.neg_log_lik < best.neg_log_lik:
            best = got
    return best


def oracle_case(c: dict, rec, extra: dict,
                bands: tuple[str, ...] = ("lowpass", "fullband")) -> dict:
    """:func:`oracle`'s numbers for one effect case: its extension's ``df`` and, per band
    (``lowpass``: the decision likelihood's 25 rad/s; ``fullband``), the noncentrality
    ``lambda`` and the oracle test's ``power``."""
    from bayespilot.diagnose import SKIP_SECONDS, _base_gls, get_extension
    from bayespilot.diagnose import decide as D
    from bayespilot.fit.fast import fit_fast
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model
    from bayespilot import presets
    from bayespilot.recording import Recording

    base_model = paper_model()
    ext = get_extension(c["truth"])
    truth = dict(presets.paper_parameters(c["task"]), **extra)
    y_ext = Likelihood(ext.build(base_model), rec).response(truth)
    clean = Recording(dict(rec.signals, u=y_ext), rec.sample_rate_hz, rec.motion_gain, rec.task,
                      {}, "clean")
    fit = fit_fast(rec, base_model, seed=0, n_starts=4, profile_step=0.005, discard=0.0)
    start = {q: v for q, v in fit.params.items() if q in base_model.parameter_names}
    skip = int(round(SKIP_SECONDS * rec.sample_rate_hz))
    row: dict = {"df": ext.df}
    for tag in bands:
        om = {"lowpass": D.OMEGA_C, "fullband": math.inf}[tag]
        _, noise, base = _base_gls(rec, base_model, start, skip=skip, omega_c=om)
        s2 = _mean_square(base.neg_log_lik, D.Whitened(base_model, rec, noise).m)
        base_truth = {q: truth[q] for q in base_model.parameter_names}
        wl, misfit = D.fit_base_gls(base_model, clean, base_truth, noise)
        misfit = _best_base(wl, misfit)
        lam = wl.m * _mean_square(misfit.neg_log_lik, wl.m) / s2
        row[tag] = {"lambda": lam, "power": optimal_power(ext, lam)}
    return row


def oracle(shard: tuple[int, int] = (0, 1)) -> None:
    """How many concealed cases could any likelihood-ratio test name at the decision's level?

    Per effect case: the base stages of ``diagnose`` (fast fit, noise model, GLS
    fit) on the case's recording give the innovation variance s2 of the
    decision likelihood; then the true extended model's noise-free response
    at the true parameters, y_ext (on the recording's own e and motion), is
    fitted by the base model under the same noise model (its best fit:
    delta_abs scanned, then every parameter refined from the scan and from
    starts of delta_abs over 0-0.02, :func:`_best_base`).  Its whitened misfit
    over s2 is the noncentrality lambda of the likelihood-ratio statistic
    (2 d(-ln L) ~ noncentral chi2(df, lambda) for a small effect), so the
    power of the oracle test of that extension at the decision's
    per-candidate level (alpha over six candidates, the chi-bar-squared
    critical value for the boundary nulls) is 1 - ncx2.cdf(crit, df, lambda).
    Summed over the concealed cases it is the number that a test of the
    right extension, knowing which one to test, would name on average: about
    the most any test at that level can do (noncentral chi2 approximation).  Both the default
    decision likelihood (low-passed at 25 rad/s) and the whole band are
    measured.  Saturation is left out (flat tops decide it; it is found at
    every size).  One JSON line per case in ``OUT/oracle.jsonl`` (resumable).
    """
    from tqdm import tqdm

    import numba

    numba.set_num_threads(1)
    k, n = shard
    out = DEFAULT_OUT / (f"oracle_{k}of{n}.jsonl" if n > 1 else "oracle.jsonl")
    done = {json.loads(line)["id"] for f in DEFAULT_OUT.glob("oracle*.jsonl")
            for line in f.read_text().splitlines() if line.strip()}
    todo = [c for c in cases() if c["truth"] not in ("none", "control-saturation")
            and c["id"] % n == k and c["id"] not in done]
    for c in tqdm(todo, desc="oracle", unit="case"):
        sim, extra = simulate_case(c)
        row = {"id": c["id"], "truth": c["truth"], "effect": c["effect"], "task": c["task"],
               "K_theta": c["K_theta"], "F_n": c["F_n"],
               **oracle_case(c, sim.recording, extra)}
        with open(out, "a") as f:
            f.write(json.dumps(row) + "\n")
    rows = [json.loads(line) for f in sorted(DEFAULT_OUT.glob("oracle*.jsonl"))
            for line in f.read_text().splitlines() if line.strip()]
    _oracle_table(rows)


def _oracle_table(rows: list[dict]) -> None:
    """The oracle's expected naming against the default study's, per entry and size; also
    the expected naming with R runs pooled (lambda times R), and the figure
    ``docs/figures/diagnose_oracle.png``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure
    from bayespilot.diagnose import get_extension

    global OUT
    keep, OUT = OUT, DEFAULT_OUT
    try:
        study = {r["case"]["id"]: r for r in load()}
        mark_concealed(list(study.values()))
    finally:
        OUT = keep

    def power(r, tag, runs=1):
        return optimal_power(get_extension(r["truth"]), runs * r[tag]["lambda"])

    print("Concealed cases: named by the default study, and the expected number the oracle test "
          "of the true extension\nwould name (sum of its powers at the level alpha/6, one run)")
    print(f"{'entry / size':<38}{'n':>4}{'named':>7}{'oracle 25 rad/s':>17}"
          f"{'oracle full band':>18}{'median lambda 25/full':>24}")
    tot = {"n": 0, "named": 0, "low": 0.0, "full": 0.0}
    panels = {}
    for e, sizes in ALL_EFFECTS.items():
        for lab, _ in sizes:
            sel = [r for r in rows if r["truth"] == e and r["effect"] == lab
                   and study.get(r["id"], {}).get("concealed")]
            if not sel:
                continue
            named = sum(study[r["id"]]["decision"] == e for r in sel)
            low = sum(power(r, "lowpass") for r in sel)
            full = sum(power(r, "fullband") for r in sel)
            lam = (np.median([r["lowpass"]["lambda"] for r in sel]),
                   np.median([r["fullband"]["lambda"] for r in sel]))
            print(f"{e + ' ' + lab:<38}{len(sel):>4}{named:>7}{low:>17.1f}"
                  f"{full:>18.1f}{lam[0]:>12.1f} / {lam[1]:<8.1f}")
            panels.setdefault(e, []).append((lab, len(sel), named, low,
                                             [sum(power(r, "lowpass", R) for r in sel)
                                              for R in (4, 8)]))
            tot["n"] += len(sel)
            tot["named"] += named
            tot["low"] += low
            tot["full"] += full
    print(f"{'all concealed (saturation left out)':<38}{tot['n']:>4}{tot['named']:>7}"
          f"{tot['low']:>17.1f}{tot['full']:>18.1f}")
    conc = [r for r in rows if study.get(r["id"], {}).get("concealed")]
    for R in (2, 4, 8, 16):
        print(f"  R = {R:>2} runs pooled (lambda x R, 25 rad/s): expected "
              f"{sum(power(r, 'lowpass', R) for r in conc):.1f} of {len(conc)}")
    ncols = 3
    nrows = math.ceil((len(panels) + 1) / ncols)  # (a cell left for the legend)
    fig, axes = plt.subplots(nrows, ncols, figsize=(7.0, 2.9 * nrows + 0.5), sharey=True,
                             squeeze=False, layout="constrained")
    for ax, (e, row) in zip(axes.flat, panels.items()):
        x = np.arange(len(row))
        n = np.array([v[1] for v in row], float)
        ax.plot(x, [v[3] for v in row] / n, "k--", lw=1, label="oracle test, 1 run")
        ax.plot(x, [v[4][0] for v in row] / n, ":", color="0.45", lw=1,
                label="oracle test, 4 runs")
        ax.plot(x, [v[4][1] for v in row] / n, "-.", color="0.65", lw=1,
                label="oracle test, 8 runs")
        for xi, v in zip(x, row):
            k, m = v[2], v[1]
            lo, hi = _wilson_95(k, m)
            ax.errorbar(xi, k / m, yerr=[[k / m - lo], [hi - k / m]], fmt="o", ms=4,
                        capsize=2, color="C0", lw=1,
                        label="diagnose, 1 run (95 % Wilson interval)" if xi == 0 else None)
        # the counts under the sizes, off the oracle's lines: named / concealed cases
        ax.set_xticks(x, [f"{v[0].split('=')[-1]}\n{v[2]}/{v[1]}" for v in row],
                      fontsize="small")
        ax.set_xlim(-0.5, len(row) - 0.5)
        ax.set_xlabel(_effect_axis(e), fontsize="small")
        ax.set_title(e, fontsize=9)
        ax.set_ylim(-0.03, 1.15)
        ax.grid(alpha=0.3, axis="y")
    for ax in axes[:, 0]:
        ax.set_ylabel("share named (concealed cases)")
    spare = list(axes.flat)[len(panels):]
    handles, labels = axes.flat[0].get_legend_handles_labels()
    for ax in spare:
        ax.set_visible(False)
    spare[0].set_visible(True)
    spare[0].axis("off")
    spare[0].legend(handles, labels, loc="center", fontsize="small", frameon=False)
    fig.suptitle("diagnose against the oracle test at its false-alarm level\n(lines: the expected "
                 "share the likelihood-ratio test of the true extension names;\nunder each "
                 "size: concealed cases named / concealed cases)", fontsize=9)
    FIG.mkdir(parents=True, exist_ok=True)
    save_figure(fig, FIG / "diagnose_oracle.png")
    plt.close(fig)


#: ``--power-round``: sizes near where the oracle test's one-run power reaches 0.9 (the
#: oracle's median power 0.7-1.0 at the study's nearest sizes), to count the restated target
#: (of the concealed effects that the oracle test names with power >= 0.9, how many
#: ``diagnose`` names) on more cases than the study's 16.  No size of the soft threshold or
#: of a 0.15-0.3 drift reaches it in one run.
POWER_EFFECTS = {
    "motion-system-dynamics": [("omega_ms=6", {"omega_ms": 6.0}), ("omega_ms=8", {"omega_ms": 8.0})],
    "motion-washout": [("omega_w=0.3", {"omega_w": 0.3}), ("omega_w=0.45", {"omega_w": 0.45})],
    "otolith-channel": [("K_ot=0.02", {"K_ot": 0.02, "h_head": 1.0}),
                        ("K_ot=0.03", {"K_ot": 0.03, "h_head": 1.0})],
    "time-varying-gains": [("drift=0.6", {"drift_v": 0.6, "drift_m": 0.6}),
                           ("drift=0.8", {"drift_v": 0.8, "drift_m": 0.8})],
}
POWER_OUT = DEFAULT_OUT.with_name("diagnose_power")


def power_cases() -> list[dict]:
    """The power round's cases (every size in every condition, new seeds 9000 + id)."""
    order = _round(POWER_EFFECTS, 0, 20261128)
    for j, c in enumerate(order):
        c["id"] = j
        c["seed"] = 9000 + j
    return order


def power_round(shard: tuple[int, int] = (0, 1)) -> None:
    """Run ``diagnose`` blind on each of :func:`power_cases` (as the study does) and the oracle's
    noncentrality on its recording; then, with the study's own cases, count the restated
    target: of the concealed effects (against the study's 48 controls) whose optimal
    one-run test has power >= 0.9 at the decision's level, how many are named.  Resumable,
    ``--shard K/N``; ``analyses/results/diagnose_power/``."""
    import numba

    numba.set_num_threads(1)
    POWER_OUT.mkdir(parents=True, exist_ok=True)
    k, n = shard
    todo = [c for c in power_cases() if c["id"] % n == k
            and not (POWER_OUT / f"{case_key(c)}.json").exists()]
    print(f"{len(todo)} case(s) to run", flush=True)
    for c in todo:
        r = run_case(c)
        sim, extra = simulate_case(c)
        r["oracle"] = oracle_case(c, sim.recording, extra, bands=("lowpass",))["lowpass"]
        path = POWER_OUT / f"{case_key(c)}.json"
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(r, indent=1, default=float))
        tmp.replace(path)
        print(f"{case_key(c)}: {r['decision']}, oracle power {r['oracle']['power']:.2f} "
              f"({r['elapsed_seconds']:.0f} s)", flush=True)
    power_summary()


def power_summary() -> None:
    """Print the power round beside the study's cases (:func:`power_round`)."""
    new = load(POWER_OUT)
    study = load(DEFAULT_OUT)
    controls = [r for r in study if r["case"]["truth"] == "none"]
    mark_concealed(controls + new)
    orc = {json.loads(line)["id"]: json.loads(line) for f in DEFAULT_OUT.glob("oracle*.jsonl")
           for line in f.read_text().splitlines() if line.strip()}
    mark_concealed(study)
    old = [dict(r, oracle=orc[r["case"]["id"]]["lowpass"]) for r in study
           if r["case"]["id"] in orc]
    print(f"power round: {len(new)} of {len(power_cases())} cases")
    print(f"{'entry / size':<36}{'n':>4}{'concealed':>11}{'power>=0.9':>12}{'both':>6}"
          f"{'named (both)':>14}{'named (all)':>13}")
    for e, sizes in POWER_EFFECTS.items():
        for lab, _ in sizes:
            sel = [r for r in new if r["case"]["truth"] == e and r["case"]["effect"] == lab]
            if not sel:
                continue
            both = [r for r in sel if r["concealed"] and r["oracle"]["power"] >= 0.9]
            print(f"{e + ' ' + lab:<36}{len(sel):>4}{sum(bool(r['concealed']) for r in sel):>11}"
                  f"{sum(r['oracle']['power'] >= 0.9 for r in sel):>12}{len(both):>6}"
                  f"{sum(r['decision'] == e for r in both):>14}"
                  f"{sum(r['decision'] == e for r in sel):>13}")
    wrong = [r for r in new if r["decision"] not in ("none", r["case"]["truth"])]
    print(f"every case of the round: named {sum(r['decision'] == r['case']['truth'] for r in new)}"
          f" of {len(new)}, concealed {sum(bool(r['concealed']) for r in new)}; wrongly named "
          f"{len(wrong)}" + "".join(f"; {case_key(r['case'])} as {r['decision']} (oracle power "
                                    f"{r['oracle']['power']:.2f})" for r in wrong))
    for name, rs in (("the study", old), ("the power round", new), ("both", old + new)):
        sel = [r for r in rs if r["concealed"] and r["oracle"]["power"] >= 0.9]
        named = sum(r["decision"] == r["case"]["truth"] for r in sel)
        wrong = sum(r["decision"] not in ("none", r["case"]["truth"]) for r in sel)
        print(f"{name}: concealed with oracle power >= 0.9: named {named} of {len(sel)}"
              + (f" ({100 * named / len(sel):.0f} %)" if sel else "")
              + f", wrongly named {wrong}; expected by the oracle test "
              f"{sum(r['oracle']['power'] for r in sel):.1f}")


def model_error(n_controls: int = 16, oversample: int = 1) -> None:
    """How visible the likelihood's own discretisation error is to the decision likelihood.

    On the first ``n_controls`` controls: the model's error at the true
    parameters, err = (u - remnant) - u_hat(truth) (the simulator integrates
    at 1 kHz, the likelihood runs at 100 Hz), is whitened by the noise model
    of the residual u - u_hat(truth) for several low-pass cut-offs; its
    whitened sum of squares over the innovation variance is the noncentrality
    lambda_err that this deterministic error adds to a likelihood-ratio
    statistic (an extension that can mimic it gains up to lambda_err / 2 in
    -ln L on correct-model data).
    """
    from bayespilot import presets
    from bayespilot.diagnose import SKIP_SECONDS
    from bayespilot.diagnose import decide as D
    from bayespilot.likelihood import Likelihood
    from bayespilot.model import paper_model

    model = paper_model(oversample=oversample)
    cuts = (math.inf, 100.0, 50.0, D.OMEGA_C)
    print("lambda_err of the model's discretisation error at the truth, per low-pass cut-off "
          f"(rad/s; inf: the whole band); likelihood: {model.name}")
    print(f"{'control':<22}" + "".join(f"{c:>10g}" for c in cuts))
    lams = []
    for c in [c for c in cases() if c["truth"] == "none"][:n_controls]:
        sim, _ = simulate_case(c)
        rec = sim.recording
        y = Likelihood(model, rec).response(presets.paper_parameters(c["task"]))
        err = (rec.u - sim.remnant) - y
        eps = rec.u - y
        skip = int(round(SKIP_SECONDS * rec.sample_rate_hz))
        row = []
        for om in cuts:
            nm = D.noise_model(eps, rec.dt, skip=skip, omega_c=om)
            row.append(float(np.sum(nm.whiten(err) ** 2) / np.mean(nm.whiten(eps) ** 2)))
        lams.append(row)
        label = f"{c['task']} K_theta {c['K_theta']:g} F_n {c['F_n']:g}"
        print(f"{label:<22}" + "".join(f"{v:>10.2f}" for v in row))
    lams = np.array(lams)
    print(f"{'median':<22}" + "".join(f"{v:>10.2f}" for v in np.median(lams, axis=0)))
    print(f"{'max':<22}" + "".join(f"{v:>10.2f}" for v in lams.max(axis=0)))


class _Twins:
    """Open-loop twins of a pooled case's runs with fresh remnants (``--simulated-power``,
    ``--delta-freedom``): the runs' recorded inputs fixed, u = the true model's noise-free
    output on them plus the remnant of another closed-loop run of the case; set ``r``
    borrows the remnants of seeds pooled_seed + OPEN_LOOP_SEED + 1000 (r + 1), set -1
    those of the ``--open-loop`` study."""

    def __init__(self, case_id: int, runs: int):
        from bayespilot import presets
        from bayespilot.diagnose import get_extension
        from bayespilot.likelihood import Likelihood
        from bayespilot.model import paper_model

        by_id = {c["id"]: c for c in cases()}
        if case_id not in by_id or by_id[case_id]["truth"] in ("none", "control-saturation"):
            raise SystemExit(f"case {case_id}: not an effect case with a GLS test")
        self.case = c = by_id[case_id]
        self.base_model = paper_model()
        self.ext = get_extension(c["truth"])
        self.model = self.ext.build(self.base_model)
        sims = [simulate_case(dict(c, seed=pooled_seed(c, j))) for j in range(runs)]
        self.extra = sims[0][1]
        self.truth = dict(presets.paper_parameters(c["task"]), **self.extra)
        self.recordings = [s.recording for s, _ in sims]
        self.clean = [Likelihood(self.model, rec).response(self.truth) for rec in self.recordings]

    def run(self, j: int, r: int):
        from bayespilot.recording import Recording

        c, rec = self.case, self.recordings[j]
        n = simulate_case(dict(c, seed=pooled_seed(c, j) + OPEN_LOOP_SEED + 1000 * (r + 1)))[0]
        return Recording(dict(rec.signals, u=self.clean[j] + n.remnant), rec.sample_rate_hz,
                         rec.motion_gain, rec.task, {}, f"run{j + 1}")

    def base_stages(self, rec, seed: int):
        """diagnose's base fit, noise model and GLS fit of one recording."""
        from bayespilot.diagnose import SKIP_SECONDS, _base_gls
        from bayespilot.diagnose import decide as D
        from bayespilot.fit.fast import fit_fast

        fit = fit_fast(rec, self.base_model, seed=seed, n_starts=4, profile_step=0.005,
                       discard=0.0)  # as diagnose's base fit
        start = {q: v for q, v in fit.params.items() if q in self.base_model.parameter_names}
        _, noise, base = _base_gls(rec, self.base_model, start,
                                   skip=int(round(SKIP_SECONDS * rec.sample_rate_hz)),
                                   omega_c=D.OMEGA_C)
        return noise, base

    def best_imitation(self, j: int, noise):
        """The base model's best fit to run j's noise-free extended response (``_best_base``)."""
        from bayespilot.diagnose import decide as D
        from bayespilot.recording import Recording

        rec = self.recordings[j]
        clean = Recording(dict(rec.signals, u=self.clean[j]), rec.sample_rate_hz,
                          rec.motion_gain, rec.task, {}, "clean")
        wl, fit = D.fit_base_gls(self.base_model, clean,
                                 {q: self.truth[q] for q in self.base_model.parameter_names},
                                 noise)
        return wl, _best_base(wl, fit)


def _power_file(case_id: int, runs: int, stem: str, shard: tuple[int, int]) -> Path:
    folder = DEFAULT_OUT.with_name(f"diagnose_pooled{runs}_openloop")
    folder.mkdir(parents=True, exist_ok=True)
    k, n = shard
    return folder / (f"{stem}_{case_id}_{k}of{n}.jsonl" if n > 1 else f"{stem}_{case_id}.jsonl")


def simulated_power(case_id: int, runs: int, n_sets: int, shard: tuple[int, int]) -> None:
    """The pooled test's real power on one case against the noncentral chi2's.

    ``n_sets`` sets of ``runs`` open-loop twins of the case (:class:`_Twins`, set r
    its own remnants), each diagnosed as the study does (``diagnose_pooled``, every
    candidate, B = 0: the decision does not use the bootstrap).  The oracle's
    lambda is computed run by run on set -1's noise models.  One line per set in
    ``analyses/results/diagnose_pooled<R>_openloop/power_<id>*.jsonl`` (resumable);
    the summary reads every shard's file.
    """
    import warnings

    from scipy import stats
    from tqdm import tqdm

    from bayespilot.diagnose import diagnose_pooled
    from bayespilot.diagnose import decide as D

    import numba

    numba.set_num_threads(1)
    tw = _Twins(case_id, runs)
    out = _power_file(case_id, runs, "power", shard)
    files = sorted(out.parent.glob(f"power_{case_id}*.jsonl"))
    rows = [json.loads(line) for f in files for line in f.read_text().splitlines() if line.strip()]
    if not any("lambda" in row for row in rows) and shard[0] == 0:
        lam = []
        for j in range(runs):
            rec = tw.run(j, -1)
            noise, base = tw.base_stages(rec, 0)
            s2 = _mean_square(base.neg_log_lik, D.Whitened(tw.base_model, rec, noise).m)
            wl, fit = tw.best_imitation(j, noise)
            lam.append(wl.m * _mean_square(fit.neg_log_lik, wl.m) / s2)
        rows.append({"lambda": lam})
        with open(out, "a") as f:
            f.write(json.dumps(rows[-1]) + "\n")
    done = {row["set"] for row in rows if "set" in row}
    todo = [r for r in range(n_sets) if r % shard[1] == shard[0] and r not in done]
    for r in tqdm(todo, desc=f"case {case_id}, {runs} twins", unit="set"):
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = diagnose_pooled([tw.run(j, r) for j in range(runs)], seed=0, n_bootstrap=0)
        cand = next(x for x in res.ranking if x.physics == tw.ext.name)
        row = {"set": r, "decision": res.physics, "stat": cand.statistic, "p": cand.p_value,
               "params": cand.params, "rebase_gain": sum(g["gain"] for g in res.settings["rebased"]),
               "seconds": time.perf_counter() - t0}
        rows.append(row)
        with open(out, "a") as f:
            f.write(json.dumps(row) + "\n")
    sets = [row for row in rows if "set" in row]
    lam = next((row["lambda"] for row in rows if "lambda" in row), None)
    if not sets or lam is None:
        return
    st = np.array([row["stat"] for row in sets])
    named = sum(row["decision"] == tw.ext.name for row in sets)
    big = float(sum(lam))
    power = optimal_power(tw.ext, big)
    crit = math.sqrt(critical_value(tw.ext))
    print(f"case {case_id} ({case_key(tw.case)}), {runs} open-loop twins, {len(sets)} sets:")
    print(f"  lambda per run {np.round(lam, 2).tolist()}, in all {big:.1f}")
    print(f"  2 d(-ln L): mean {st.mean():.2f} +- {st.std() / math.sqrt(len(st)):.2f} (noncentral "
          f"chi2: {1 + big:.1f}); named {named} of {len(sets)} ({named / len(sets):.2f}; "
          f"noncentral chi2: {power:.2f}); other names: "
          f"{sorted({row['decision'] for row in sets} - {tw.ext.name, 'none'}) or 'none'}")
    if tw.ext.boundary_null and tw.ext.df == 1 and 0 < named < len(sets):
        implied = (crit - stats.norm.isf(named / len(sets))) ** 2
        print(f"  the lambda that gives the measured power: {implied:.1f} ({implied / big:.0%} of "
              "the oracle's)")
    print(f"  the base model refitted from the extensions' fits gained a mean "
          f"{np.mean([row['rebase_gain'] for row in sets]):.2f} in -ln L per set")


def delta_freedom(case_id: int, runs: int, n_sets: int, shard: tuple[int, int]) -> None:
    """What delta_abs's freedom buys the crisp dead zone on twins of a soft-threshold case.

    Per run of ``n_sets`` sets of open-loop twins (:class:`_Twins`): the soft model at
    the true width (every other parameter refitted, from the truth and from the crisp
    fit) against the crisp dead zone with delta_abs held at delta* (its value in the
    base model's best imitation of the noise-free soft response, the others refitted)
    and with delta_abs free (scanned, refined, and multi-started over delta_abs,
    ``_best_base``).  Linear theory: 2 d(-ln L) has mean lambda + 1 against the first,
    lambda against the second, and freeing delta_abs gains 1 (one parameter).  One
    line per run in ``.../delta_freedom_<id>*.jsonl`` (resumable by set).
    """
    from tqdm import tqdm

    from bayespilot.diagnose import decide as D

    import numba

    numba.set_num_threads(1)
    tw = _Twins(case_id, runs)
    if tw.case["truth"] != "threshold-shape":
        raise SystemExit(f"--delta-freedom: case {case_id} is not a threshold-shape case")
    out = _power_file(case_id, runs, "delta_freedom", shard)
    files = sorted(out.parent.glob(f"delta_freedom_{case_id}*.jsonl"))
    rows = [json.loads(line) for f in files for line in f.read_text().splitlines() if line.strip()]
    done = {row["set"] for row in rows}
    bm, em = tw.base_model, tw.model
    names = bm.parameter_names
    but_delta = tuple(q for q in names if q != "delta_abs")
    but_w = tuple(q for q in em.parameter_names if q != "w_soft")
    todo = [r for r in range(n_sets) if r % shard[1] == shard[0] and r not in done]
    for r in tqdm(todo, desc=f"case {case_id}, delta's freedom", unit="set"):
        for j in range(runs):
            rec = tw.run(j, r)
            noise, base = tw.base_stages(rec, j)
            wl_clean, star = tw.best_imitation(j, noise)
            wl, wle = D.Whitened(bm, rec, noise), D.Whitened(em, rec, noise)
            s2 = _mean_square(base.neg_log_lik, wl.m)
            fixed = D._gls_refine(wl, star.params, but_delta)
            free = _best_base(wl, D.refine_threshold(bm, rec, base, noise))
            free = min(free, D._gls_refine(wl, fixed.params, names), key=lambda f: f.neg_log_lik)
            soft = min(D._gls_refine(wle, tw.truth, but_w),
                       D._gls_refine(wle, {**free.params, "w_soft": tw.extra["w_soft"]}, but_w),
                       key=lambda f: f.neg_log_lik)
            row = {"set": r, "run": j,
                   "lambda": wl_clean.m * _mean_square(star.neg_log_lik, wl_clean.m) / s2,
                   "delta_star": star.params["delta_abs"], "delta_free": free.params["delta_abs"],
                   "T_fixed": 2.0 * (fixed.neg_log_lik - soft.neg_log_lik),
                   "T_free": 2.0 * (free.neg_log_lik - soft.neg_log_lik),
                   "delta_gain": 2.0 * (fixed.neg_log_lik - free.neg_log_lik)}
            rows.append(row)
            with open(out, "a") as f:
                f.write(json.dumps(row) + "\n")
    if not rows:
        return

    def mean(key):
        v = np.array([row[key] for row in rows])
        return f"{v.mean():.2f} +- {v.std() / math.sqrt(len(v)):.2f}"

    lam = np.mean([row["lambda"] for row in rows])
    gain = np.array([row["delta_gain"] for row in rows])
    print(f"case {case_id}, {len(rows)} twin runs ({len({row['set'] for row in rows})} sets), "
          f"mean lambda {lam:.2f}:")
    print(f"  2 d(-ln L), crisp with delta_abs at delta* against soft at the true width: "
          f"{mean('T_fixed')} (theory lambda + 1 = {lam + 1:.2f})")
    print(f"  the same with delta_abs free: {mean('T_free')} (theory lambda = {lam:.2f})")
    print(f"  what freeing delta_abs gains: {mean('delta_gain')} (one parameter: 1); more than 3 "
          f"in {int((gain > 3).sum())} of {len(gain)} runs")


def width_profile(ids: list[int]) -> None:
    """-ln L of the soft dead zone over fixed corner widths, against the crisp dead zone.

    For threshold-shape cases that ``diagnose`` missed: is the improvement
    small at every width (the data), or only where the fit ended (the optimiser)?
    Each width is a start and stays fixed; the other parameters are refitted
    as ``diagnose`` refits them, on the base fit's noise model.
    """
    from bayespilot.diagnose import SKIP_SECONDS, _base_gls, get_extension
    from bayespilot.diagnose import decide as D
    from bayespilot.fit.fast import fit_fast
    from bayespilot.model import paper_model

    by_id = {c["id"]: c for c in cases()}
    widths = (0.001, 0.004, 0.01, 0.02, 0.03, 0.045, 0.05)
    print("-ln L(crisp) - -ln L(soft, w_soft fixed), the others refitted:")
    print(f"{'case':<48}" + "".join(f"{w:>8g}" for w in widths))
    for i in ids:
        c = by_id[i]
        if c["truth"] != "threshold-shape":
            raise SystemExit(f"case {i} is not a threshold-shape case")
        rec = simulate_case(c)[0].recording
        base_model = paper_model()
        # diagnose's base fit and its GLS refit under the base residual's noise model
        fit = fit_fast(rec, base_model, seed=0, n_starts=4, profile_step=0.005, discard=0.0)
        start = {k: v for k, v in fit.params.items() if k in base_model.parameter_names}
        _, noise, base = _base_gls(rec, base_model, start,
                                   skip=int(round(SKIP_SECONDS * rec.sample_rate_hz)))
        model = get_extension("threshold-shape").build(base_model)
        wl = D.Whitened(model, rec, noise)
        names = tuple(n for n in model.parameter_names if n != "w_soft")
        row = []
        for w in widths:
            f = D._gls_refine(wl, {**base.params, "w_soft": w}, names)
            row.append(base.neg_log_lik - f.neg_log_lik)
        print(f"{case_key(c):<48}" + "".join(f"{d:+8.2f}" for d in row))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--chunk", type=int, default=None, help="run at most N unfinished cases")
    ap.add_argument("--tag", default="", metavar="SUFFIX",
                    help="append SUFFIX to the results folder (a rerun beside the stored one)")
    ap.add_argument("--summarize", action="store_true", help="only print and plot the summary")
    ap.add_argument("--example", action="store_true",
                    help="diagnose the docs' example (a concealed washout) and write its figures")
    ap.add_argument("--threshold-null", action="store_true",
                    help="threshold-shape's test alone on the controls: its null distribution")
    ap.add_argument("--example-pooled", action="store_true",
                    help="a weak washout in four runs, diagnosed one at a time and pooled; "
                         "writes docs/figures/diagnose_pooled_*.png")
    ap.add_argument("--profile-noise", action="store_true",
                    help="diagnose with profile_noise=True (the AR noise model re-estimated "
                         "with each fit); results in analyses/results/diagnose_profile_noise/, "
                         "figures with the suffix _profile_noise")
    ap.add_argument("--pooled", type=int, default=0, metavar="R",
                    help="diagnose R runs of each case's condition together (diagnose_pooled, "
                         "new seeds); results in analyses/results/diagnose_pooled/, figures "
                         "with the suffix _pooled (R = 4) or diagnose_pooledR/, _pooledR")
    ap.add_argument("--misses-of", type=int, default=0, metavar="R",
                    help="run only the cases that the stored study with R runs per case (1: "
                         "one run) decided wrongly: what more data changes, first")
    ap.add_argument("--open-loop", action="store_true",
                    help="with --pooled R: each run an open-loop twin (the true model's output "
                         "on the recorded inputs plus another run's remnant); results get the "
                         "suffix _openloop")
    ap.add_argument("--entry", metavar="NAME",
                    help="run only this catalogue entry's cases (or none: the controls); "
                         "with --shared-posterior-check, the entry whose posterior is checked "
                         "(motion-washout, motion-system-dynamics, time-varying-gains, "
                         "otolith-channel)")
    ap.add_argument("--shard", default="0/1", metavar="K/N",
                    help="run only the cases whose id is K modulo N (two processes: 0/2 and 1/2); "
                         "with --misses-of or --entry, whose rank in that selection is")
    ap.add_argument("--pooled-null", type=int, default=0, metavar="N",
                    help="N new pooled controls (four runs each): the pooled washout and "
                         "platform tests' null distributions beside one run's on the same runs")
    ap.add_argument("--rebase", action="store_true",
                    help="with --pooled-null: test against the base model's best fit found, "
                         "refitted from each candidate's fit as diagnose does (null_study_rebase)")
    ap.add_argument("--omega-c", type=float, default=None, metavar="RAD_S",
                    help="cut-off of the decision likelihood's low-pass (inf: the whole band, "
                         "no decimation); results and figures get the suffix _fullband (inf) "
                         "or _omega<RAD_S>")
    ap.add_argument("--noise-passes", type=int, default=1, metavar="P",
                    help="diagnose(noise_passes=P): the AR noise model estimated P times (2: "
                         "again from the GLS base fit's residual); results and figures get "
                         "the suffix _np<P>")
    ap.add_argument("--power-round", action="store_true",
                    help="diagnose and the oracle on new cases near the oracle test's 0.9 power "
                         "(the restated target on more cases); analyses/results/diagnose_power/")
    ap.add_argument("--oracle", action="store_true",
                    help="per effect case, the expected power of the likelihood-ratio test of the "
                         "true extension (noncentrality from the noise-free extended model), "
                         "beside the study's naming; analyses/results/diagnose/oracle.jsonl")
    ap.add_argument("--model-error", action="store_true",
                    help="the noncentrality that the likelihood's discretisation error adds to "
                         "the decision likelihood on 16 controls, per low-pass cut-off")
    ap.add_argument("--oversample", type=int, default=1, metavar="M",
                    help="the likelihood's vestibular channel at M times the recording's rate "
                         "(default 1): diagnose(oversample=M), and --model-error's likelihood; "
                         "results and figures get the suffix _os<M>")
    ap.add_argument("--calibrate", type=int, default=0, metavar="B",
                    help="diagnose(n_calibrate=B): the chosen candidate's test calibrated by B "
                         "bootstrap replicates; results and figures get the suffix _cal<B>; a "
                         "case the stored uncalibrated study decided none is copied, not rerun")
    ap.add_argument("--calibration-check", metavar="ITEMS",
                    help="diagnose with the bootstrap calibration (B from --calibrate, default "
                         "39) on these comma-separated items: null<i> (a pooled null control), "
                         "case<i> (a study case, eight runs), controls<N> (the washout's and "
                         "platform's scale on N single-run controls)")
    ap.add_argument("--compare-runs", action="store_true",
                    help="one run, four and eight pooled on the cases all three studies have "
                         "done (after --pooled 8)")
    ap.add_argument("--locate-null", action="store_true",
                    help="the located evidence's bootstrap p-values (B = 39) on the 48 "
                         "controls: calibrated? (analyses/results/diagnose/locate_null*.jsonl)")
    ap.add_argument("--posterior-check", type=int, default=0, metavar="N",
                    help="GLS standard errors and posteriors of the chosen washout against "
                         "their spread over N runs (analyses/results/diagnose/"
                         "posterior_check.jsonl)")
    ap.add_argument("--width-profile", metavar="IDS",
                    help="-ln L over fixed soft-threshold widths for these threshold-shape "
                         "case ids (comma-separated), against the crisp dead zone")
    ap.add_argument("--open-loop-null", type=int, default=0, metavar="N",
                    help="N controls, closed loop and with the remnant replaced (open loop): "
                         "the washout's, platform's and drifts' null distributions in each "
                         "(analyses/results/diagnose/open_loop_null*.jsonl)")
    ap.add_argument("--simulated-power", type=int, default=None, metavar="ID",
                    help="with --pooled R: the pooled test's power on --sets sets of R open-loop "
                         "twins of case ID with fresh remnants, against the noncentral chi2's "
                         "(analyses/results/diagnose_pooled<R>_openloop/power_<ID>*.jsonl)")
    ap.add_argument("--delta-freedom", type=int, default=None, metavar="ID",
                    help="with --pooled R: per run of --sets sets of twins of soft-threshold "
                         "case ID, what delta_abs's freedom buys the crisp dead zone "
                         "(.../delta_freedom_<ID>*.jsonl)")
    ap.add_argument("--bayes-factor-check", type=int, default=0, metavar="N",
                    help="the nested-sampling Bayes factor on the first N controls and N effect "
                         "cases (resumable, --shard)")
    ap.add_argument("--bayes-factor-repeat", metavar="IDS",
                    help="bayes_factor again on these case ids (comma-separated) with "
                         "--seeds more nested-sampling seeds: scatter against stated error "
                         "(resumable, --shard)")
    ap.add_argument("--seeds", type=int, default=4, metavar="N",
                    help="seeds for --bayes-factor-repeat (default 4)")
    ap.add_argument("--shared-posterior-check", type=int, default=0, metavar="N",
                    help="N sets of two runs with a shared washout: shared_posterior's "
                         "intervals against the truth (resumable, --shard)")
    ap.add_argument("--weak", action="store_true",
                    help="with --shared-posterior-check: four 81.92-s runs, omega_w 0.3 rad/s, "
                         "F_n 0.25")
    ap.add_argument("--final-fit-check", type=int, default=0, metavar="N",
                    help="N single runs with --entry (motion-system-dynamics, motion-washout, "
                         "time-varying-gains, otolith-channel, threshold-shape): the reported "
                         "fit against the test's fit "
                         "(resumable, --shard)")
    ap.add_argument("--pooled-bayes-factor", type=int, default=0, metavar="N",
                    help="the pooled Laplace Bayes factor (shared_posterior) on the first N "
                         "controls and N effect cases of the four-run study (resumable, "
                         "--shard)")
    ap.add_argument("--platform-band", action="store_true",
                    help="the platform's gain by band (25 rad/s, whole at 1x and 8x) on the "
                         "controls --bayes-factor-check weighed it on")
    ap.add_argument("--sets", type=int, default=48, metavar="N",
                    help="sets of twins for --simulated-power / --delta-freedom (default 48)")
    args = ap.parse_args(argv)
    global OUT, FIG_SUFFIX, PROFILE_NOISE, POOLED, OMEGA_C, OVERSAMPLE, REBASE, N_CALIBRATE, \
        NOISE_PASSES, OPEN_LOOP
    if args.pooled:
        if args.pooled < 2 or args.profile_noise:
            ap.error("--pooled R needs R >= 2 and does not combine with --profile-noise")
        # four runs (the study of docs/diagnose-evidence.md) keep the plain names; other R their own
        tag = "_pooled" if args.pooled == 4 else f"_pooled{args.pooled}"
        OUT = ROOT / "analyses" / "results" / f"diagnose{tag}"
        FIG_SUFFIX, POOLED = tag, args.pooled
    if args.profile_noise:
        OUT = ROOT / "analyses" / "results" / "diagnose_profile_noise"
        FIG_SUFFIX, PROFILE_NOISE = "_profile_noise", True
    if args.omega_c is not None:
        if not args.omega_c > 0:
            ap.error(f"--omega-c must be > 0 rad/s (inf: the whole band), got {args.omega_c!r}")
        OMEGA_C = args.omega_c
        tag = "_fullband" if math.isinf(OMEGA_C) else f"_omega{OMEGA_C:g}"
        OUT = OUT.with_name(OUT.name + tag)
        FIG_SUFFIX += tag
    if args.oversample != 1:
        OVERSAMPLE = args.oversample
        OUT = OUT.with_name(OUT.name + f"_os{OVERSAMPLE}")
        FIG_SUFFIX += f"_os{OVERSAMPLE}"
    if args.noise_passes != 1:
        from bayespilot.diagnose import MAX_NOISE_PASSES

        if not 1 <= args.noise_passes <= MAX_NOISE_PASSES:
            ap.error(f"--noise-passes: 1 to {MAX_NOISE_PASSES}, got {args.noise_passes}")
        NOISE_PASSES = args.noise_passes
        OUT = OUT.with_name(OUT.name + f"_np{NOISE_PASSES}")
        FIG_SUFFIX += f"_np{NOISE_PASSES}"
    if args.calibrate:
        N_CALIBRATE = args.calibrate
        OUT = OUT.with_name(OUT.name + f"_cal{N_CALIBRATE}")
        FIG_SUFFIX += f"_cal{N_CALIBRATE}"
    if args.open_loop:
        if not args.pooled:
            ap.error("--open-loop needs --pooled R")
        OPEN_LOOP = True
        OUT = OUT.with_name(OUT.name + "_openloop")
        FIG_SUFFIX += "_openloop"
    if args.entry is not None and args.entry not in ("none", *EFFECTS):
        ap.error(f"--entry: one of none, {', '.join(EFFECTS)}; got {args.entry!r}")
    if args.tag:
        if not re.fullmatch(r"[A-Za-z0-9_.-]+", args.tag):
            ap.error(f"--tag: letters, digits, _ . - only, got {args.tag!r}")
        OUT = OUT.with_name(OUT.name + args.tag)
        FIG_SUFFIX += args.tag
    try:
        k, n = (int(v) for v in args.shard.split("/"))
        if not 0 <= k < n:
            raise ValueError
    except ValueError:
        ap.error(f"--shard: K/N with 0 <= K < N, got {args.shard!r}")
    if args.simulated_power is not None or args.delta_freedom is not None:
        if not args.pooled or args.sets < 1:
            ap.error("--simulated-power / --delta-freedom need --pooled R and --sets >= 1")
        if args.simulated_power is not None:
            simulated_power(args.simulated_power, args.pooled, args.sets, (k, n))
        else:
            delta_freedom(args.delta_freedom, args.pooled, args.sets, (k, n))
        return 0
    if args.example:
        example()
        return 0
    if args.threshold_null:
        threshold_null()
        return 0
    if args.example_pooled:
        example_pooled()
        return 0
    if args.pooled_null:
        REBASE = args.rebase
        pooled_null(args.pooled_null, (k, n))
        return 0
    if args.open_loop_null:
        open_loop_null(args.open_loop_null, (k, n))
        return 0
    if args.oracle:
        oracle((k, n))
        return 0
    if args.power_round:
        if args.summarize:
            power_summary()
        else:
            power_round((k, n))
        return 0
    if args.model_error:
        model_error(oversample=args.oversample)
        return 0
    if args.calibration_check:
        calibration_check(args.calibration_check.split(","), args.calibrate or 39)
        return 0
    if args.compare_runs:
        res = compare_runs()
        (DEFAULT_OUT.with_name("diagnose_pooled8") / "compare_runs.json").write_text(
            json.dumps(res, indent=1))
        return 0
    if args.locate_null:
        locate_null(shard=(k, n))
        return 0
    if args.bayes_factor_check:
        bayes_factor_check(args.bayes_factor_check, (k, n))
        return 0
    if args.bayes_factor_repeat:
        bayes_factor_repeat([int(x) for x in args.bayes_factor_repeat.split(",")], args.seeds,
                            (k, n), args.tag)
        return 0
    if args.shared_posterior_check:
        if args.entry is not None and args.entry != "motion-washout":
            if args.entry not in POSTERIOR_CHECK:
                ap.error(f"--shared-posterior-check checks motion-washout, "
                         f"{', '.join(POSTERIOR_CHECK)}; not {args.entry}")
            shared_posterior_check_entry(args.entry, args.shared_posterior_check, (k, n))
        else:
            shared_posterior_check(args.shared_posterior_check, shard=(k, n), weak=args.weak)
        return 0
    if args.final_fit_check:
        if args.entry not in FINAL_FIT_CHECK:
            ap.error(f"--final-fit-check needs --entry, one of {', '.join(FINAL_FIT_CHECK)}")
        final_fit_check(args.entry, args.final_fit_check, (k, n))
        return 0
    if args.pooled_bayes_factor:
        pooled_bayes_factor(args.pooled_bayes_factor, shard=(k, n))
        return 0
    if args.platform_band:
        platform_band()
        return 0
    if args.posterior_check:
        posterior_check(args.posterior_check)
        return 0
    if args.width_profile:
        width_profile([int(v) for v in args.width_profile.split(",")])
        return 0
    only = wrong_ids(args.misses_of) if args.misses_of else None
    if args.entry is not None:
        only = {c["id"] for c in cases() if c["truth"] == args.entry
                and (only is None or c["id"] in only)}
    if not args.summarize:
        run(args.chunk, (k, n), only)
    if OPEN_LOOP and args.entry is not None:
        open_loop_table(args.entry)
        return 0
    if args.misses_of:
        misses_table(args.misses_of)
        return 0
    summarize()
    return 0


if __name__ == "__main__":
    sys.exit(main())
