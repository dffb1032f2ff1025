"""The recording checks' statistics on clean simulated runs and on motion logged after a filter.

``bayespilot.recording.questionable`` checks a recording's columns against each
other when it is read (docs/recording-format.md, "Checks of the columns against
each other"). This script simulates the paper's FD and FT tasks at 50, 100 and
1000 Hz with remnant fractions 0, 0.15 and 0.3 (18 runs of 81.92 s, K_theta 1)
and prints

* on the clean runs: the smallest R^2 of each sign identity, the range of the
  judged coefficients (a column of the other sign gives -1), and the largest
  spike statistic against its two limits (``SPIKE_K`` times the run's
  sample-to-sample scatter, ``SPIKE_SD`` standard deviations of u);
* with theta_ddot_m passed through a washout or a motion platform before the
  check (bilinear discretisation, optional delay): the motion identity's R^2
  per task, which decides whether its sign is judged (``SIGN_R2_MIN``);
* the bias check of theta_ddot_m (``BIAS_DRIFT``, ``BIAS_Z``): its drift ratio
  on these runs, on 6 shorter ones (25, 30 and 40.96 s, 100 Hz, K_theta 0.75)
  and on both after the filters above, then how many of the clean runs a
  bias of 0.3, 0.5, 1 and 3 % of std(theta_ddot_m) (either sign) is warned on;
  and the largest drift ratio of 20-, 25- and 30-s windows cut anywhere from
  the 81.92-s runs (10 per run and length; with ``--bias``, also 40 per record
  from the corpus's 60- and 81.92-s records, the docs' windows).

Usage::

    python analyses/recording_checks.py            # about a minute on one core
    python analyses/recording_checks.py --bias     # + the bias check's 96-record corpus

``--bias`` adds the corpus the bias check's limits were set on (FD and FT,
50 to 1000 Hz, K_theta 0.5 to 1, F_n 0 to 0.3, 10 to 81.92 s, a washout in
the pilot or not, one seed each; some 8 minutes): the largest drift ratio
per record length, clean and after the filters, and the detection rates
per length. Nothing is written. The tables in docs/recording-format.md are
this script's output.
"""
from __future__ import annotations

import dataclasses
import sys
import warnings

import numpy as np
from scipy import signal

from bayespilot import recording as R
from bayespilot.simulate import TrackingTask, simulate

RATES = (50.0, 100.0, 1000.0)
TASKS = ("FD", "FT")
REMNANT = (0.0, 0.15, 0.3)
W, Z = 5.0, 0.7
#: name -> (num, den, delay in s) of what theta_ddot_m is logged after
FILTERS = {
    "washout omega_w 1 rad/s, zeta_w 0.7": ([1.0, 0.0, 0.0], [1.0, 1.4, 1.0], 0.0),
    "washout omega_w 4 rad/s, zeta_w 0.7": ([1.0, 0.0, 0.0], [1.0, 5.6, 16.0], 0.0),
    "MotionSystem 5 rad/s, zeta 0.7, + 30 ms": ([W * W], [1.0, 2 * Z * W, W * W], 0.03),
    "first-order lag 5/(s + 5), + 30 ms": ([5.0], [1.0, 5.0], 0.03),
}


def _runs():
    for task in TASKS:
        for rate in RATES:
            for fn in REMNANT:
                tt = dataclasses.replace(TrackingTask.paper(task, 1.0), sample_rate_hz=rate)
                yield (task, rate, fn), simulate(task=tt, remnant_fraction=fn, seed=7).recording


SHORT = (25.0, 30.0, 40.96)
BIASES = (0.003, 0.005, 0.01, 0.03)


def _short_runs():
    for task in TASKS:
        for duration in SHORT:
            tt = dataclasses.replace(TrackingTask.paper(task, 0.75), sample_rate_hz=100.0)
            yield (task, duration), simulate(task=tt, remnant_fraction=0.15, seed=7,
                                             duration=duration).recording


def _bias_corpus():
    """The bias check's corpus: 96 records, one seed each (docs/recording-format.md)."""
    from bayespilot import diagnose
    from bayespilot.model import paper_model

    washout = diagnose.get_extension("motion-washout").build(paper_model())
    rates, gains, fns = (50.0, 100.0, 200.0, 1000.0), (0.5, 0.75, 1.0), (0.0, 0.15, 0.3)
    durations = (10.0, 20.0, 23.7, 30.0, 40.96, 60.0, 81.92)
    for i in range(96):
        task, rate, kt = TASKS[i % 2], rates[(i // 2) % 4], gains[i % 3]
        fn, duration, wo = fns[(i // 3) % 3], durations[(i * 5) % 7], (i // 7) % 2 == 1
        tt = dataclasses.replace(TrackingTask.paper(task, kt), sample_rate_hz=rate)
        yield duration, simulate(washout if wo else None, task=tt, remnant_fraction=fn,
                                 seed=100 + i, duration=duration).recording


def _bias_caught(rec, share):
    a = rec.theta_ddot_m
    return R._motion_bias_problem(rec.with_signals(theta_ddot_m=a + share * np.std(a))) \
        is not None


def _bias_report(runs, label):
    """Print the largest drift ratio per record length (clean, and after FILTERS) and how many
    runs a bias of each size in BIASES, either sign, is warned on. ``runs``: (length, rec)."""
    worst, worst_f, caught, n = {}, {}, {}, {}
    for duration, rec in runs:
        st = R._motion_bias_statistics(rec)
        if st is None:  # shorter than BIAS_MIN_S: not judged; its ratios measured all the same
            judged = R.BIAS_MIN_S
            try:
                R.BIAS_MIN_S = 0.0
                st = R._motion_bias_statistics(rec)
                sf = [R._motion_bias_statistics(_logged_after(rec, *f))["ratio"]
                      for f in FILTERS.values()]
            finally:
                R.BIAS_MIN_S = judged
            if st is not None:
                worst[duration] = max(worst.get(duration, 0.0), st["ratio"])
                worst_f[duration] = max(worst_f.get(duration, 0.0), *sf)
            continue
        assert R._motion_bias_problem(rec) is None, (duration, st)
        worst[duration] = max(worst.get(duration, 0.0), st["ratio"])
        for num, den, delay in FILTERS.values():
            sf = R._motion_bias_statistics(_logged_after(rec, num, den, delay))
            worst_f[duration] = max(worst_f.get(duration, 0.0), sf["ratio"])
        n[duration] = n.get(duration, 0) + 2
        for share in BIASES:
            key = (duration, share)
            caught[key] = caught.get(key, 0) + _bias_caught(rec, share) + _bias_caught(rec, -share)
    print(f"\nthe bias check of theta_ddot_m, {label}: largest drift ratio (limit "
          f"{R.BIAS_DRIFT:g}; from {R.BIAS_MIN_S:g} s), and the runs a bias of "
          + ", ".join(f"{b:.1%}" for b in BIASES) + " of std(theta_ddot_m) is warned on")
    for d in sorted(worst):
        print(f"  {d:6g} s: clean {worst[d]:.3f}, after a filter {worst_f[d]:.3f};  "
              + ("  ".join(f"{caught[(d, b)]}/{n[d]}" for b in BIASES) if d in n
                 else "not judged"))


def _windows(runs, length, count=10):
    """``count`` records of ``length`` s cut at even steps from each of ``runs``."""
    for rec in runs:
        m = int(round(length * rec.sample_rate_hz))
        for off in np.linspace(0, rec.n_samples - m, count).astype(int):
            sig = {k: np.asarray(v)[off:off + m] for k, v in rec.signals.items()}
            sig["t"] = np.arange(m) / rec.sample_rate_hz
            yield R.Recording(sig, rec.sample_rate_hz, rec.motion_gain, rec.task)


def _logged_after(rec, num, den, delay):
    b, a = signal.bilinear(num, den, fs=rec.sample_rate_hz)
    x = signal.lfilter(b, a, rec.theta_ddot_m)
    n = int(round(delay * rec.sample_rate_hz))
    x = np.concatenate([np.zeros(n), x[:x.size - n]])
    return dataclasses.replace(rec, signals=dict(rec.signals, theta_ddot_m=x))


def main() -> None:
    warnings.simplefilter("ignore")
    r2 = {}
    coefs = {}
    spike_k = spike_sd = 0.0
    filtered = {}
    long_runs = []
    for (task, rate, fn), rec in _runs():
        long_runs.append((rec.duration, rec))
        for name, st in R._sign_statistics(rec).items():
            r2[name] = min(r2.get(name, 1.0), st["r2"])
            judged = st["coef"][st["share"] >= R.SIGN_TERM_MIN]
            lo, hi = coefs.get(name, (np.inf, -np.inf))
            coefs[name] = (min(lo, judged.min()), max(hi, judged.max()))
        r, scale, sd = R._spike_statistics(rec)
        spike_k = max(spike_k, float(r.max() / scale))
        spike_sd = max(spike_sd, float(r.max() / sd))
        for name, (num, den, delay) in FILTERS.items():
            st = R._sign_statistics(_logged_after(rec, num, den, delay))["motion"]
            filtered.setdefault((name, task), []).append(st["r2"])
    print(f"clean runs ({len(TASKS) * len(RATES) * len(REMNANT)}): sign identities")
    for name in r2:
        print(f"  {name:7s} smallest R^2 {r2[name]:.4f}, judged coefficients "
              f"{coefs[name][0]:.3f} to {coefs[name][1]:.3f}")
    print(f"  spikes: largest difference {spike_k:.1f} times the scatter (limit {R.SPIKE_K:g}), "
          f"{spike_sd:.2f} standard deviations of u (limit {R.SPIKE_SD:g})")
    print(f"\ntheta_ddot_m logged after a filter: the motion identity's R^2 "
          f"(judged from {R.SIGN_R2_MIN:g})")
    for name in FILTERS:
        fd, ft = (np.array(filtered[(name, t)]) for t in TASKS)
        print(f"  {name:42s} FD {fd.min():.3f} to {fd.max():.3f}   "
              f"FT {ft.min():.3f} to {ft.max():.3f}")
    _bias_report(long_runs + [(d, rec) for (_, d), rec in _short_runs()],
                 "the runs above and 6 shorter ones")
    judged = R.BIAS_MIN_S  # (20 s too, under BIAS_MIN_S: why it is not judged there)
    worst = {}
    try:
        R.BIAS_MIN_S = 0.0
        for length in (20.0, 25.0, 30.0):
            worst[length] = max(R._motion_bias_statistics(w)["ratio"]
                                for w in _windows([r for _, r in long_runs], length))
    finally:
        R.BIAS_MIN_S = judged
    print("  windows cut anywhere from the 81.92-s runs, largest drift ratio: "
          + ", ".join(f"{length:g} s {ratio:.3f}" for length, ratio in worst.items()))
    if "--bias" in sys.argv[1:]:
        corpus = list(_bias_corpus())
        _bias_report(corpus, "the 96-record corpus")
        # the docs' windows: 40 per record from the corpus's 60- and 81.92-s records
        longest = [r for d, r in corpus if d >= 60.0]
        worst = {}
        try:
            R.BIAS_MIN_S = 0.0
            for length in (20.0, 25.0, 30.0):
                worst[length] = max(R._motion_bias_statistics(w)["ratio"]
                                    for w in _windows(longest, length, count=40))
        finally:
            R.BIAS_MIN_S = judged
        print(f"  windows cut anywhere from the corpus's {len(longest)} records of 60 and "
              f"81.92 s ({40 * len(longest)} per length), largest drift ratio: "
              + ", ".join(f"{length:g} s {ratio:.3f}" for length, ratio in worst.items()))


if __name__ == "__main__":
    main()
