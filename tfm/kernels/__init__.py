"""Pure jitted array functions. They know nothing of the model, files or parameters.

Numba's disk cache keys each compiled kernel on its own source file only. A kernel that
calls one in another file (snap_rounds calls the FFT of fft.py) compiles the callee into
itself, so after an edit or upgrade of that other file the cache would serve the old
code, silently, or crash. Importing this package therefore compares a hash of every
kernel source (and of tfm/config.py, whose constants are compiled in) with the one that
made the cache, and empties the cache folder if they differ (purge_stale_cache).
"""
from __future__ import annotations

import hashlib
from pathlib import Path

STAMP = "tfm-kernels.sha256"


def source_digest(sources) -> str:
    """sha256 over the names and bytes of the given source files, in the order given."""
    h = hashlib.sha256()
    for path in sources:
        path = Path(path)
        h.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()


def purge_stale_cache(cache_dir, sources) -> bool:
    """Delete the compiled kernels (*.nbi, *.nbc) in ``cache_dir`` unless its stamp file
    names the digest of ``sources``, then write the stamp. True if it deleted anything.

    Held under an exclusive lock, and the stamp is written after the deletion, so a
    process that finds a current stamp can never lose a file it is loading to another
    process's purge."""
    cache_dir = Path(cache_dir)
    digest = source_digest(sources)
    stamp = cache_dir / STAMP
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        with open(cache_dir / (STAMP + ".lock"), "a") as lock:
            try:
                import fcntl
                fcntl.flock(lock, fcntl.LOCK_EX)
            except ImportError:          # not POSIX: no lock, the race is only at first start
                pass
            try:
                if stamp.read_text() == digest:      # another process purged meanwhile
                    return False
            except OSError:
                pass
            stale = list(cache_dir.glob("*.nbi")) + list(cache_dir.glob("*.nbc"))
            for path in stale:
                path.unlink(missing_ok=True)
            tmp = stamp.with_suffix(".tmp")
            tmp.write_text(digest)
            tmp.replace(stamp)
            return bool(stale)
    except OSError:
        return False                     # a read-only cache: Numba will not write there either


def _cache_dir() -> Path | None:
    """The folder where Numba caches the kernels of this package (its own locator rules:
    NUMBA_CACHE_DIR, else __pycache__ here, else the user-wide cache)."""
    try:
        from numba.core.caching import CompileResultCacheImpl
        return Path(CompileResultCacheImpl(source_digest)._locator.get_cache_path())
    except Exception:                    # a Numba without this internal API: skip the check
        return None


def _check_cache() -> None:
    here = Path(__file__).resolve().parent
    cache = _cache_dir()
    if cache is not None:
        purge_stale_cache(cache, sorted(here.glob("*.py")) + [here.parent / "config.py"])


_check_cache()


def _without(name: str, module: str) -> None:
    """Import ``module`` while ``name`` cannot be imported (unless it already is): it stays
    out of the process until something else imports it."""
    import importlib
    import sys

    if name in sys.modules:
        importlib.import_module(module)
        return
    sys.modules[name] = None              # `import name` raises ImportError meanwhile
    try:
        importlib.import_module(module)
    finally:
        if sys.modules.get(name, 0) is None:
            del sys.modules[name]


def lean_start() -> None:
    """For `tfm run`'s own process, whose compiled code is all tfm's: import rocket-fft
    without scipy.fft, which it imports only to register its scipy.fft overloads (the
    kernels call NumPy's FFT interface and rocket-fft's low-level transforms), and Numba's
    array functions without scipy.linalg, which they import only to see whether np.dot may
    call BLAS (the kernels have no matrix products; a compiled np.dot would still import it).
    0.1-0.2 s of a 1.2 s run at 1/128. Both stay importable; the process then lacks only
    rocket-fft's scipy.fft overloads."""
    _without("scipy.fft", "rocket_fft")
    _without("scipy.linalg", "numba.np.arraymath")
