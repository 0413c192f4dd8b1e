"""Compiled zero-padded FFT convolution with the compliance, on a square box of the grid.

rocket-fft registers scipy.fft inside @njit, so the contact solve can call pocketfft
without returning to Python. A linear convolution of a W x W box needs a periodic box
P >= 2 W - 1 (no images); the transform is pruned: only the rows that hold sources are
transformed along the rows, and only the W wanted rows are transformed back.

Threads: the 1-D transforms are cut into fixed chunks of CHUNK rows or columns, and each
chunk is one single-threaded pocketfft call. Which thread runs a chunk changes nothing,
so the result is bitwise the same for any thread count (pocketfft's own workers= would
regroup the transforms into SIMD bundles by thread, which changes the last bits).
"""
import time

import numpy as np
import rocket_fft  # noqa: F401  (registers scipy.fft for Numba)
import scipy.fft as sfft
from numba import njit, prange

from ..config import FFT_THREADED_SIZE, NUMBA_OPTS, PARALLEL_OPTS
from .compliance import offdiag

CHUNK = 16               # 1-D transforms per pocketfft call (fixed: see the docstring)
CHUNKED_SIZE = 192       # P from which the transforms go in chunks (cache-friendly columns)
THREADED_SIZE = FFT_THREADED_SIZE


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
    sources and targets within a (P + 1) // 2 wide box (offsets |a|, |b| <= half - 1)."""
    half = (P + 1) // 2
    K = np.zeros((P, P))
    for i in range(P):
        a = i if i < half else (i - P if i > P - half else 0)
        if a == 0 and i != 0:
            continue
        for j in range(P):
            b = j if j < half else (j - P if j > P - half else 0)
            if b == 0 and j != 0:
                continue
            if a == 0 and b == 0:
                K[i, j] = diag0
            else:
                K[i, j] = offdiag((a * a + b * b) * spacing * spacing, cut2)
    # the kernel is real and even, so its transform is real up to round-off
    return np.ascontiguousarray(sfft.rfft2(K).real)


@njit(**NUMBA_OPTS)
def _rows_forward(src, r0, r1, spec, P, c, chunk):
    lo = r0 + c * chunk
    hi = min(r1, lo + chunk)
    spec[lo:hi] = sfft.rfft(src[lo:hi], n=P, axis=1)


@njit(**NUMBA_OPTS)
def _columns(spec, W, sym, c, chunk):
    lo = c * chunk
    hi = min(spec.shape[1], lo + chunk)
    col = sfft.fft(spec[:W, lo:hi], n=sym.shape[0], axis=0)
    col *= sym[:, lo:hi]
    spec[:W, lo:hi] = sfft.ifft(col, axis=0)[:W]


@njit(**NUMBA_OPTS)
def _rows_inverse(spec, out, P, c, chunk):
    lo = c * chunk
    hi = min(out.shape[0], lo + chunk)
    out[lo:hi] = sfft.irfft(spec[lo:hi], n=P, axis=1)


# The same three stages twice: serial (no thread start-up for small boxes) and parallel.
# ``chunk`` is CHUNK in the engine (an argument so that the bench can compare lengths).
@njit(**NUMBA_OPTS)
def _stages_serial(src, r0, r1, spec, out, P, sym, chunk):
    W = out.shape[0]
    for c in range((r1 - r0 + chunk - 1) // chunk):
        _rows_forward(src, r0, r1, spec, P, c, chunk)
    for c in range((spec.shape[1] + chunk - 1) // chunk):
        _columns(spec, W, sym, c, chunk)
    for c in range((W + chunk - 1) // chunk):
        _rows_inverse(spec, out, P, c, chunk)


@njit(**PARALLEL_OPTS)
def _stages_parallel(src, r0, r1, spec, out, P, sym, chunk):
    W = out.shape[0]
    for c in prange((r1 - r0 + chunk - 1) // chunk):
        _rows_forward(src, r0, r1, spec, P, c, chunk)
    for c in prange((spec.shape[1] + chunk - 1) // chunk):
        _columns(spec, W, sym, c, chunk)
    for c in prange((W + chunk - 1) // chunk):
        _rows_inverse(spec, out, P, c, chunk)


def threads_pay(w, sym, threads, repeats=5):
    """Whether spreading the chunks over ``threads`` Numba threads is faster, timed now on
    a w x w box with the symbol ``sym`` (``repeats`` calls each way, a few ms). The bits
    are the same either way, so the choice is free; it matters on a busy machine, where a barrier can wait a scheduler
    slice (`python -m bench.run_bench --only fft` with two other jobs running: one
    convolution at P = 480 took 24 ms threaded against 2.4 ms on one thread)."""
    P = sym.shape[0]
    if threads < 2 or P < THREADED_SIZE:
        return False
    src = np.random.default_rng(0).random((w, w))
    spec = np.zeros((w, P // 2 + 1), dtype=np.complex128)
    out = np.empty((w, P))
    times = {_stages_serial: [], _stages_parallel: []}
    for k in range(repeats + 1):          # round 0 warms up the thread pool
        for stages, kept in times.items():
            t = time.perf_counter()
            stages(src, 0, w, spec, out, P, sym, CHUNK)
            if k:
                kept.append(time.perf_counter() - t)
    # medians: a lucky threaded call must not hide the barriers' waits under load
    return float(np.median(times[_stages_parallel])) < 0.9 * float(np.median(times[_stages_serial]))


@njit(**NUMBA_OPTS)
def convolve(src, r0, r1, spec, out, sym, threaded):
    """out[:W, :W] = (K * src) on a W x W box, src zero outside rows r0:r1.

    ``spec`` (W x (P//2 + 1) complex) and ``out`` (W x P) are work buffers. Small boxes
    take whole-array transforms (fewer calls; bench: faster below P ~ 200), large ones the
    fixed chunks (cache-friendly columns), spread over the Numba threads from THREADED_SIZE
    if ``threaded`` (decided in Python by threads_pay: a thread count read in jitted code
    would make the kernels uncacheable). Whether chunks are used depends on P only, and
    chunks give the same bits serial or threaded."""
    P = sym.shape[0]
    if P >= CHUNKED_SIZE:
        spec[:r0] = 0.0
        spec[r1:] = 0.0
        if threaded and P >= THREADED_SIZE:
            _stages_parallel(src, r0, r1, spec, out, P, sym, CHUNK)
        else:
            _stages_serial(src, r0, r1, spec, out, P, sym, CHUNK)
        return
    W = out.shape[0]
    a = sfft.rfft(src[r0:r1], n=P, axis=1)
    col = np.zeros((P, P // 2 + 1), dtype=a.dtype)
    col[r0:r1] = a
    col = sfft.fft(col, axis=0)
    col *= sym
    out[:] = sfft.irfft(sfft.ifft(col, axis=0)[:W], n=P, axis=1)


@njit(**NUMBA_OPTS)
def box_apply(sym, src, vals, tgt, n, i0, j0, w, threaded):
    """u at the flat grid indices tgt of C applied to vals at src, on the w x w box at
    (i0, j0) that holds both (P = sym.shape[0] >= 2 w - 1)."""
    P = sym.shape[0]
    box = np.zeros((w, w))
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
    spec = np.empty((w, P // 2 + 1), dtype=np.complex128)
    out = np.empty((w, P))
    convolve(box, r0, r1, spec, out, sym, threaded)
    for k in range(tgt.size):
        res[k] = out[tgt[k] // n - i0, tgt[k] % n - j0]
    return res
