"""The compliance C and the preconditioner M, restricted to a contact set, in compiled code.

Algorithm 1's loop (tfm.kernels.contact) is written once, for every operator. It sees an
operator only through three calls:

    ws = restrict(op, idx)          once per solve: box and symbols, trees, buffers
    apply_set(op, ws, idx, v, out)  out = C_SS v on the contact set idx
    field(op, ws, idx, v, u)        u = C F on every spring (F = v on idx, 0 elsewhere)

``op`` is the operator's data, a NamedTuple made by its ``compiled()`` (tfm.operators):
FFTData (square grid), DirectData (any layout), TreeData (Barnes-Hut, 1/r) or SparseData
(the local and truncated kernels as a neighbour list). Numba picks the implementation from
the type when it compiles, so the loop is compiled once per operator kind, each kept in
the disk cache, with no function passed at run time (which Numba cannot cache).

The preconditioner is one type, PreData, with a kind code: restrict_pre and precondition.
Each implementation calls the same kernels as the operator's own ``apply``, on the same
inputs, so the compiled loop gives the bits of the Python operator calls.
"""
from typing import NamedTuple

import numba
import numpy as np
from numba import njit, types
from numba.extending import overload
from numba.typed import Dict

from ..config import FIELD_BOX_FRACTIONS, NUMBA_OPTS, PRE_BOX_MARGIN
from .direct import _pair_sums
from .fft import convolve, fast_len, symbol, wrapped_symbol
from .grid import grid_reach, index_box, stencil_apply
from .tree import (MORTON_BITS, build_nodes, csr_apply, evaluate, node_boxes, node_geometry,
                   node_moments, subset_order)

# preconditioner codes
PRE_NONE, PRE_DIAGONAL, PRE_FFT, PRE_STENCIL = 0, 1, 2, 3


class FFTData(NamedTuple):
    """Zero-padded convolution on the n x n grid (tfm.operators.FFTOperator)."""
    n: int
    spacing: float
    cut2: float
    diag: np.ndarray        # C_ii per spring
    syms: object            # typed dict P -> symbol (shared with the operator)
    sym_full: np.ndarray    # symbol of the whole grid's box, P = fast_len(2 n - 1) (fft.symbol's layout)
    src: np.ndarray         # work buffers of the whole-grid field (fft.buffers(n, P))
    col: np.ndarray
    out: np.ndarray
    bsrc: np.ndarray        # flat work buffers of C's box on a contact set (box_buffers)
    bcol: np.ndarray
    bout: np.ndarray
    bat: np.ndarray         # where each contact spring sits in that box
    threads: int            # Numba threads for large transforms (1: one)


class DirectData(NamedTuple):
    """Direct O(N_S^2) sums on any layout (tfm.operators.DirectOperator)."""
    x: np.ndarray
    y: np.ndarray
    diag: np.ndarray
    cut2: float             # 0 for the local kernel: no pair sums at all


class TreeData(NamedTuple):
    """Barnes-Hut sums of the 1/r kernel (tfm.tree_operator.TreeOperator). The g* arrays
    are the target groups of all springs, built once (the field u = C F)."""
    x: np.ndarray
    y: np.ndarray
    diag: np.ndarray
    keys: np.ndarray        # Morton key per spring
    order_all: np.ndarray   # all springs in Morton order
    theta: float
    order: int
    leaf_size: int
    group_size: int
    gperm: np.ndarray
    gtx: np.ndarray
    gty: np.ndarray
    gtidx: np.ndarray
    gtdiag: np.ndarray
    gstart: np.ndarray
    gend: np.ndarray
    gbox: np.ndarray


class SparseData(NamedTuple):
    """The local or truncated kernel as a neighbour list (CSR rows; empty rows for local)."""
    indptr: np.ndarray
    indices: np.ndarray
    weights: np.ndarray
    diag: np.ndarray


class PreData(NamedTuple):
    """The preconditioner: kind (PRE_*) and its data."""
    kind: int
    inv_diag: np.ndarray    # 1 / C_ii (PRE_DIAGONAL)
    stencil: np.ndarray     # truncated inverse kernel (PRE_STENCIL)
    n: int                  # grid side (PRE_FFT, PRE_STENCIL)
    kinv: np.ndarray        # C^-1 in real space on the whole grid's box (PRE_FFT)
    floor: float            # lower bound of its box symbols: half the smallest exact value
    psyms: object           # typed dict P -> symbol of kinv wrapped onto the P box (PRE_FFT)
    bsrc: np.ndarray        # flat work buffers of its box (PRE_FFT; box_buffers)
    bcol: np.ndarray
    bout: np.ndarray
    bat: np.ndarray
    threads: int


def start_threads():
    """Start Numba's thread pool, if not yet running. A cached kernel that calls a parallel
    one does not start it when it is loaded from the disk cache (numba issue #8578), and
    the first parallel loop then crashes the process; every ``compiled()`` calls this."""
    numba.get_num_threads()


# ---------------------------------------------------------------- symbols on a box
SYMBOL_ARRAY = types.float64[:, ::1]


@njit(**NUMBA_OPTS)
def new_symbol_cache(P, sym):
    """An empty typed dict P -> symbol (with ``sym`` at P if P > 0).

    Made in compiled code: filling a typed dict from Python compiles its methods anew in
    every process (about 1.7 s of a 1/128 run's start-up)."""
    syms = Dict.empty(key_type=types.int64, value_type=SYMBOL_ARRAY)
    if P > 0:
        syms[P] = sym
    return syms


@njit(**NUMBA_OPTS)
def cached_symbol(syms, P, cut2, spacing, diag0):
    """The kernel's symbol for box size P, cached in the typed dict."""
    if P not in syms:
        syms[P] = symbol(cut2, spacing, diag0, P)
    return syms[P]


@njit(**NUMBA_OPTS)
def pre_len(w):
    """Box size of the FFT preconditioner for a w-wide contact (config.PRE_BOX_MARGIN),
    never more than the image-free size of C's own box."""
    return min(fast_len(w + 2 * PRE_BOX_MARGIN), fast_len(2 * w - 1))


@njit(**NUMBA_OPTS)
def pre_symbol(psyms, kinv, floor, P):
    """The preconditioner's symbol for box size P, cached in the typed dict."""
    if P not in psyms:
        psyms[P] = wrapped_symbol(kinv, P, floor)
    return psyms[P]


@njit(**NUMBA_OPTS)
def box_apply_set(sym, at, vals, h, box, col, out, res, threads):
    """res = K vals for springs at the flat positions ``at`` of the W x P box (the first h
    rows hold them; the transform's output has the same layout), K given by its symbol.
    Only these positions of ``box`` are ever written in a solve, so the rest stays zero."""
    flat = box.reshape(-1)
    for k in range(at.size):
        flat[at[k]] = vals[k]
    convolve(box, 0, h, col, out, sym, threads)
    flat_out = out.reshape(-1)
    for k in range(at.size):
        res[k] = flat_out[at[k]]


@njit(**NUMBA_OPTS)
def box_places(idx, n, i0, j0, P, at):
    """at[k]: where spring idx[k] sits in a box with corner (i0, j0) and rows P long. Made
    once per solve: an integer division per spring and application cost a quarter of a CG
    iteration at 1/256 (and here one division per row of a sorted idx)."""
    i = -1
    start = -n
    for k in range(idx.size):
        v = idx[k]
        if v < start or v >= start + n:
            i = v // n
            start = i * n
        at[k] = (i - i0) * P + v - start - j0
    return at


@njit(**NUMBA_OPTS)
def box_views(fsrc, fcol, fout, W, P, h):
    """The W x P source and result boxes and the (P // 2 + 1) x P spectra of a convolution
    (fft.convolve, transposed), as views of flat buffers kept for the whole run, with the h source
    rows zeroed: the spectra need no zeros (the transform writes every entry it reads) and
    the result rows are written. Zeroed arrays of the solve's own made restrict take 0.10
    ms a solve at 1/256 (a full contact, P = 240), these 0.04 ms (2026-11-28)."""
    src = fsrc[:W * P].reshape((W, P))
    src[:h] = 0.0
    return src, fcol[:P * (P // 2 + 1)].reshape((P // 2 + 1, P)), fout[:W * P].reshape((W, P))


def box_buffers(W, P, N):
    """Flat buffers for box_views of every box up to W x P, and N places (Python side)."""
    return (np.zeros(W * P), np.zeros(P * (P // 2 + 1), dtype=np.complex128), np.zeros(W * P),
            np.zeros(N, dtype=np.int64))


# ---------------------------------------------------------------- the operator
def restrict(op, idx):
    """The operator restricted to the contact set idx (compiled code only)."""
    raise NotImplementedError


def apply_set(op, ws, idx, vals, res):
    """res = C_SS vals (compiled code only)."""
    raise NotImplementedError


def field(op, ws, idx, vals, u):
    """u = C F on every spring, F = vals on idx and 0 elsewhere (compiled code only)."""
    raise NotImplementedError


# The FFT operator on the square grid: the contact's bounding box, zero-padded to P.
def _fft_restrict(op, idx):
    i0, j0, w, h = index_box(op.n, idx)
    P = fast_len(2 * w - 1)
    sym = cached_symbol(op.syms, P, op.cut2, op.spacing, op.diag[0])
    at = box_places(idx, op.n, i0, j0, P, op.bat[:idx.size])
    return (h, sym, at) + box_views(op.bsrc, op.bcol, op.bout, w, P, h)


def _fft_apply(op, ws, idx, vals, res):
    h, sym, at, box, col, out = ws
    box_apply_set(sym, at, vals, h, box, col, out, res, op.threads)


def _fft_field(op, ws, idx, vals, u):
    field_on_grid(idx, vals, op.n, op.syms, op.cut2, op.spacing, op.diag[0], op.src, op.col,
                  op.out, u, op.threads)


# The direct sums (tfm.operators.DirectOperator.apply: the same kernels, the same order).
def _direct_restrict(op, idx):
    return op.x[idx], op.y[idx]


def _direct_apply(op, ws, idx, vals, res):
    _direct(op, ws[0], ws[1], idx, vals, ws[0], ws[1], np.arange(idx.size), res)


def _direct_field(op, ws, idx, vals, u):
    _direct(op, ws[0], ws[1], idx, vals, op.x, op.y, idx, u)


@njit(**NUMBA_OPTS)
def _direct(op, xs, ys, idx, vals, xt, yt, self_at, out):
    """out = C vals at the targets (xt, yt) from the sources (xs, ys) = springs idx, the
    self term C_ii vals added at the target positions self_at."""
    if op.cut2 > 0.0:
        out[:] = _pair_sums(xs, ys, vals, xt, yt, op.cut2)
    else:
        out[:] = 0.0
    for k in range(idx.size):
        out[self_at[k]] += op.diag[idx[k]] * vals[k]


# The Barnes-Hut tree (tfm.tree_operator.TreeOperator.evaluate: the same kernels).
def _tree_restrict(op, idx):
    # sources and targets are the same set: one Morton order, cut into leaves and groups
    perm = subset_order(op.order_all, idx, op.x.size)
    sidx = idx[perm]
    keys = op.keys[sidx]
    px, py = op.x[sidx], op.y[sidx]
    start, end, skip, parent, leaf = build_nodes(keys, op.leaf_size, MORTON_BITS)
    geo = node_geometry(node_boxes(start, end, parent, leaf, px, py))
    ts, te, _, tp, tl = build_nodes(keys, op.group_size, MORTON_BITS)
    tbox = node_boxes(ts, te, tp, tl, px, py)
    groups = np.flatnonzero(tl)
    gbox = np.empty((groups.size, 4))
    for g in range(groups.size):
        gbox[g] = tbox[groups[g]]
    return perm, sidx, px, py, start, end, skip, leaf, geo, ts[groups], te[groups], gbox, op.diag[sidx]


def _tree_apply(op, ws, idx, vals, res):
    perm, sidx, px, py, start, end, skip, leaf, geo, gstart, gend, gbox, tdiag = ws
    pf = vals[perm]
    mom = node_moments(start, end, skip, leaf, geo, px, py, pf, op.order)
    res[perm] = evaluate(start, end, skip, leaf, geo, mom, op.order, op.theta, px, py, pf,
                         gstart, gend, gbox, px, py, tdiag * pf)


def _tree_field(op, ws, idx, vals, u):
    perm, sidx, px, py, start, end, skip, leaf, geo, gstart, gend, gbox, tdiag = ws
    if idx.size == 0:
        u[:] = 0.0
        return
    pf = vals[perm]
    mom = node_moments(start, end, skip, leaf, geo, px, py, pf, op.order)
    ffull = np.zeros(op.x.size)
    ffull[sidx] = pf
    u[op.gperm] = evaluate(start, end, skip, leaf, geo, mom, op.order, op.theta, px, py, pf,
                           op.gstart, op.gend, op.gbox, op.gtx, op.gty, op.gtdiag * ffull[op.gtidx])


# The neighbour list (tfm.tree_operator.TreeOperator.apply for the local and truncated
# kernels); the workspace is a zeroed force field on every spring.
def _sparse_restrict(op, idx):
    return np.zeros(op.diag.size)


def _sparse_apply(op, ws, idx, vals, res):
    ws[idx] = vals
    res[:] = csr_apply(op.indptr, op.indices, op.weights, op.diag, ws, idx)
    ws[idx] = 0.0


def _sparse_field(op, ws, idx, vals, u):
    ws[idx] = vals
    u[:] = csr_apply(op.indptr, op.indices, op.weights, op.diag, ws, np.arange(op.diag.size))
    ws[idx] = 0.0


# Which implementation, by the type of the operator's data (read when Numba compiles).
_IMPLS = {FFTData: (_fft_restrict, _fft_apply, _fft_field),
          DirectData: (_direct_restrict, _direct_apply, _direct_field),
          TreeData: (_tree_restrict, _tree_apply, _tree_field),
          SparseData: (_sparse_restrict, _sparse_apply, _sparse_field)}


def _impl(op, which):
    impls = _IMPLS.get(getattr(op, "instance_class", None))
    return None if impls is None else impls[which]


overload(restrict, jit_options=NUMBA_OPTS)(lambda op, idx: _impl(op, 0))
overload(apply_set, jit_options=NUMBA_OPTS)(lambda op, ws, idx, vals, res: _impl(op, 1))
overload(field, jit_options=NUMBA_OPTS)(lambda op, ws, idx, vals, u: _impl(op, 2))


@njit(**NUMBA_OPTS)
def field_box(n, need):
    """The smallest box size P >= need on the ladder config.FIELD_BOX_FRACTIONS of the
    whole grid's fast_len(2 n - 1)."""
    full = fast_len(2 * n - 1)
    for f in FIELD_BOX_FRACTIONS:
        P = fast_len(int(np.ceil(f * full)))
        if P >= need:
            return min(P, full)
    return full


@njit(**NUMBA_OPTS)
def field_on_grid(idx, vals, n, syms, cut2, spacing, diag0, src, col, out, u, threads):
    """u = C F on the whole n x n grid for forces vals on the springs idx (F = 0 elsewhere).

    Every target-source offset is at most H = grid_reach(n, idx), so a periodic box of
    P >= 2 H + 1 has no images: for a contact in the middle of the grid P ~ n + w, not
    2 n. P is the smallest such rung of field_box. The buffers (``buffers(n, P)`` for
    P = fast_len(2 n - 1)) serve smaller P in part; only the rows holding sources are
    transformed forward."""
    u[:] = 0.0
    if idx.size == 0:
        return
    P = field_box(n, 2 * grid_reach(n, idx) + 1)
    sym = cached_symbol(syms, P, cut2, spacing, diag0)
    src_p = src.reshape(-1)[:n * P].reshape((n, P))
    col_p = col.reshape(-1)[:P * (P // 2 + 1)].reshape((P // 2 + 1, P))
    out_p = out.reshape(-1)[:n * P].reshape((n, P))
    r0 = idx[0] // n
    r1 = idx[idx.size - 1] // n + 1
    src_p[r0:r1] = 0.0
    for k in range(idx.size):
        src_p[idx[k] // n, idx[k] % n] = vals[k]
    convolve(src_p, r0, r1, col_p, out_p, sym, threads)
    for i in range(n):
        for j in range(n):
            u[i * n + j] = out_p[i, j]


# ---------------------------------------------------------------- the preconditioner
@njit(**NUMBA_OPTS)
def restrict_pre(pre, idx):
    """M restricted to idx: for PRE_FFT the box's symbol, places and transform buffers;
    empty for the others.

    PRE_FFT is R C^-1 R^T with C^-1 wrapped onto a periodic box only PRE_BOX_MARGIN wider
    than the contact on each side (pre_len), not the 2 w - 1 that C needs: the inverse
    kernel decays like 1/r^3, so its images cost CG almost nothing, and the box has about a
    quarter of the cells."""
    if pre.kind == PRE_FFT:
        i0, j0, w, h = index_box(pre.n, idx)
        P = pre_len(w)
        psym = pre_symbol(pre.psyms, pre.kinv, pre.floor, P)
        at = box_places(idx, pre.n, i0, j0, P, pre.bat[:idx.size])
        return (h, psym, at) + box_views(pre.bsrc, pre.bcol, pre.bout, w, P, h)
    return (0, np.zeros((1, 1)), pre.bat[:0]) + box_views(pre.bsrc, pre.bcol, pre.bout, 1, 1, 0)


@njit(**NUMBA_OPTS)
def precondition(pre, pws, idx, r, z):
    """z = M r on the contact set idx."""
    if pre.kind == PRE_FFT:
        h, psym, at, box, col, out = pws
        box_apply_set(psym, at, r, h, box, col, out, z, pre.threads)
    elif pre.kind == PRE_DIAGONAL:
        for k in range(idx.size):
            z[k] = pre.inv_diag[idx[k]] * r[k]
    elif pre.kind == PRE_STENCIL:
        z[:] = stencil_apply(idx // pre.n, idx % pre.n, r, pre.n, pre.stencil)
    else:
        z[:] = r
