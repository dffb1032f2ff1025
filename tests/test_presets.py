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
