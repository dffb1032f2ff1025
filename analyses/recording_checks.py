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
  per task, which decides whether its sign is judged (``SIGN_R2_MIN``).

Usage::

    python analyses/recording_checks.py

About a minute on one core; nothing is written. The R^2 table in
docs/recording-format.md is this script's output.
"""
from __future__ import annotations

import dataclasses
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
    for (task, rate, fn), rec in _runs():
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


if __name__ == "__main__":
    main()
