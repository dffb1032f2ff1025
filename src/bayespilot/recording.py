"""The in-memory form of one tracking run: signals, sample rate and metadata.

A :class:`Recording` is what every later stage consumes (likelihood, fits,
posteriors, diagnosis).  It validates its own contents on construction, so a
Recording that exists is a Recording that is fit to use; :mod:`bayespilot.io`
turns files into Recordings and adds the file name to any error.
"""

from __future__ import annotations

import copy
import difflib
import functools
import math
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

__all__ = ["Recording", "RecordingError", "QuestionableRecordingWarning", "questionable",
           "REQUIRED_SIGNALS", "OPTIONAL_SIGNALS", "OPTIONAL_KEYS", "TASKS", "SHORT_RECORDING_S",
           "LOW_SAMPLE_RATE_HZ", "OFFSET_RATIO"]

#: Columns every recording must have (recording format, version 1).
REQUIRED_SIGNALS = ("t", "e", "u", "theta_ddot_m")
#: Columns the model may use when present.
OPTIONAL_SIGNALS = ("theta", "f_t", "f_d")
#: Allowed values of the ``task`` key.
TASKS = ("FD", "FT", "other")
#: The optional keys of ``NAME.json`` (recording format, version 1); other keys are kept.
OPTIONAL_KEYS = ("controlled_element_gain", "controlled_element", "control_gain", "subject",
                 "run", "forcing", "notes")
# every key the format defines (the required ones are bayespilot.io.REQUIRED_KEYS)
_FORMAT_KEYS = ("format", "sample_rate_hz", "motion_gain", "task") + OPTIONAL_KEYS


class RecordingError(ValueError):
    """A recording (in memory or on disk) is not valid.

    The message names the file, when there is one, and the problem.
    """


#: Records shorter than this (s) are read with a warning; the paper's runs are 81.92 s.
SHORT_RECORDING_S = 30.0
#: Sample rates below this (Hz) are read with a warning; the paper's is 100 Hz.
LOW_SAMPLE_RATE_HZ = 50.0


class QuestionableRecordingWarning(UserWarning):
    """A valid recording that is unlike the data the method was made for.

    Issued by :func:`~bayespilot.io.read_recording` and
    :func:`~bayespilot.io.read_mat` for a record shorter than
    :data:`SHORT_RECORDING_S` (the paper's runs are 81.92 s) or sampled below
    :data:`LOW_SAMPLE_RATE_HZ` (the paper's rate is 100 Hz), whose metadata
    contradicts its data or looks mistyped, or whose columns contradict each
    other (a sign, an offset in e, spikes in u, a bias in theta_ddot_m; see
    :func:`questionable`), and by
    :func:`~bayespilot.fit.fast.fit_fast` and
    :func:`~bayespilot.fit.three_step.fit_paper` for a control output u with
    an offset (its mean more than
    :data:`~bayespilot.fit.three_step.OFFSET_RATIO` of its standard
    deviation).  The recording is still returned and can be used; the
    estimates from it are less certain.  Silence it, once you know, with
    ``warnings.simplefilter("ignore", QuestionableRecordingWarning)``.
    """


def questionable(recording: "Recording") -> list[str]:
    """Why ``recording`` is questionable as input to the method, if it is.

    Parameters
    ----------
    recording : Recording

    Returns
    -------
    list of str
        One sentence per problem; empty if there is none.  The problems are:
        a record shorter than :data:`SHORT_RECORDING_S`; a sample rate below
        :data:`LOW_SAMPLE_RATE_HZ`; ``motion_gain`` 0 (no motion) with a
        ``theta_ddot_m`` column that is not all zeros; a ``control_gain``
        that is not positive; a metadata key that looks like a misspelling of
        an optional key of the recording format (``controlled_elment``; keys
        that merely extend one, such as ``subject_id``, are not); a column
        whose sign contradicts the others (e = f_t - theta; theta_ddot_m of
        the sign of K_theta theta''; theta = G(s) (K_delta_u u + f_d) with
        the sidecar's plant: each only when its columns are there, see
        :data:`SIGN_R2_MIN`); an identity that holds exactly (R^2 >=
        :data:`GAIN_R2_MIN`) with a coefficient of another size than the
        sidecar says, by more than :data:`GAIN_TOLERANCE` (theta_ddot_m = c
        theta'' with c off motion_gain; theta = G(s) (K_delta_u u + f_d) with
        a coefficient off 1: the sidecar's plant or control_gain is not the
        run's, and the sentence says by what factor); an unknown key inside
        ``controlled_element`` (the plant is num and den alone); an offset in
        e against f_t - theta over
        :data:`OFFSET_RATIO` of std(e) that e carries (not a theta or f_t
        logged about another zero); spikes in u (:data:`SPIKE_K`,
        :data:`SPIKE_SD`; from :data:`LOW_SAMPLE_RATE_HZ` up); a constant bias in
        theta_ddot_m, whose running integral, the pitch rate, then drifts away
        (:data:`BIAS_DRIFT`, :data:`BIAS_Z`; with motion, from :data:`BIAS_MIN_S`
        s up; theta is not needed).  See "Checks
        of the columns against each other" in docs/recording-format.md for
        the thresholds and what they were measured on.
    """
    reasons = []
    if recording.duration < SHORT_RECORDING_S:
        reasons.append(
            f"the record is {recording.duration:g} s long, much shorter than the 81.92 s runs of "
            f"Pool et al. (2012); the estimates (of delta_abs above all) will be far less certain")
    if recording.sample_rate_hz < LOW_SAMPLE_RATE_HZ:
        reasons.append(
            f"the sample rate is {recording.sample_rate_hz:g} Hz, under {LOW_SAMPLE_RATE_HZ:g} Hz "
            f"(the paper's is 100 Hz); the pilot's delays and neuromuscular dynamics "
            f"(omega_nm ~ 10 rad/s) are poorly resolved")
    if recording.motion_gain == 0:
        peak = float(np.max(np.abs(recording.theta_ddot_m)))
        if peak > 0:
            reasons.append(
                f"the motion column moves although motion_gain is 0 (no motion, in the recording "
                f"format): max |theta_ddot_m| = {peak:.3g} rad/s^2; the model takes theta_ddot_m "
                f"as the motion the pilot felt, so give the run's motion_gain, or zeros in "
                f"theta_ddot_m if there was no motion")
    gain = recording.metadata.get("control_gain")
    if gain is not None and float(_plain(gain)) <= 0:
        gain = float(_plain(gain))
        effect = ("would move the controlled element the opposite way" if gain < 0
                  else "would not move the controlled element")
        reasons.append(
            f"control_gain (K_delta_u) is {gain:g}, not positive (the paper's is 0.69): the "
            f"stick {effect}, and diagnose simulates the loop with it; check its sign")
    for key in recording.metadata:
        if key in _FORMAT_KEYS:
            continue
        near = _near_miss(key, [k for k in OPTIONAL_KEYS if k not in recording.metadata])
        if near is not None:
            reasons.append(f"unknown key {key!r} (did you mean {near!r}?): it is kept but "
                           f"ignored, as the recording format does with unknown keys")
    plant = recording.metadata.get("controlled_element")
    extra = [k for k in plant if k not in ("num", "den")] if isinstance(plant, Mapping) else []
    if extra:
        said = ", ".join(repr(k) + (f" (did you mean {near!r}?)"
                                    if (near := _near_miss(k, ["num", "den"])) else "")
                         for k in extra)
        reasons.append(f"unknown key{'s' if len(extra) > 1 else ''} {said} in "
                       f"controlled_element: kept but ignored, as the recording format does "
                       f"with unknown keys; the plant is num(s)/den(s) alone, so a delay or "
                       f"anything else given there is not in the plant diagnose simulates "
                       f"(the fits do not use the plant): fold what matters into num and den")
    with np.errstate(all="ignore"):  # a record of extreme values says nothing, quietly
        reasons += _sign_problems(recording)
        spikes = _spike_problem(recording)
        bias = _motion_bias_problem(recording)
    if spikes:
        reasons.append(spikes)
    if bias:
        reasons.append(bias)
    return reasons


#: |mean| / std above which an offset is warned of: in u over the fitted samples, by the
#: fitters (:func:`bayespilot.fit.three_step._warn_offset`, where its calibration is
#: given), and in e, against f_t - theta, by :func:`questionable`.  e's own mean is no
#: measure of an offset: it does not average out over a run (clean simulated runs: up to 0.31
#: of std(e) over 30 s, 0.21 on the 40.96-s whole-period run of docs/model.md, 0.54 over
#: 10 s), while e - (f_t - theta) is 0 to rounding on a clean record however short; an offset
#: of 0.3 std(e) moved K_v by 2 run-to-run standard deviations, one of 1 std(e) halved it.
#: A theta (or f_t) logged about another zero, a trim attitude, gives e - (f_t - theta) the same
#: mean; e is blamed only when removing that mean from e brings e's mean nearer 0
#: (:func:`_offset_in_e`).
OFFSET_RATIO = 0.2
#: The sign checks (:func:`_sign_problems`) fit each identity between the recorded columns by
#: least squares with a free coefficient per term, and judge the signs of the coefficients only
#: when the fit explains at least this fraction of the variance of the identity's left side
#: (104 clean simulated records: R^2 at least 0.9997, 0.94 with u clipped, every judged
#: coefficient 0.96 to 1.34, while a column of the other sign gives -1; a theta_ddot_m logged
#: after a washout at 4 rad/s (R^2 0.11 to 0.42 on 18 simulated 81.92-s runs) or a platform,
#: omega^2 / (s^2 + 1.4 omega s + omega^2) at 5 rad/s with 30 ms of delay (0.001 to 0.03), or
#: a plant the sidecar does not describe, explains less and is not judged: here only signs
#: are checked, sizes from :data:`GAIN_R2_MIN` up; docs/recording-format.md gives the runs).
SIGN_R2_MIN = 0.5
#: ... and only the coefficients of terms that carry at least this fraction of the left
#: side's standard deviation (an all but zero f_t or f_d says nothing of its sign).
SIGN_TERM_MIN = 0.1
#: The gain checks (:func:`_gain_problem`): an identity that the columns meet this well
#: (R^2, the least squares of :data:`SIGN_R2_MIN`) is taken as exact, and its judged
#: coefficients are compared in size with what the sidecar says: theta_ddot_m's with
#: motion_gain (K_theta), the plant's with 1 (the sidecar's plant and control_gain).  Only
#: from :data:`LOW_SAMPLE_RATE_HZ` up: below it the two central differences that make theta''
#: shrink it by several % while R^2 stays above this (a clean 19-Hz FD run gave theta_ddot_m's
#: coefficient 1.10, f_d's 0.79 to 0.88 from 10 to 20 Hz).
GAIN_R2_MIN = 0.99
#: ... and warned of when one is off by more than this fraction (|c / expected - 1|).  On
#: 116 records simulated by the package (the paper's FD and FT tasks at K_theta 0.5, 0.75
#: and 1, F_n 0, 0.15 and 0.3, 50, 100 and 1000 Hz, 10 to 81.92 s, a washout in the pilot
#: model or not, u quantised to 8 bits; 28 of another lab's task: plants 2/s^2,
#: 8/(s (s + 2)), 8/(s (s + 2) (0.05 s + 1)) and 2 (s + 1)/(s^2 (s + 5)) at 50 and 250 Hz,
#: K_theta 0.5, single-forcing tasks) every R^2 was at least 0.9998 and every judged
#: coefficient 0.977 to 1.016 of its expected value (theta_ddot_m's 1.000 to 1.016, u's
#: 0.984 to 1.002, f_d's 0.977 to 1.000: the low-pass and central differences at 50 Hz),
#: a quarter of the tolerance; so did 8 runs with u saturated in the loop (the catalogue's
#: control saturation).  A u column clipped after the fact at 1.6 standard deviations
#: reaches it (R^2 0.991, u's coefficient 1.10; at 1 standard deviation R^2 is 0.94 to 0.98
#: and nothing is judged).  A sidecar K_theta of 1 for 0.5, a plant gain of 4 for 8, or a
#: control_gain left out (the paper's 0.69 taken for 1) is off by 44 % and more.
GAIN_TOLERANCE = 0.1
#: The sign checks low-pass both sides of an identity (zero phase, 4th order) at the lower of
#: this (Hz) and a fifth of the sample rate before differentiating, and leave out this many
#: seconds (at most a tenth of the record) at each end, where the filter starts up.
SIGN_CUTOFF_HZ = 5.0
SIGN_EDGE_S = 1.0
#: A sample of u is a spike when it stands out from the median of its four neighbours by more
#: than SPIKE_K times the median such deviation (scaled as a standard deviation) AND by more
#: than SPIKE_SD times the standard deviation of u (the larger of std(u) and its
#: median-absolute-deviation estimate: a pilot who pulses the stick leaves u near 0 between
#: pulses, where the MAD estimate alone collapsed: 65 to 87 samples of each synthetic 82-s
#: train of pulses through a 30-rad/s neuromuscular system at 50 Hz were spikes, now 0, or 7
#: to 15 for the sharpest, 0.05-s pulses).  Clean simulated records (50 to 1000 Hz, remnant
#: 0 to 0.3): at most 10.3 times the median and 0.17 standard deviations; a clipped u's
#: corners reach 587 times the median (a quantised u's median is 0) but stay under 0.18
#: standard deviations, hence the second condition.  Not checked below
#: :data:`LOW_SAMPLE_RATE_HZ`, where a pulse through the neuromuscular system is a sample or
#: two wide and 5 to 6 standard deviations from its neighbours' median (89 to 145 flags per
#: 82-s train of such pulses at 20 Hz, with either estimate).
SPIKE_K = 15.0
SPIKE_SD = 2.0
#: A constant bias b in theta_ddot_m is read by the canal (DC gain 5.97) as a sustained
#: rotation, which the fit follows by lowering K_m; the pitch rate the motion presents (the
#: integral of theta_ddot_m) cannot drift away on a platform, while a bias makes it a ramp
#: b t.  Warned of when the drift |b| T exceeds BIAS_DRIFT times the integral's rms about its
#: straight line AND b stands BIAS_Z standard errors (of white noise in the column) from 0,
#: b being the smaller in size of the integral's least-squares slope and the column's
#: Hann-window mean; not under BIAS_MIN_S s, where the forcing's slowest lines do not average
#: out.  Measured on 96 clean records (largest ratio 0.09 from 30 s up) and their windows:
#: docs/recording-format.md, "A bias in theta_ddot_m".
BIAS_DRIFT = 0.75
BIAS_Z = 5.0
BIAS_MIN_S = 25.0


def _one_blas_thread(func):
    """:func:`bayespilot._blas.one_blas_thread`, imported on the first call.  Every read runs
    the checks, whose dot products and least squares over a whole record (81920 x 2 at
    1000 Hz) multi-threaded BLAS only slows: on a simulated 81.92-s FD run at 1000 Hz,
    questionable() took 224-242 ms with OpenBLAS's two threads on a busy 2-core machine and
    18 ms with one (read_recording 391-408 ms and 151-154 ms).  Importing threadpoolctl up
    front would make ``import bayespilot.recording`` heavier, hence on the first call."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from ._blas import one_blas_thread

        return one_blas_thread(func)(*args, **kwargs)

    return wrapper


def _lowpassed(x: np.ndarray, rate: float) -> np.ndarray:
    from scipy import signal

    sos = signal.butter(4, min(SIGN_CUTOFF_HZ, 0.2 * rate), fs=rate, output="sos")
    return signal.sosfiltfilt(sos, np.asarray(x, float))


def _poly_d(coeffs: np.ndarray, x: np.ndarray, dt: float) -> np.ndarray:
    """p(d/dt) x for p's coefficients (highest power first), by repeated central
    differences."""
    out = np.zeros_like(x)
    deriv = x
    for c in coeffs[::-1]:
        if c:
            out = out + c * deriv
        deriv = np.gradient(deriv, dt)
    return out


def _corr(a: np.ndarray, b: np.ndarray) -> float:
    a = a - a.mean()
    b = b - b.mean()
    den = math.sqrt(float(a @ a) * float(b @ b))
    return float(a @ b) / den if den > 0 else 0.0


#: The identities the sign checks test: (left-side column, [term columns], the identity as
#: said, the correlation as said).
_IDENTITIES = {
    "error": ("e", ["f_t", "theta"], "e = f_t - theta (the format's definition of e)",
              "corr(e, f_t - theta)"),
    "motion": ("theta_ddot_m", ["theta"], "theta_ddot_m = K_theta theta'' (the motion is "
               "the pitch acceleration, of the same sign)", "corr(theta_ddot_m, theta'')"),
    "plant": ("theta", ["u", "f_d"], "theta = G(s) (K_delta_u u + f_d) with the sidecar's "
              "controlled element G", "corr(den(s) theta, num(s) (K_delta_u u + f_d))"),
}


@_one_blas_thread
def _sign_statistics(recording: "Recording", only: str | None = None
                     ) -> dict[str, dict[str, Any]]:
    """For each identity between the columns the recording has (:data:`_IDENTITIES`): the
    least-squares fit of its left side on its terms (each with the format's sign), as
    ``{"r2", "coef" (per term), "share" (|coef| * std(term) / std(left)), "corr" (as
    recorded)}``.  theta_ddot_m and the plant are compared after a zero-phase low-pass
    (:data:`SIGN_CUTOFF_HZ`) and without :data:`SIGN_EDGE_S` at each end.  ``only``: the
    one identity to compute (the likelihood's start state needs "motion" alone)."""
    sig = recording.signals
    n = recording.n_samples
    rate = recording.sample_rate_hz
    edge = min(int(round(SIGN_EDGE_S * rate)), n // 10)
    keep = slice(edge, n - edge)
    if n - 2 * edge < max(16, int(2.0 * rate)):  # under 2 s left: nothing to judge
        return {}
    lp: dict[str, np.ndarray] = {}

    def low(name: str) -> np.ndarray:
        if name not in lp:
            lp[name] = _lowpassed(sig[name], rate)
        return lp[name]

    def moves(name: str) -> bool:
        return name in sig and bool(np.ptp(sig[name]) > 0)

    sides: dict[str, tuple[np.ndarray, list[np.ndarray]]] = {}
    if only in (None, "error") and moves("e") and moves("theta") and "f_t" in sig:
        sides["error"] = (np.asarray(sig["e"], float)[keep],
                          [np.asarray(sig["f_t"], float)[keep],
                           -np.asarray(sig["theta"], float)[keep]])
    if only in (None, "motion") and moves("theta") and recording.motion_gain > 0 \
            and moves("theta_ddot_m"):
        sides["motion"] = (low("theta_ddot_m")[keep],
                           [_poly_d(np.array([1.0, 0.0, 0.0]), low("theta"), recording.dt)[keep]])
    if only in (None, "plant") and moves("theta") and moves("u") and "f_d" in sig:
        num, den = recording.controlled_element
        num = np.trim_zeros(num, "f")
        den = np.trim_zeros(den, "f")
        sides["plant"] = (_poly_d(den, low("theta"), recording.dt)[keep],
                          [_poly_d(num, recording.control_gain * low("u"), recording.dt)[keep],
                           _poly_d(num, low("f_d"), recording.dt)[keep]])
    out: dict[str, dict[str, Any]] = {}
    if "error" in sides:  # e's constant offset from f_t - theta, over the whole record
        e = np.asarray(sig["e"], float)
        gap = e - (np.asarray(sig["f_t"], float) - np.asarray(sig["theta"], float))
        offset = {"offset": float(gap.mean()), "sd_e": float(e.std()),
                  "mean_e": float(e.mean())}
    for name, (lhs, terms) in sides.items():
        y = lhs - lhs.mean()
        X = np.stack([x - x.mean() for x in terms], axis=1)
        sy = float(np.sqrt(y @ y))
        if not sy > 0:
            continue
        coef = np.linalg.lstsq(X, y, rcond=None)[0]
        res = y - X @ coef
        r2 = 1.0 - float(res @ res) / float(y @ y)
        share = np.abs(coef) * np.sqrt((X * X).sum(axis=0)) / sy
        signs = np.where(share >= SIGN_TERM_MIN, np.sign(coef), 1.0)
        out[name] = {"r2": r2, "coef": coef, "share": share,
                     "corr": _corr(lhs, np.sum(terms, axis=0)),
                     "corr_fixed": _corr(lhs, np.sum([k * x for k, x in zip(signs, terms)],
                                                     axis=0))}
        if name == "error":
            out[name].update(offset)
    return out


def _offset_in_e(st: Mapping[str, float]) -> bool:
    """Whether the "error" statistics of :func:`_sign_statistics` show an offset in e: the mean
    of e - (f_t - theta) over :data:`OFFSET_RATIO` of std(e), and e the column that carries it.
    A constant in theta or f_t (theta logged about a trim attitude) gives the same mean; then
    it is f_t - theta that is off centre, and e is centred already: removing the mean from e
    would put the constant into e.  So e is blamed only when removing the mean from e brings
    e's own mean nearer 0 (on a short run whose e does not average out, see
    :data:`OFFSET_RATIO`, this can go either way), and otherwise nothing is said: theta enters
    the paper's model only through its rate, so its zero does no harm."""
    off = st["offset"]
    return abs(off) > OFFSET_RATIO * st["sd_e"] and abs(st["mean_e"] - off) < abs(st["mean_e"])


def _sign_problems(recording: "Recording") -> list[str]:
    """One sentence per identity between the recorded columns (:data:`_IDENTITIES`) that
    holds (R^2 >= :data:`SIGN_R2_MIN`) with a term of the opposite sign: the column(s)
    whose sign turned round explains it with the fewest columns."""
    try:
        stats = _sign_statistics(recording)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError):  # pragma: no cover
        return []
    reasons = []
    for name, st in stats.items():
        if st["r2"] < SIGN_R2_MIN:
            continue
        left, cols, what, measure = _IDENTITIES[name]
        big = st["share"] >= SIGN_TERM_MIN
        negative = [c for c, b, k in zip(cols, big, st["coef"]) if b and k < 0]
        if not negative:
            if name == "error" and _offset_in_e(st):
                reasons.append(
                    f"e has an offset: e - (f_t - theta), which the format defines as 0, has a "
                    f"mean of {st['offset']:.3g} rad, {abs(st['offset']) / st['sd_e']:.2f} of "
                    f"e's standard "
                    f"deviation {st['sd_e']:.3g} (more than {OFFSET_RATIO:g}); the model takes "
                    f"e as the error the pilot saw, zero when on target, so an offset biases "
                    f"the fit (K_v, T_vl, K_m) and can make diagnose name a channel the pilot "
                    f"does not have; remove it from e")
            gain = _gain_problem(recording, name, st)
            if gain:
                reasons.append(gain)
            continue
        positive = [c for c, b, k in zip(cols, big, st["coef"]) if b and k > 0]
        # turning round the left side and the positive terms is the same as turning round
        # the negative terms (the identity is linear): name the shorter, both on a tie
        options = sorted([[left] + positive, negative], key=len)
        if len(options[0]) < len(options[1]):
            options = options[:1]
        culprit = " or of ".join(" and ".join(o) for o in options)
        turned = " (or ".join(" and ".join(o) for o in options) + ")" * (len(options) - 1)
        reasons.append(
            f"the sign of {culprit} looks inverted: {what} fails, {measure} = "
            f"{st['corr']:+.2f}, but holds with {turned} turned round "
            f"(correlation {st['corr_fixed']:+.2f}); check the sign conventions of the logged "
            f"columns (the model needs e, u and theta_ddot_m with the recording format's "
            f"signs) and turn the wrong one round")
    return reasons


def _plant_said(recording: "Recording") -> str:
    """The sidecar's controlled element as said in messages."""
    meta = recording.metadata
    if meta.get("controlled_element") is not None:
        return "the controlled element (controlled_element)"
    if "controlled_element_gain" in meta:
        return "the controlled element's gain (controlled_element_gain)"
    return "the controlled element (the paper's 4/s^2: the sidecar gives none)"


def _columns_motion_gain(recording: "Recording",
                         st: Mapping[str, Any] | None = None) -> float | None:
    """The K_theta of the columns, c in theta_ddot_m = c theta'' (the "motion" statistics of
    :func:`_sign_statistics`, or ``st``), when the identity holds (R^2 >=
    :data:`GAIN_R2_MIN`) with c of the right sign but off motion_gain by more than
    :data:`GAIN_TOLERANCE`; else None (the columns agree with motion_gain, or cannot tell).
    What :func:`questionable` warns of, and what makes the likelihood start the canal from
    theta_ddot_m alone (:func:`bayespilot.likelihood._pitch_rate_at_start`)."""
    if recording.sample_rate_hz < LOW_SAMPLE_RATE_HZ:  # (sizes not judged there: GAIN_R2_MIN)
        return None
    if st is None:
        try:
            with np.errstate(all="ignore"):
                st = _sign_statistics(recording, "motion").get("motion")
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):  # pragma: no cover
            return None
    if st is None or st["r2"] < GAIN_R2_MIN or st["share"][0] < SIGN_TERM_MIN:
        return None
    c = float(st["coef"][0])
    return c if c > 0 and abs(c / recording.motion_gain - 1.0) > GAIN_TOLERANCE else None


def _gain_problem(recording: "Recording", name: str, st: Mapping[str, Any]) -> str | None:
    """A sentence on an identity (:data:`_IDENTITIES`) that the columns meet exactly (R^2 >=
    :data:`GAIN_R2_MIN`) with a judged coefficient of the right sign but not the size the
    sidecar says (off by more than :data:`GAIN_TOLERANCE`), or None: theta_ddot_m's against
    motion_gain, and the plant's (u's against the sidecar's plant times control_gain, f_d's
    against its plant)."""
    if name == "motion":  # (its rule, _columns_motion_gain's, is the likelihood's too)
        K = recording.motion_gain
        c = _columns_motion_gain(recording, st)
        if c is None:
            return None
        return (f"theta_ddot_m = K_theta theta'' holds (R^2 {st['r2']:.4f}) with K_theta = "
                f"{c:.3g}, but the sidecar's motion_gain (K_theta) is {K:g}, {K / c:.3g} times "
                f"that (more than {GAIN_TOLERANCE:.0%} off): either motion_gain is not the "
                f"run's K_theta, or theta_ddot_m is not the motion the pilot felt, K_theta "
                f"theta'' (the plant's theta'' logged, say); diagnose simulates the loop with "
                f"motion_gain and pools runs by it, and a channel on theta_m takes K_theta "
                f"theta (the fits take the columns' K_theta for the canal's start state); "
                f"give the run's K_theta as motion_gain, or log K_theta theta'' in "
                f"theta_ddot_m")
    if (name != "plant" or st["r2"] < GAIN_R2_MIN
            or recording.sample_rate_hz < LOW_SAMPLE_RATE_HZ):  # (GAIN_R2_MIN)
        return None
    judged = st["share"] >= SIGN_TERM_MIN
    cu, cd = (float(x) for x in st["coef"])
    off_u = bool(judged[0]) and abs(cu - 1.0) > GAIN_TOLERANCE
    off_d = bool(judged[1]) and abs(cd - 1.0) > GAIN_TOLERANCE
    if not (off_u or off_d):
        return None
    kdu = recording.control_gain
    given = "control_gain" in recording.metadata
    kdu_said = (f"control_gain (K_delta_u) {kdu:g}" if given else
                f"control_gain (K_delta_u), which the sidecar does not give (the paper's "
                f"{kdu:g} is taken)")
    plant = _plant_said(recording)
    coefs = " and ".join(f"{c}'s coefficient {k:.3g}" for c, k, j in
                         (("u", cu, judged[0]), ("f_d", cd, judged[1])) if j)
    if off_u and off_d and abs(cu / cd - 1.0) <= GAIN_TOLERANCE:
        why = (f"both by about {(cu + cd) / 2:.3g}: the plant of the columns is "
               f"{(cu + cd) / 2:.3g} times {plant} in size; check its gain")
    elif off_u and not judged[1]:
        why = (f"the plant's gain times K_delta_u of the columns is {cu:.3g} times that of "
               f"{plant} and {kdu_said}; check both")
    elif off_u and not off_d:
        why = (f"{kdu_said} is not the run's: the columns say K_delta_u = {cu * kdu:.3g}, "
               f"{cu:.3g} times it; give the run's control_gain (if it is the run's, u is "
               f"logged in other units than the stick's, or clipped)")
    elif off_d and not judged[0]:  # (u too small a share to judge: f_d's is the plant's)
        why = (f"the plant of the columns is {cd:.3g} times {plant} in size, or f_d is in "
               f"other units than K_delta_u u (the format adds them at the plant's input); "
               f"check the plant's gain and f_d's units")
    elif off_d and not off_u:
        why = (f"f_d enters the plant {cd:.3g} times as large as the column says (the format "
               f"adds f_d to K_delta_u u at the plant's input, in the same units); check the "
               f"units of f_d")
    else:
        why = (f"neither {plant} nor {kdu_said} matches the columns (f_d's coefficient is "
               f"the plant's factor, u's the plant's times K_delta_u's); check both")
    return (f"the sidecar's plant does not match the columns in size: theta = G(s) (K_delta_u u "
            f"+ f_d) holds (R^2 {st['r2']:.4f}) with {coefs}, not 1 (more than "
            f"{GAIN_TOLERANCE:.0%} off): {why}; the fits do not use the plant, but diagnose's "
            f"bootstrap simulates the loop with it and control_gain")


def _spike_statistics(recording: "Recording") -> tuple[np.ndarray, float, float]:
    """(|u - median of its 4 neighbours| at samples 2..n-3, the median of it scaled as a
    standard deviation, the standard deviation of u: the larger of its median-absolute-deviation
    estimate and std(u), see :data:`SPIKE_SD`)."""
    u = np.asarray(recording.u, float)
    if u.size < 5:
        return np.zeros(0), 0.0, 0.0
    neighbours = np.stack([u[:-4], u[1:-3], u[3:-1], u[4:]])
    r = np.abs(u[2:-2] - np.median(neighbours, axis=0))
    scale = 1.4826 * float(np.median(r))
    sd = max(1.4826 * float(np.median(np.abs(u - np.median(u)))), float(np.std(u)))
    return r, scale, sd


def _spike_problem(recording: "Recording") -> str | None:
    """A sentence on the spikes in u (:data:`SPIKE_K`, :data:`SPIKE_SD`), or None; None below
    :data:`LOW_SAMPLE_RATE_HZ`, where the pilot's own pulses are a sample or two wide."""
    if recording.sample_rate_hz < LOW_SAMPLE_RATE_HZ:
        return None
    r, scale, sd = _spike_statistics(recording)
    if r.size == 0 or not sd > 0:
        return None
    limit = max(SPIKE_K * scale, SPIKE_SD * sd)
    at = np.flatnonzero(r > limit) + 2
    if at.size == 0:
        return None
    t = recording.t
    first = ", ".join(f"{t[k]:.6g}" for k in at[:5]) + (", ..." if at.size > 5 else "")
    peak = float(r.max())
    return (f"{at.size} sample(s) of u jump away from their neighbours (spikes), by up to "
            f"{peak:.3g} rad, {peak / sd:.3g} standard deviations of u, where the run's "
            f"sample-to-sample scatter is {scale:.3g} (a sample is a spike past "
            f"{SPIKE_K:g} times that and {SPIKE_SD:g} standard deviations), at t = {first} s; "
            f"the fit takes them as the pilot's control, so remove them (interpolate over "
            f"them, or cut the record) before fitting")


@_one_blas_thread
def _motion_bias_statistics(recording: "Recording") -> dict[str, float] | None:
    """theta_ddot_m's bias as :data:`BIAS_DRIFT` judges it: ``{"bias"`` (rad/s^2, the
    smaller in size of the rate's least-squares slope and theta_ddot_m's Hann-window mean),
    ``"sd"`` (std of theta_ddot_m), ``"drift"`` (bias times the record's duration, rad/s),
    ``"spread"`` (rms of the rate, theta_ddot_m integrated from 0, about its straight line,
    rad/s), ``"ratio"`` (|drift| / spread), ``"z"`` (|bias| over its standard error from
    white noise in theta_ddot_m)``}``; None with no motion (motion_gain 0, or theta_ddot_m
    all zeros) or under :data:`BIAS_MIN_S` s.  Needs no theta."""
    if not recording.motion_gain > 0 or recording.duration < BIAS_MIN_S:
        return None
    a = np.asarray(recording.theta_ddot_m, float)
    n = a.size
    dt = recording.dt
    if not np.any(a) or n < 16:  # (16: as the sign checks, too few samples to judge)
        return None
    rate = np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]))]) * dt
    t = np.arange(n) * dt
    tc = t - t.mean()
    rc = rate - rate.mean()
    slope = float(tc @ rc) / float(tc @ tc)
    res = rc - slope * tc
    spread = math.sqrt(float(res @ res) / n)
    w = np.sin(np.pi * (np.arange(n) + 0.5) / n) ** 2
    hann = float(w @ a) / float(w.sum())
    bias = slope if abs(slope) <= abs(hann) else hann
    d2 = a[2:] - 2.0 * a[1:-1] + a[:-2]
    noise = 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / math.sqrt(6.0)
    stderr = noise * math.sqrt(1.5 / n)  # the Hann window's (the parabolic one's: 1.2 / n)
    drift = bias * recording.duration

    def over(x: float, scale: float) -> float:
        return abs(x) / scale if scale > 0 else (math.inf if x else 0.0)

    sd = float(a.std()) if np.ptp(a) > 0 else 0.0  # (a constant's std is not 0 to rounding)
    return {"bias": bias, "sd": sd, "drift": drift, "spread": spread,
            "ratio": over(drift, spread), "z": over(bias, stderr)}


def _motion_bias_problem(recording: "Recording") -> str | None:
    """A sentence on a constant bias in theta_ddot_m (:data:`BIAS_DRIFT`, :data:`BIAS_Z`), or
    None."""
    st = _motion_bias_statistics(recording)
    if st is None or not (st["ratio"] > BIAS_DRIFT and st["z"] > BIAS_Z):
        return None
    share = (f"{abs(st['bias']) / st['sd']:.2%} of its standard deviation {st['sd']:.3g} "
             f"rad/s^2" if st["sd"] > 0 else "all of it: the column is constant")
    return (f"theta_ddot_m looks biased: it has a constant part of about {st['bias']:.3g} "
            f"rad/s^2 ({share}), so the pitch rate it presents, its running integral, drifts by "
            f"{st['drift']:.3g} rad/s over the {recording.duration:g}-s run, "
            f"{st['ratio']:.3g} times that rate's spread about its trend ({st['spread']:.3g} "
            f"rad/s; more than {BIAS_DRIFT:g}); a motion platform's pitch rate cannot drift "
            f"away, and the model's canal takes the bias for a sustained rotation, which biases "
            f"the fit (K_m low); if the lab knows it is a sensor or logging bias, remove it "
            f"(subtract the mean of theta_ddot_m over whole periods of the forcing, or the "
            f"estimate above) before fitting")


def _near_miss(name: Any, known: "list[str] | tuple[str, ...]") -> str | None:
    """The name in ``known`` that ``name`` looks like a misspelling of, or None.

    A near miss differs in case only, or is close by :func:`difflib.get_close_matches`
    (ratio >= 0.85: a letter or two left out, added or swapped); a name that extends a known
    one by a ``_`` part (``subject_id``, ``lab_run``) is a lab's own key, not a misspelling.
    """
    if not isinstance(name, str) or not name or name in known:
        return None
    if any(name.startswith(k + "_") or name.endswith("_" + k) for k in known):
        return None
    low = name.lower()
    if low in known:
        return low
    match = difflib.get_close_matches(low, list(known), n=1, cutoff=0.85)
    return match[0] if match else None


class _ReadOnlyDict(dict):
    """A recording's ``signals`` or ``metadata``: a dict (JSON, ``dict(...)``, ``**`` and
    comparisons work as on any) that refuses to be changed in place.  A changed recording is
    a new one (:meth:`Recording.with_signals`, or :class:`Recording` with other metadata), so
    that every column and value passes the recording's checks."""

    #: What a change in place is told (a subclass, e.g. a fit's, says its own).
    _REFUSAL = ("a Recording's signals and metadata cannot be changed in place: make a new "
                "recording (Recording.with_signals(...), or Recording(...) with the new "
                "metadata), which checks them")

    def _refuse(self, *args: Any, **kwargs: Any) -> None:
        raise TypeError(self._REFUSAL)

    __setitem__ = __delitem__ = __ior__ = _refuse
    clear = pop = popitem = setdefault = update = _refuse

    def __reduce__(self):
        return (type(self), (dict(self),))

    # a copy is the caller's to edit (copy.deepcopy(rec.metadata), then a new Recording)
    def __copy__(self) -> dict:
        return dict(self)

    def __deepcopy__(self, memo: dict) -> dict:
        return {k: copy.deepcopy(v, memo) for k, v in self.items()}


class _ReadOnlyList(list):
    """A list in a recording's metadata (a forcing's lines, a plant's coefficients) that
    refuses to be changed in place, as :class:`_ReadOnlyDict`."""

    _REFUSAL = _ReadOnlyDict._REFUSAL
    _refuse = _ReadOnlyDict._refuse
    __setitem__ = __delitem__ = __iadd__ = __imul__ = _refuse
    append = extend = insert = pop = remove = clear = sort = reverse = _refuse

    def __reduce__(self):
        return (type(self), (list(self),))

    def __copy__(self) -> list:
        return list(self)

    def __deepcopy__(self, memo: dict) -> list:
        return [copy.deepcopy(v, memo) for v in self]


def _frozen(value: Any, mapping: type = _ReadOnlyDict, sequence: type = _ReadOnlyList) -> Any:
    """``value`` with its dicts, lists and arrays copied read-only, at every depth: a
    recording's metadata, which no one (the caller who built it included) can then change
    behind its checks.  ``mapping`` and ``sequence``: the read-only types to use (a fit's
    carry its own message)."""
    if isinstance(value, Mapping):
        return mapping({k: _frozen(v, mapping, sequence) for k, v in value.items()})
    if isinstance(value, list):
        return sequence(_frozen(v, mapping, sequence) for v in value)
    if isinstance(value, np.ndarray):
        value = value.copy()
        value.setflags(write=False)
    return value


def _thawed(value: Any) -> Any:
    """A :func:`_frozen` value as plain dicts and lists (arrays kept)."""
    if isinstance(value, Mapping):
        return {k: _thawed(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_thawed(v) for v in value]
    return value


def _warn_if_questionable(recording: "Recording") -> None:
    """Issue one :class:`QuestionableRecordingWarning` per reason :func:`questionable` gives,
    at the user's line (a recording read inside a batch or the CLI as much as a direct one)."""
    from ._caller import warn_at_caller

    where = f"{recording.source}: " if recording.source else ""
    for reason in questionable(recording):
        warn_at_caller(where + reason, QuestionableRecordingWarning)


# ---------------------------------------------------------------------------
# metadata values (shared with bayespilot.io, which checks JSON sidecars and
# .mat files with the same function)
# ---------------------------------------------------------------------------
def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _describe(x: Any) -> str:
    """A short description of a JSON value for messages."""
    names = {dict: "an object", list: "an array", str: "a string", bool: "a boolean",
             type(None): "null", int: "an integer", float: "a number"}
    return names.get(type(x), type(x).__name__)


def _plain(value: Any) -> Any:
    """``value`` with numpy scalars and arrays and tuples made plain Python (for checking)."""
    if isinstance(value, Mapping):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    return value


def _check_number_list(key: str, value: Any, *, integral: bool = False) -> None:
    if not isinstance(value, list):
        raise RecordingError(f"{key} must be an array of numbers, got {_describe(value)}")
    for i, v in enumerate(value):
        if not _is_number(v) or not math.isfinite(v):
            raise RecordingError(f"{key}[{i}] must be a finite number, got {v!r}")
        if integral and not float(v).is_integer():
            raise RecordingError(f"{key}[{i}] must be an integer, got {v!r}")


#: What a forcing's message says of a task without one of its two forcing functions.
_ONE_FORCING_HINT = ('; for a task without a {name}, give "{name}": {{"n": [], "amplitude": [], '
                     '"phase": []}}')


def _check_forcing(forcing: Any, rate: float | None = None) -> None:
    """Check a ``forcing`` value (plain Python); with the record's ``rate`` (Hz), also that
    no line of nonzero amplitude is at or above the Nyquist frequency (the rule of
    :class:`~bayespilot.simulate.TrackingTask`)."""
    if not isinstance(forcing, Mapping):
        raise RecordingError(f"forcing must be an object with base_frequency, target and "
                             f"disturbance, got {_describe(forcing)}")
    if "base_frequency" not in forcing:
        raise RecordingError("forcing has no base_frequency")
    w0 = forcing["base_frequency"]
    if not _is_number(w0) or not math.isfinite(w0) or w0 <= 0:
        raise RecordingError(f"forcing.base_frequency must be a positive finite number (rad/s), "
                             f"got {w0!r}")
    for name in ("target", "disturbance"):
        if name not in forcing:
            raise RecordingError(f"forcing has no {name!r} object"
                                 + _ONE_FORCING_HINT.format(name=name))
        part = forcing[name]
        if not isinstance(part, Mapping):
            raise RecordingError(f"forcing.{name} must be an object with arrays n, amplitude and "
                                 f"phase, got {_describe(part)}"
                                 + _ONE_FORCING_HINT.format(name=name))
        for arr in ("n", "amplitude", "phase"):
            if arr not in part:
                raise RecordingError(f"forcing.{name} has no {arr!r} array")
            _check_number_list(f"forcing.{name}.{arr}", part[arr], integral=(arr == "n"))
        low = [v for v in part["n"] if v < 1]
        if low:  # (the multisine's harmonic numbers: a line at 0 or below has no frequency)
            raise RecordingError(f"forcing.{name}.n must hold integers >= 1 (multiples of "
                                 f"base_frequency), got {low[0]!r}")
        lengths = {arr: len(part[arr]) for arr in ("n", "amplitude", "phase")}
        if len(set(lengths.values())) != 1:
            raise RecordingError(f"forcing.{name} arrays have unequal lengths "
                                 f"(n: {lengths['n']}, amplitude: {lengths['amplitude']}, "
                                 f"phase: {lengths['phase']})")
        if rate is not None:
            from .forcing import above_nyquist  # (the one rule, TrackingTask's too)

            nyquist = math.pi * rate  # rad/s
            ns = [float(n) for n in part["n"]]
            high = [(ns[i] * w0, ns[i]) for i in above_nyquist(
                [n * w0 for n in ns], [float(a) for a in part["amplitude"]], rate)]
            if high:
                w, n = max(high)
                raise RecordingError(
                    f"forcing.{name}'s line n = {int(n)} at {w / (2 * math.pi):.6g} Hz "
                    f"({w:.6g} rad/s, n times base_frequency {w0:.6g} rad/s) is at or above the "
                    f"Nyquist frequency {rate / 2:g} Hz ({nyquist:.6g} rad/s) of the "
                    f"{rate:g}-Hz recording: it cannot be in the columns (it would be recorded "
                    f"aliased); leave the line out, or check base_frequency (rad/s), n and "
                    f"sample_rate_hz"
                    + (f" ({len(high)} of its lines are at or above the Nyquist frequency)"
                       if len(high) > 1 else ""))


def _check_plant(ce: Any) -> None:
    """Check a ``controlled_element`` value (plain Python): num and den, a plant that is
    neither zero nor improper."""
    if not isinstance(ce, Mapping):
        raise RecordingError(f"controlled_element must be an object with arrays num and den, "
                             f"got {_describe(ce)}")
    for part in ("num", "den"):
        if part not in ce:
            raise RecordingError(f"controlled_element has no {part!r} array")
        _check_number_list(f"controlled_element.{part}", ce[part])
        if not ce[part]:
            raise RecordingError(f"controlled_element.{part} is empty")
    if not any(ce["den"]):
        raise RecordingError("controlled_element.den is all zeros")
    if not any(ce["num"]):
        raise RecordingError(f"controlled_element.num is all zeros ({ce['num']}): a plant that "
                             f"is zero, which the stick could not move")
    num = np.trim_zeros(np.asarray(ce["num"], float), "f")
    den = np.trim_zeros(np.asarray(ce["den"], float), "f")
    if num.size > den.size:
        raise RecordingError(
            f"controlled_element is improper (num {ce['num']} of degree {num.size - 1} over den "
            f"{ce['den']} of degree {den.size - 1}): a plant's num must not be of higher degree "
            f"than its den (coefficients in powers of s, highest first)")


def _metadata_problems(meta: Mapping[str, Any], rate: float | None = None) -> list[str]:
    """One message per optional metadata key whose value the recording format refuses (see
    :func:`_check_metadata_values`), in the order of :data:`OPTIONAL_KEYS`; ``rate``: the
    sample rate (Hz), when known, for the forcing's lines against the Nyquist frequency."""
    obj = {k: _plain(meta[k]) for k in OPTIONAL_KEYS if k in meta}
    problems: list[str] = []
    for key in ("controlled_element_gain", "control_gain"):
        if key in obj:
            v = obj[key]
            if not _is_number(v) or not math.isfinite(v):
                problems.append(f"{key} must be a finite number, got {v!r}")
            elif key == "controlled_element_gain" and v == 0:
                problems.append("controlled_element_gain is 0: a plant that is zero, which the "
                                "stick could not move")
    if "controlled_element" in obj:
        if "controlled_element_gain" in obj:
            problems.append("give either controlled_element or controlled_element_gain, not both")
        try:
            _check_plant(obj["controlled_element"])
        except RecordingError as exc:
            problems.append(str(exc))
    for key in ("subject", "notes"):
        if key in obj and not isinstance(obj[key], str):
            problems.append(f"{key} must be a string, got {obj[key]!r}")
    if "run" in obj:
        v = obj["run"]
        if not isinstance(v, int) or isinstance(v, bool):
            problems.append(f"run must be an integer, got {v!r}")
    if "forcing" in obj:
        try:
            _check_forcing(obj["forcing"], rate)
        except RecordingError as exc:
            problems.append(str(exc))
    return problems


def _check_metadata_values(meta: Mapping[str, Any], rate: float | None = None) -> None:
    """Check the optional metadata keys whose values the recording format fixes.

    ``controlled_element_gain`` (a finite number, not 0) and ``control_gain``
    (a finite number), ``controlled_element`` (``num`` and ``den``:
    non-empty arrays of finite numbers, neither all zeros, ``num`` not of
    higher degree than ``den``; not together with
    ``controlled_element_gain``), ``subject`` and ``notes`` (strings),
    ``run`` (an integer) and ``forcing`` (with ``rate``, the sample rate in Hz:
    no line of nonzero amplitude at or above the Nyquist frequency).  Other keys
    are not looked at.
    numpy scalars and arrays and tuples count as the numbers and arrays they
    hold.  Used for a Recording built in Python and, by
    :mod:`bayespilot.io`, for files, so both are held to the same rules.

    Raises
    ------
    RecordingError
        Naming every bad key and its problem, ``"; "``-separated, in one
        message (no file or source prefix).
    """
    problems = _metadata_problems(meta, rate)
    if problems:
        raise RecordingError("; ".join(problems))


def _time_unit_hint(step: float, dt: float) -> str:
    """A hint when ``t``'s mean step says it is not in seconds: "; t in ms? ..."."""
    if abs(step / (1000.0 * dt) - 1.0) < 1e-2:
        return "; t in ms? the format wants seconds"
    if abs(step - 1.0) < 1e-6 and abs(dt - 1.0) > 1e-2:
        return "; t counts samples? the format wants seconds"
    return ""


@dataclass(frozen=True, eq=False)
class Recording:
    """One tracking run: equally spaced samples of the signals and what the run was.

    Parameters
    ----------
    signals : mapping of str to ndarray
        1-D float arrays of equal length, by column name.  Must hold ``t``,
        ``e``, ``u`` and ``theta_ddot_m``; ``theta``, ``f_t`` and ``f_d`` are
        used when present and any other column is kept.
    sample_rate_hz : float
        Samples per second; must agree with ``t``.
    motion_gain : float
        K_theta, the pitch motion cueing gain (0 means no motion).
    task : {"FD", "FT", "other"}
        Mainly disturbance rejection, mainly target following, or other.
    metadata : mapping, optional
        Every other key of the recording's JSON sidecar (``controlled_element_gain``,
        ``controlled_element``, ``control_gain``, ``subject``, ``run``,
        ``forcing``, ``notes`` and unknown keys), kept as given (a read-only
        copy at every depth, as ``signals`` is: a changed recording is a new
        :class:`Recording`, which checks it).
    source : str, optional
        Where the recording came from (a file stem), used in messages.

    Raises
    ------
    RecordingError
        If ``signals`` or ``metadata`` is not a mapping; a required signal is
        missing, a signal is complex, not numeric (text or booleans included),
        not one-dimensional, not finite or of another length; there are fewer
        than 2 samples; ``sample_rate_hz`` is not a positive finite number or
        ``motion_gain`` not a finite number >= 0 (a bool or a string is not a
        number); ``task`` is not ``"FD"``, ``"FT"`` or ``"other"``; ``t``
        does not start at 0, is not uniform or disagrees with
        ``sample_rate_hz``; or a metadata value is out of
        range (the checks :func:`~bayespilot.io.read_recording` makes of a
        JSON sidecar: ``controlled_element_gain`` (not 0) and ``control_gain``
        finite numbers, ``controlled_element`` with non-empty numeric ``num``
        and ``den``, neither all zeros, ``num`` not of higher degree than
        ``den`` (an improper plant), and not together with
        ``controlled_element_gain``; ``subject``/``notes`` strings, ``run`` an
        integer, a well-formed ``forcing`` with no line of nonzero amplitude at or
        above the Nyquist frequency; numpy values count as the numbers
        and arrays they hold; other keys are not checked; every bad key is
        named in the one message).

    Notes
    -----
    ``t`` is uniform when every sample lies within a tolerance of the grid
    ``t[0] + k * step`` (``step`` the mean step), the tolerance being the
    larger of ``1e-4 * dt`` and 4 single-precision (float32) ulps at
    ``max|t|``, but at most ``dt / 4``: a ``t`` saved as float32 (as MATLAB
    often saves it) is accepted, while a dropped or repeated sample, or
    jitter of a percent of ``dt`` in an 81.92-s, 100-Hz run, is refused.  The
    mean step must then agree with ``1 / sample_rate_hz`` to ``1e-4 * dt``.
    """

    signals: Mapping[str, np.ndarray]
    sample_rate_hz: float
    motion_gain: float
    task: str = "other"
    metadata: Mapping[str, Any] = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self) -> None:
        where = f"{self.source}: " if self.source else ""

        def fail(msg: str) -> None:
            raise RecordingError(where + msg)

        if not isinstance(self.signals, Mapping):
            fail("signals must be a mapping of column name to array")
        missing = [c for c in REQUIRED_SIGNALS if c not in self.signals]
        if missing:
            fail(f"missing required column(s): {', '.join(missing)}")
        clean: dict[str, np.ndarray] = {}
        length = None
        for name, values in self.signals.items():
            try:
                arr = np.asarray(values)
            except (TypeError, ValueError):
                fail(f"column {name!r} is not numeric")
            if np.iscomplexobj(arr):
                fail(f"column {name!r} is complex; only real values can be used")
            if arr.dtype.kind in "USb":  # text or booleans: numbers only by accident
                fail(f"column {name!r} holds {'booleans' if arr.dtype.kind == 'b' else 'text'}"
                     f", not numbers")
            try:
                arr = np.asarray(arr, dtype=np.float64)
            except (TypeError, ValueError):
                fail(f"column {name!r} is not numeric")
            if arr.ndim != 1:
                fail(f"column {name!r} must be one-dimensional, got shape {arr.shape}")
            if length is None:
                length = arr.size
            elif arr.size != length:
                fail(f"columns have unequal lengths ({name!r} has {arr.size}, expected {length})")
            bad = ~np.isfinite(arr)
            if bad.any():
                k = int(np.argmax(bad))
                fail(f"column {name!r} has a non-finite value ({float(arr[k])!r}) at sample {k}")
            arr = arr.copy()
            arr.setflags(write=False)
            clean[str(name)] = arr
        if length is None or length < 2:
            fail("a recording needs at least 2 samples")
        for what in ("sample_rate_hz", "motion_gain"):
            v = getattr(self, what)
            if isinstance(v, (bool, np.bool_, str, bytes)):
                fail(f"{what} must be a number, got {v!r}")
        try:
            rate = float(self.sample_rate_hz)
        except (TypeError, ValueError):
            fail(f"sample_rate_hz must be a number, got {self.sample_rate_hz!r}")
        if not math.isfinite(rate) or rate <= 0:
            fail(f"sample_rate_hz must be a positive finite number, got {self.sample_rate_hz!r}")
        try:
            kth = float(self.motion_gain)
        except (TypeError, ValueError):
            fail(f"motion_gain must be a number, got {self.motion_gain!r}")
        if not math.isfinite(kth) or kth < 0:
            fail(f"motion_gain must be a finite number >= 0, got {self.motion_gain!r}")
        if self.task not in TASKS:
            fail(f"task must be one of {', '.join(TASKS)}, got {self.task!r}")
        t = clean["t"]
        dt = 1.0 / rate
        steps = np.diff(t)
        step = steps.mean()
        if abs(t[0]) > 1e-6 * dt + 1e-12:
            fail(f"t must start at 0, starts at {float(t[0])!r}")
        # Uniform: every t_k within tol of the grid t_0 + k * step, where tol is
        # the larger of 1e-4 * dt and 4 float32 ulps at max|t| (t saved in single
        # precision, as MATLAB often does, is uniform to that), but at most dt / 4,
        # so that a dropped or repeated sample (>= dt / 2 off the grid) is refused.
        tol = min(max(1e-4 * dt, 4.0 * float(np.spacing(np.float32(np.max(np.abs(t)))))),
                  0.25 * dt)
        if np.any(np.abs(t - (t[0] + np.arange(t.size) * step)) > tol):
            k = int(np.argmax(np.abs(steps - step)))
            fail(f"t is not uniformly spaced (step {float(steps[k])!r} s at sample {k + 1}"
                 f"{_time_unit_hint(step, dt)})")
        if abs(step - dt) > 1e-4 * dt:
            fail(
                f"t has a step of {step:.6g} s, which disagrees with "
                f"sample_rate_hz = {rate:g} (step {dt:.6g} s{_time_unit_hint(step, dt)})"
            )
        if not isinstance(self.metadata, Mapping):
            fail(f"metadata must be a mapping of key to value, got {type(self.metadata).__name__}")
        meta = dict(self.metadata)
        try:
            _check_metadata_values(meta, rate)
        except RecordingError as exc:
            fail(str(exc))
        # read-only like the arrays: a column put in afterwards would skip every check above
        object.__setattr__(self, "signals", _ReadOnlyDict(clean))
        object.__setattr__(self, "sample_rate_hz", rate)
        object.__setattr__(self, "motion_gain", kth)
        object.__setattr__(self, "metadata", _frozen(meta))  # nested too: the plant, forcing

    def __reduce__(self):
        # Built again through the checks when unpickled or deep-copied (a dask worker's copy):
        # numpy's pickles come back writable, and the checks make them read-only again.
        return (type(self), (dict(self.signals), self.sample_rate_hz, self.motion_gain,
                             self.task, _thawed(self.metadata), self.source))

    # -- convenience views -------------------------------------------------
    def __getitem__(self, name: str) -> np.ndarray:
        return self.signals[name]

    def __contains__(self, name: object) -> bool:
        return name in self.signals

    @property
    def t(self) -> np.ndarray:
        """Time since the start of the run, s."""
        return self.signals["t"]

    @property
    def e(self) -> np.ndarray:
        """Tracking error shown on the display, rad."""
        return self.signals["e"]

    @property
    def u(self) -> np.ndarray:
        """Pilot control deflection, rad."""
        return self.signals["u"]

    @property
    def theta_ddot_m(self) -> np.ndarray:
        """Commanded pitch motion acceleration, rad/s^2."""
        return self.signals["theta_ddot_m"]

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.signals["t"].size)

    @property
    def dt(self) -> float:
        """Sample interval, s."""
        return 1.0 / self.sample_rate_hz

    @property
    def duration(self) -> float:
        """Length of the record, n_samples / sample_rate_hz, s."""
        return self.n_samples / self.sample_rate_hz

    @property
    def control_gain(self) -> float:
        """K_delta_u, the stick-to-control-input gain: the metadata's ``control_gain``, or
        the paper's 0.69 when it is not given (``diagnose`` warns when a task ``"other"``
        leaves it out and its bootstrap would simulate the loop with 0.69)."""
        return float(self.metadata.get("control_gain", 0.69))

    @property
    def controlled_element(self) -> tuple[np.ndarray, np.ndarray]:
        """Controlled element delta -> theta as (num, den) in powers of s, highest first."""
        ce = self.metadata.get("controlled_element")
        if ce is not None:
            return np.asarray(ce["num"], float), np.asarray(ce["den"], float)
        kc = float(self.metadata.get("controlled_element_gain", 4.0))
        return np.array([kc]), np.array([1.0, 0.0, 0.0])

    def with_signals(self, **signals: np.ndarray) -> "Recording":
        """Return a copy with some signals replaced or added.

        Parameters
        ----------
        **signals : ndarray
            Column name -> 1-D array of :attr:`n_samples` values, in the
            column's units (e.g. ``u=...`` in rad).

        Returns
        -------
        Recording
            The same rate, K_theta, task, metadata and source with the new
            columns; this recording is unchanged.

        Raises
        ------
        RecordingError
            If a new column fails the checks of :class:`Recording` (another
            length, complex or non-finite values, a ``t`` that is not the
            rate's grid).
        """
        new = dict(self.signals)
        new.update(signals)
        return Recording(new, self.sample_rate_hz, self.motion_gain, self.task,
                         self.metadata, self.source)

    def __repr__(self) -> str:
        cols = ", ".join(self.signals)
        src = f" from {self.source!r}" if self.source else ""
        return (f"Recording({self.n_samples} samples at {self.sample_rate_hz:g} Hz, "
                f"task={self.task}, K_theta={self.motion_gain:g}, columns=[{cols}]{src})")


def _recording_digest(recording: Recording) -> str:
    """SHA-256 of what a recording holds: its signals (names and float64 values), its sample
    rate and K_theta; the same run however it is named or wherever it lies.

    Fits (``settings["recording_sha256"]``), :func:`~bayespilot.sample.sample` and
    :func:`~bayespilot.compare.compare` record it, and ``compare`` refuses a posterior whose
    digest is not that of the recording it compares on.  (The batches key their seeds and
    resume on :func:`_signals_digest`, the signals' alone: a resumed batch keeps its seeds.)

    Parameters
    ----------
    recording : Recording

    Returns
    -------
    str
        64 hexadecimal digits.
    """
    import hashlib

    h = hashlib.sha256(_signals_digest(recording).encode())
    h.update(repr((float(recording.sample_rate_hz), float(recording.motion_gain))).encode())
    return h.hexdigest()


def _signals_digest(recording: Recording) -> str:
    """SHA-256 of a recording's signals (names and float64 values): the same run however it
    is named or wherever it lies (a batch's resume; pooling one run twice)."""
    import hashlib

    h = hashlib.sha256()
    for name in sorted(recording.signals):
        h.update(name.encode())
        h.update(np.ascontiguousarray(recording.signals[name], dtype=float).tobytes())
    return h.hexdigest()
