"""Warnings attributed to the user's code, not to the package's insides."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent


def warn_at_caller(message: str | Warning, category: type[Warning] | None = None) -> None:
    """``warnings.warn(message, category)`` at the first frame outside bayespilot.

    A warning raised deep in a computation (a likelihood built by a fit built
    by a diagnosis) then names the line of the user's code that started it,
    and Python's default filter shows it once for that line however many
    times the computation raises it.

    ``message`` may also be a Warning instance (one that carries attributes,
    such as :class:`bayespilot.sample.ConvergenceWarning`); ``category`` is
    then ignored, as in :func:`warnings.warn`.
    """
    if category is None and not isinstance(message, Warning):
        category = UserWarning
    level, frame = 2, sys._getframe(1)
    while frame is not None and Path(frame.f_code.co_filename).resolve().is_relative_to(_PACKAGE):
        level, frame = level + 1, frame.f_back
    warnings.warn(message, category, stacklevel=level)
