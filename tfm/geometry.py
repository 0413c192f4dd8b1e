"""Spring layouts and the undeformed surface heights x0.

Sign convention (docs/physics.md, §3): the apex is at height 0 and the surface lies below
it, x0 <= 0; the rigid flat is at height d, and indentation is delta = -d.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .params import Params


@dataclass(frozen=True)
class Layout:
    """Springs as flat arrays. ``shape`` is (n, n) for the square grid, else None."""

    x: np.ndarray
    y: np.ndarray
    area: np.ndarray          # tributary area of each spring
    spacing: float
    shape: tuple[int, int] | None
    edge: np.ndarray          # True for springs on the outer ring of the region

    @property
    def n(self) -> int:
        return self.x.size


def _edge_mask(x, y, half_width, spacing):
    return np.maximum(np.abs(x), np.abs(y)) > half_width - 1.5 * spacing


def square_grid(spacing: float, half_width: float) -> Layout:
    m = int(math.ceil(half_width / spacing - 1e-9))
    coords = np.arange(-m, m + 1) * spacing
    X, Y = np.meshgrid(coords, coords, indexing="ij")
    x, y = X.ravel().copy(), Y.ravel().copy()
    area = np.full(x.size, spacing * spacing)
    hw = m * spacing
    return Layout(x, y, area, spacing, (2 * m + 1, 2 * m + 1), _edge_mask(x, y, hw + spacing, spacing))


def row_pitch(spacing: float) -> float:
    """Distance between the rows of the hexagonal (triangular) lattice."""
    return spacing * math.sqrt(3.0) / 2.0


def hexagonal_grid(spacing: float, half_width: float) -> Layout:
    """Triangular lattice with nearest-neighbour distance ``spacing``.

    Each spring's tributary (Voronoi) area is sqrt(3)/2 spacing^2."""
    dy = row_pitch(spacing)
    rows = int(math.ceil(half_width / dy))
    cols = int(math.ceil(half_width / spacing)) + 1
    xs, ys = [], []
    for r in range(-rows, rows + 1):
        shift = 0.5 * spacing if r % 2 else 0.0
        xr = np.arange(-cols, cols + 1) * spacing + shift
        xr = xr[np.abs(xr) <= half_width + 1e-12]
        xs.append(xr)
        ys.append(np.full(xr.size, r * dy))
    x, y = np.concatenate(xs), np.concatenate(ys)
    area = np.full(x.size, spacing * dy)
    return Layout(x, y, area, spacing, None, _edge_mask(x, y, half_width, spacing))


def jittered_grid(spacing: float, half_width: float, jitter: float, seed: int) -> Layout:
    """Square grid with uniform random offsets of up to ``jitter`` spacings per axis.

    The tributary area stays spacing^2 per spring (each spring still owns one cell of
    the underlying grid); the threshold and self term therefore match the square grid."""
    base = square_grid(spacing, half_width)
    rng = np.random.default_rng(seed)
    dx = rng.uniform(-jitter, jitter, size=(2, base.n)) * spacing
    x, y = base.x + dx[0], base.y + dx[1]
    return Layout(x, y, base.area.copy(), spacing, None, base.edge.copy())


def layout_reach(p: Params, half_width: float) -> float:
    """How far from the centre the springs of ``p``'s layout built for ``half_width`` can
    lie along x or y (the grids above: square rows stop at ceil(hw / spacing) spacings,
    hexagonal rows at ceil(hw / dy) dy, jittered springs up to jitter spacings further)."""
    if p.layout == "hexagonal":
        dy = row_pitch(p.spacing)
        return max(half_width, math.ceil(half_width / dy) * dy)
    reach = math.ceil(half_width / p.spacing - 1e-9) * p.spacing
    return reach + (p.jitter * p.spacing if p.layout == "jittered" else 0.0)


def largest_half_width(p: Params, reach: float) -> float:
    """The largest half-width on the layout's own steps whose springs stay within
    ``reach`` of the centre (``layout_reach`` <= reach), or 0."""
    if p.layout == "hexagonal":
        dy = row_pitch(p.spacing)
        k = math.floor(reach / dy + 1e-9)
        hw = k * dy
        while hw > 0 and math.ceil(hw / dy) > k:     # k dy / dy may round above k
            hw = math.nextafter(hw, 0.0)
        return max(hw, 0.0)
    if p.layout == "jittered":
        reach -= p.jitter * p.spacing
    return max(math.floor(reach / p.spacing + 1e-9), 0) * p.spacing


def make_layout(p: Params) -> Layout:
    hw = p.half_width
    if p.layout == "square":
        return square_grid(p.spacing, hw)
    if p.layout == "hexagonal":
        return hexagonal_grid(p.spacing, hw)
    return jittered_grid(p.spacing, hw, p.jitter, p.seed)


def heights(p: Params, layout: Layout) -> np.ndarray:
    """Undeformed spring lengths x0 (surface height), apex at 0.

    The body's shape plus its roughness (``tfm.surfaces``), or a height map; a rough
    surface or a map is shifted so that its highest spring is at 0, so the flat first
    touches at d = 0 and the indentation counts from first contact."""
    if p.shape == "height_map":
        from .surfaces import map_heights
        x0 = map_heights(p, layout.x, layout.y)
    else:
        x0 = _shape_heights(p, layout)
    if p.rms_slope > 0 or p.rms_height > 0:
        from .surfaces import roughness
        x0 = x0 + roughness(p, layout.x, layout.y)
    if p.shape == "height_map" or p.rms_slope > 0 or p.rms_height > 0:
        x0 = x0 - x0[np.isfinite(x0)].max()
    return x0


def _shape_heights(p: Params, layout: Layout) -> np.ndarray:
    r2 = layout.x ** 2 + layout.y ** 2
    R = p.radius
    if p.shape == "paraboloid":
        return -r2 / (2.0 * R)
    if p.shape == "flat_punch":
        # a rigid-ended cylinder of radius R: flat face at 0, nothing outside r = R
        return np.where(r2 <= R * R, 0.0, -np.inf)
    # exact spherical cap; below the equator there is no surface facing the flat. Not as
    # R - sqrt(R^2 - r^2), which cancels for R >> r (at R = 1e7 it flattened the apex)
    with np.errstate(invalid="ignore"):
        return np.where(r2 <= R * R, -r2 / (R + np.sqrt(np.maximum(R * R - r2, 0.0))), -np.inf)
