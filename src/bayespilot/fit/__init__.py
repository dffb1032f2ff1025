"""Point estimation of pilot-model parameters: the three-step procedure of Pool et al. (2012).

Step I is :mod:`bayespilot.fit.genetic` (a binary-encoded genetic algorithm run
repeatedly; its best runs give the first threshold estimate).  Import the
submodules directly; this package module imports nothing so that
``import bayespilot.fit`` stays cheap.
"""
