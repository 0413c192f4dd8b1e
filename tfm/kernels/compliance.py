"""The compliance kernel C(r): the one home of 1/r and of the kernel kinds (paper, Eq. 4).

Kind codes: BOUSSINESQ 1/r; LOCAL no off-diagonal term (Winkler); NEIGHBORS 1/r truncated
at ``cutoff``. The truncation test is r^2 <= cut2 with cut2 = cutoff^2 (1 + 1e-12), so a
neighbour exactly at the cutoff is kept whatever the round-off of its coordinates.
The diagonal C_ii (Love's self term, or c_w/A) comes per spring from tfm.operators.
"""
import math

import numpy as np
from numba import njit

from ..config import NUMBA_OPTS

BOUSSINESQ, LOCAL, NEIGHBORS = 0, 1, 2


def cutoff_squared(kind: int, cutoff: float) -> float:
    """cut2 of the kind: infinite for 1/r, 0 for the local kernel."""
    if kind == BOUSSINESQ:
        return math.inf
    if kind == LOCAL:
        return 0.0
    return cutoff * cutoff * (1.0 + 1e-12)


@njit(**NUMBA_OPTS)
def offdiag(r2, cut2):
    """C at squared distance r2 > 0 (0 beyond the cutoff; cut2 = 0 for the local kernel)."""
    return 1.0 / np.sqrt(r2) if r2 <= cut2 else 0.0
