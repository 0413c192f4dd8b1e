"""Direct O(N_src * N_tgt) compliance sums, parallel over targets.

Kernel codes: 0 Boussinesq 1/r; 1 local (diagonal only); 2 Boussinesq truncated at
``cutoff``. The diagonal C_ii comes per spring in ``diag``. Each target's sum runs over
the sources in a fixed order, so results do not depend on the thread count.
"""
import numpy as np
from numba import njit, prange

from ..config import PARALLEL_OPTS

BOUSSINESQ, LOCAL, NEIGHBORS = 0, 1, 2


@njit(**PARALLEL_OPTS)
def direct_sum(x, y, diag, src, f_src, tgt, kind, cutoff):
    """u[t] = sum_s C(tgt[t], src[s]) f_src[s]."""
    nt = tgt.size
    ns = src.size
    out = np.zeros(nt)
    cut2 = cutoff * cutoff * (1.0 + 1e-12)
    for t in prange(nt):
        i = tgt[t]
        xi = x[i]
        yi = y[i]
        acc = 0.0
        for s in range(ns):
            j = src[s]
            if j == i:
                acc += diag[i] * f_src[s]
            elif kind != LOCAL:
                dx = x[j] - xi
                dy = y[j] - yi
                r2 = dx * dx + dy * dy
                if kind == BOUSSINESQ or r2 <= cut2:
                    acc += f_src[s] / np.sqrt(r2)
        out[t] = acc
    return out
