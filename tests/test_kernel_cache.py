"""The guard against stale compiled kernels (tfm.kernels.purge_stale_cache): Numba keys a
cached kernel on its own file only, so a change in a file it calls must empty the cache."""
from pathlib import Path

import tfm.kernels as kernels
from tfm.kernels import STAMP, purge_stale_cache, source_digest


def _cached(folder):
    return sorted(p.name for p in folder.iterdir() if p.suffix in (".nbi", ".nbc"))


def test_cache_is_emptied_exactly_when_a_source_changes(tmp_path):
    src = [tmp_path / "a.py", tmp_path / "b.py"]
    src[0].write_text("x = 1\n")
    src[1].write_text("y = 2\n")
    cache = tmp_path / "cache"
    cache.mkdir()
    for name in ("a.f-1.py311.nbi", "a.f-1.py311.1.nbc"):
        (cache / name).write_bytes(b"old")
    (cache / "keep.pyc").write_bytes(b"")
    assert purge_stale_cache(cache, src) is True          # no stamp yet: unknown origin
    assert _cached(cache) == [] and (cache / "keep.pyc").exists()
    assert (cache / STAMP).read_text() == source_digest(src)
    (cache / "a.f-1.py311.nbi").write_bytes(b"new")        # compiled from these sources
    assert purge_stale_cache(cache, src) is False
    assert _cached(cache) == ["a.f-1.py311.nbi"]
    src[1].write_text("y = 3\n")                           # a callee changed, not a.py
    assert purge_stale_cache(cache, src) is True
    assert _cached(cache) == []


def test_importing_the_kernels_stamps_their_cache():
    here = Path(kernels.__file__).resolve().parent
    sources = sorted(here.glob("*.py")) + [here.parent / "config.py"]
    folder = kernels._cache_dir()
    assert folder is not None
    assert (folder / STAMP).read_text() == source_digest(sources)
