"""The paper as data: every number of Pool et al. (2012) that bayespilot builds against.

Source
------
D.M. Pool, A.R. Valente Pais, A.M. de Vroome, M.M. van Paassen, M. Mulder,
"Identification of Nonlinear Motion Perception Dynamics Using Time-Domain Pilot
Modeling", J. Guidance, Control, and Dynamics 35(3), 749-763, 2012,
doi:10.2514/1.56236.  Table and figure numbers below are the paper's.

Everything here is plain data (dicts, tuples, floats) plus a few small
constructors; no model code.
"""

from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np

from .forcing import Multisine

__all__ = [
    "CITATION", "PARAMETER_NAMES", "PARAMETER_UNITS", "TABLE1_BOUNDS", "TABLE2",
    "TABLE3", "TABLE3_T_N", "TABLE4_K_N", "TABLE5", "FIG10", "FIG11", "FIG14_15",
    "T0", "OMEGA0", "SAMPLE_RATE_HZ", "K_C", "K_DU", "K_SCC", "T_SCC1", "T_SCC2",
    "DELTA_ABS_PASSIVE", "MOTION_GAINS", "REMNANT_FRACTIONS", "TASK_SCALING",
    "FORCING_SCALE", "paper_forcing", "paper_parameters",
]

CITATION = ("Pool, D.M., Valente Pais, A.R., de Vroome, A.M., van Paassen, M.M., Mulder, M. "
            "(2012). Identification of Nonlinear Motion Perception Dynamics Using Time-Domain "
            "Pilot Modeling. J. Guidance, Control, and Dynamics 35(3), 749-763. "
            "doi:10.2514/1.56236")

#: Eq. 3 parameters, in the order of Table 1 (and of every parameter vector here).
PARAMETER_NAMES = ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm", "delta_abs")
PARAMETER_UNITS = MappingProxyType({
    "K_v": "-", "T_vl": "s", "tau_v": "s", "K_m": "rad/IPUT", "tau_m": "s",
    "omega_nm": "rad/s", "zeta_nm": "-", "delta_abs": "IPUT",
})

# --- Section II / III.B.1: the task ------------------------------------------
#: Measurement time T0, s (Section III.B.1).
T0 = 81.92
#: Base frequency omega_0 = 2 pi / T0, rad/s.
OMEGA0 = 2 * math.pi / T0
#: Sample rate giving N = 8192 in T0.
SAMPLE_RATE_HZ = 100.0
#: Controlled element gain K_c (theta = K_c / s^2 delta).
K_C = 4.0
#: Stick-to-control-input gain K_delta_u.
K_DU = 0.69
#: Reduced semicircular-canal model, Eq. 1: K_scc (1 + T1 s) / (1 + T2 s).
K_SCC = 5.97
T_SCC1 = 0.11
T_SCC2 = 5.9
#: Passive pitch perception threshold (Groen et al., via Heerspink et al.), IPUT.
DELTA_ABS_PASSIVE = 0.00734
#: Motion cueing gains K_theta studied.
MOTION_GAINS = (0.25, 0.5, 0.75, 1.0)
#: Remnant fractions F_n of the simulation study (Section III.B.2).
REMNANT_FRACTIONS = (0.0, 0.1, 0.2, 0.25, 0.3)

# --- Table 1: bounds used in Steps I and III ---------------------------------
TABLE1_BOUNDS = MappingProxyType({
    "K_v": (0.0, 10.0), "T_vl": (0.0, 10.0), "tau_v": (0.0, 1.0), "K_m": (0.0, 10.0),
    "tau_m": (0.0, 1.0), "omega_nm": (5.0, 30.0), "zeta_nm": (0.0, 1.0), "delta_abs": (0.0, 0.1),
})

# --- Table 2: forcing functions (as printed) ---------------------------------
#: Columns n, omega (rad/s), amplitude (rad), phase (rad); disturbance amplitudes
#: are as inserted before the controlled element (pre-shaped by its inverse).
TABLE2 = MappingProxyType({
    "disturbance": MappingProxyType({
        "n": (5, 8, 11, 17, 28, 46, 59, 82, 106, 137, 178, 211),
        "omega": (0.3835, 0.6136, 0.8437, 1.3039, 2.1476, 3.5282, 4.5252, 6.2893,
                  8.1301, 10.5078, 13.6524, 16.1835),
        "amplitude": (0.0031, 0.0071, 0.0115, 0.0193, 0.0284, 0.0363, 0.0407, 0.0488,
                      0.0590, 0.0755, 0.1033, 0.1308),
        "phase": (-1.2726, -3.0424, 0.1229, 1.5607, -1.0470, 2.3832, -0.4468, 1.0625,
                  -1.5272, -1.0093, -2.8089, -2.3834),
    }),
    "target": MappingProxyType({
        "n": (6, 9, 13, 19, 29, 47, 61, 83, 107, 139, 179, 213),
        "omega": (0.4602, 0.6903, 0.9971, 1.4573, 2.2243, 3.6049, 4.6786, 6.3660,
                  8.2068, 10.6612, 13.7291, 16.3369),
        "amplitude": (0.0876, 0.0764, 0.0613, 0.0430, 0.0250, 0.0120, 0.0081, 0.0052,
                      0.0038, 0.0029, 0.0024, 0.0021),
        "phase": (6.0641, 3.3242, 6.2580, 5.7018, 1.6352, 4.7074, 2.3684, 1.3033,
                  0.7234, 0.1830, 0.5258, 2.9077),
    }),
})

#: Section III.B.1: FD scales the target by 0.5, FT scales the disturbance by 0.5.
TASK_SCALING = MappingProxyType({
    "FD": MappingProxyType({"target": 0.5, "disturbance": 1.0}),
    "FT": MappingProxyType({"target": 1.0, "disturbance": 0.5}),
})

#: Overall amplitude scaling of the simulation study relative to Table 2 as
#: printed.  ``"printed"`` is 1; ``"paper_simulation"`` is the factor determined
#: from the paper's own evidence (std and peaks of i, Table 5, Table 4); see
#: ``docs/faithfulness.md`` and ``analyses/faithfulness.py`` for how.
FORCING_SCALE = MappingProxyType({"printed": 1.0, "paper_simulation": 0.2})

# --- Table 3: true parameters of the simulation study ------------------------
TABLE3 = MappingProxyType({
    "FD": MappingProxyType({"K_v": 1.057, "T_vl": 0.409, "tau_v": 0.279, "K_m": 0.532,
                            "tau_m": 0.203, "omega_nm": 12.00, "zeta_nm": 0.220,
                            "delta_abs": 0.0075}),
    "FT": MappingProxyType({"K_v": 0.875, "T_vl": 0.630, "tau_v": 0.290, "K_m": 0.425,
                            "tau_m": 0.186, "omega_nm": 11.14, "zeta_nm": 0.259,
                            "delta_abs": 0.0075}),
})
#: Remnant filter time constant T_n (Table 3, last column), s.
TABLE3_T_N = MappingProxyType({"FD": 0.0578, "FT": 0.0645})

# --- Table 4: remnant gain K_n by (task, F_n, K_theta) -----------------------
TABLE4_K_N = MappingProxyType({
    ("FD", 0.1): (0.080, 0.060, 0.058, 0.063), ("FD", 0.2): (0.148, 0.101, 0.096, 0.104),
    ("FD", 0.25): (0.209, 0.128, 0.119, 0.129), ("FD", 0.3): (0.370, 0.165, 0.149, 0.162),
    ("FT", 0.1): (0.073, 0.062, 0.058, 0.057), ("FT", 0.2): (0.129, 0.106, 0.098, 0.096),
    ("FT", 0.25): (0.172, 0.135, 0.122, 0.119), ("FT", 0.3): (0.248, 0.177, 0.156, 0.151),
})  # columns: K_theta = 0.25, 0.5, 0.75, 1

# --- Table 5: P(|i| > 0.0075) at F_n = 0.25, mean and +- over 100 realizations
TABLE5 = MappingProxyType({
    ("FD", 0.25): (0.73, 0.0072), ("FD", 0.5): (0.77, 0.0045), ("FD", 0.75): (0.82, 0.0029),
    ("FD", 1.0): (0.86, 0.0024), ("FT", 0.25): (0.64, 0.0074), ("FT", 0.5): (0.75, 0.0050),
    ("FT", 0.75): (0.81, 0.0042), ("FT", 1.0): (0.84, 0.0034),
})

# --- Fig. 10: final delta_abs from the experiment (mu, sigma), 40 data sets -----
FIG10 = MappingProxyType({
    ("FD", 0.25): (0.0326, 0.0133), ("FD", 0.5): (0.0481, 0.0230), ("FD", 0.75): (0.0125, 0.0135),
    ("FD", 1.0): (0.0089, 0.0080), ("FT", 0.25): (0.0215, 0.0118), ("FT", 0.5): (0.0201, 0.0201),
    ("FT", 0.75): (0.0112, 0.0135), ("FT", 1.0): (0.0077, 0.0077),
})

# --- Fig. 11: mean final -ln L with / without threshold, t(78), p ------------
FIG11 = MappingProxyType({
    ("FD", 0.25): (-20032.5, -20195.8, 0.204, 0.84), ("FT", 0.25): (-21441.0, -21714.3, 0.353, 0.73),
    ("FD", 0.5): (-20594.4, -20840.0, 0.346, 0.73), ("FT", 0.5): (-22196.6, -22323.7, 0.188, 0.85),
    ("FD", 0.75): (-20704.0, -20692.8, 0.017, 0.99), ("FT", 0.75): (-22490.3, -22489.6, 0.001, 1.00),
    ("FD", 1.0): (-20660.1, -20643.1, 0.028, 0.98), ("FT", 1.0): (-22332.8, -22325.2, 0.014, 0.99),
})

# --- Figs. 14 (FD) and 15 (FT): three-step delta_abs over 100 realizations ----
#: (task, F_n, K_theta) -> (mu, sigma, N50%)
FIG14_15 = MappingProxyType({
    ("FD", 0.0, 0.25): (0.0671, 0.0109, 0), ("FD", 0.0, 0.5): (0.0666, 0.0117, 0),
    ("FD", 0.0, 0.75): (0.0527, 0.0187, 2), ("FD", 0.0, 1.0): (0.0056, 0.0015, 93),
    ("FD", 0.2, 0.25): (0.0680, 0.0127, 0), ("FD", 0.2, 0.5): (0.0710, 0.0141, 0),
    ("FD", 0.2, 0.75): (0.0287, 0.0210, 24), ("FD", 0.2, 1.0): (0.0088, 0.0049, 55),
    ("FD", 0.3, 0.25): (0.0626, 0.0218, 1), ("FD", 0.3, 0.5): (0.0644, 0.0189, 1),
    ("FD", 0.3, 0.75): (0.0186, 0.0172, 27), ("FD", 0.3, 1.0): (0.0112, 0.0072, 42),
    ("FT", 0.0, 0.25): (0.0594, 0.0124, 0), ("FT", 0.0, 0.5): (0.0589, 0.0161, 0),
    ("FT", 0.0, 0.75): (0.0337, 0.0200, 14), ("FT", 0.0, 1.0): (0.0095, 0.0031, 88),
    ("FT", 0.2, 0.25): (0.0596, 0.0144, 0), ("FT", 0.2, 0.5): (0.0548, 0.0170, 0),
    ("FT", 0.2, 0.75): (0.0189, 0.0151, 32), ("FT", 0.2, 1.0): (0.0090, 0.0047, 65),
    ("FT", 0.3, 0.25): (0.0587, 0.0136, 0), ("FT", 0.3, 0.5): (0.0543, 0.0216, 4),
    ("FT", 0.3, 0.75): (0.0141, 0.0129, 37), ("FT", 0.3, 1.0): (0.0098, 0.0070, 40),
})


def paper_parameters(task: str) -> dict[str, float]:
    """Table 3 pilot parameters for ``task`` ("FD" or "FT"), by name.

    Parameters
    ----------
    task : {"FD", "FT"}
        The task of the simulation study: mainly disturbance rejection (FD)
        or mainly target following (FT).

    Returns
    -------
    dict of str to float
        K_v (-), T_vl (s), tau_v (s), K_m (rad/IPUT), tau_m (s), omega_nm
        (rad/s), zeta_nm (-) and delta_abs (IPUT), a new dict on each call.
        The remnant filter's T_n is in :data:`TABLE3_T_N`.

    Raises
    ------
    ValueError
        If ``task`` is not "FD" or "FT".

    Examples
    --------
    >>> paper_parameters("FD")["K_v"]
    1.057
    """
    if task not in TABLE3:
        raise ValueError(f"task must be 'FD' or 'FT', got {task!r}")
    return dict(TABLE3[task])


def paper_forcing(task: str, scale: str | float = "paper_simulation") -> tuple[Multisine, Multisine]:
    """Table 2 target and disturbance forcing functions for ``task``.

    Parameters
    ----------
    task : {"FD", "FT"}
        Applies the task scaling of Section III.B.1 (FD: target x 0.5; FT:
        disturbance x 0.5).
    scale : str or float, default "paper_simulation"
        Overall amplitude factor: a key of :data:`FORCING_SCALE` or a number.
        ``"printed"`` gives Table 2 exactly as printed.

    Returns
    -------
    target, disturbance : Multisine
        f_t (rad) and f_d (rad, as inserted before the controlled element).

    Raises
    ------
    ValueError
        If ``task`` is not "FD" or "FT", or ``scale`` is neither a key of
        :data:`FORCING_SCALE` nor a finite real number >= 0 (a complex
        number is refused, not truncated).
    """
    if task not in TASK_SCALING:
        raise ValueError(f"task must be 'FD' or 'FT', got {task!r}")
    if isinstance(scale, str):
        if scale not in FORCING_SCALE:
            raise ValueError(f"scale must be one of {sorted(FORCING_SCALE)} or a number, got {scale!r}")
        factor = FORCING_SCALE[scale]
    else:
        if np.iscomplexobj(scale):
            raise ValueError(f"scale must be a real number, got {scale!r}")
        factor = float(scale)
        if not np.isfinite(factor) or factor < 0:
            raise ValueError(f"scale must be a finite number >= 0, got {scale!r}")
    out = []
    for name in ("target", "disturbance"):
        row = TABLE2[name]
        out.append(Multisine(OMEGA0, row["n"], np.asarray(row["amplitude"]) * factor
                             * TASK_SCALING[task][name], row["phase"]))
    return out[0], out[1]
