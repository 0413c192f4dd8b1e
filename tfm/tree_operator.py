"""The compliance applied by a Barnes-Hut tree: fast sums for any spring layout.

Same call as the FFT and direct operators: ``apply(src, f_src, tgt=None)`` returns
u_t = sum_s C_ts f_s at the target springs (all springs if ``tgt`` is None).

What each kernel type uses, and why:

* ``boussinesq`` (1/r everywhere): the quadtree of ``tfm.kernels.tree``, built over
  the springs that carry force. The self term C_ii is exact (it is applied in the
  near field, which is always summed directly).
* ``local`` (diagonal only): u_i = C_ii F_i; no tree, no sum.
* ``neighbors`` (1/r truncated at a few spacings): a sparse matrix, i.e. a neighbour
  list (CSR) built once from the layout. A tree would only spend time proving that
  far nodes contribute nothing.

Rebuilding is cheap by design. The Morton order of all springs is computed once
(springs never move); a new source set is put in that order by one linear scan, the
nodes are cut from the sorted keys, and only the moments depend on the forces. The
source tree and the target groups are cached by their index arrays, so the conjugate
gradient iterations of one contact solve (same contact set, new forces) pay for the
moments and the walk only.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .kernels.compliance import BOUSSINESQ, LOCAL, NEIGHBORS
from .kernels.ops import SparseData, TreeData, start_threads
from .kernels.tree import (MORTON_BITS, build_nodes, csr_apply, evaluate, morton_keys,
                           node_boxes, node_geometry, node_moments, subset_order)

# Defaults chosen from the accuracy/speed table (bench/bench_tree.py, README).
TREE_ORDER = 4          # expansion order about the node's geometric centre (hexadecapole)
LEAF_SIZE = 16          # max sources in a leaf (the near field is summed exactly)
GROUP_SIZE = 64         # max targets sharing one tree walk (8 AVX-512 vectors)


class SourceTree(NamedTuple):
    perm: np.ndarray        # positions into src, Morton order
    idx: np.ndarray         # spring index of each sorted source
    px: np.ndarray
    py: np.ndarray
    start: np.ndarray
    end: np.ndarray
    skip: np.ndarray
    leaf: np.ndarray
    geo: np.ndarray         # cx, cy, size, radius per node


class TargetGroups(NamedTuple):
    perm: np.ndarray        # positions into tgt, Morton order
    tx: np.ndarray
    ty: np.ndarray
    tidx: np.ndarray
    tdiag: np.ndarray
    gstart: np.ndarray
    gend: np.ndarray
    gbox: np.ndarray        # xmin, xmax, ymin, ymax per group


def tree_error_bound(theta: float, order: int = TREE_ORDER) -> float:
    """eps(theta): |u_tree - u_exact|_t <= eps * sum_{s != t} |f_s| / r_ts at every target."""
    q = min(theta / np.sqrt(2.0), 0.75)
    return q ** (order + 1) * (1.0 + q) / (1.0 - q)


def neighbour_csr(x, y, cutoff):
    """Springs within ``cutoff`` of each spring (the direct sum's test, r^2 <= cutoff^2
    (1 + 1e-12)), as CSR rows sorted by column, with weights 1/r."""
    from scipy.spatial import cKDTree

    pts = np.column_stack([x, y])
    pairs = cKDTree(pts).query_pairs(r=cutoff * (1.0 + 1e-9), output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    r2 = (x[i] - x[j]) ** 2 + (y[i] - y[j]) ** 2
    keep = r2 <= cutoff * cutoff * (1.0 + 1e-12)
    i, j, r2 = i[keep], j[keep], r2[keep]
    rows = np.concatenate([i, j])
    cols = np.concatenate([j, i])
    w = np.concatenate([1.0 / np.sqrt(r2)] * 2)
    order = np.lexsort((cols, rows))
    rows, cols, w = rows[order], cols[order], w[order]
    indptr = np.zeros(x.size + 1, dtype=np.int64)
    np.add.at(indptr, rows + 1, 1)
    return np.cumsum(indptr), cols.astype(np.int64), w


class TreeOperator:
    """Barnes-Hut sums for the Boussinesq kernel; exact sparse sums for the others."""

    name = "tree"

    def __init__(self, spec, layout, theta: float = 0.5, order: int = TREE_ORDER,
                 leaf_size: int = LEAF_SIZE, group_size: int = GROUP_SIZE):
        if not 0.0 < theta <= 1.5:
            raise ValueError(f"theta: must be in (0, 1.5], got {theta!r}")
        if order not in (1, 2, 3, 4):
            raise ValueError(f"order: must be 1, 2, 3 or 4, got {order!r}")
        self.spec = spec
        self.kind = spec.kind
        self.theta = float(theta)
        self.order = int(order)
        self.leaf_size = int(leaf_size)
        self.group_size = int(group_size)
        self.x = np.ascontiguousarray(layout.x, dtype=float)
        self.y = np.ascontiguousarray(layout.y, dtype=float)
        self.diag = np.ascontiguousarray(spec.diag, dtype=float)
        self.n = self.x.size
        self.all = np.arange(self.n, dtype=np.int64)
        if self.kind == NEIGHBORS:
            self.csr = neighbour_csr(self.x, self.y, spec.cutoff)
        elif self.kind == BOUSSINESQ:
            # the root box: the bounding square of the layout, fixed for the run
            x0, y0 = self.x.min(), self.y.min()
            side = max(self.x.max() - x0, self.y.max() - y0, 1e-300) * (1.0 + 1e-9)
            self.keys = morton_keys(self.x, self.y, x0, y0, side, MORTON_BITS)
            self.order_all = np.argsort(self.keys, kind="stable").astype(np.int64)
            self.keys_sorted = self.keys[self.order_all]
        self._src = None
        self._src_tree = None
        self._tgt = None
        self._tgt_groups = None
        self._all_groups = None

    # ---------------------------------------------------------------- building
    def _sorted(self, sub, what):
        perm = subset_order(self.order_all, sub, self.n)
        if perm.size != sub.size:
            raise ValueError(f"{what}: spring indices must be distinct")
        return perm

    def build_sources(self, src) -> SourceTree:
        perm = self._sorted(src, "src")
        idx = src[perm]
        keys = self.keys[idx]
        start, end, skip, parent, leaf = build_nodes(keys, self.leaf_size, MORTON_BITS)
        px, py = self.x[idx], self.y[idx]
        geo = node_geometry(node_boxes(start, end, parent, leaf, px, py))
        return SourceTree(perm, idx, px, py, start, end, skip, leaf, geo)

    def build_targets(self, tgt) -> TargetGroups:
        if tgt is None:                  # position in 'all springs' is the spring index
            perm = tidx = self.order_all
        else:
            perm = self._sorted(tgt, "tgt")
            tidx = tgt[perm]
        keys = self.keys[tidx]
        start, end, skip, parent, leaf = build_nodes(keys, self.group_size, MORTON_BITS)
        tx, ty = self.x[tidx], self.y[tidx]
        box = node_boxes(start, end, parent, leaf, tx, ty)
        return TargetGroups(perm, tx, ty, tidx, self.diag[tidx], start[leaf].copy(),
                            end[leaf].copy(), np.ascontiguousarray(box[leaf]))

    def _source_tree(self, src):
        if self._src is None or not (src is self._src or np.array_equal(src, self._src)):
            self._src_tree = self.build_sources(src)
            self._src = src.copy()
        return self._src_tree

    def _targets(self, tgt):
        if tgt is None:
            if self._all_groups is None:
                self._all_groups = self.build_targets(None)
            return self._all_groups
        if self._tgt is None or not (tgt is self._tgt or np.array_equal(tgt, self._tgt)):
            self._tgt_groups = self.build_targets(tgt)
            self._tgt = tgt.copy()
        return self._tgt_groups

    def compiled(self):
        """The operator's data for the compiled loop (tfm.kernels.ops): the tree's for 1/r,
        the neighbour list (empty rows for the local kernel) otherwise."""
        start_threads()
        if self.kind == BOUSSINESQ:
            g = self._targets(None)
            return TreeData(self.x, self.y, self.diag, self.keys, self.order_all, self.theta, self.order,
                            self.leaf_size, self.group_size, g.perm, g.tx, g.ty, g.tidx, g.tdiag, g.gstart,
                            g.gend, g.gbox)
        if self.kind == NEIGHBORS:
            indptr, indices, weights = self.csr
        else:
            indptr, indices, weights = np.zeros(self.n + 1, dtype=np.int64), np.zeros(0, dtype=np.int64), np.zeros(0)
        return SparseData(indptr, indices, weights, self.diag)

    # ---------------------------------------------------------------- applying
    def evaluate(self, tree: SourceTree, groups: TargetGroups, f_src) -> np.ndarray:
        """u at the targets of ``groups`` (in the caller's order) from forces f_src."""
        pf = np.ascontiguousarray(f_src[tree.perm])
        mom = node_moments(tree.start, tree.end, tree.skip, tree.leaf, tree.geo,
                           tree.px, tree.py, pf, self.order)
        ffull = np.zeros(self.n)
        ffull[tree.idx] = pf
        tself = groups.tdiag * ffull[groups.tidx]       # the exact self term C_tt F_t
        u = evaluate(tree.start, tree.end, tree.skip, tree.leaf, tree.geo, mom, self.order,
                     self.theta, tree.px, tree.py, pf, groups.gstart, groups.gend,
                     groups.gbox, groups.tx, groups.ty, tself)
        out = np.empty(u.size)
        out[groups.perm] = u
        return out

    def apply(self, src, f_src, tgt=None):
        src = np.ascontiguousarray(src, dtype=np.int64)
        f = np.ascontiguousarray(f_src, dtype=float)
        if tgt is not None:
            tgt = np.ascontiguousarray(tgt, dtype=np.int64)
        nt = self.n if tgt is None else tgt.size
        if src.size == 0 or nt == 0:
            return np.zeros(nt)
        if self.kind == BOUSSINESQ:
            return self.evaluate(self._source_tree(src), self._targets(tgt), f)
        ffull = np.zeros(self.n)
        ffull[src] = f
        t = self.all if tgt is None else tgt
        if self.kind == LOCAL:
            return self.diag[t] * ffull[t]
        indptr, indices, weights = self.csr
        return csr_apply(indptr, indices, weights, self.diag, ffull, t)
