"""Closed-loop simulator: determinism, remnant (Eq. 6-7), signs, and agreement with the likelihood."""

from dataclasses import replace

import numpy as np
import pytest
from scipy import integrate

from bayespilot import presets
from bayespilot.forcing import Multisine
from bayespilot.likelihood import Likelihood
from bayespilot.model import paper_model
from bayespilot.simulate import TrackingTask, remnant, simulate


def test_same_seed_same_run_and_other_seed_differs():
    a = simulate(task="FT", motion_gain=0.5, remnant_fraction=0.2, seed=11, duration=8.0)
    b = simulate(task="FT", motion_gain=0.5, remnant_fraction=0.2, seed=11, duration=8.0)
    c = simulate(task="FT", motion_gain=0.5, remnant_fraction=0.2, seed=12, duration=8.0)
    for name in ("e", "u", "theta_ddot_m", "theta"):
        assert np.array_equal(a.recording[name], b.recording[name])
    assert not np.array_equal(a.recording.u, c.recording.u)


def test_requested_remnant_fraction_is_met():
    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.25, seed=4, duration=40.0)
    assert sim.remnant_fraction == pytest.approx(0.25, abs=2e-4)
    assert np.var(sim.remnant) / np.var(sim.recording.u) == pytest.approx(0.25, abs=2e-4)


def test_remnant_variance_matches_closed_form():
    """var of K/(T s + 1)^4 white noise of two-sided PSD S is K^2 S 5/(32 T)."""
    rng = np.random.default_rng(0)
    T, K, S, dt = 0.06, 0.3, 0.01, 0.001
    n = remnant(400_000, dt, K, T, rng, S)
    expected = K**2 * S * 5.0 / (32.0 * T)
    # 400 s of a process with ~0.2 s correlation time: ~2% standard error
    assert np.var(n) == pytest.approx(expected, rel=0.06)


def test_motion_channel_sign_is_stabilising():
    """With the motion channel added (+) the loop diverges for Table 3; with (-) it is stable."""
    model = paper_model()
    plus = replace(model, channels=(model.channels[0], replace(model.channels[1], sign=1.0)))
    simulate(model, task="FD", motion_gain=1.0, duration=20.0)
    with pytest.raises(RuntimeError, match="diverged"):
        simulate(plus, task="FD", motion_gain=1.0, duration=20.0)


def test_likelihood_reproduces_simulator_without_remnant():
    """u_hat at the true parameters vs the simulated u: only discretisation error remains."""
    model = paper_model()
    for task, k in (("FD", 1.0), ("FT", 0.25)):
        sim = simulate(model, task=task, motion_gain=k, seed=0)
        uh = Likelihood(model, sim.recording).response(sim.params)
        rel = np.sqrt(np.mean((uh - sim.recording.u) ** 2)) / np.std(sim.recording.u)
        assert rel < 0.01, (task, k, rel)


def test_likelihood_reproduces_u_minus_n_with_remnant():
    model = paper_model()
    sim = simulate(model, task="FD", motion_gain=0.75, remnant_fraction=0.2, seed=5, duration=40.96)
    rec = sim.recording
    uh = Likelihood(model, rec).response(sim.params)
    err = uh - (rec.u - sim.remnant)
    assert np.sqrt(np.mean(err[500:] ** 2)) / np.std(rec.u - sim.remnant) < 0.01


def test_error_comes_from_the_likelihood_discretisation_not_the_simulator():
    """Halving the simulator step changes the recorded u far less than the model-vs-sim error."""
    model = paper_model()
    a = simulate(model, task="FD", motion_gain=1.0, seed=0, oversample=10, duration=20.0)
    b = simulate(model, task="FD", motion_gain=1.0, seed=0, oversample=20, duration=20.0)
    sim_change = np.sqrt(np.mean((a.recording.u - b.recording.u) ** 2))
    uh = Likelihood(model, a.recording).response(a.params)
    model_err = np.sqrt(np.mean((uh - a.recording.u) ** 2))
    assert sim_change < 0.05 * model_err


def test_linear_loop_matches_scipy_ode_solver():
    """Without threshold and with delays replaced by none, the loop is linear: compare with solve_ivp.

    Pilot: u = H_nm [K_v (1 + T_vl s) e - K_m H_scc theta_ddot_m], delays 0, plant K_c/s^2.
    """
    p = dict(presets.TABLE3["FD"], delta_abs=0.0, tau_v=0.0, tau_m=0.0)
    ft = Multisine(presets.OMEGA0, [6, 19], [0.02, 0.01], [0.3, 1.0])
    fd = Multisine(presets.OMEGA0, [11, 46], [0.01, 0.02], [0.0, 2.0])
    task = TrackingTask(ft, fd, motion_gain=1.0, duration=10.0, run_in=0.0)
    sim = simulate(paper_model(), params=p, task=task, seed=0, oversample=10)
    Kc, Kdu, K, T1, T2 = presets.K_C, presets.K_DU, presets.K_SCC, presets.T_SCC1, presets.T_SCC2
    w, z = p["omega_nm"], p["zeta_nm"]

    def rhs(t, x):
        th, thd, xs, z1v, z2v, z1m, z2m = x
        u = w**2 * (z1v + p["T_vl"] * z2v) + w**2 * z1m
        thdd = Kc * (Kdu * u + fd(np.array([t]))[0])
        e = ft(np.array([t]))[0] - th
        # canal: K (1 + T1 s)/(1 + T2 s) = K T1/T2 + K (1 - T1/T2)/T2 / (s + 1/T2)
        i = K * T1 / T2 * thdd + K * (1 - T1 / T2) / T2 * xs
        return [thd, thdd, -xs / T2 + thdd,
                z2v, -w**2 * z1v - 2 * z * w * z2v + p["K_v"] * e,
                z2m, -w**2 * z1m - 2 * z * w * z2m - p["K_m"] * i]

    t = sim.recording.t
    sol = integrate.solve_ivp(rhs, (0, t[-1]), np.zeros(7), t_eval=t, rtol=1e-10, atol=1e-12,
                              method="DOP853")
    u_ref = w**2 * (sol.y[3] + p["T_vl"] * sol.y[4]) + w**2 * sol.y[5]
    assert np.max(np.abs(sim.recording.u - u_ref)) < 1e-6 * np.max(np.abs(u_ref)) + 1e-9


def test_a_drifting_gain_keeps_its_start_value_through_the_run_in():
    """The linear loop of the test above with K_v drifting by 1.5 over a 10-s run, after a 5-s
    run-in, against solve_ivp with the gain K_v (1 + 1.5 (clip(t / T, 0, 1) - 1/2)).  The
    kernel extrapolated the drift back into the run-in: over the default 41-s run-in the
    visual gain went negative and the recorded FD run started with e at 22 rad rms."""
    from bayespilot.model import LinearDrift, Parameter

    d, T, run_in = 1.5, 10.0, 5.0
    p = dict(presets.TABLE3["FD"], delta_abs=0.0, tau_v=0.0, tau_m=0.0, drift_v=d)
    m = paper_model().with_modulation("visual", LinearDrift("drift_v"),
                                      [Parameter("drift_v", -1.5, 1.5, 0.0)])
    ft = Multisine(presets.OMEGA0, [6, 19], [0.02, 0.01], [0.3, 1.0])
    fd = Multisine(presets.OMEGA0, [11, 46], [0.01, 0.02], [0.0, 2.0])
    task = TrackingTask(ft, fd, motion_gain=1.0, duration=T, run_in=run_in)
    sim = simulate(m, params=p, task=task, seed=0, oversample=10)
    Kc, Kdu, K, T1, T2 = presets.K_C, presets.K_DU, presets.K_SCC, presets.T_SCC1, presets.T_SCC2
    w, z = p["omega_nm"], p["zeta_nm"]

    def rhs(s, x):  # s: simulation time, the record's t = s - run_in
        th, thd, xs, z1v, z2v, z1m, z2m = x
        u = w**2 * (z1v + p["T_vl"] * z2v) + w**2 * z1m
        thdd = Kc * (Kdu * u + fd(np.array([s]))[0])
        e = ft(np.array([s]))[0] - th
        i = K * T1 / T2 * thdd + K * (1 - T1 / T2) / T2 * xs
        K_v = p["K_v"] * (1.0 + d * (min(max((s - run_in) / T, 0.0), 1.0) - 0.5))
        return [thd, thdd, -xs / T2 + thdd,
                z2v, -w**2 * z1v - 2 * z * w * z2v + K_v * e,
                z2m, -w**2 * z1m - 2 * z * w * z2m - p["K_m"] * i]

    s = sim.recording.t + run_in
    sol = integrate.solve_ivp(rhs, (0, s[-1]), np.zeros(7), t_eval=s, rtol=1e-10, atol=1e-12,
                              method="DOP853", max_step=0.01)
    u_ref = w**2 * (sol.y[3] + p["T_vl"] * sol.y[4]) + w**2 * sol.y[5]
    assert np.max(np.abs(sim.recording.u - u_ref)) < 1e-5 * np.max(np.abs(u_ref))


def test_results_are_continuous_in_tau():
    """A delay change smaller than the step changes the run by a proportionally small amount."""
    base = simulate(task="FD", motion_gain=1.0, seed=0, duration=10.0)
    u = [simulate(task="FD", motion_gain=1.0, seed=0, duration=10.0,
                  params={"tau_m": presets.TABLE3["FD"]["tau_m"] + d}).recording.u
         for d in (1e-5, 2e-5)]
    d1 = np.max(np.abs(u[0] - base.recording.u))
    d2 = np.max(np.abs(u[1] - base.recording.u))
    assert 0 < d1 < 1e-3 * np.std(base.recording.u)
    assert d2 == pytest.approx(2 * d1, rel=0.1)


def test_other_plant_and_sample_rate():
    """A non-paper task: K/(s (s + 1)) at 50 Hz; the likelihood still reproduces the run."""
    ft = Multisine(0.1, [3, 7, 15], [0.05, 0.03, 0.01], [0.0, 1.0, 2.0])
    fd = Multisine(0.1, [5, 11], [0.02, 0.03], [0.5, 1.5])
    task = TrackingTask(ft, fd, motion_gain=0.8, controlled_element=([3.0], [1.0, 1.0, 0.0]),
                        sample_rate_hz=50.0, duration=30.0, run_in=20.0)
    model = paper_model()
    sim = simulate(model, params=presets.TABLE3["FT"], task=task, seed=1)
    rec = sim.recording
    assert rec.sample_rate_hz == 50.0 and rec.n_samples == 1500
    assert rec.metadata["controlled_element"] == {"num": [3.0], "den": [1.0, 1.0, 0.0]}
    uh = Likelihood(model, rec).response(sim.params)
    assert np.sqrt(np.mean((uh[250:] - rec.u[250:]) ** 2)) / np.std(rec.u) < 0.02


def test_an_unreachable_remnant_fraction_is_said_so():
    """Without motion feedback F_n levels off near 0.085-0.09 as K_n grows: asking for 0.1 is refused
    as unreachable (it widened K_n to 1e6 and reported a diverged loop); 0.08 is reached."""
    with pytest.raises(ValueError, match=r"remnant fraction 0.1 cannot be reached .*F_n stays "
                                         r"at 0.0[89]"):
        simulate(task="FD", motion_gain=0.0, remnant_fraction=0.1, seed=2, duration=40.96)
    sim = simulate(task="FD", motion_gain=0.0, remnant_fraction=0.08, seed=2, duration=40.96)
    assert sim.remnant_fraction == pytest.approx(0.08, abs=1e-6)


def test_a_remnant_gain_means_the_same_remnant_at_any_rate():
    """The default noise PSD is a physical density (0.01 rad^2 s, unit-variance samples at
    100 Hz), so K_n = 0.104 (Table 4) gives the remnant's variance the filter
    K_n^2 / (T_n s + 1)^4 passes: K_n^2 PSD 5 / (32 T_n) for any rate (it was 1/rate, and at
    1000 Hz the remnant's variance was a tenth)."""
    ft = Multisine(0.1, [3, 7, 15], [0.05, 0.03, 0.01], [0.0, 1.0, 2.0])
    fd = Multisine(0.1, [5, 11], [0.02, 0.03], [0.5, 1.5])
    T_n, kn = 0.0578, 0.104
    want = kn**2 * 0.01 * 5 / (32 * T_n)  # PSD / (2 pi) * integral of 1/(1 + T^2 w^2)^4 dw
    for rate in (50.0, 100.0, 1000.0):
        task = TrackingTask(ft, fd, motion_gain=1.0, sample_rate_hz=rate, duration=200.0,
                            run_in=20.0)
        sim = simulate(params=presets.TABLE3["FD"], task=task, seed=3, remnant_gain=kn, T_n=T_n)
        assert sim.settings["noise_psd"] == 0.01
        assert np.var(sim.remnant) == pytest.approx(want, rel=0.15), rate


@pytest.mark.parametrize("kwargs, message", [
    ({"task": "XX"}, "task must be"),
    ({"remnant_fraction": 1.2}, "remnant_fraction"),
    ({"remnant_fraction": 0.2, "remnant_gain": 0.1}, "not both"),
    ({"oversample": 1}, "oversample"),
    ({"params": {"K_x": 1.0}}, "unknown parameter"),
    ({"duration": -1.0}, "duration"),
])
def test_bad_input_is_refused_clearly(kwargs, message):
    with pytest.raises(ValueError, match=message):
        simulate(**kwargs)


def test_settings_that_were_ignored_or_misread_are_refused():
    """A motion gain or forcing scale beside a TrackingTask (which carries its own) was ignored;
    params as a list failed with dict()'s message; calibrating over no seeds gave NaN."""
    from bayespilot.simulate import calibrate_remnant_gain

    task = TrackingTask.paper("FD", 0.5)
    with pytest.raises(ValueError, match=r"motion_gain set\(s\) the paper's preset task; the "
                                         r"TrackingTask given carries its own \(K_theta = 0.5\)"):
        simulate(task=task, motion_gain=0.25, duration=2.0)
    with pytest.raises(ValueError, match="forcing_scale set"):
        simulate(task=task, forcing_scale=1.0, duration=2.0)
    assert simulate(task=task, duration=2.0).recording.motion_gain == 0.5
    assert simulate(task="FD", duration=2.0).recording.motion_gain == 1.0  # the default
    with pytest.raises(TypeError, match="params must be a mapping .* got list"):
        simulate(params=[1.0, 2.0, 3.0], duration=2.0)
    with pytest.raises(ValueError, match="seeds is empty"):
        calibrate_remnant_gain(0.2, seeds=[])


def test_improper_plant_is_refused():
    ft, fd = presets.paper_forcing("FD")
    with pytest.raises(ValueError, match="relative degree"):
        TrackingTask(ft, fd, controlled_element=([1.0, 0.0], [1.0, 1.0]))


@pytest.mark.parametrize("name, value, bounds", [
    ("tau_m", -0.05, "[0, 1]"), ("tau_v", -0.02, "[0, 1]"), ("delta_abs", -0.01, "[0, 0.1]"),
    ("K_m", 20.0, "[0, 10]"), ("omega_nm", 4.0, "[5, 30]"),
])
def test_parameters_outside_the_bounds_are_refused(name, value, bounds):
    """A negative delay or threshold was simulated by extrapolation while the likelihood reads
    future samples: the two disagreed.  Table 1's bounds now hold in simulate."""
    with pytest.raises(ValueError, match=f"{name} = .* outside its bounds \\{bounds[:-1]}\\]"):
        simulate(task="FD", params={name: value}, duration=2.0)


def test_fixed_parameter_outside_the_bounds_is_refused_and_bounds_are_inclusive():
    with pytest.raises(ValueError, match="delta_abs = -0.01 is outside"):
        simulate(paper_model(threshold=False), {"delta_abs": -0.01}, task="FD", duration=2.0)
    with pytest.raises(ValueError, match="real"):
        simulate(paper_model(threshold=False), {"delta_abs": np.complex128(0.01 + 1j)}, task="FD",
                 duration=2.0)
    sim = simulate(params={"tau_m": 0.0, "tau_v": 0.0, "delta_abs": 0.1}, task="FD", duration=2.0)
    assert sim.params["delta_abs"] == 0.1 and sim.params["tau_m"] == 0.0


@pytest.mark.parametrize("run_in", [0.0104, 0.0015, 2.00049])
def test_run_in_off_the_integration_grid(run_in):
    """The loop records from the step nearest run_in: the remnant and the metadata's forcing
    phases must start there too (they used run_in itself)."""
    p = dict(presets.TABLE3["FD"], K_v=0.0, K_m=0.0)  # no pilot: u is the remnant
    task = TrackingTask.paper("FD", 1.0, duration=4.0, run_in=run_in)
    sim = simulate(params=p, task=task, remnant_gain=0.1, seed=2)
    rec = sim.recording
    assert np.max(np.abs(rec.u - sim.remnant)) < 1e-10 * np.std(sim.remnant)
    meta = rec.metadata["forcing"]
    for name in ("target", "disturbance"):
        f = Multisine.from_dict(meta["base_frequency"], meta[name])
        col = rec["f_t" if name == "target" else "f_d"]
        assert np.max(np.abs(f(rec.t) - col)) < 1e-10 * np.std(col)
    assert sim.settings["run_in"] == pytest.approx(run_in, abs=1e-3 / 2 + 1e-12)


def test_default_integration_is_1_khz_or_finer():
    """10 steps a sample at the paper's 100 Hz (the paper's computation, unchanged), 20 at
    50 Hz, 2 at 1 kHz (a fixed 10 integrated a 1-kHz task at 10 kHz)."""
    from bayespilot.simulate import integration_steps

    assert [integration_steps(r) for r in (50.0, 60.0, 100.0, 250.0, 1000.0, 5000.0)] == \
        [20, 17, 10, 4, 2, 2]
    a = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=0, duration=5.0)
    b = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=0, duration=5.0,
                 oversample=10)
    assert a.settings["oversample"] == 10 and np.array_equal(a.recording.u, b.recording.u)
    ft = Multisine(0.1, [3, 7], [0.05, 0.03], [0.0, 1.0])
    fd = Multisine(0.1, [5, 11], [0.02, 0.03], [0.5, 1.5])
    task = TrackingTask(ft, fd, motion_gain=1.0, sample_rate_hz=1000.0, duration=2.0,
                        run_in=1.0)
    assert simulate(params=presets.TABLE3["FD"], task=task, seed=0).settings["oversample"] == 2
    with pytest.raises(ValueError, match="oversample"):
        simulate(task="FD", motion_gain=1.0, seed=0, duration=5.0, oversample=True)


def test_a_diverging_loop_is_refused_not_recorded(tmp_path, capsys):
    """K_v = 2.7 (FD, K_theta = 1) diverges slowly, about 2.3 times every 10 s: the loop's states
    stay under the kernel's 1e6 limit, and the run was returned as a valid recording (rms u
    4.3 rad in its first 5 s, 3100 rad in its last 5).  The growth test refuses it, through
    every entry (simulate, the remnant calibration, the command line), as the 1e6 case is."""
    from bayespilot.cli import main
    from bayespilot.simulate import calibrate_remnant_gain

    with pytest.raises(RuntimeError, match=r"the closed loop diverged for these parameters "
                                           r"\(.*'K_v': 2.7.*\): the rms of u grows"):
        simulate(task="FD", params={"K_v": 2.7}, seed=1)
    with pytest.raises(RuntimeError, match="the closed loop diverged"):
        simulate(task="FD", params={"K_v": 2.7}, remnant_fraction=0.2, seed=1)
    with pytest.raises(RuntimeError, match="the closed loop diverged"):
        calibrate_remnant_gain(0.2, params={"K_v": 2.7}, seeds=[0])
    with pytest.raises(RuntimeError, match="plant's state passed 1e6"):  # as before
        simulate(task="FD", params={"K_v": 2.8}, seed=1)
    (tmp_path / "p.json").write_text('{"K_v": 2.7}')
    code = main(["simulate", "--task", "FD", "--motion-gain", "1", "--remnant-fraction", "0",
                 "--seed", "1", "--params", str(tmp_path / "p.json"), "-o",
                 str(tmp_path / "kv27")])
    assert code == 1 and "diverged" in capsys.readouterr().err
    assert not (tmp_path / "kv27.csv").exists()
    from bayespilot.simulate import _diverging, _growth

    # K_v = 2.6 is stable but lightly damped (rms u 0.23-0.77 over 10-s windows): recorded
    sim = simulate(task="FD", params={"K_v": 2.6}, seed=1, remnant_gain=0.1)
    assert _diverging(sim.recording.u, 100.0) is None
    # the statistic: 4 windows, steady growth by over 10 times; windows under 5 s not judged
    t = np.arange(8192) / 100.0
    grow = np.exp(t / 20) * np.sin(2 * t) * (1 + 0.5 * np.sin(0.3 * t))
    assert "grows 21.8 times" in _diverging(grow, 100.0)
    assert _diverging(grow[::-1], 100.0) is None
    assert _growth(grow[:1999], 100.0) is None and _growth(grow[:2000], 100.0) is not None
    assert _diverging(np.zeros(8192), 100.0) is None
    for p in (1.5, 2, 3, 6):  # a start-up from rest grows, but ever more slowly
        r = _growth(t**p * np.sin(2 * t), 100.0)
        assert r[-1] > 10 * r[0] and np.all(np.diff(r) > 0)
        assert _diverging(t**p * np.sin(2 * t), 100.0) is None


@pytest.mark.parametrize("task, motion_gain", [("FD", 0.0), ("FT", 0.5), ("FD", 1.0)])
def test_the_growth_test_leaves_stable_loops_alone(task, motion_gain):
    """Stable loops, the paper's and from rest (run_in = 0, where the record begins with the
    loop's start-up): the rise of u's rms over the record stays far below the growth test's
    limit (at most 1.8 and 4.5 over many seeds), and the calibration still meets F_n."""
    from bayespilot.simulate import GROWTH_RATIO, _growth

    for tt, kw in ((TrackingTask.paper(task, motion_gain, duration=20.0), {"remnant_gain": 0.1}),
                   (TrackingTask.paper(task, motion_gain, duration=20.0, run_in=0.0),
                    {"remnant_gain": 0.0})):
        r = _growth(simulate(task=tt, seed=2, **kw).recording.u, 100.0)
        assert r[-1] / r[0] < GROWTH_RATIO / 2, r
    fn = 0.2 if motion_gain else 0.08  # (without motion feedback 0.1 cannot be reached)
    sim = simulate(task=task, motion_gain=motion_gain, remnant_fraction=fn, seed=4,
                   duration=20.0)
    assert sim.remnant_fraction == pytest.approx(fn, abs=1e-4)


def test_a_plant_of_relative_degree_below_2_is_refused_with_why_and_the_workaround():
    """K/s was refused with "must be strictly proper with relative degree >= 2" alone: the
    message says why (theta_ddot, the motion cue, is made from the plant's state and input)
    and the workaround that works, a fast extra pole."""
    ft, fd = presets.paper_forcing("FD")
    with pytest.raises(ValueError) as info:
        TrackingTask(ft, fd, controlled_element=([2.0], [1.0, 0.0]))
    msg = str(info.value)
    assert "relative degree 1" in msg and "num=[2.0], den=[1.0, 0.0]" in msg
    assert "theta_ddot" in msg and "derivative of delta" in msg
    assert "K/(s (0.01 s + 1))" in msg and "controlled_element=([2.0], [0.01, 1.0, 0.0])" in msg
    with pytest.raises(ValueError, match=r"relative degree 0.*\[0.0002, 0.04, 2.0\]"):
        TrackingTask(ft, fd, controlled_element=([3.0], [2.0]))
    # the suggested plant runs (with a pilot for a rate-command plant: little lead)
    task = TrackingTask(ft, fd, controlled_element=([2.0], [0.01, 1.0, 0.0]), duration=20.0,
                        run_in=20.0)
    assert task.controlled_element == ((2.0,), (0.01, 1.0, 0.0))
    pilot = dict(K_v=1.0, T_vl=0.05, tau_v=0.25, K_m=0.1, tau_m=0.2, omega_nm=11.0,
                 zeta_nm=0.3, delta_abs=0.004)
    sim = simulate(params=pilot, task=task, remnant_fraction=0.05, seed=0)
    assert sim.remnant_fraction == pytest.approx(0.05, abs=1e-4)


def test_a_forcing_line_at_or_above_nyquist_is_refused():
    """A 30-Hz line at 50 Hz was recorded aliased, without a word."""
    w0 = 2 * np.pi / 40.96
    fd = Multisine(w0, [4, 8, 14], [0.005, 0.01, 0.015], [0, 1, 2])

    def task(n, amplitude=0.001, fs=50.0, where="target"):
        f = Multisine(w0, [3, 7, n], [0.03, 0.02, amplitude], [0, 0, 0])
        pair = (f, fd) if where == "target" else (fd, f)
        return TrackingTask(*pair, sample_rate_hz=fs, duration=40.96, run_in=20.48)

    with pytest.raises(ValueError, match=r"the target's line n = 1229 at 30.0049 Hz "
                                         r"\(188.526 rad/s\) is at or above the Nyquist "
                                         r"frequency 25 Hz of the 50-Hz recording"):
        task(1229)
    with pytest.raises(ValueError, match="disturbance's line n = 1024 at 25 Hz"):  # exactly at
        task(1024, where="disturbance")
    assert task(1023).sample_rate_hz == 50.0  # just below
    assert task(1229, amplitude=0.0).sample_rate_hz == 50.0  # no amplitude: nothing recorded
    assert task(1229, fs=100.0).sample_rate_hz == 100.0
    with pytest.raises(ValueError, match="Nyquist"):  # the paper's lines reach 2.6 Hz
        TrackingTask.paper("FD", sample_rate_hz=5.0)


def test_a_simulation_writes_its_truth_with_the_recording(tmp_path):
    """Simulation.write keeps the truth in the sidecar, as `bayespilot simulate` does
    (write_recording(sim.recording) leaves it out, and a posterior then has no truth)."""
    from bayespilot.io import read_recording
    from bayespilot.sample import _true_parameters

    sim = simulate(task="FT", motion_gain=0.75, remnant_fraction=0.2, seed=5, duration=20.0)
    csv_path, json_path = sim.write(tmp_path / "run")
    assert (csv_path.name, json_path.name) == ("run.csv", "run.json")
    rec = read_recording(tmp_path / "run")
    truth = rec.metadata["simulation"]
    assert truth["parameters"] == sim.params and truth["seed"] == 5
    assert truth["remnant_fraction"] == pytest.approx(0.2, abs=1e-3)
    assert truth["remnant_gain"] == sim.remnant_gain and truth["T_n"] == sim.settings["T_n"]
    # what a replay needs beside the seed (the forcing scale, run-in, noise convention, ...)
    assert truth["settings"] == sim.settings
    np.testing.assert_array_equal(rec.u, sim.recording.u)
    assert _true_parameters(rec, list(sim.params)) == sim.params
    assert "simulation" not in sim.recording.metadata  # the simulation's own is untouched
