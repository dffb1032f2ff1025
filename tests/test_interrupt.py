"""Ctrl-C while a sampler runs: at the end of the step, without emcee's or dynesty's dump of
the parameters and a traceback (their wrappers print both when the likelihood raises)."""

from __future__ import annotations

import os
import signal
import threading

import numpy as np
import pytest

from bayespilot._interrupt import interrupt_between_steps


@pytest.fixture
def default_sigint():
    """Python's own SIGINT handler (as in a command-line run), restored afterwards."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals are handled in the main thread only")
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, before)


def _ctrl_c() -> None:
    os.kill(os.getpid(), signal.SIGINT)


def test_the_first_ctrl_c_waits_for_check_and_a_second_is_at_once(default_sigint):
    with interrupt_between_steps() as check:
        _ctrl_c()  # deferred: no KeyboardInterrupt here
        with pytest.raises(KeyboardInterrupt):
            _ctrl_c()  # a second one: at once
        with pytest.raises(KeyboardInterrupt):
            check()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_without_ctrl_c_check_does_nothing_and_another_handler_is_left(default_sigint):
    with interrupt_between_steps() as check:
        check()
    mine = lambda signum, frame: None  # noqa: E731 - a notebook's handler, say
    signal.signal(signal.SIGINT, mine)
    with interrupt_between_steps() as check:
        assert signal.getsignal(signal.SIGINT) is mine
        check()
    assert signal.getsignal(signal.SIGINT) is mine


def test_emcee_is_interrupted_between_steps_without_its_dump(default_sigint, capsys):
    from bayespilot.sample import _run_emcee

    calls = []

    def log_prob(X):
        calls.append(len(X))
        if len(calls) == 3:
            _ctrl_c()  # (Ctrl-C inside the likelihood, where the time goes)
        return -0.5 * np.sum(X ** 2, axis=1)

    p0 = np.random.default_rng(0).normal(size=(8, 2))
    with pytest.raises(KeyboardInterrupt):
        _run_emcee(log_prob, p0, n_walkers=8, ndim=2, max_steps=50, min_steps=10,
                   check_every=10, tau_factor=50.0, tau_rtol=0.01)
    out, err = capsys.readouterr()
    assert "Exception while calling" not in out + err and "Traceback" not in err
    # the initial ensemble's call, then step 1's two half-ensembles: the Ctrl-C in its second
    # half, and the step finished before the interrupt
    assert calls == [8, 4, 4]


def test_nested_sampling_is_interrupted_between_iterations_without_its_dump(default_sigint,
                                                                          capsys):
    from bayespilot.compare import nested_evidence

    calls = []

    def loglike(x):
        calls.append(1)
        if len(calls) == 60:
            _ctrl_c()
        return -0.5 * float(x @ x)

    with pytest.raises(KeyboardInterrupt):
        nested_evidence(loglike, [-5, -5], [5, 5], nlive=20, seed=1)
    out, err = capsys.readouterr()
    assert "Exception while calling" not in out + err and "Traceback" not in err
    assert 60 <= len(calls) < 200  # stopped within an iteration or two of the Ctrl-C
