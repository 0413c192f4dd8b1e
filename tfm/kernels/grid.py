"""Jitted helpers on the square grid: preconditioner stencil and deterministic reductions."""
import numpy as np
from numba import njit, prange

from ..config import PARALLEL_OPTS, NUMBA_OPTS, REDUCTION_BLOCK


@njit(**PARALLEL_OPTS)
def stencil_apply(ii, jj, vals, n, stencil):
    """out[k] = sum over the stencil of stencil[a, b] * v at (ii[k]+a-m, jj[k]+b-m).

    ``vals`` live on the points (ii, jj) (the contact set); other grid points count as 0.
    """
    grid = np.zeros((n, n))
    for k in range(ii.size):
        grid[ii[k], jj[k]] = vals[k]
    m = (stencil.shape[0] - 1) // 2
    out = np.empty(ii.size)
    for k in prange(ii.size):
        i0 = ii[k]
        j0 = jj[k]
        acc = 0.0
        for a in range(-m, m + 1):
            i = i0 + a
            if i < 0 or i >= n:
                continue
            for b in range(-m, m + 1):
                j = j0 + b
                if j < 0 or j >= n:
                    continue
                acc += stencil[a + m, b + m] * grid[i, j]
        out[k] = acc
    return out


@njit(**PARALLEL_OPTS)
def blocked_dot(a, b):
    """Dot product summed in fixed blocks: same bits for any thread count."""
    n = a.size
    nb = (n + REDUCTION_BLOCK - 1) // REDUCTION_BLOCK
    part = np.zeros(nb)
    for k in prange(nb):
        lo = k * REDUCTION_BLOCK
        hi = min(n, lo + REDUCTION_BLOCK)
        acc = 0.0
        for i in range(lo, hi):
            acc += a[i] * b[i]
        part[k] = acc
    total = 0.0
    for k in range(nb):
        total += part[k]
    return total


@njit(**NUMBA_OPTS)
def scatter_grid(buf, n, idx, vals):
    """Write vals at flat indices idx of an n x n block at the corner of a zeroed buffer."""
    for k in range(idx.size):
        f = idx[k]
        buf[f // n, f % n] = vals[k]


@njit(**NUMBA_OPTS)
def clear_grid(buf, n, idx):
    for k in range(idx.size):
        f = idx[k]
        buf[f // n, f % n] = 0.0
