"""The kernels' on-disk cache sees an edit to a callee in another file."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

CALLER = textwrap.dedent("""
    from bayespilot._jit import njit
    from .callee import scale

    @njit
    def run(x):
        return scale(x) + 1.0
""")
CALLEE = textwrap.dedent("""
    from bayespilot._jit import njit

    @njit
    def scale(x):
        return {factor} * x
""")
RUN = "import sys; sys.path.insert(0, {root!r}); from kern.caller import run; print(run(2.0))"


def _call(root) -> float:
    env = dict(os.environ, NUMBA_NUM_THREADS="1")
    env.pop("NUMBA_CACHE_DIR", None)  # the cache beside the sources, as installed
    out = subprocess.run([sys.executable, "-c", RUN.format(root=str(root))], env=env,
                         capture_output=True, text=True, check=True, timeout=300)
    return float(out.stdout.split()[-1])


def test_editing_a_callee_in_another_file_recompiles_its_caller(tmp_path):
    # numba keys a cached kernel on its own file only: a caller compiled with
    # the old callee inlined was loaded after the callee's file was edited (a
    # lab's new block in kernels/_blocks.py ran as the old code).  The 2.0 ->
    # 3.0 edit keeps the callee's bytecode and its file's size.
    pkg = tmp_path / "kern"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "caller.py").write_text(CALLER)
    (pkg / "callee.py").write_text(CALLEE.format(factor="2.0"))
    assert _call(tmp_path) == 5.0
    assert list((pkg / "__pycache__").glob("caller.run-*.nbi")), "the caller was not cached"
    (pkg / "callee.py").write_text(CALLEE.format(factor="3.0"))
    assert _call(tmp_path) == 7.0


def test_the_package_kernels_carry_the_folder_keyed_cache():
    import pytest

    from bayespilot._jit import _FolderCache, njit
    from bayespilot.kernels import _blocks, _response

    assert isinstance(_response.periodic_state._cache, _FolderCache)
    assert isinstance(_blocks.stage_tf._cache, _FolderCache)
    with pytest.raises(TypeError, match="no signature"):
        njit("f8(f8)")


def test_a_cache_that_cannot_be_saved_is_said_once_and_the_work_goes_on(monkeypatch):
    """A full disk under numba's cache (numba raised OSError from its save, and every command
    died at its first compile): said once per process, as a RuntimeWarning naming the
    folder, and the compile's result kept."""
    import errno
    import warnings

    from numba.core.caching import FunctionCache

    import bayespilot._jit as J

    def add_one(x):
        return x + 1

    cache = J._FolderCache(add_one)
    saved = []

    def full(self, sig, data):
        saved.append(sig)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(FunctionCache, "save_overload", full)
    monkeypatch.setattr(J, "_unsaved_said", False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert cache.save_overload("sig1", None) is None
        assert cache.save_overload("sig2", None) is None
    assert saved == ["sig1", "sig2"]  # (numba's own save was tried each time)
    assert [w.category for w in caught] == [RuntimeWarning]
    assert str(caught[0].message).startswith(
        f"bayespilot: cannot save numba's compiled kernels in {cache._cache_path} (No space "
        "left on device); going on without caching them")
