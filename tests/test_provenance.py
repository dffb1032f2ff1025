"""Provenance of the files the commands write (audit of the outputs, sections 3.3, 4.2, 4.8, 6).

- a figure saved twice as SVG or PDF gives the same bytes (no random ids, no dates);
- the full demo's recordings carry their truth (the ``simulation`` block), as ``simulate``'s;
- a simulated sidecar names the release that simulated it, and one without it still reads;
- the local cluster's workers keep a user's lower ``NUMBA_NUM_THREADS``;
- a campaign result's nested ``fit.seed`` has an exact text twin, as the top-level seeds do.
"""

from __future__ import annotations

import io
import json
import os
import re
import time
from contextlib import ExitStack

import numpy as np
import pytest

import bayespilot


# --- figures: the same figure gives the same file --------------------------------------
def _figure():
    """A figure with what made the files differ: clipped lines (SVG clip-path ids), text."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(3, 2))
    t = np.linspace(0, 1, 50)
    ax.plot(t, np.sin(2 * np.pi * t), label="sin")
    ax.plot(t, np.cos(2 * np.pi * t), label="cos")
    ax.set_title("same twice")
    ax.legend()
    return fig


@pytest.mark.parametrize("fmt", ["svg", "pdf"])
def test_a_vector_figure_saved_twice_gives_the_same_bytes(tmp_path, monkeypatch, fmt):
    """Audit 6: SVGs had random clip-path ids and a dc:date, PDFs a CreationDate, so the same
    command twice wrote different files.  (The saves are more than a second apart, the PDF
    date's resolution; SOURCE_DATE_EPOCH, which would fix matplotlib's dates, is unset.)"""
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure

    monkeypatch.delenv("SOURCE_DATE_EPOCH", raising=False)
    fig = _figure()
    try:
        save_figure(fig, tmp_path / f"a.{fmt}")
        time.sleep(1.1)
        save_figure(fig, tmp_path / f"b.{fmt}")
        first, second = (tmp_path / f"a.{fmt}").read_bytes(), (tmp_path / f"b.{fmt}").read_bytes()
        # a file object (the format from savefig.format) is written the same way
        buffers = []
        for _ in range(2):
            buf = io.BytesIO()
            with plt.rc_context({"savefig.format": fmt}):
                save_figure(fig, buf)
            buffers.append(buf.getvalue())
    finally:
        plt.close(fig)
    assert first == second
    assert buffers[0] == buffers[1] == first
    if fmt == "svg":
        assert first.startswith(b"<?xml") and b"clip-path" in first and b"<dc:date>" not in first
    else:
        assert first.startswith(b"%PDF") and b"/CreationDate" not in first


def test_a_png_is_written_as_before(tmp_path):
    """The PNG path is unchanged: a PNG of the figure at the dpi asked (its pixel size)."""
    import matplotlib.pyplot as plt

    from bayespilot._figstyle import save_figure

    fig = _figure()
    try:
        save_figure(fig, tmp_path / "f.png", dpi=50)
    finally:
        plt.close(fig)
    data = (tmp_path / "f.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert (width, height) == (150, 100)  # 3 x 2 in at 50 dpi


# --- simulated recordings carry their truth and the release -----------------------------
class _Stop(Exception):
    """Stops the demo after it has written its first recording."""


def test_the_full_demo_writes_its_recordings_with_their_truth(tmp_path, monkeypatch):
    """Audit 4.2: run_example wrote write_recording(sim.recording), with no ``simulation``
    block (true parameters, seed), so its posteriors had no truth; simulate and the quick
    demo write it.  The demo is stopped at its first fit: the recording is written by then."""
    import bayespilot.fit.fast as fast
    from bayespilot import presets
    from bayespilot.example import run_example
    from bayespilot.io import read_recording
    from bayespilot.sample import _true_parameters

    def stop(*args, **kwargs):
        raise _Stop

    monkeypatch.setattr(fast, "fit_fast", stop)
    with pytest.raises(_Stop):
        run_example(tmp_path, seed=11, motion_gains=(1.0,), duration=8.0, progress=False,
                    say=lambda s: None)
    side = json.loads((tmp_path / "recordings" / "FD_k1.json").read_text())
    truth = presets.paper_parameters("FD")
    assert side["simulation"]["parameters"] == truth
    assert side["simulation"]["seed"] == 11
    assert side["simulation"]["bayespilot_version"] == bayespilot.__version__
    rec = read_recording(tmp_path / "recordings" / "FD_k1.csv")
    assert _true_parameters(rec, list(truth)) == truth


def test_a_simulated_sidecar_names_the_release_and_one_without_it_reads(tmp_path):
    """Audit 4.2: the ``simulation`` block had no bayespilot_version although the data depend
    on the simulator's code.  A sidecar written before it (no such key) still reads, with the
    same truth."""
    from bayespilot.io import read_recording
    from bayespilot.sample import _true_parameters
    from bayespilot.simulate import simulate

    sim = simulate(task="FD", motion_gain=1.0, remnant_fraction=0.1, seed=4, duration=8.0)
    _, json_path = sim.write(tmp_path / "run")
    side = json.loads(json_path.read_text())
    assert side["simulation"]["bayespilot_version"] == bayespilot.__version__
    rec = read_recording(tmp_path / "run")
    assert rec.metadata["simulation"]["bayespilot_version"] == bayespilot.__version__
    del side["simulation"]["bayespilot_version"]  # as an older release wrote it
    json_path.write_text(json.dumps(side))
    old = read_recording(tmp_path / "run")
    assert "bayespilot_version" not in old.metadata["simulation"]
    assert _true_parameters(old, list(sim.params)) == _true_parameters(rec, list(sim.params)) \
        == sim.params
    np.testing.assert_array_equal(old.u, rec.u)


# --- the local cluster's numba threads ---------------------------------------------------
@pytest.mark.parametrize("cpus, workers, user, expected", [
    (2, 1, None, 2),      # the default: the cores shared among the workers
    (8, 2, None, 4),
    (2, 1, "1", 1),       # a user's lower setting is kept (the audit's case)
    (8, 2, "3", 3),
    (8, 2, "16", 4),      # a higher one is not: the workers would oversubscribe the cores
    (2, 1, "", 2),        # set but empty, or not a whole number >= 1: the default
    (2, 1, "two", 2),
    (2, 1, "0", 2),
    (3, 4, None, 1),      # more workers than cores: one each
])
def test_worker_numba_threads(cpus, workers, user, expected):
    from bayespilot.campaign import _worker_numba_threads

    environ = {} if user is None else {"NUMBA_NUM_THREADS": user}
    assert _worker_numba_threads(workers, cpu_count=cpus, environ=environ) == expected


def test_the_local_cluster_gets_the_users_numba_threads(monkeypatch):
    """Audit 4.8: with NUMBA_NUM_THREADS=1 exported, fit-batch's workers ran with 2 numba
    threads (the cores // workers) on a 2-core machine.  The LocalCluster is stood in for:
    its env is what the workers would get."""
    import distributed

    from bayespilot import campaign

    seen = []

    def cluster(*args, **kwargs):
        seen.append(kwargs.get("env"))
        raise AssertionError  # (no cluster is started: _connect gives up after its retry)

    monkeypatch.setattr(distributed, "LocalCluster", cluster)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    monkeypatch.setenv("NUMBA_NUM_THREADS", "1")
    with ExitStack() as stack, pytest.raises(campaign.CampaignError, match="local dask cluster"):
        campaign._connect(stack, None, 1, 5.0)
    assert seen == [{"NUMBA_NUM_THREADS": "1"}] * 2
    seen.clear()
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    with ExitStack() as stack, pytest.raises(campaign.CampaignError):
        campaign._connect(stack, None, 1, 5.0)
    assert seen == [{"NUMBA_NUM_THREADS": "2"}] * 2  # the default, as before


# --- a campaign result's nested seed ------------------------------------------------------
def test_the_nested_fit_seed_has_an_exact_text_twin():
    """Audit 3.3: ``remnant_seed_text``/``fit_seed_text`` are exact, but the nested
    ``fit.seed`` (the same seed, up to 2**63) read back rounded by a double-only reader."""
    from bayespilot.campaign import Job, run_job

    job = Job("FD", 1.0, 0.0, 0, method="fast", fit_kwargs={"n_starts": 1, "profile_step": 0.02},
              duration=4.0)
    assert job.fit_seed > 2**53 and float(job.fit_seed) != job.fit_seed  # needs the text
    res = run_job(job)
    assert res["fit"]["seed"] == job.fit_seed
    assert res["fit"]["seed_text"] == str(job.fit_seed)
    doubles = json.loads(json.dumps(res), parse_int=float)  # as jq or JavaScript read it
    assert doubles["fit"]["seed"] != job.fit_seed  # rounded
    assert int(doubles["fit"]["seed_text"]) == job.fit_seed
    # the fit still reads back as a FitResult (the twin is an extra key it ignores)
    from bayespilot.fit.result import FitResult

    assert FitResult.from_dict(res["fit"]).seed == job.fit_seed


def test_figures_name_the_release_that_drew_them(tmp_path):
    """Outputs audit 4.8: a figure named Matplotlib alone as its maker (a PNG's Software, a
    PDF's and SVG's Creator), so it could not be traced to the bayespilot that drew it; the
    files stay the same bytes run to run."""
    import matplotlib
    from PIL import Image

    from bayespilot._figstyle import save_figure

    made = f"bayespilot {bayespilot.__version__}, Matplotlib {matplotlib.__version__}"
    fig = _figure()
    for fmt in ("png", "pdf", "svg"):
        a, b = tmp_path / f"a.{fmt}", tmp_path / f"b.{fmt}"
        save_figure(fig, a)
        save_figure(fig, b)
        assert a.read_bytes() == b.read_bytes()
        if fmt == "png":
            assert Image.open(a).info["Software"] == made
        elif fmt == "pdf":
            assert f"/Creator ({made})".encode() in a.read_bytes()
        else:
            creator = re.search(r"<dc:creator>\s*<cc:Agent>\s*<dc:title>(.*?)</dc:title>",
                                a.read_text())
            assert creator is not None and creator.group(1) == made
