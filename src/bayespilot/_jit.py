"""The one place that sets numba options for every kernel in bayespilot.

``cache=True`` writes compiled kernels next to the source so a new process
(a test run, a dask worker) loads them instead of compiling again.
``error_model="numpy"`` makes 0/0 give NaN instead of raising, which the
kernels turn into +inf costs rather than exceptions.  ``fastmath`` stays off:
the likelihood must be reproducible to the last bit between the scalar and
batch forms.  (Two kernels make documented exceptions: ``_recursion_2`` allows
``contract``, and the segmented SIMD kernel, ``kernels/_segmented.py``, writes
its fused multiply-adds and one AVX-512 instruction explicitly through the
intrinsics of ``kernels/_simd.py``; ``Likelihood`` sends single evaluations
through the same routine as the batch, so single and batch still agree to
the bit.)

The cache is keyed on the CPU features numba compiles for, so a kernel cached
on one machine is never loaded on a CPU it was not built for.  numba itself
checks only the source file of the function it caches, so a kernel kept its
stale callee after ``kernels/_blocks.py``, ``_oversample.py`` or ``_simd.py``
alone was edited (their code is compiled into ``_response``'s,
``_sensitivity``'s and ``_segmented``'s kernels; a lab adding a block edits
exactly those files).  Our cache's source stamp therefore also holds a
digest of every source file in the kernel's folder and of this file
(``_FolderCache``): an edit to any of them recompiles every kernel in the
folder at its first call.

Where numba finds no writable folder for that cache (a read-only install with
an unwritable home folder: a container image, a site-wide install on a
cluster), numba refuses every ``cache=True`` kernel at import.  ``njit`` then
points numba's cache at a private folder under :func:`tempfile.gettempdir`
(through ``NUMBA_CACHE_DIR``, numba's own setting, so worker processes use it
too), or compiles without a cache if that is not writable either, with one
warning (``_jit``).  Where numba finds a folder, nothing changes.
"""

from __future__ import annotations

import functools
import hashlib
import os
import stat
import tempfile
import warnings
from pathlib import Path

# numba's OpenMP threading layer spin-waits between parallel regions by
# default; on a shared machine (dask workers, a second process) that made
# Likelihood.batch 3-8x slower per row.  Passive waiting costs nothing when the
# machine is idle.  Set before numba starts its thread pool (lazily, at the
# first parallel call); a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402
from numba.core.caching import FunctionCache  # noqa: E402

JIT_OPTIONS = {"cache": True, "error_model": "numpy", "nogil": True}

# How the cache is kept when numba found no folder for it: None (numba's own choice, the
# normal case), "temporary" (NUMBA_CACHE_DIR set to _temporary_cache_dir()) or "off".
_cache_fallback: str | None = None


@functools.lru_cache(maxsize=None)
def _folder_digest(folder: str) -> str:
    """sha256 of the names and contents of every ``.py`` file in ``folder`` and of this
    file (``JIT_OPTIONS``)."""
    h = hashlib.sha256()
    for path in [*sorted(Path(folder).glob("*.py")), Path(__file__)]:
        h.update(path.name.encode())
        h.update(b"\0")
        h.update(path.read_bytes())
    return h.hexdigest()


class _FolderCache(FunctionCache):
    """numba's on-disk cache, its source stamp extended by the digest of the sources beside
    the function's file.  numba invalidates a kernel's cache on its own file only, so a jitted
    callee from another file, compiled into the caller, went stale unseen (written here
    because numba has no option for it; see the module text).  An edit anywhere in the folder
    makes every kernel's index stale, which numba then rewrites."""

    def __init__(self, py_func):
        super().__init__(py_func)
        digest = _folder_digest(str(Path(py_func.__code__.co_filename).resolve().parent))
        cache_file = self._cache_file
        cache_file._source_stamp = (cache_file._source_stamp, digest)

    def save_overload(self, sig, data):
        """numba's save of a compiled kernel, a failure to write it (a full disk, a quota)
        said once per process and the computation going on: the cache only spares the next
        process a compile, and every command died at its first compile on a full disk (in a
        batch, every recording failed in seconds, named as an OSError of no file)."""
        try:
            super().save_overload(sig, data)
        except OSError as exc:
            _say_unsaved(getattr(self, "_cache_path", "?"), exc)


# Whether :func:`_say_unsaved` has spoken in this process (60 kernels failed to save in one fit).
_unsaved_said = False


def _say_unsaved(where: str, exc: OSError) -> None:
    global _unsaved_said
    if _unsaved_said:
        return
    _unsaved_said = True
    warnings.warn(f"bayespilot: cannot save numba's compiled kernels in {where} "
                  f"({exc.strerror or exc}); going on without caching them (the next process "
                  f"compiles them again). Free space there, or set NUMBA_CACHE_DIR to a folder "
                  f"with room.", RuntimeWarning, stacklevel=2)


def _with_folder_cache(dispatcher):
    cache = getattr(dispatcher, "_cache", None)
    if isinstance(cache, FunctionCache):
        try:
            dispatcher._cache = _FolderCache(dispatcher.py_func)
        except AttributeError:  # numba's private cache layout changed: its own cache then
            import warnings

            warnings.warn("bayespilot: numba's cache internals changed; after editing a file in "
                          "bayespilot/kernels, delete its __pycache__ folder", RuntimeWarning)
    return dispatcher


def _temporary_cache_dir() -> Path | None:
    """A folder under the temporary folder that only this user can write, or None.

    numba loads its cache files with pickle, so a folder another user could write into would
    let them run code in this process: a shared name is used only if it is a real folder,
    owned by this user and writable by no one else; otherwise a fresh private folder."""
    try:
        base = Path(tempfile.gettempdir())  # raises when no candidate folder is writable
    except OSError:
        return None
    if hasattr(os, "getuid"):
        shared = base / f"bayespilot-numba-cache-{os.getuid()}"
        try:
            shared.mkdir(mode=0o700, exist_ok=True)
            st = os.lstat(shared)
            if (stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid()
                    and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)):
                tempfile.TemporaryFile(dir=shared).close()  # numba's own writability test
                return shared
        except OSError:
            pass
    try:
        return Path(tempfile.mkdtemp(prefix="bayespilot-numba-cache-"))
    except OSError:
        return None


def _warn_fallback(tried: str, where: str) -> None:
    shown = f"NUMBA_CACHE_DIR={tried}, " if tried else ""
    # stacklevel: _warn_fallback, _jit, njit (or its lambda), then the kernel's module
    warnings.warn(f"bayespilot: numba finds no writable folder for its cache of compiled kernels "
                  f"({shown}the package's __pycache__ folders or the user's cache folder); "
                  f"{where}. Set NUMBA_CACHE_DIR to a writable folder to choose where.",
                  RuntimeWarning, stacklevel=4)


def _jit(opts: dict, func):
    """``numba.njit(**opts)(func)``; where numba refuses to cache for want of a writable
    folder (it raises at decoration, so at the import of a kernel module), the same with the
    cache in :func:`_temporary_cache_dir`, else without a cache, from then on for every
    kernel, with one warning."""
    global _cache_fallback
    if _cache_fallback == "off":
        opts = {**opts, "cache": False}
    try:
        return numba.njit(**opts)(func)
    except RuntimeError as exc:
        if not opts.get("cache") or "no locator available" not in str(exc):
            raise
    tried = numba.config.CACHE_DIR
    folder = _temporary_cache_dir() if _cache_fallback is None else None
    if folder is not None:
        before = os.environ.get("NUMBA_CACHE_DIR")
        # numba's documented setting, in the environment: numba re-reads it before each
        # compilation (setting numba.config alone would not last), and worker processes
        # inherit it; reload_config applies it at once
        os.environ["NUMBA_CACHE_DIR"] = str(folder)
        numba.config.reload_config()
        try:
            dispatcher = numba.njit(**opts)(func)
        except RuntimeError as exc:
            if "no locator available" not in str(exc):
                raise
            if before is None:  # useless: numba's setting as it was
                del os.environ["NUMBA_CACHE_DIR"]
            else:
                os.environ["NUMBA_CACHE_DIR"] = before
            numba.config.reload_config()
        else:
            _cache_fallback = "temporary"
            _warn_fallback(tried, f"caching them in {folder}")
            return dispatcher
    _cache_fallback = "off"
    _warn_fallback(tried, "compiling them anew in every process (slower to start)")
    return numba.njit(**{**opts, "cache": False})(func)


def njit(*args, **kwargs):
    """``numba.njit`` with the package defaults; keyword arguments override them.

    No signature: numba would compile it at once, with its own cache, before
    ``_FolderCache`` is attached."""
    opts = dict(JIT_OPTIONS)
    opts.update(kwargs)
    if args and callable(args[0]):
        return _with_folder_cache(_jit(opts, args[0]))
    if args:
        raise TypeError("bayespilot's njit takes no signature (kernels compile lazily, so that "
                        "their disk cache is keyed on the kernels' sources)")
    return lambda func: _with_folder_cache(_jit(opts, func))


def pjit(*args, **kwargs):
    """``njit`` with ``parallel=True``, for kernels that ``prange`` over independent items."""
    kwargs.setdefault("parallel", True)
    return njit(*args, **kwargs)
