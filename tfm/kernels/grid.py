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


@njit(**NUMBA_OPTS)
def abs_max(a):
    """The largest |a_i| (0.0 for an empty a). Four interleaved chains: one chain waits
    on every comparison (14 us for the 25,281 springs of a 1/256 grid, against 6 us on
    the 2-core VM, 2026-11-29); max is exact, so the value is the same."""
    m0 = m1 = m2 = m3 = 0.0
    n4 = a.size - a.size % 4
    for i in range(0, n4, 4):
        m0 = max(m0, abs(a[i]))
        m1 = max(m1, abs(a[i + 1]))
        m2 = max(m2, abs(a[i + 2]))
        m3 = max(m3, abs(a[i + 3]))
    for i in range(n4, a.size):
        m0 = max(m0, abs(a[i]))
    return max(max(m0, m1), max(m2, m3))


# Lanes of blocked_dot: 16 independent partial sums, which the compiler keeps in two
# vector registers. One running sum waits for each addition before the next (6.6 us for
# 8000 elements on the 2-core VM); 16 lanes take 2.5 us (2026-11-29; 8 lanes in scalar
# registers, 4.3 us). REDUCTION_BLOCK is a multiple of DOT_LANES.
DOT_LANES = 16


@njit(**NUMBA_OPTS)
def blocked_dot(a, b):
    """Dot product in fixed blocks of REDUCTION_BLOCK elements, each summed in DOT_LANES
    lanes (element i of a block in lane i % DOT_LANES) that are then added pairwise in a
    fixed order, and the blocks added in order: the same bits for any thread count (a
    parallel version would add the same partials)."""
    n = a.size
    total = 0.0
    acc = np.empty(DOT_LANES)
    for lo in range(0, n, REDUCTION_BLOCK):
        hi = min(n, lo + REDUCTION_BLOCK)
        acc[:] = 0.0
        i = lo
        while i + DOT_LANES <= hi:
            for j in range(DOT_LANES):
                acc[j] += a[i + j] * b[i + j]
            i += DOT_LANES
        for j in range(hi - i):
            acc[j] += a[i + j] * b[i + j]
        width = DOT_LANES // 2
        while width > 0:
            for j in range(width):
                acc[j] += acc[j + width]
            width //= 2
        total += acc[0]
    return total


@njit(**NUMBA_OPTS)
def index_bounds(n, idx):
    """First and last row and column (i0, i1, j0, j1) of flat indices on an n x n grid."""
    i0 = n
    j0 = n
    i1 = -1
    j1 = -1
    i = -1
    start = -n                  # the current row i holds the flat indices start ... start + n - 1
    for k in range(idx.size):
        v = idx[k]
        if v < start or v >= start + n:
            i = v // n          # one division per row for a sorted idx (per spring cost 10 % of restrict)
            start = i * n
        j = v - start
        i0 = min(i0, i)
        i1 = max(i1, i)
        j0 = min(j0, j)
        j1 = max(j1, j)
    return i0, i1, j0, j1


@njit(**NUMBA_OPTS)
def index_box(n, idx):
    """Bounding box of flat indices on an n x n grid: top-left (i0, j0), square width w,
    row count h."""
    i0, i1, j0, j1 = index_bounds(n, idx)
    return i0, j0, max(i1 - i0, j1 - j0) + 1, i1 - i0 + 1


@njit(**NUMBA_OPTS)
def grid_reach(n, idx):
    """The largest offset, along either axis, from a spring of idx to any point of the
    n x n grid: the farthest grid edge from idx's bounding box."""
    i0, i1, j0, j1 = index_bounds(n, idx)
    return max(max(i1, n - 1 - i0), max(j1, n - 1 - j0))
