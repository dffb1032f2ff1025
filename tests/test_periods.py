"""Whole periods of the forcing: one rule for the start-up discard and the frequency evidence.

:func:`bayespilot.likelihood.whole_periods` (does the fitter leave the model's start-up out?)
and :func:`bayespilot.diagnose.locate.forcing_of` (are the forcing lines DFT bins, for the
frequency evidence?) decided it by two rules that disagreed at the edges: a line of zero
amplitude (counted by the diagnosis only, in the test and in the gcd of its snap), lines each
near whole cycles but at no one base frequency (whole periods to the likelihood only), a column
zero throughout next to one with a line on DFT bin 1 (its placeholder line "shared").  Both now
read :func:`bayespilot.forcing.whole_periods_frequency` (a sidecar) and
:func:`bayespilot.forcing.columns_whole_periods` (the f_t and f_d columns).  The records are
built in memory: 10 s at 100 Hz, the pilot's signals zero (only the forcing is read).
"""

from __future__ import annotations

import numpy as np
import pytest

from bayespilot.diagnose.locate import forcing_of
from bayespilot.forcing import (EXACT_TOLERANCE, SNAP_TOLERANCE, Multisine, columns_whole_periods,
                                whole_periods_frequency)
from bayespilot.likelihood import whole_periods
from bayespilot.recording import Recording

T = 10.0  # s
RATE = 100.0  # Hz
t = np.arange(int(T * RATE)) / RATE


def record(forcing: dict | None = None, **columns) -> Recording:
    """A 10-s record with the sidecar ``forcing`` (base_frequency, target, disturbance) and
    the forcing ``columns`` given."""
    signals = {"t": t, **{k: np.zeros(t.size) for k in ("e", "u", "theta", "theta_ddot_m")},
               **columns}
    meta = {} if forcing is None else {"forcing": forcing}
    return Recording(signals, RATE, 1.0, "other", meta)


def sidecar(m: float, target: Multisine, disturbance: Multisine) -> dict:
    """A sidecar whose base frequency makes the 10-s record ``m`` base periods."""
    return {"base_frequency": 2 * np.pi * m / T, "target": target.to_dict(),
            "disturbance": disturbance.to_dict()}


def lines(n, amplitude=None) -> Multisine:
    n = np.atleast_1d(n)
    a = np.ones(n.size) if amplitude is None else np.asarray(amplitude, float)
    return Multisine(1.0, n, a, np.linspace(0.3, 2.0, n.size))


def agree(rec: Recording) -> bool | None:
    """whole_periods, after checking that forcing_of (its extra needs met) says the same."""
    wp = whole_periods(rec)
    fo = forcing_of(rec)
    assert fo is not None and fo.periodic is bool(wp), (wp, fo.periodic, fo.notes)
    return wp


# --- the normal cases keep their verdicts ----------------------------------------------------
@pytest.mark.parametrize("m, whole", [(1.0, True), (2.0, True),  # the sidecar's own w0
                                      (1.0001, True),  # a rounded w0: snapped
                                      (0.5, False), (1.3, False), (0.4, False)])  # cut records
def test_the_sidecar_and_the_columns_read_a_record_alike(m, whole):
    ft, fd = lines([2, 5, 9, 15]), lines([3, 7, 11, 19])
    side = record(sidecar(m, ft, fd))
    assert agree(side) is whole
    w0 = 2 * np.pi * (round(m) if whole else m) / T  # (the signal a rounded w0 stands for)
    cols = record(f_t=Multisine(w0, ft.n, ft.amplitude, ft.phase)(t),
                  f_d=Multisine(w0, fd.n, fd.amplitude, fd.phase)(t))
    assert agree(cols) is whole
    if whole:
        np.testing.assert_array_equal(forcing_of(cols).k_target, forcing_of(side).k_target)


def test_the_rule_itself():
    w0 = 2 * np.pi / T
    n, a = [2, 5, 9], [1.0, 1.0, 1.0]
    assert whole_periods_frequency(w0, n, a, T) == w0  # exact: kept as it is
    assert whole_periods_frequency(w0 * (1 + 0.5 * EXACT_TOLERANCE / 9), n, a, T) == \
        w0 * (1 + 0.5 * EXACT_TOLERANCE / 9)  # within 1e-3 cycle: not snapped
    rounded = w0 * (1 + 0.9 * SNAP_TOLERANCE / 9)
    assert whole_periods_frequency(rounded, n, a, T) == pytest.approx(w0, rel=1e-13)
    assert whole_periods_frequency(w0 * (1 + 1.1 * SNAP_TOLERANCE / 9), n, a, T) is None
    assert whole_periods_frequency(w0 * 0.3, n, a, T) is None  # shorter than half a period
    assert whole_periods_frequency(w0, [], [], T) == w0  # nothing to cut
    with pytest.raises(ValueError, match="same length"):
        whole_periods_frequency(w0, [1, 2], [1.0], T)
    with pytest.raises(ValueError, match="positive finite"):
        whole_periods_frequency(-w0, n, a, T)
    assert columns_whole_periods([]) is None
    assert columns_whole_periods([np.zeros(t.size)]) is None
    assert columns_whole_periods([np.zeros(t.size), np.sin(2 * np.pi * t / T)]) is True
    assert columns_whole_periods([np.sin(2 * np.pi * t / 7.3)]) is False


# --- where the two rules disagreed ------------------------------------------------------------
def test_a_zero_amplitude_line_off_its_bin_does_not_decide():
    """A rounded base frequency (10.01 s of the 10-s record: 0.005 and 0.007 cycle at the
    lines 5 and 7) and a line n = 100 of zero amplitude, 0.1 cycle off.  The likelihood
    (start-up) said whole periods, the diagnosis not (no frequency evidence): the line is not
    in the signal, so whole periods, and at the snapped frequency it is on bin 100."""
    rec = record(sidecar(1.001, lines([5]), lines([7, 100], [1.0, 0.0])))
    assert agree(rec) is True
    fo = forcing_of(rec)
    assert fo.target.base_frequency == pytest.approx(2 * np.pi / T, rel=1e-13)
    assert fo.k_target.tolist() == [5] and fo.k_disturbance.tolist() == [7, 100]
    # (and, every line being above 2 rad/s, that frequency.motion_low has none)
    assert len(fo.notes) == 2 and "taken as" in fo.notes[0]
    assert "0.007 cycle" in fo.notes[0]  # the lines in the signal, not the zero one's 0.1
    assert "frequency.motion_low" in fo.notes[1] and "OMEGA_SPLIT" in fo.notes[1]


def test_a_zero_placeholder_does_not_change_the_forcing_period():
    """A target-only run (the disturbance written as Multisine.zero(): n = 1, amplitude 0)
    whose target lines 2, 4, 6 have a period of half the base period, over one such period
    with a rounded base frequency (0.5005 base periods: the lines 0.001-0.003 cycle off).  The
    diagnosis took the placeholder's n = 1 into the gcd, found the record half a base period
    and gave no frequency evidence; the likelihood said whole periods.  Whole periods, with
    the placeholder (not on a bin of the snapped frequency, 0.5 cycle) left out."""
    target = lines([2, 4, 6])
    rec = record(sidecar(0.5005, target, Multisine.zero()))
    assert agree(rec) is True
    fo = forcing_of(rec)
    assert fo.target.base_frequency == pytest.approx(np.pi / T, rel=1e-13)  # 0.5 periods
    assert fo.k_target.tolist() == [1, 2, 3]
    assert fo.disturbance.n.size == 0 and fo.k_disturbance.size == 0
    assert fo.zero == ("f_d",) and not fo.two_input
    np.testing.assert_allclose(fo.f_d, 0.0)


def test_lines_near_whole_cycles_at_no_one_base_frequency_are_not_whole_periods():
    """Lines 20 and 21 over 1.0488 base periods: 20.976 and 22.025 cycles, each within
    0.05 cycle of whole cycles, so the likelihood said whole periods (and fitted without a
    start-up discard); but no base frequency near the sidecar's puts both there (the record
    is 1.05 periods of their sum), and the diagnosis said not.  Not whole periods: the lines'
    own roundings contradict the one base frequency the sidecar gives them."""
    rec = record(sidecar(1.0488, lines([20]), lines([21])))
    assert agree(rec) is False
    note = forcing_of(rec).notes[0]
    assert "1.049 periods" in note and "not a whole number" in note
    # (shorter than one period: 0.0488 base periods, 0.976 and 1.025 cycles)
    rec = record(sidecar(0.0488, lines([20]), lines([21])))
    assert agree(rec) is False
    assert "shorter than one period" in forcing_of(rec).notes[0]


def test_a_column_zero_throughout_shares_no_line():
    """f_t with a line on DFT bin 1 (one period of it in the record) and f_d zero throughout:
    the diagnosis read f_d as a multisine of one line, n = 1, of zero amplitude, found it
    "shared" with f_t's and gave no frequency evidence (not even the target's power), while
    the likelihood said whole periods."""
    f_t = np.sin(2 * np.pi * t / T + 0.3) + 0.5 * np.sin(2 * np.pi * 3 * t / T)
    rec = record(f_t=f_t, f_d=np.zeros(t.size))
    assert agree(rec) is True
    fo = forcing_of(rec)
    assert fo.k_target.tolist() == [1, 3] and fo.zero == ("f_d",) and not fo.two_input
    assert len(fo.notes) == 1 and "target only" in fo.notes[0]
    # both zero throughout: not known, and said so (not "share 1 DFT line(s)")
    rec = record(f_t=np.zeros(t.size), f_d=np.zeros(t.size))
    assert whole_periods(rec) is None
    fo = forcing_of(rec)
    assert not fo.periodic and "zero throughout" in fo.notes[0] and "share" not in fo.notes[0]


@pytest.mark.parametrize("period, whole", [(T, True), (7.3, False)])
def test_one_forcing_column_tells_whole_periods_but_is_no_forcing(period, whole):
    """f_t alone: the likelihood reads whole periods from it (a record cut mid-period cuts
    both forcing functions); the diagnosis has no forcing (the disturbance is not known,
    which the bootstrap and the two-input estimate need), not a different verdict."""
    f_t = np.sin(2 * np.pi * t / period) + 0.3 * np.sin(2 * np.pi * 4 * t / period + 1.0)
    rec = record(f_t=f_t)
    assert whole_periods(rec) is whole
    assert forcing_of(rec) is None
