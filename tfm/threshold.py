"""The tensile threshold F_th of each spring: the one home of the formula.

Paper (Sec. 2): a spring in contact snaps when its tensile force exceeds
F_th = K_th A^alpha, with A the spring's tributary area; or an explicit F_th is given.
The tributary area depends on the layout (Delta^2 on the square and jittered grids,
sqrt(3)/2 Delta^2 on the hexagonal one), so the mean threshold does too.
"""
from __future__ import annotations

import math

import numpy as np


def nominal_area(p) -> float:
    """Tributary area of one spring of the layout (the same for every spring)."""
    if p.layout == "hexagonal":
        return math.sqrt(3.0) / 2.0 * p.spacing ** 2
    return p.spacing ** 2


def mean_threshold(p) -> float:
    """F_th of a spring of the layout's nominal area (the summary's ``f_th``)."""
    if p.f_th is not None:
        return float(p.f_th)
    return float(p.k_th) * nominal_area(p) ** p.alpha


def threshold_forces(p, area: np.ndarray) -> np.ndarray:
    """F_th per spring, from each spring's own tributary area."""
    if p.f_th is not None:
        return np.full(area.size, float(p.f_th))
    return float(p.k_th) * np.asarray(area, dtype=float) ** p.alpha
