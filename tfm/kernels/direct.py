"""Direct O(N_src * N_tgt) compliance sums, parallel over targets.

Kernel codes and the truncation rule: tfm.kernels.compliance. The diagonal C_ii comes per spring in ``diag``. Each target's sum runs over
the sources in a fixed order, so results do not depend on the thread count. The inner
loop may be vectorized (fastmath 'reassoc'): that fixes a summation order per compiled
binary, the same for every thread count, and changes sums only at round-off level.
"""
import numpy as np
from numba import njit, prange

from ..config import NUMBA_OPTS
from .compliance import BOUSSINESQ, LOCAL, NEIGHBORS, cutoff_squared  # noqa: F401 (re-exported)

_VEC = dict(NUMBA_OPTS, parallel=True, fastmath={"reassoc", "contract"})


@njit(**_VEC)
def _pair_sums(xs, ys, fs, xt, yt, cut2):
    """sum_s f_s / r_ts over sources at r > 0 (and r^2 <= cut2)."""
    nt = xt.size
    ns = xs.size
    out = np.zeros(nt)
    for t in prange(nt):
        xi = xt[t]
        yi = yt[t]
        acc = 0.0
        for s in range(ns):
            dx = xs[s] - xi
            dy = ys[s] - yi
            r2 = dx * dx + dy * dy
            keep = (r2 > 0.0) and (r2 <= cut2)
            acc += fs[s] / np.sqrt(r2) if keep else 0.0
        out[t] = acc
    return out


@njit(**NUMBA_OPTS)
def _add_self(out, diag, src, f_src, tgt, n):
    where = np.full(n, -1)
    for s in range(src.size):
        where[src[s]] = s
    for t in range(tgt.size):
        s = where[tgt[t]]
        if s >= 0:
            out[t] += diag[tgt[t]] * f_src[s]


def direct_sum(x, y, diag, src, f_src, tgt, kind, cutoff):
    """u[t] = sum_s C(tgt[t], src[s]) f_src[s]."""
    f_src = np.ascontiguousarray(f_src, dtype=np.float64)
    if kind == LOCAL:
        out = np.zeros(tgt.size)
    else:
        out = _pair_sums(x[src], y[src], f_src, x[tgt], y[tgt], cutoff_squared(kind, cutoff))
    _add_self(out, diag, src, f_src, tgt, x.size)
    return out
