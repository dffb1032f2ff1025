"""Axis labels of parameters for every figure: the paper's notation in mathtext, with units.

One table for all figures, so that ``delta_abs`` reads $\\delta_\\mathrm{abs}$ (IPUT) in a
posterior plot, a diagnosis report and a replication histogram alike.  A name the package
does not know (another lab's extension) follows the same rule: a Greek base name becomes
its letter, one Latin letter stays italic, a longer base is upright, and what follows the
first underscore is an upright subscript.
"""

from __future__ import annotations

from typing import Any

_GREEK = frozenset("alpha beta gamma delta epsilon zeta eta theta iota kappa lambda mu nu xi "
                   "pi rho sigma tau upsilon phi chi psi omega Gamma Delta Theta Lambda Xi Pi "
                   "Sigma Phi Psi Omega".split())


def symbol(name: str) -> str:
    """The mathtext symbol of parameter ``name``: ``"tau_v"`` -> ``"$\\tau_\\mathrm{v}$"``.

    Examples
    --------
    >>> symbol("delta_abs"), symbol("K_m"), symbol("drift_v")
    ('$\\\\delta_\\\\mathrm{abs}$', '$K_\\\\mathrm{m}$', '$\\\\mathrm{drift}_\\\\mathrm{v}$')
    >>> symbol("K_theta")
    '$K_\\\\theta$'
    """
    base, _, sub = str(name).partition("_")
    if base in _GREEK:
        head = "\\" + base
    elif len(base) == 1:
        head = base
    else:
        head = r"\mathrm{%s}" % base.replace("_", r"\_")
    if not sub:
        return f"${head}$"
    if sub in _GREEK:  # K_theta: K with a theta under it
        return "$%s_\\%s$" % (head, sub)
    return "$%s_\\mathrm{%s}$" % (head, sub.replace("_", r"\_"))


def unit_text(unit: str | None) -> str:
    """A unit as a label shows it ("" for none or ``"-"``); powers as superscripts."""
    if not unit or unit == "-":
        return ""
    return unit.replace("^2", "$^2$").replace("^-1", "$^{-1}$")


def label(name: str, unit: str | None = None) -> str:
    """``symbol(name)`` with ``unit`` in parentheses when it has one.

    Examples
    --------
    >>> label("omega_nm", "rad/s")
    '$\\\\omega_\\\\mathrm{nm}$ (rad/s)'
    >>> label("zeta_nm", "-")
    '$\\\\zeta_\\\\mathrm{nm}$'
    """
    u = unit_text(unit)
    return f"{symbol(name)} ({u})" if u else symbol(name)


def parameter_label(model: Any, name: str) -> str:
    """:func:`label` of ``name`` with the unit ``model`` declares for it (none if ``model`` is
    None or does not have the parameter)."""
    unit = None
    if model is not None:
        try:
            unit = model.parameter(name).unit
        except (KeyError, ValueError, AttributeError):
            unit = None
    return label(name, unit)
