"""Numba kernels.  Private: they take arrays and scalars only and do not validate.

The public, validating API lives in :mod:`bayespilot.likelihood` and
:mod:`bayespilot.simulate`.
"""
