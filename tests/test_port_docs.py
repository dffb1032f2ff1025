"""What a simulation of another lab's task records about itself (port audit, finding 12).

``simulate`` writes the forcing scale it applied into ``settings["forcing_scale"]``
(and the sidecar's ``simulation.settings``).  A preset task's scale, also when
the preset comes as ``TrackingTask.paper(...)`` (as the command line passes
it), is checked against the amplitudes actually written to the sidecar; a
``TrackingTask`` of the caller's own carries its amplitudes and no scale is
applied, so none may be recorded.
"""

import json

import numpy as np
import pytest

from bayespilot import presets
from bayespilot.cli import main
from bayespilot.forcing import Multisine
from bayespilot.simulate import TrackingTask, simulate


def _sidecar_settings(sim, tmp_path, name):
    _, json_path = sim.write(tmp_path / name)
    with open(json_path, encoding="utf-8") as f:
        return json.load(f)


def test_custom_task_records_no_forcing_scale(tmp_path):
    w0 = 2 * np.pi / 10.0
    ft = Multisine(w0, [2, 5, 11], [0.02, 0.01, 0.005], [0.1, 1.2, 2.3])
    fd = Multisine(w0, [3, 7, 13], [0.004, 0.008, 0.012], [0.4, 2.0, 5.1])
    lab = TrackingTask(ft, fd, motion_gain=0.5, controlled_element=([8.0], [1.0, 2.0, 0.0]),
                       control_gain=1.0, sample_rate_hz=50.0, duration=10.0, run_in=5.0)
    sim = simulate(task=lab, remnant_fraction=0.0, seed=0)
    assert sim.settings["forcing_scale"] is None
    side = _sidecar_settings(sim, tmp_path, "lab")
    assert side["simulation"]["settings"]["forcing_scale"] is None
    # the amplitudes written are the task's own, unscaled
    np.testing.assert_allclose(side["forcing"]["target"]["amplitude"], ft.amplitude, rtol=0, atol=0)
    np.testing.assert_allclose(side["forcing"]["disturbance"]["amplitude"], fd.amplitude,
                               rtol=0, atol=0)


@pytest.mark.parametrize("scale", [None, 0.5])
def test_preset_task_records_the_scale_it_applied(tmp_path, scale):
    sim = simulate(task="FD", remnant_fraction=0.0, seed=0, duration=5.0, forcing_scale=scale)
    recorded = sim.settings["forcing_scale"]
    assert recorded == ("paper_simulation" if scale is None else scale)
    factor = presets.FORCING_SCALE[recorded] if isinstance(recorded, str) else recorded
    side = _sidecar_settings(sim, tmp_path, "fd")
    assert side["simulation"]["settings"]["forcing_scale"] == recorded
    # Table 2 as printed, with FD's task scaling, times the recorded factor
    printed = np.asarray(presets.TABLE2["disturbance"]["amplitude"])
    np.testing.assert_allclose(side["forcing"]["disturbance"]["amplitude"],
                               factor * presets.TASK_SCALING["FD"]["disturbance"] * printed,
                               rtol=1e-12)
    printed_t = np.asarray(presets.TABLE2["target"]["amplitude"])
    np.testing.assert_allclose(side["forcing"]["target"]["amplitude"],
                               factor * presets.TASK_SCALING["FD"]["target"] * printed_t,
                               rtol=1e-12)


def _assert_fd_amplitudes(side, factor):
    """The sidecar's FD forcing is Table 2 as printed, FD's task scaling, times ``factor``."""
    for name in ("target", "disturbance"):
        printed = np.asarray(presets.TABLE2[name]["amplitude"])
        np.testing.assert_allclose(side["forcing"][name]["amplitude"],
                                   factor * presets.TASK_SCALING["FD"][name] * printed,
                                   rtol=1e-12)


@pytest.mark.parametrize("scale", ["paper_simulation", "printed", 0.3])
def test_paper_tracking_task_records_its_scale(tmp_path, scale):
    task = TrackingTask.paper("FD", 1.0, scale=scale, sample_rate_hz=50.0, duration=5.0)
    sim = simulate(task=task, remnant_fraction=0.0, seed=0, duration=4.0)  # replace() keeps it
    side = _sidecar_settings(sim, tmp_path, "paper50")
    recorded = side["simulation"]["settings"]["forcing_scale"]
    assert recorded == scale == sim.settings["forcing_scale"]
    _assert_fd_amplitudes(side, presets.FORCING_SCALE[scale] if isinstance(scale, str) else scale)


def test_command_line_simulation_records_the_paper_scale(tmp_path, capsys):
    out = tmp_path / "run50"
    assert main(["simulate", "--task", "FD", "--sample-rate", "50", "--duration", "4",
                 "--seed", "1", "-o", str(out)]) == 0
    capsys.readouterr()
    with open(f"{out}.json", encoding="utf-8") as f:
        side = json.load(f)
    assert side["simulation"]["settings"]["forcing_scale"] == "paper_simulation"
    _assert_fd_amplitudes(side, presets.FORCING_SCALE["paper_simulation"])


@pytest.mark.parametrize("bad", ["paper", -0.1, float("nan"), True])
def test_tracking_task_refuses_a_bad_forcing_scale(bad):
    ft, fd = presets.paper_forcing("FD")
    with pytest.raises(ValueError, match="forcing_scale must be None"):
        TrackingTask(ft, fd, forcing_scale=bad)


def test_a_preset_with_forcing_of_ones_own_must_drop_its_scale():
    """dataclasses.replace of a preset kept its forcing_scale for a forcing that is no longer
    Table 2's (simulate then recorded the paper's scale for it): refused, saying how; the
    replace that keeps the forcing (another rate or duration), or drops the scale, is fine."""
    import dataclasses

    paper = TrackingTask.paper("FD", 1.0)
    w0 = 2 * np.pi / 10.0
    mine = Multisine(w0, [2, 5, 11], [0.02, 0.01, 0.005], [0.1, 1.2, 2.3])
    with pytest.raises(ValueError, match=r"the target is not; give forcing_scale=None"):
        dataclasses.replace(paper, target=mine)
    louder = Multisine(paper.disturbance.base_frequency, paper.disturbance.n,
                       paper.disturbance.amplitude * 1.01, paper.disturbance.phase)
    with pytest.raises(ValueError, match=r"the disturbance is not"):
        dataclasses.replace(paper, disturbance=louder)
    with pytest.raises(ValueError, match=r"forcing_scale=1.0 says"):
        TrackingTask.paper("FT", 1.0, scale=1.0).__class__(
            paper.target, paper.disturbance, task="FT", forcing_scale=1.0)
    assert dataclasses.replace(paper, sample_rate_hz=50.0, duration=40.96).forcing_scale == \
        "paper_simulation"
    own = dataclasses.replace(paper, target=mine, forcing_scale=None)
    assert own.forcing_scale is None and own.target is mine
    assert TrackingTask.paper("FT", 0.5, scale="printed").forcing_scale == "printed"
