"""Rough surfaces: self-affine synthesis and measured height maps, on the spring grid.

Self-affine roughness follows the conventions of SurfaceTopography's
``fourier_synthesis`` (Jacobs, Junge & Pastewka, Surf. Topogr.: Metrol. Prop. 5,
013001 (2017); Ramisetti et al., J. Phys.: Condens. Matter 23, 215004 (2011)), so the
same statistics can be generated in either tool:

- the isotropic PSD is C(q) = C0 q^(-2-2H), q = |q| = 2 pi / lambda;
- it is zero above q_s = 2 pi / short_cutoff (a disc in q-space);
- below q_L = 2 pi / long_cutoff it is constant, rolloff^2 C(q_L) (rolloff = 1: flat,
  0: no wavelengths longer than long_cutoff); the q = 0 coefficient is zero;
- C(q) = (1/A) |h~(q)|^2 with h~ = spacing^2 * numpy's unnormalized fft2 and
  A = (n spacing)^2 the area of the periodic synthesis box;
- random Fourier coefficients are complex normal (standard normal amplitude, uniform
  phase), drawn from ``numpy.random.default_rng(roughness_seed)`` (PCG64).

Normalization (where tfm differs from SurfaceTopography on purpose): SurfaceTopography
scales C0 so that the *expected* rms of the ensemble is the request; tfm rescales each
*realization* so that its own rms is the request to round-off. ``rms_height`` is the
rms of the heights over the synthesis grid (their mean is zero). ``rms_slope`` is the
*spectral* rms slope, sqrt(sum_q q^2 |h~(q)|^2 / A^2) -- the slope of the band-limited
continuous surface, as in SurfaceTopography -- not a finite-difference slope, which is
smaller (by about 5 % at short_cutoff = 4 spacings, less at longer cutoffs).

What a seed guarantees: the same ``roughness_seed``, grid (spacing and number of
springs a side, i.e. the grid half-width) and spectral parameters give the same
surface bit for bit with the same NumPy version (NumPy does not promise PCG64 normal
streams across versions). The synthesis box is the spring grid itself, so a run whose
extent changes (``extent``, or ``max_indent``/``radius`` through the automatic extent)
draws a different surface; to compare loads on one surface, fix ``extent``. Changing
only ``rms_height`` or ``rms_slope`` rescales the same surface.

The box is periodic; the contact problem is not (the elastic half-space is loaded only
where springs touch), so periodicity matters only through the box size, which bounds
the longest wavelength (``long_cutoff`` must not exceed the grid side).

Height maps: a 2-D array of heights, pixel (i, j) at ((i - c_x) a, (j - c_y) a) with
a = ``map_pixel_size`` and c = (n - 1) // 2 the centre pixel (axis 0 is x), so a map
whose pixel equals the spacing lands exactly on the springs. Otherwise heights are
interpolated bilinearly at the spring positions (no smoothing: a map finer than the
spacing is sampled, not averaged; a coarser one gains no detail).
"""
from __future__ import annotations

import contextlib
import hashlib
import math
import os
import threading
import warnings
from pathlib import Path

import numpy as np

#: default short-wavelength cutoff, in spacings (see ``default_short_cutoff``)
SHORT_CUTOFF_SPACINGS = 4.0
#: the shortest wavelength a grid carries (Nyquist), in spacings
NYQUIST_SPACINGS = 2.0


class MapError(ValueError):
    """A height map cannot be read or is unusable (raised as ParameterError by Params)."""


class MapUnitWarning(UserWarning):
    """A map file gives its size but no length unit: it is read in metres."""


# ---- self-affine synthesis -------------------------------------------------
def default_short_cutoff(spacing: float) -> float:
    """4 spacings. Two spacings is the Nyquist wavelength: there the grid cannot tell a
    wave from its phase and each summit is one spring. Four resolves the shortest
    wavelength by four springs a period (a summit by about two), which keeps most of the
    grid's bandwidth. For converged contact mechanics of the asperities use 8 or more
    (bench/validate_contactmechanics.py: the force against a pixel BEM agrees to a few
    per cent from 8 spacings on)."""
    return SHORT_CUTOFF_SPACINGS * spacing


def wavevectors(n: int, spacing: float) -> np.ndarray:
    """|q| on the full n x n fft2 grid of a periodic box of side n * spacing."""
    q = 2.0 * np.pi * np.fft.fftfreq(n, d=spacing)
    return np.hypot(q[:, None], q[None, :])


def self_affine_psd(q, hurst: float, short_cutoff: float, long_cutoff: float | None,
                    rolloff: float = 1.0) -> np.ndarray:
    """The unnormalized PSD shape q^(-2-2H) with SurfaceTopography's cutoffs (C0 = 1)."""
    q = np.asarray(q, dtype=float)
    exponent = -2.0 - 2.0 * hurst
    q_s = 2.0 * np.pi / short_cutoff
    psd = np.zeros_like(q)
    inside = (q > 0) & (q <= q_s)
    psd[inside] = q[inside] ** exponent
    if long_cutoff is not None:
        q_l = 2.0 * np.pi / long_cutoff
        psd[inside & (q < q_l)] = rolloff ** 2 * q_l ** exponent
    return psd


def has_modes(n: int, spacing: float, short_cutoff: float, long_cutoff: float | None,
              rolloff: float = 1.0) -> bool:
    """Whether some wavevector of the n x n grid carries power under self_affine_psd (the
    same test as its mask, on integer frequency pairs: no n x n array)."""
    scale = n * spacing                      # |q| = 2 pi k / scale, k = |(i, j)|, |i|, |j| <= n // 2
    k_hi = scale / short_cutoff
    k_lo = scale / long_cutoff if long_cutoff is not None and rolloff == 0 else 0.0
    half = n // 2
    for i in range(0, half + 1):
        # the smallest j >= 0 with i^2 + j^2 >= k_lo^2 and (i, j) != (0, 0)
        j = max(math.ceil(math.sqrt(max(k_lo * k_lo - i * i, 0.0))), 1 if i == 0 else 0)
        while j <= half and i * i + j * j < k_lo * k_lo:
            j += 1
        if j <= half and math.sqrt(i * i + j * j) <= k_hi * (1 + 1e-12):
            return True
    return False


def fourier_synthesis(n: int, spacing: float, hurst: float, *, rms_height: float = 0.0,
                      rms_slope: float = 0.0, short_cutoff: float | None = None,
                      long_cutoff: float | None = None, rolloff: float = 1.0,
                      seed: int = 0) -> np.ndarray:
    """A random self-affine surface on an n x n periodic grid (module docstring).

    Give ``rms_height`` or ``rms_slope`` (> 0); the realization is rescaled so that its
    rms height or spectral rms slope equals the request."""
    if (rms_height > 0) == (rms_slope > 0):
        raise ValueError("fourier_synthesis: give one of rms_height and rms_slope (> 0)")
    short = default_short_cutoff(spacing) if short_cutoff is None else short_cutoff
    q = wavevectors(n, spacing)
    amplitude = np.sqrt(self_affine_psd(q, hurst, short, long_cutoff, rolloff))
    rng = np.random.default_rng(seed)
    noise = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    # the real part of the inverse transform of a complex white spectrum is the
    # Hermitian-symmetrized spectrum: every coefficient keeps the PSD shape
    h = np.fft.ifft2(amplitude * noise).real
    h -= h.mean()
    H = np.fft.fft2(h)
    power = np.abs(H) ** 2
    if rms_height > 0:
        realized = math.sqrt(float(power.sum())) / (n * n)
        target = rms_height
    else:
        realized = math.sqrt(float((q ** 2 * power).sum())) / (n * n)
        target = rms_slope
    if realized == 0.0:
        raise ValueError("fourier_synthesis: no wavevector of the grid lies between the cutoffs")
    return h * (target / realized)


def spectral_rms_slope(h: np.ndarray, spacing: float) -> float:
    """sqrt(<|grad h|^2>) from the Fourier coefficients of a periodic square map."""
    n = h.shape[0]
    q = wavevectors(n, spacing)
    dev = h - h.mean()
    # in units of the largest deviation: rms_height 1e300 overflowed the squares to NaN,
    # which passed the steep-surface check (only the guards read this slope)
    scale = float(np.abs(dev).max()) if dev.size else 0.0
    if not 0.0 < scale < math.inf:
        return 0.0 if scale == 0.0 else math.inf
    H = np.fft.fft2(dev / scale)
    return scale * math.sqrt(float((q ** 2 * np.abs(H) ** 2).sum())) / (n * n)


def radial_psd(h: np.ndarray, spacing: float, nbins: int | None = None):
    """Radially averaged PSD C(q) = spacing^2 |fft2(h)|^2 / n^2 of a square periodic map,
    in SurfaceTopography's normalization; bins of equal width in q up to pi / spacing.
    Returns (q, C) for the non-empty bins (bin centres: mean |q| of the members)."""
    n = h.shape[0]
    q = wavevectors(n, spacing).ravel()
    C = (spacing ** 2 * np.abs(np.fft.fft2(h - h.mean())) ** 2 / (n * n)).ravel()
    nbins = nbins or n // 2
    edges = np.linspace(0.0, np.pi / spacing, nbins + 1)
    which = np.digitize(q, edges) - 1
    keep = (q > 0) & (which < nbins)
    counts = np.bincount(which[keep], minlength=nbins)
    qsum = np.bincount(which[keep], weights=q[keep], minlength=nbins)
    csum = np.bincount(which[keep], weights=C[keep], minlength=nbins)
    ok = counts > 0
    return qsum[ok] / counts[ok], csum[ok] / counts[ok]


def psd_exponent(h: np.ndarray, spacing: float, q_low: float, q_high: float, nbins: int = 20) -> float:
    """Slope of log C against log q: least squares over ``nbins`` logarithmically spaced
    radial bins between q_low and q_high (each bin's mean C at its mean |q|), so every
    decade of q weighs the same."""
    n = h.shape[0]
    q = wavevectors(n, spacing).ravel()
    C = (spacing ** 2 * np.abs(np.fft.fft2(h - h.mean())) ** 2 / (n * n)).ravel()
    edges = np.geomspace(q_low, q_high, nbins + 1)
    which = np.digitize(q, edges) - 1
    keep = (which >= 0) & (which < nbins)
    counts = np.bincount(which[keep], minlength=nbins)
    ok = counts > 0
    lq = np.bincount(which[keep], weights=q[keep], minlength=nbins)[ok] / counts[ok]
    lc = np.bincount(which[keep], weights=C[keep], minlength=nbins)[ok] / counts[ok]
    return float(np.polyfit(np.log(lq), np.log(lc), 1)[0])


# ---- the run's roughness -----------------------------------------------------
def is_rough(p) -> bool:
    return p.rms_slope > 0 or p.rms_height > 0


def grid_side(p) -> int:
    """Springs a side of the square grid that covers the run's region."""
    return 2 * int(math.ceil(p.half_width / p.spacing - 1e-9)) + 1


_ROUGH_GRID: dict = {}      # the last surface made: the guards' slope check and the run share it


def _rough_grid(p) -> np.ndarray:
    """The run's roughness on the square grid of its spacing and half-width (read-only).
    Kept until another surface is made, so a run synthesizes its surface once."""
    key = (grid_side(p), p.spacing, p.hurst, p.rms_height, p.rms_slope, p.short_cutoff, p.long_cutoff,
           p.rolloff, p.roughness_seed)
    h = _ROUGH_GRID.get(key)
    if h is None:
        h = fourier_synthesis(key[0], p.spacing, p.hurst, rms_height=p.rms_height, rms_slope=p.rms_slope,
                              short_cutoff=p.short_cutoff, long_cutoff=p.long_cutoff,
                              rolloff=p.rolloff, seed=p.roughness_seed)
        h.setflags(write=False)
        _ROUGH_GRID.clear()
        _ROUGH_GRID[key] = h
    return h


def roughness(p, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The run's random heights at spring positions (x, y); zero when smooth.

    Synthesized on the square grid of the run's spacing and half-width, and read at the
    springs: exactly on the square layout, bilinearly on the jittered and hexagonal ones."""
    if not is_rough(p):
        return np.zeros(x.size)
    # the synthesized surface is periodic: jittered springs beyond the box wrap around
    return sample(_rough_grid(p), p.spacing, x, y, periodic=True)


def roughness_rms_slope(p) -> float:
    """The spectral rms slope of the run's roughness: ``rms_slope`` as given, or that of the
    surface an ``rms_height`` makes (its realization's, so it depends on the seed)."""
    if p.rms_slope > 0:
        return float(p.rms_slope)
    if p.rms_height > 0:
        return spectral_rms_slope(_rough_grid(p), p.spacing)
    return 0.0


def sample(h: np.ndarray, pixel: float, x: np.ndarray, y: np.ndarray, periodic: bool = False) -> np.ndarray:
    """Bilinear interpolation of map h (centre pixel at the origin) at points (x, y).

    Points on pixel centres get the pixel's value exactly; points outside the map are
    an error unless the map is ``periodic`` (the validation keeps the grid inside a
    measured map)."""
    nx, ny = h.shape
    cx, cy = (nx - 1) // 2, (ny - 1) // 2
    fx = np.asarray(x, dtype=float) / pixel + cx
    fy = np.asarray(y, dtype=float) / pixel + cy
    # snap round-off (x = k * spacing computed in floating point) onto the pixel
    fx = np.where(np.abs(fx - np.rint(fx)) < 1e-9, np.rint(fx), fx)
    fy = np.where(np.abs(fy - np.rint(fy)) < 1e-9, np.rint(fy), fy)
    if periodic:
        i0, j0 = np.floor(fx).astype(np.int64), np.floor(fy).astype(np.int64)
        tx, ty = fx - i0, fy - j0
        i0, j0 = i0 % nx, j0 % ny
        i1, j1 = (i0 + 1) % nx, (j0 + 1) % ny
    else:
        if fx.size and (fx.min() < 0 or fy.min() < 0 or fx.max() > nx - 1 or fy.max() > ny - 1):
            raise MapError("height map: a spring lies outside the map")
        i0 = np.clip(np.floor(fx).astype(np.int64), 0, max(nx - 2, 0))
        j0 = np.clip(np.floor(fy).astype(np.int64), 0, max(ny - 2, 0))
        tx, ty = fx - i0, fy - j0
        i1, j1 = np.minimum(i0 + 1, nx - 1), np.minimum(j0 + 1, ny - 1)
    return ((1 - tx) * (1 - ty) * h[i0, j0] + tx * (1 - ty) * h[i1, j0]
            + (1 - tx) * ty * h[i0, j1] + tx * ty * h[i1, j1])


# ---- height maps -------------------------------------------------------------
_MAP_CACHE: dict[tuple, "HeightMap"] = {}
# maps handed over with a task (a Dask worker may not see the client's files): per
# thread, for the task's duration only, so no later task reads a stale copy
_GIVEN = threading.local()


MAP_BLOCK = 1 << 16       # pixels per block of HeightMap.step_rms (0.5 MiB of differences)


class HeightMap:
    """Heights (float64, 2-D), the file's own pixel size if it has one, the content hash."""

    def __init__(self, heights: np.ndarray, pixel_size: float | None, unit: str | None):
        self.heights = heights
        self.pixel_size = pixel_size
        self.unit = unit
        digest = hashlib.sha256()
        digest.update(repr(heights.shape).encode())
        digest.update(np.ascontiguousarray(heights, dtype="<f8"))       # its buffer: no bytes copy
        if pixel_size is not None:
            digest.update(repr(float(pixel_size)).encode())
        if unit is not None:                 # scales heights and pixel (unit_to_metres)
            digest.update(unit.encode())
        self.sha256 = digest.hexdigest()
        self._step_rms = None

    @property
    def step_rms(self) -> float:
        """sqrt(<|grad h|^2>) in file units per pixel, by differences between neighbouring
        pixels; computed once per map (a campaign checks every run against it)."""
        if self._step_rms is None:
            # by blocks of rows: whole-map differences and their squares held four copies
            # of the map (a 6001^2 map: 1.1 GiB where the run's estimate said 430 MiB)
            h = self.heights
            n, m = h.shape
            sx = sy = 0.0
            rows = max(1, MAP_BLOCK // m)
            for i in range(0, n, rows):
                block = h[i:min(i + rows + 1, n)]          # one row more: the differences across
                gx, gy = np.diff(block, axis=0), np.diff(block[:-1] if i + rows < n else block, axis=1)
                sx += float(np.sum(gx * gx))
                sy += float(np.sum(gy * gy))
            self._step_rms = math.sqrt(sx / ((n - 1) * m) + sy / (n * (m - 1)))
        return self._step_rms


@contextlib.contextmanager
def given_maps(maps: dict[str, HeightMap]):
    """Within this block, in this thread, ``load_height_map(path)`` returns ``maps[path]``
    instead of reading the file."""
    before = getattr(_GIVEN, "maps", {})
    _GIVEN.maps = {**before, **maps}
    try:
        yield
    finally:
        _GIVEN.maps = before


def load_height_map(path: str) -> HeightMap:
    """Read and check a height map: ``.npy`` with NumPy; any other format through
    SurfaceTopography (``pip install tfm[topography]``), which supplies the pixel size
    and the unit. Raises MapError for a missing, non-2-D or non-finite map."""
    given = getattr(_GIVEN, "maps", {}).get(str(path))
    if given is not None:
        return given
    file = Path(os.path.expanduser(str(path)))
    try:
        stat = file.stat()
    except OSError:
        raise MapError(f"height_map: no such file {str(path)!r}") from None
    if file.is_dir():
        raise MapError(f"height_map: {str(path)!r} is a folder, not a map file")
    key = (str(file.resolve()), stat.st_mtime_ns, stat.st_size)
    if key in _MAP_CACHE:
        return _MAP_CACHE[key]
    pixel = unit = None
    if file.suffix.lower() == ".npy":
        with open(file, "rb") as fh:
            if fh.read(6) != b"\x93NUMPY":
                # NumPy calls any file without its header "pickled data"
                raise MapError(f"height_map: cannot read {str(path)!r} as a .npy array: it has no NumPy "
                               "header (save the heights with numpy.save)")
        try:
            heights = np.load(file, allow_pickle=False)
        except (ValueError, OSError, EOFError) as exc:      # EOFError: an empty file
            raise MapError(f"height_map: cannot read {str(path)!r} as a .npy array: {exc}") from None
    else:
        heights, pixel, unit = _read_with_surface_topography(file)
    heights = np.asarray(heights)
    if heights.ndim != 2:
        raise MapError(f"height_map: must be a 2-D array of heights, got shape {heights.shape}")
    if not np.issubdtype(heights.dtype, np.number) or np.iscomplexobj(heights):
        raise MapError(f"height_map: heights must be real numbers, got dtype {heights.dtype}")
    heights = heights.astype(np.float64, copy=False)      # a float64 map is not copied again
    bad = ~np.isfinite(heights)
    if bad.any():
        i, j = np.argwhere(bad)[0]
        raise MapError(f"height_map: {int(bad.sum())} heights are NaN or infinite "
                       f"(first at pixel [{i}, {j}]); fill or crop the missing data first")
    if min(heights.shape) < 2:
        raise MapError(f"height_map: needs at least 2 x 2 pixels, got {heights.shape}")
    hm = HeightMap(heights, pixel, unit)
    _MAP_CACHE[key] = hm
    return hm


def _read_with_surface_topography(file: Path):
    try:
        from SurfaceTopography import open_topography
    except ImportError:
        raise MapError(f"height_map: {file.suffix!r} files need SurfaceTopography "
                       "(pip install 'tfm[topography]'); or save the heights as .npy") from None
    try:
        with open_topography(str(file)) as reader:
            channel = reader.default_channel
            # a plain matrix (text) has no size: its heights are read as a .npy's are
            # (map_pixel_size, or the spacing), not refused for the size it lacks
            sized = channel.physical_sizes is not None
            topo = reader.topography() if sized else reader.topography(physical_sizes=channel.nb_grid_pts)
    except Exception as exc:  # noqa: BLE001 - any reader failure is a bad map
        if type(exc).__name__ == "CannotDetectFileFormat":
            # its message lists every reader it tried (48 lines for a .csv)
            raise MapError(f"height_map: SurfaceTopography cannot tell the format of {str(file)!r} (none of its "
                           "readers accepts it); save a matrix of heights with numpy.save (.npy) or "
                           "numpy.savetxt (space-separated text)") from None
        raise MapError(f"height_map: SurfaceTopography cannot read {str(file)!r}: {exc}") from None
    if topo.dim != 2:
        raise MapError(f"height_map: {str(file)!r} is a line scan, not a 2-D map")
    if not sized:
        return np.asarray(topo.heights()), None, None
    sx, sy = (_stored_decimal(v) for v in topo.physical_sizes)
    nx, ny = topo.nb_grid_pts
    if not math.isclose(sx / nx, sy / ny, rel_tol=1e-9):
        raise MapError(f"height_map: pixels must be square, got {sx / nx:g} x {sy / ny:g}")
    heights = topo.heights()
    if np.ma.isMaskedArray(heights):
        # missing data: the mask's fill value (1e20) would be read as a height
        heights = np.ma.filled(heights.astype(np.float64), np.nan)
    unit = getattr(topo, "unit", None)
    if unit is None:
        # sizes without a unit: the map is read in metres (L* in paper units), as before,
        # but not in silence
        warnings.warn(f"height_map: {str(file)!r} gives its size ({sx:g} x {sy:g}) but no length unit; its sizes "
                      "and heights are taken in metres (in paper units, in L*)", MapUnitWarning, stacklevel=2)
    return np.asarray(heights), sx / nx, unit


def _stored_decimal(size: float) -> float:
    """A file's size as the decimal it was written as. SurfaceTopography's NetCDF keeps
    sizes in single precision: 65 mm came back as 0.064999998 m, a pixel 4e-8 short of
    the 1 mm spacing, and the grid lost its outer ring of springs without a note. A value
    that is exactly a single-precision number is read as the shortest decimal that rounds
    to it (a change below 6e-8 relative); any other value is kept as it is."""
    size = float(size)
    single = np.float32(size)
    return float(str(single)) if np.isfinite(single) and float(single) == size else size


def map_pixel(p, hm: HeightMap) -> float:
    """The map's pixel size in the run's length unit: map_pixel_size, else the file's
    own, else the spacing."""
    if p.map_pixel_size is not None:
        return float(p.map_pixel_size)
    if hm.pixel_size is not None:
        return float(hm.pixel_size) * unit_to_metres(hm.unit, p)
    return float(p.spacing)


def _height_scale(p, hm: HeightMap) -> float:
    """Run length units per height unit of the map: a file with its own size has a unit,
    a map without one (.npy, text) is in the run's units."""
    return unit_to_metres(hm.unit, p) if hm.pixel_size is not None else 1.0


def heights_in_run_units(p, hm: HeightMap) -> np.ndarray:
    scale = _height_scale(p, hm)
    return hm.heights * scale if scale != 1.0 else hm.heights


def map_rms_slope(p, hm: HeightMap) -> float:
    """The map's rms slope in the run: heights and pixel in one length unit."""
    return hm.step_rms * _height_scale(p, hm) / map_pixel(p, hm)


# SurfaceTopography's length units (it writes and reads "A" as "Å")
_SI_UNITS = {"Gm": 1e9, "Mm": 1e6, "km": 1e3, "m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "nm": 1e-9,
             "Å": 1e-10, "A": 1e-10, "pm": 1e-12, "fm": 1e-15}


def unit_to_metres(unit: str | None, p) -> float:
    """Factor from a file's length unit to metres (a file without a unit: 1). A map read
    by SurfaceTopography is in metres in either unit system (in paper units, L* = 1 m),
    so an SI run and its paper-units twin see the same heights."""
    if unit is None:
        return 1.0
    if unit not in _SI_UNITS:
        raise MapError(f"height_map: unknown length unit {unit!r} in the file; "
                       f"known: {', '.join(_SI_UNITS)}")
    return _SI_UNITS[unit]


def map_reach(p, hm: HeightMap) -> tuple[float, float]:
    """How far a grid centred on the map's centre pixel ((n - 1) // 2 along each axis) can
    reach along x and y: the shorter side of each axis (an even pixel count leaves its
    last pixel over on one side)."""
    a = map_pixel(p, hm)
    nx, ny = hm.heights.shape
    return min((nx - 1) // 2, nx - 1 - (nx - 1) // 2) * a, min((ny - 1) // 2, ny - 1 - (ny - 1) // 2) * a


def map_half_width(p, hm: HeightMap) -> float:
    """Half-width of the largest centred grid of the run's layout that the map covers."""
    from .geometry import largest_half_width
    return largest_half_width(p, min(map_reach(p, hm)))


def map_cropped_edge(p, x: np.ndarray, y: np.ndarray, edge: np.ndarray) -> np.ndarray:
    """The springs of the grid's outer ring (``edge``) on the sides where the grid stops
    short of the map's own edge, by ``extent`` or as the centred square of an oblong map.
    Contact there is a sign of a too-small grid, as for the other shapes; contact at the
    map's own edge is physical (a finite body), and is not flagged."""
    reach_x, reach_y = map_reach(p, load_height_map(p.height_map))
    hw = float(max(np.abs(x).max(), np.abs(y).max())) if x.size else 0.0
    near = 1.5 * p.spacing                                    # as wide as the ring (geometry)
    # another ring of springs fits on both sides: the grid is centred, so the row that an
    # even pixel count leaves over on one side is no crop a larger extent could undo
    cut = lambda room: room >= p.spacing * (1 - 1e-9)
    cut_x, cut_y = cut(reach_x - hw), cut(reach_y - hw)
    sides = ((cut_x, x >= hw - near), (cut_x, x <= -hw + near), (cut_y, y >= hw - near), (cut_y, y <= -hw + near))
    mask = np.zeros(x.shape, dtype=bool)
    for cropped, on_side in sides:
        if cropped:
            mask |= on_side
    return edge & mask


def map_unused_note(p) -> str | None:
    """A note if the automatic grid, the map's largest centred square, leaves part of an
    oblong map unused (None otherwise)."""
    hm = load_height_map(p.height_map)
    a = map_pixel(p, hm)
    nx, ny = hm.heights.shape
    # the grid keeps whole spacings: a square map always leaves less than a spacing of its
    # reach unused, which is not worth a note
    reach_x, reach_y = map_reach(p, hm)
    hw = p.half_width
    if max(reach_x, reach_y) - hw >= p.spacing * (1 - 1e-9):
        if p.layout != "square" and abs(reach_x - reach_y) < 1e-9 * p.spacing + 1e-12:
            # a square map: what is left unused is the layout's margin, not an oblong's strip
            from .geometry import layout_reach
            return (f"height_map: the {p.layout} layout's springs lie up to {layout_reach(p, hw):.4g} from the "
                    f"centre on a grid of half-width {hw:.4g}"
                    + (f" (jitter {p.jitter:g} spacings beyond it)" if p.layout == "jittered" else "")
                    + f", so the grid is kept that far inside the map, which reaches ±{reach_x:.4g}: its pixels "
                    "beyond are not used")
        return (f"height_map: the grid is the map's largest centred square (half-width {hw:.4g}); the map "
                f"({nx} x {ny} pixels) reaches ±{reach_x:.4g} along x and ±{reach_y:.4g} along y, and its "
                "pixels beyond the square are not used")
    if a >= p.spacing * (1 - 1e-9) and (nx % 2 == 0 or ny % 2 == 0):
        # the row left over holds springs: contact there is not flagged (map_cropped_edge)
        return (f"height_map: {nx} x {ny} pixels, an even count: the grid, centred on pixel "
                f"({(nx - 1) // 2}, {(ny - 1) // 2}), leaves the map's last pixel along "
                f"{'x and y' if nx % 2 == ny % 2 else 'x' if nx % 2 == 0 else 'y'} unused (contact next to it is "
                "not flagged); crop the map to an odd count to use all of it")
    return None


def map_heights(p, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The run's height map at the spring positions: the heights its run id was made
    from (height_map_hash), or MapError. The record is checked when it is made, but a run
    of a campaign starts later: a file changed in between ran, and was stored under the
    old content's run id."""
    hm = load_height_map(p.height_map)
    if p.height_map_hash is not None and hm.sha256 != p.height_map_hash:
        raise MapError(f"height_map: {p.height_map} has changed since the run was made: its content hash is "
                       f"{hm.sha256[:12]}..., the run's (height_map_hash) {p.height_map_hash[:12]}.... "
                       "Restore the file, or make the run again from the new file")
    return sample(heights_in_run_units(p, hm), map_pixel(p, hm), x, y)
