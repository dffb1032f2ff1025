"""bayespilot: motion-perception thresholds and pilot-model parameters from tracking recordings.

Implements and extends the time-domain identification method of Pool et al.
(2012), J. Guidance, Control, and Dynamics 35(3), 749-763.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("bayespilot")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"
