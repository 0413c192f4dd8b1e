"""Compiled zero-padded FFT convolution with the compliance, on a square box of the grid.

rocket-fft's low-level transforms (rocket_fft.r2c, c2c, c2r) call pocketfft from @njit
code and write into the caller's arrays, so the contact solve never returns to Python and
a convolution allocates nothing. A linear convolution of a W x W box needs a periodic box
P >= 2 W - 1 (no images); the transform is pruned: only the rows that hold sources are
transformed along the rows, and only the W wanted rows are transformed back. The rows'
spectra are written straight into the column array and the columns are transformed in
place: a separate spectrum array, zero-padded into the columns by pocketfft, made a
convolution on one thread 1.09-1.18x slower at P = 192-960 (`python -m bench.run_bench
--only fft`, both versions, 2026-11-24).

The column array is stored transposed, (P // 2 + 1) x P: each column of the spectrum is a
contiguous row, so the column transforms, the dominant stage, run along the contiguous
axis (pocketfft's copies of strided columns into its buffers and back took 16-20 % of a
1/256 curve under `perf`). The rows' transforms write and read it through transposed
views. The symbols are stored in the same layout (``symbol``). The same bits as the
untransposed layout; one convolution on one thread 1.05-1.09x faster at P = 120-256
(2026-11-29).

Threads: each stage's 1-D transforms are cut into one part per Numba thread, each part one
single-threaded pocketfft call. pocketfft works through a call's transforms in SIMD
bundles; parts cut at multiples of ALIGN leave the bundles whole, and the result is then
bitwise that of one call over all of them (tests/test_engine.py), for any thread count.
(pocketfft's own threads cut the bundles where they like, which changes the last bits.)
"""
import time

import numpy as np
import rocket_fft  # noqa: F401  (registers numpy.fft for Numba)
from numba import njit, prange
from rocket_fft import c2c, c2r, r2c

from ..config import FFT_THREADED_SIZE, NUMBA_OPTS, PARALLEL_OPTS
from .compliance import offdiag

# Parts of a stage start at multiples of ALIGN transforms: pocketfft bundles 2, 4 or 8 of
# them (SSE2, AVX2, AVX-512 doubles); cuts at multiples of 4 kept the bits in every case
# tried, cuts at any place did not (P = 320).
ALIGN = 8
THREADED_SIZE = FFT_THREADED_SIZE
AXIS1 = np.array([1], dtype=np.int64)


@njit(**NUMBA_OPTS)
def fast_len(target):
    """Smallest 2^a 3^b 5^c >= target (scipy.fft.next_fast_len(target, real=True))."""
    n = max(int(target), 1)
    while True:
        m = n
        for f in (2, 3, 5):
            while m % f == 0:
                m //= f
        if m == 1:
            return n
        n += 1


@njit(**NUMBA_OPTS)
def symbol(cut2, spacing, diag0, P):
    """Real symbol of the kernel on a P x P periodic box: exact linear convolution for
    sources and targets within a (P + 1) // 2 wide box (offsets |a|, |b| <= half - 1).
    Transposed, as ``convolve`` reads it: shape (P // 2 + 1, P), entry [j, i] the value at
    [i, j] of np.fft.rfft2's layout (``spectrum`` turns it back).
    The box holds the kernel at every offset, P / 2 of an even P included: left at zero,
    that line put a checkerboard dip in the symbol (1/r: a minimum of (self_term - 2.905)
    / spacing instead of the lattice's (self_term - 1.6155) / spacing), which refused
    positive definite self terms, loosened the solver's bounds and skewed C^-1."""
    half = (P + 1) // 2
    K = np.zeros((P, P))
    for i in range(P):
        a = i if i < half else (i - P if i > P - half else P // 2)
        for j in range(P):
            b = j if j < half else (j - P if j > P - half else P // 2)
            if a == 0 and b == 0:
                K[i, j] = diag0
            else:
                K[i, j] = offdiag((a * a + b * b) * spacing * spacing, cut2)
    # the kernel is real and even, so its transform is real up to round-off
    return np.ascontiguousarray(np.fft.rfft2(K).real.T)


@njit(**NUMBA_OPTS)
def spectrum(sym):
    """A symbol (``symbol``'s transposed layout) in np.fft.rfft2's layout, P x (P // 2 + 1)."""
    return np.ascontiguousarray(sym.T)


@njit(**NUMBA_OPTS)
def inverse_kernel(sym):
    """The inverse of the kernel with symbol ``sym`` (P x P periodic box), in real space:
    C^-1 as a kernel on the same box (offset 0 at [0, 0])."""
    P = sym.shape[1]
    return np.ascontiguousarray(np.fft.irfft2(1.0 / spectrum(sym), s=(P, P)))


@njit(**NUMBA_OPTS)
def wrapped_symbol(kernel, P, floor):
    """Symbol of ``kernel`` (real space on a larger periodic box, offset 0 at [0, 0])
    truncated to the offsets -P//2 ... P - P//2 - 1 of a P x P periodic box and wrapped
    onto it, floored at ``floor`` > 0 so that the circulant stays positive definite. The
    offsets form a symmetric set modulo P, so an even kernel stays even. In ``symbol``'s
    transposed layout."""
    Q = kernel.shape[0]
    half = P // 2
    K = np.empty((P, P))
    for a in range(-half, P - half):
        for b in range(-half, P - half):
            K[a % P, b % P] = kernel[a % Q, b % Q]
    s = np.ascontiguousarray(np.fft.rfft2(K).real.T)
    for i in range(s.shape[0]):
        for j in range(s.shape[1]):
            s[i, j] = max(s[i, j], floor)
    return s


@njit(**NUMBA_OPTS)
def _cut(n, k, parts):
    """Start of part k of range(n) cut into ``parts`` (k = parts gives n), at a multiple of
    ALIGN, as even as that allows."""
    if k >= parts:
        return n
    return min(n, ((n * k // parts + ALIGN // 2) // ALIGN) * ALIGN)


@njit(**NUMBA_OPTS)
def _rows_forward(src, col, lo, hi):
    """Rows lo:hi of the source, transformed into columns lo:hi of the (transposed) column
    array."""
    if hi > lo:
        r2c(src[lo:hi], col[:, lo:hi].T, AXIS1, True, 1.0, 1)


@njit(**NUMBA_OPTS)
def _columns(col, sym, r0, r1, lo, hi):
    """Columns lo:hi of the spectrum (rows of the transposed array), in place: zero outside
    the source rows r0:r1, forward, times the symbol, back."""
    if hi > lo:
        col[lo:hi, :r0] = 0.0
        col[lo:hi, r1:] = 0.0
        c2c(col[lo:hi], col[lo:hi], AXIS1, True, 1.0, 1)
        for j in range(lo, hi):
            for i in range(col.shape[1]):
                col[j, i] *= sym[j, i]
        c2c(col[lo:hi], col[lo:hi], AXIS1, False, 1.0, 1)


@njit(**NUMBA_OPTS)
def _rows_inverse(col, out, lo, hi):
    if hi > lo:
        P = out.shape[1]
        c2r(col[:, lo:hi].T, out[lo:hi], AXIS1, False, 1.0 / (P * P), 1)


# The three stages twice: whole calls on one thread, and in ``parts`` parts over the Numba
# threads (one per thread; the count is passed in: read in jitted code, it would make the
# kernels uncacheable).
@njit(**NUMBA_OPTS)
def _stages_serial(src, r0, r1, col, out, sym):
    _rows_forward(src, col, r0, r1)
    _columns(col, sym, r0, r1, 0, col.shape[0])
    _rows_inverse(col, out, 0, out.shape[0])


@njit(**PARALLEL_OPTS)
def _stages_parallel(src, r0, r1, col, out, sym, parts):
    for k in prange(parts):
        _rows_forward(src, col, r0 + _cut(r1 - r0, k, parts), r0 + _cut(r1 - r0, k + 1, parts))
    H = col.shape[0]
    for k in prange(parts):
        _columns(col, sym, r0, r1, _cut(H, k, parts), _cut(H, k + 1, parts))
    W = out.shape[0]
    for k in prange(parts):
        _rows_inverse(col, out, _cut(W, k, parts), _cut(W, k + 1, parts))


def threads_pay(w, sym, threads, repeats=5):
    """Whether spreading the stages over ``threads`` Numba threads is faster, timed now on
    a w x w box with the symbol ``sym`` (``repeats`` calls each way, a few ms). The bits
    are the same either way, so the choice is free; it matters on a busy machine, where a
    barrier can wait a scheduler slice (`python -m bench.run_bench --only fft` with two
    other jobs running: one convolution at P = 480 took 24 ms threaded against 2.4 ms on
    one thread)."""
    P = sym.shape[1]
    if threads < 2 or P < THREADED_SIZE:
        return False
    src, col, out = buffers(w, P)
    src[:, :w] = np.random.default_rng(0).random((w, w))
    times = {1: [], threads: []}
    for k in range(repeats + 1):          # round 0 warms up the thread pool
        for parts, kept in times.items():
            t = time.perf_counter()
            convolve(src, 0, w, col, out, sym, parts)
            if k:
                kept.append(time.perf_counter() - t)
    # medians: a lucky threaded call must not hide the barriers' waits under load
    return float(np.median(times[threads])) < 0.9 * float(np.median(times[1]))


@njit(**NUMBA_OPTS)
def buffers(W, P):
    """Zeroed work arrays of a convolution of a W x W box on the P x P periodic box: the
    sources (W x P: columns from W on stay zero), the spectra (transposed: (P // 2 + 1) x P)
    and the result."""
    return (np.zeros((W, P)), np.zeros((P // 2 + 1, P), dtype=np.complex128), np.zeros((W, P)))


@njit(**NUMBA_OPTS)
def convolve(src, r0, r1, col, out, sym, threads):
    """out[:W, :W] = (K * src) on a W x W box: src (W x P) zero outside rows r0:r1 and
    columns from W on; col and out as made by ``buffers``. Cut into ``threads`` parts over
    the Numba threads from THREADED_SIZE if threads > 1 (decided in Python by threads_pay);
    the bits are the same either way."""
    P = sym.shape[1]
    if threads > 1 and P >= THREADED_SIZE:
        _stages_parallel(src, r0, r1, col, out, sym, threads)
    else:
        _stages_serial(src, r0, r1, col, out, sym)


@njit(**NUMBA_OPTS)
def box_apply(sym, src, vals, tgt, n, i0, j0, w, threads):
    """u at the flat grid indices tgt of C applied to vals at src, on the w x w box at
    (i0, j0) that holds both (P = sym.shape[1] >= 2 w - 1)."""
    P = sym.shape[1]
    box, col, out = buffers(w, P)
    r0 = w
    r1 = 0
    for k in range(src.size):
        i = src[k] // n - i0
        box[i, src[k] % n - j0] = vals[k]
        r0 = min(r0, i)
        r1 = max(r1, i + 1)
    res = np.zeros(tgt.size)
    if r1 <= r0:
        return res
    convolve(box, r0, r1, col, out, sym, threads)
    for k in range(tgt.size):
        res[k] = out[tgt[k] // n - i0, tgt[k] % n - j0]
    return res
