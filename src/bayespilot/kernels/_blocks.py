"""Block primitives shared by the likelihood and the closed-loop simulator.

Every linear block of a channel is a continuous-time biquad

    H(s) = (b2 s^2 + b1 s + b0) / (a2 s^2 + a1 s + a0)

whose coefficients come from :func:`stage_tf` (a kind code and up to two
parameter values).  The likelihood discretises it with Tustin's rule
(:func:`tustin`) at the recording's rate; the simulator integrates the same
biquad in state-space form (:func:`biquad_ss`) at a finer step.  A static
nonlinearity is :func:`nonlinearity` (a kind code and two parameters).

Extension point: a new parametric linear block is a new ``STAGE_*`` code with
its coefficients in :func:`stage_tf` and their derivative in
``_sensitivity.stage_tf_tangent``; a new static nonlinearity is a new ``NL_*``
code in :func:`nonlinearity` and :func:`nonlinearity_tangent` (and, if it is
piecewise linear, in ``_oversample._piece`` and ``_oversample._piecewise``), and
its number of parameters in ``ARITY_STAGE``, ``ARITY_NL`` or ``ARITY_MOD``.
``model.py`` refuses a block whose code is not here (the functions below pass an
unknown code through as no block) or whose parameters are not as many as its
code reads.
"""

from __future__ import annotations

import math

from .._jit import njit

# Stage kinds (linear blocks before the nonlinearity).
STAGE_NONE = 0
STAGE_FIXED = 1       # constant coefficients (b0, b1, b2, a0, a1, a2)
STAGE_HIGHPASS1 = 2   # s / (s + p0)                      washout, p0 = break frequency, rad/s
STAGE_LOWPASS2 = 3    # p0^2 / (s^2 + 2 p1 p0 s + p0^2)   e.g. motion-platform bandwidth
STAGE_LOWPASS1 = 4    # 1 / (p0 s + 1)                     first-order lag, p0 = time constant, s
STAGE_HIGHPASS2 = 5   # s^2 / (s^2 + 2 p1 p0 s + p0^2)     second-order washout

# Static nonlinearities.
NL_NONE = 0
NL_DEADZONE = 1       # sign(x) max(|x| - p0, 0)            Pool et al. (2012), Fig. 3
NL_SOFT_DEADZONE = 2  # smooth dead zone, width p1 (see nonlinearity)
NL_SATURATION = 3     # clip(x, -p0, p0)

# Channel gain modulation.
MOD_NONE = 0
MOD_LINEAR = 1        # gain x (1 + p0 (t / T - 1/2)): a gain that drifts linearly over the run

# How many parameters the functions below read for each code (p0, then p1): a block must name
# exactly that many (``model._check_block``).  A third name would never be read, and a missing
# one would be taken as 0 (a second-order stage with damping 0, a soft dead zone of width 0).
# A new code needs its entry here too.
ARITY_STAGE = {STAGE_FIXED: 0, STAGE_HIGHPASS1: 1, STAGE_LOWPASS2: 2, STAGE_LOWPASS1: 1,
               STAGE_HIGHPASS2: 2}
ARITY_NL = {NL_DEADZONE: 1, NL_SOFT_DEADZONE: 2, NL_SATURATION: 1}
ARITY_MOD = {MOD_LINEAR: 1}


@njit
def stage_tf(kind, p0, p1, const):
    """Continuous biquad coefficients (b0, b1, b2, a0, a1, a2) of a stage."""
    if kind == STAGE_FIXED:
        return const[0], const[1], const[2], const[3], const[4], const[5]
    if kind == STAGE_HIGHPASS1:
        return 0.0, 1.0, 0.0, p0, 1.0, 0.0
    if kind == STAGE_LOWPASS2:
        w2 = p0 * p0
        return w2, 0.0, 0.0, w2, 2.0 * p1 * p0, 1.0
    if kind == STAGE_LOWPASS1:
        return 1.0, 0.0, 0.0, 1.0, p0, 0.0
    if kind == STAGE_HIGHPASS2:
        return 0.0, 0.0, 1.0, p0 * p0, 2.0 * p1 * p0, 1.0
    return 1.0, 0.0, 0.0, 1.0, 0.0, 0.0


@njit
def tustin(b0, b1, b2, a0, a1, a2, dt):
    """Tustin (bilinear) discretisation of a continuous biquad.

    Returns (B0, B1, B2, A1, A2) of
    y[k] = B0 x[k] + B1 x[k-1] + B2 x[k-2] - A1 y[k-1] - A2 y[k-2].
    """
    c = 2.0 / dt
    # a factor s common to numerator and denominator (a washout at omega_w = 0: s / s) cancels;
    # kept, it would put a pole on the unit circle
    while a0 == 0.0 and b0 == 0.0 and (a1 != 0.0 or a2 != 0.0):
        b0, b1, b2 = b1, b2, 0.0
        a0, a1, a2 = a1, a2, 0.0
    if a2 == 0.0 and b2 == 0.0 and a1 == 0.0 and b1 == 0.0:
        # Zero order (a first-order stage at its limit, e.g. a lag with T = 0): a gain.  The
        # first-order formulas below would give a pole at z = -1.
        return b0 / a0, 0.0, 0.0, 0.0, 0.0
    if a2 == 0.0 and b2 == 0.0:
        # First order: keep it first order.  The biquad formulas below would
        # add a cancelled pole/zero pair at z = -1, which a warm start excites.
        d0 = a1 * c + a0
        return (b1 * c + b0) / d0, (b0 - b1 * c) / d0, 0.0, (a0 - a1 * c) / d0, 0.0
    c2 = c * c
    d0 = a2 * c2 + a1 * c + a0
    d1 = 2.0 * (a0 - a2 * c2)
    d2 = a2 * c2 - a1 * c + a0
    n0 = b2 * c2 + b1 * c + b0
    n1 = 2.0 * (b0 - b2 * c2)
    n2 = b2 * c2 - b1 * c + b0
    return n0 / d0, n1 / d0, n2 / d0, d1 / d0, d2 / d0


@njit
def stable(A1, A2):
    """True if z^2 + A1 z + A2 has both roots strictly inside the unit circle (Jury)."""
    return abs(A2) < 1.0 and abs(A1) < 1.0 + A2


@njit
def biquad_ss(b0, b1, b2, a0, a1, a2):
    """State-space form of a proper continuous biquad.

    Returns (order, alpha0, alpha1, c0, c1, d) for
    order 2:  x1' = x2,  x2' = -alpha0 x1 - alpha1 x2 + in,  y = c0 x1 + c1 x2 + d in
    order 1:  x1' = -alpha0 x1 + in,                          y = c0 x1 + d in
    order 0:  y = d in
    """
    if a2 != 0.0:
        d = b2 / a2
        al0 = a0 / a2
        al1 = a1 / a2
        return 2, al0, al1, b0 / a2 - d * al0, b1 / a2 - d * al1, d
    if a1 != 0.0:
        d = b1 / a1
        al0 = a0 / a1
        return 1, al0, 0.0, b0 / a1 - d * al0, 0.0, d
    return 0, 0.0, 0.0, 0.0, 0.0, b0 / a0


@njit
def nonlinearity(kind, x, p0, p1):
    """Static nonlinearity of a channel (threshold shapes, saturation)."""
    if kind == NL_DEADZONE:
        ax = abs(x) - p0
        if ax <= 0.0:
            return 0.0
        return ax if x > 0.0 else -ax
    if kind == NL_SOFT_DEADZONE:
        # Softplus-rounded dead zone: w log(1 + exp((|x| - d) / w)) minus its value
        # at x = 0, so the output is 0 at 0, odd, and tends to the crisp dead zone
        # as w -> 0.
        w = p1 if p1 > 1e-12 else 1e-12
        a = (abs(x) - p0) / w
        a0 = -p0 / w
        sp = a + math.log1p(math.exp(-a)) if a > 0.0 else math.log1p(math.exp(a))
        sp0 = a0 + math.log1p(math.exp(-a0)) if a0 > 0.0 else math.log1p(math.exp(a0))
        y = w * (sp - sp0)
        return y if x >= 0.0 else -y
    if kind == NL_SATURATION:
        if x > p0:
            return p0
        if x < -p0:
            return -p0
        return x
    return x


@njit
def nonlinearity_tangent(kind, x, p0, p1, dx, dp0, dp1):
    """Derivative of ``nonlinearity`` along (dx, dp0, dp1)."""
    if kind == NL_DEADZONE:
        if abs(x) - p0 <= 0.0:
            return 0.0
        return dx - dp0 if x > 0.0 else dx + dp0
    if kind == NL_SOFT_DEADZONE:
        w = p1 if p1 > 1e-12 else 1e-12
        dw = dp1 if p1 > 1e-12 else 0.0
        ax = abs(x)
        dax = dx if x >= 0.0 else -dx
        a = (ax - p0) / w
        a0 = -p0 / w
        da = (dax - dp0) / w - a * dw / w
        da0 = -dp0 / w - a0 * dw / w
        sp = a + math.log1p(math.exp(-a)) if a > 0.0 else math.log1p(math.exp(a))
        sp0 = a0 + math.log1p(math.exp(-a0)) if a0 > 0.0 else math.log1p(math.exp(a0))
        sig = 1.0 / (1.0 + math.exp(-a))
        sig0 = 1.0 / (1.0 + math.exp(-a0))
        dy = dw * (sp - sp0) + w * (sig * da - sig0 * da0)
        return dy if x >= 0.0 else -dy
    if kind == NL_SATURATION:
        if x > p0:
            return dp0
        if x < -p0:
            return -dp0
        return dx
    return dx


@njit
def _run_fraction(t_frac):
    """``t_frac`` held within the run, [0, 1]: a modulated gain keeps its start value before
    the record (the simulator's run-in, a likelihood's lead-in from rest) instead of being
    extrapolated back, where a drift of 1.5 over the run made the visual gain negative for
    the first third of the simulator's 41-s run-in and the loop diverged."""
    if t_frac < 0.0:
        return 0.0
    if t_frac > 1.0:
        return 1.0
    return t_frac


@njit
def modulation(kind, t_frac, p0):
    """Gain modulation factor at run fraction ``t_frac`` (held within [0, 1])."""
    if kind == MOD_LINEAR:
        return 1.0 + p0 * (_run_fraction(t_frac) - 0.5)
    return 1.0


@njit
def modulation_slope(kind, t_frac):
    """Derivative of :func:`modulation` with respect to its parameter ``p0``."""
    if kind == MOD_LINEAR:
        return _run_fraction(t_frac) - 0.5
    return 0.0


@njit
def param_or(theta, idx, default):
    """``theta[idx]``, or ``default`` where the index is -1 (no parameter)."""
    if idx < 0:
        return default
    return theta[idx]

