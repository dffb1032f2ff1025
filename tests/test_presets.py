"""The paper as data: internal consistency of the transcribed tables."""

import math

import numpy as np
import pytest

from bayespilot import presets
from bayespilot.forcing import Multisine


def test_table2_frequencies_are_integer_multiples_of_the_base_frequency():
    """Table 2 prints omega = n omega_0 to 4 decimals: check every row against T0 = 81.92 s."""
    for name in ("disturbance", "target"):
        row = presets.TABLE2[name]
        assert len(row["n"]) == len(row["omega"]) == len(row["amplitude"]) == len(row["phase"]) == 12
        np.testing.assert_allclose(np.array(row["n"]) * 2 * math.pi / 81.92, row["omega"], atol=6e-5)


def test_canal_gain_is_unity_at_one_rad_per_second():
    """Section II.B: K_scc = 5.97 makes |H_scc(j 1)| = 1 for the reduced model (1.0037 as printed)."""
    h = presets.K_SCC * abs(1 + 1j * presets.T_SCC1) / abs(1 + 1j * presets.T_SCC2)
    assert h == pytest.approx(1.0, abs=5e-3)


def test_task_scalings_and_scale_presets():
    ft_fd, fd_fd = presets.paper_forcing("FD", "printed")
    ft_ft, fd_ft = presets.paper_forcing("FT", "printed")
    np.testing.assert_allclose(ft_fd.amplitude, 0.5 * np.array(presets.TABLE2["target"]["amplitude"]))
    np.testing.assert_allclose(fd_fd.amplitude, presets.TABLE2["disturbance"]["amplitude"])
    np.testing.assert_allclose(fd_ft.amplitude, 0.5 * np.array(presets.TABLE2["disturbance"]["amplitude"]))
    ft_s, _ = presets.paper_forcing("FT")
    np.testing.assert_allclose(ft_s.amplitude, presets.FORCING_SCALE["paper_simulation"] * ft_ft.amplitude)
    with pytest.raises(ValueError, match="task"):
        presets.paper_forcing("XY")
    with pytest.raises(ValueError, match="scale"):
        presets.paper_forcing("FD", "bogus")


def test_disturbance_is_preshaped_by_the_inverse_plant():
    """|K_c/(j w)^2| A_d falls with frequency like the target: the pre-shaping of Section III.B.1."""
    row = presets.TABLE2["disturbance"]
    effect = presets.K_C * np.array(row["amplitude"]) / np.array(row["omega"]) ** 2
    assert np.all(np.diff(effect) < 0)
    assert effect[0] == pytest.approx(presets.TABLE2["target"]["amplitude"][0], rel=0.1)


def test_table3_within_table1_bounds_and_tables_complete():
    for task in ("FD", "FT"):
        for k, v in presets.TABLE3[task].items():
            lo, hi = presets.TABLE1_BOUNDS[k]
            assert lo <= v <= hi
    assert len(presets.FIG14_15) == 24 and len(presets.TABLE5) == 8 and len(presets.TABLE4_K_N) == 8


def test_multisine_derivatives_match_finite_differences():
    f = Multisine(presets.OMEGA0, [6, 13], [0.1, 0.05], [0.3, 2.0])
    t = np.linspace(0, 5, 11)
    h = 1e-5
    np.testing.assert_allclose(f(t, 1), (f(t + h) - f(t - h)) / (2 * h), rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(f(t, 2), (f(t + h, 1) - f(t - h, 1)) / (2 * h), rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("args, message", [
    ((1.0, [1], np.array([1 + 1j]), [0.0]), "amplitude must be real"),
    ((1.0, [1], [1.0], np.array([0.5j])), "phase must be real"),
    ((np.complex128(1 + 1j), [1], [1.0], [0.0]), "base_frequency must be real"),
    ((1.0, np.array([2 + 0j]), [1.0], [0.0]), "n must be real"),
    ((1.0, [1.5], [1.0], [0.0]), "n must hold integers >= 1"),
    ((1.0, [0], [1.0], [0.0]), "n must hold integers >= 1"),
    ((1.0, [2, -3], [1.0, 1.0], [0.0, 0.0]), "n must hold integers >= 1.*-3"),
    ((1.0, [True], [1.0], [0.0]), "n must hold integers >= 1"),
])
def test_multisine_refuses_complex_values_and_non_integer_multiples(args, message):
    """Complex values were truncated (a ComplexWarning only); n = 1.5 was kept in the signal but
    saved as 1 by to_dict, so the recorded forcing disagreed with the saved one."""
    with pytest.raises(ValueError, match=message):
        Multisine(*args)


def test_multisine_integer_valued_n_is_stored_as_int_and_round_trips():
    f = Multisine(0.5, np.array([3.0, 7.0]), [1.0, 0.5], [0.2, 0.1])
    assert f.n.dtype.kind == "i" and f.n.tolist() == [3, 7]
    g = Multisine.from_dict(0.5, f.to_dict())
    t = np.linspace(0, 10, 101)
    np.testing.assert_array_equal(f(t), g(t))
    assert f.to_dict()["n"] == [3, 7]


def test_paper_forcing_refuses_a_complex_scale():
    with pytest.raises(ValueError, match="scale must be a real number"):
        presets.paper_forcing("FD", np.complex128(0.2 + 1j))
    with pytest.raises(ValueError, match="scale must be a real number"):
        presets.paper_forcing("FD", 0.2 + 0j)
    np.testing.assert_allclose(presets.paper_forcing("FD", np.float64(0.2))[0].amplitude,
                               presets.paper_forcing("FD", 0.2)[0].amplitude)


# The paper's printed tables, copied row by row from Pool et al. (2012) (the extract in
# shared/paper/targets.md), independent of presets.py: a typo in the presets (a transposed
# amplitude, an N50 of 73 for 37) passed every other test, which take the presets as truth.
TABLE2_ROWS = """
5 0.3835 0.0031 -1.2726 6 0.4602 0.0876 6.0641
8 0.6136 0.0071 -3.0424 9 0.6903 0.0764 3.3242
11 0.8437 0.0115 0.1229 13 0.9971 0.0613 6.2580
17 1.3039 0.0193 1.5607 19 1.4573 0.0430 5.7018
28 2.1476 0.0284 -1.0470 29 2.2243 0.0250 1.6352
46 3.5282 0.0363 2.3832 47 3.6049 0.0120 4.7074
59 4.5252 0.0407 -0.4468 61 4.6786 0.0081 2.3684
82 6.2893 0.0488 1.0625 83 6.3660 0.0052 1.3033
106 8.1301 0.0590 -1.5272 107 8.2068 0.0038 0.7234
137 10.5078 0.0755 -1.0093 139 10.6612 0.0029 0.1830
178 13.6524 0.1033 -2.8089 179 13.7291 0.0024 0.5258
211 16.1835 0.1308 -2.3834 213 16.3369 0.0021 2.9077
"""
TABLE3_ROWS = """
FD 1.057 0.409 0.279 0.532 0.203 12.00 0.220 0.0075 0.0578
FT 0.875 0.630 0.290 0.425 0.186 11.14 0.259 0.0075 0.0645
"""
TABLE4_ROWS = """
0.1 0.080 0.060 0.058 0.063 0.073 0.062 0.058 0.057
0.2 0.148 0.101 0.096 0.104 0.129 0.106 0.098 0.096
0.25 0.209 0.128 0.119 0.129 0.172 0.135 0.122 0.119
0.3 0.370 0.165 0.149 0.162 0.248 0.177 0.156 0.151
"""
TABLE5_ROWS = """
0.25 0.73 0.0072 0.64 0.0074
0.5 0.77 0.0045 0.75 0.0050
0.75 0.82 0.0029 0.81 0.0042
1 0.86 0.0024 0.84 0.0034
"""
FIG14_15_ROWS = """
FD 0 0.25 0.0671 0.0109 0
FD 0 0.5 0.0666 0.0117 0
FD 0 0.75 0.0527 0.0187 2
FD 0 1 0.0056 0.0015 93
FD 0.2 0.25 0.0680 0.0127 0
FD 0.2 0.5 0.0710 0.0141 0
FD 0.2 0.75 0.0287 0.0210 24
FD 0.2 1 0.0088 0.0049 55
FD 0.3 0.25 0.0626 0.0218 1
FD 0.3 0.5 0.0644 0.0189 1
FD 0.3 0.75 0.0186 0.0172 27
FD 0.3 1 0.0112 0.0072 42
FT 0 0.25 0.0594 0.0124 0
FT 0 0.5 0.0589 0.0161 0
FT 0 0.75 0.0337 0.0200 14
FT 0 1 0.0095 0.0031 88
FT 0.2 0.25 0.0596 0.0144 0
FT 0.2 0.5 0.0548 0.0170 0
FT 0.2 0.75 0.0189 0.0151 32
FT 0.2 1 0.0090 0.0047 65
FT 0.3 0.25 0.0587 0.0136 0
FT 0.3 0.5 0.0543 0.0216 4
FT 0.3 0.75 0.0141 0.0129 37
FT 0.3 1 0.0098 0.0070 40
"""


def _rows(text):
    return [line.split() for line in text.strip().splitlines()]


def test_presets_are_the_papers_printed_tables():
    names = ("K_v", "T_vl", "tau_v", "K_m", "tau_m", "omega_nm", "zeta_nm", "delta_abs")
    rows = [[float(x) for x in r] for r in _rows(TABLE2_ROWS)]
    for col, part in ((0, "disturbance"), (4, "target")):
        got = {k: list(presets.TABLE2[part][k]) for k in ("n", "omega", "amplitude", "phase")}
        assert got == {"n": [int(r[col]) for r in rows], "omega": [r[col + 1] for r in rows],
                       "amplitude": [r[col + 2] for r in rows],
                       "phase": [r[col + 3] for r in rows]}, part
    for task, *vals in _rows(TABLE3_ROWS):
        assert [presets.TABLE3[task][n] for n in names] == [float(v) for v in vals[:8]], task
        assert presets.TABLE3_T_N[task] == float(vals[8])
    for fn, *gains in _rows(TABLE4_ROWS):
        g = [float(x) for x in gains]
        assert presets.TABLE4_K_N[("FD", float(fn))] == tuple(g[:4])
        assert presets.TABLE4_K_N[("FT", float(fn))] == tuple(g[4:])
    for k, fd_mu, fd_sd, ft_mu, ft_sd in _rows(TABLE5_ROWS):
        assert presets.TABLE5[("FD", float(k))] == (float(fd_mu), float(fd_sd))
        assert presets.TABLE5[("FT", float(k))] == (float(ft_mu), float(ft_sd))
    want = {(t, float(fn), float(k)): (float(mu), float(sd), int(n50))
            for t, fn, k, mu, sd, n50 in _rows(FIG14_15_ROWS)}
    assert {key: tuple(v) for key, v in presets.FIG14_15.items()} == want
