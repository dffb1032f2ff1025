"""Ctrl-C between a sampler's steps, not inside its call of the likelihood.

emcee and dynesty call the likelihood through a wrapper whose bare ``except:`` prints the
parameters, the arguments and a traceback before it re-raises, so a Ctrl-C that lands in the
likelihood (nearly always: that is where the time goes) put about 40 lines of debris on
stdout and stderr before ``bayespilot: interrupted``.  While a sampler runs, the first Ctrl-C
only sets a flag, which the sampler's loop (our code, outside the wrapper) turns into a
KeyboardInterrupt at the end of the step; a second Ctrl-C interrupts at once, as usual.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from typing import Callable, Iterator

__all__ = ["interrupt_between_steps", "caused_by_interrupt"]


@contextlib.contextmanager
def interrupt_between_steps() -> Iterator[Callable[[], None]]:
    """Defer the first Ctrl-C to the next call of the function this yields.

    Yields
    ------
    callable
        ``check()``: raises KeyboardInterrupt if Ctrl-C was pressed since the context was
        entered; call it between the sampler's steps.

    Notes
    -----
    Only in the main thread with Python's default SIGINT handler installed (a command-line
    run, a script); elsewhere (a dask worker's thread, a notebook's own handler) nothing is
    changed and ``check`` never raises.  The handler in place before (the one
    ``signal.getsignal`` returned on entry) is restored on exit, and at the first Ctrl-C so
    that a second one acts at once.
    """
    if threading.current_thread() is not threading.main_thread():
        yield lambda: None
        return
    # what is restored, on exit and at the first Ctrl-C: the handler getsignal reports,
    # not signal.default_int_handler by name, so that the restore stays right if the test
    # below is ever relaxed
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.default_int_handler:
        yield lambda: None
        return
    pressed: list[bool] = []

    def defer(signum, frame) -> None:
        pressed.append(True)
        signal.signal(signal.SIGINT, previous)  # a second one: at once

    def check() -> None:
        if pressed:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, defer)
    try:
        yield check
    finally:
        signal.signal(signal.SIGINT, previous)


def caused_by_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is, or was raised while handling or because of, a KeyboardInterrupt
    (its ``__cause__``/``__context__`` chain): Ctrl-C inside a numba kernel surfaces as a
    SystemError ("returned a result with an exception set") with the interrupt as context.
    The command (its exit code 130) and the campaign's numba warm-up read it.

    Parameters
    ----------
    exc : BaseException
        The exception caught.

    Returns
    -------
    bool
        True if a KeyboardInterrupt is ``exc`` or in its chain.
    """
    todo, seen = [exc], set()
    while todo:
        e = todo.pop()
        if e is None or id(e) in seen:
            continue
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        todo += [e.__cause__, e.__context__]
    return False
