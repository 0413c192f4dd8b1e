"""The compliance C applied to a force field: u_t = sum_s C_ts F_s.

C_ij = 1/r_ij off the diagonal (paper, Eq. 4, nondimensional), truncated at
``neighbor_rings * spacing`` for kernel="neighbors", absent for kernel="local"; the
diagonal is ``self_term / sqrt(A_i)`` (Love's regularization; the paper's 3.8/Delta on the
square grid) or ``c_w / A_i`` for the Winkler kernel.

Every operator has the same call: ``apply(src, f_src, tgt=None)`` with index arrays of
springs; ``tgt=None`` means every spring. The dense matrix is never formed. For the
compiled loop of Algorithm 1 each operator and preconditioner also gives its data as
``compiled()`` (tfm.kernels.ops), which runs the same kernels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numba

from .config import STENCIL_RADIUS
from .geometry import Layout
from .kernels import fft as fftk
from .kernels.compliance import BOUSSINESQ, LOCAL, NEIGHBORS, cutoff_squared
from .kernels.ops import (PRE_DIAGONAL, PRE_FFT, PRE_NONE, PRE_STENCIL, DirectData, FFTData, PreData,
                          SparseData, TreeData, box_buffers, cached_symbol, new_symbol_cache, pre_len,
                          precondition, restrict_pre, start_threads)
from .kernels.direct import direct_sum
from .kernels.grid import index_box, stencil_apply
from .params import ParameterError, Params


class IllPosedKernel(ParameterError):
    """The compliance matrix is not positive definite: the contact problem is ill-posed."""


@dataclass(frozen=True)
class KernelSpec:
    kind: int             # BOUSSINESQ, LOCAL or NEIGHBORS
    cutoff: float         # truncation radius for NEIGHBORS
    diag: np.ndarray      # C_ii per spring

    def offdiag(self, r: np.ndarray) -> np.ndarray:
        """C(r) for r > 0 (NumPy, for small dense checks; the rule of tfm.kernels.compliance)."""
        r2 = np.asarray(r, dtype=float) ** 2
        with np.errstate(divide="ignore"):
            inv = 1.0 / np.sqrt(np.where(r2 > 0, r2, 1.0))
        return np.where((r2 > 0) & (r2 <= cutoff_squared(self.kind, self.cutoff)), inv, 0.0)


def kernel_spec(p: Params, layout: Layout) -> KernelSpec:
    if p.kernel == "local":
        return KernelSpec(LOCAL, 0.0, p.c_w / layout.area)
    diag = p.self_term / np.sqrt(layout.area)
    if p.kernel == "neighbors":
        return KernelSpec(NEIGHBORS, p.neighbor_rings * p.spacing, diag)
    return KernelSpec(BOUSSINESQ, math.inf, diag)


# --------------------------------------------------------------------------- FFT
def box_symbol(spec: KernelSpec, P: int, spacing: float) -> np.ndarray:
    """Real symbol of the kernel on a P x P periodic box: exact linear convolution for any
    sources and targets within a (P + 1) // 2 wide box."""
    return fftk.symbol(cutoff_squared(spec.kind, spec.cutoff), spacing, float(spec.diag[0]), P)


def grid_symbol(spec: KernelSpec, layout: Layout) -> tuple[np.ndarray, int]:
    """Symbol of the circulant embedding of C on the whole square grid, and its size P."""
    P = fftk.fast_len(2 * layout.shape[0] - 1)
    return box_symbol(spec, P, layout.spacing), P


class FFTOperator:
    """Exact zero-padded convolution on the square grid (compiled pocketfft, tfm.kernels.fft).

    The convolution runs on the bounding box (width w) of the sources and targets only,
    padded to a fast size P >= 2w - 1: inside the contact solve both are the contact set,
    far smaller than the grid. Symbols are cached per P in a typed dict that the compiled
    contact solve shares."""

    name = "fft"

    def __init__(self, spec: KernelSpec, layout: Layout, symbol=None):
        if layout.shape is None:
            raise ParameterError("operator: 'fft' needs a regular square grid")
        self.spec, self.spacing = spec, layout.spacing
        self.n = layout.shape[0]
        self.cut2 = cutoff_squared(spec.kind, spec.cutoff)
        self.diag = np.ascontiguousarray(spec.diag, dtype=float)
        self.all = np.arange(layout.n)
        self._threads_pay = None
        if symbol is None:
            self.syms = new_symbol_cache(0, np.ones((1, 1)))
        else:
            self.syms = new_symbol_cache(symbol[1], np.ascontiguousarray(symbol[0], dtype=float))

    def symbol(self, P: int) -> np.ndarray:
        """The kernel's symbol on a P x P periodic box (cached)."""
        return cached_symbol(self.syms, P, self.cut2, self.spacing, float(self.diag[0]))

    def threaded(self) -> bool:
        """Whether transforms of this grid's size run faster over the Numba threads, timed
        once (tfm.kernels.fft.threads_pay), for ``apply`` only; the bits are the same
        either way."""
        if self._threads_pay is None:
            sym = self.symbol(fftk.fast_len(2 * self.n - 1))
            self._threads_pay = fftk.threads_pay(self.n, sym, numba.get_num_threads())
        return self._threads_pay

    def threads(self) -> int:
        """Numba threads for the large transforms: all of them if threaded(), else 1."""
        return numba.get_num_threads() if self.threaded() else 1

    def compiled(self) -> FFTData:
        """The operator's data for the compiled loop, with buffers for the whole-grid field.
        On one thread: the contact solve sets the mode step by step (tfm.solver.ThreadChoice),
        so no start-up timing is spent on it."""
        start_threads()
        n = self.n
        P = fftk.fast_len(2 * n - 1)
        return FFTData(n, self.spacing, self.cut2, self.diag, self.syms, self.symbol(P),
                       *fftk.buffers(n, P), *box_buffers(n, P, n * n), 1)

    def apply(self, src, f_src, tgt=None):
        n = self.n
        src = np.ascontiguousarray(src, dtype=np.int64)
        if tgt is None:
            i0, j0, w, tgt = 0, 0, n, self.all
        else:
            tgt = np.ascontiguousarray(tgt, dtype=np.int64)
            i0, j0, w, _ = index_box(n, np.concatenate((src, tgt)))
        w = max(w, 1)
        sym = self.symbol(fftk.fast_len(2 * w - 1))
        return fftk.box_apply(sym, src, np.ascontiguousarray(f_src, dtype=float), tgt, n, i0, j0, w,
                              self.threads())


class DirectOperator:
    """Numba parallel direct sum over the springs that carry force."""

    name = "direct"

    def __init__(self, spec: KernelSpec, layout: Layout):
        self.spec = spec
        self.x, self.y = layout.x, layout.y
        self.all = np.arange(layout.n)

    def compiled(self) -> DirectData:
        start_threads()
        return DirectData(np.ascontiguousarray(self.x, dtype=float), np.ascontiguousarray(self.y, dtype=float),
                          np.ascontiguousarray(self.spec.diag, dtype=float),
                          cutoff_squared(self.spec.kind, self.spec.cutoff))

    def apply(self, src, f_src, tgt=None):
        tgt = self.all if tgt is None else tgt
        return direct_sum(self.x, self.y, self.spec.diag, src, np.ascontiguousarray(f_src, dtype=float),
                          tgt, self.spec.kind, self.spec.cutoff)


#: the classes of the operators' compiled data (tfm.kernels.ops), which the compiled loop
#: is specialised on
DATA_CLASSES = (FFTData, DirectData, TreeData, SparseData)


def compiled_data_name(p: Params) -> str:
    """The class name of ``make_operator(p, ...).compiled()``: the tree operator hands a
    neighbour list (SparseData) to the loop for the short-ranged kernels (the local one's
    with no neighbours)."""
    if p.operator_used == "fft":
        return FFTData.__name__
    if p.operator_used == "direct":
        return DirectData.__name__
    return (TreeData if p.kernel == "boussinesq" else SparseData).__name__


def make_operator(p: Params, spec: KernelSpec, layout: Layout, symbol=None):
    if p.operator_used == "fft":
        return FFTOperator(spec, layout, symbol)
    if p.operator_used == "direct":
        return DirectOperator(spec, layout)
    from .tree_operator import TreeOperator
    return TreeOperator(spec, layout, theta=p.theta)


# ------------------------------------------------------------ positive definiteness
def check_positive_definite(p: Params, spec: KernelSpec, layout: Layout, symbol=None) -> float:
    """Refuse a compliance that is not positive definite; return the smallest symbol value.

    Square grid: the circulant embedding's symbol bounds the spectrum of the grid matrix
    (a principal submatrix), so min symbol > 0 proves positive definiteness; for a
    truncated kernel it samples the lattice symbol exactly, including the checkerboard.
    Other layouts: every close pair of springs (``_check_pairs``, all springs), then the
    smallest eigenvalue of the dense matrix of a central patch."""
    if spec.kind == LOCAL:
        return float(spec.diag.min())
    if layout.shape is not None:
        sym = symbol[0] if symbol is not None else grid_symbol(spec, layout)[0]
        smin = float(sym.min())
        scale = float(np.abs(sym).max())
    else:
        _check_pairs(p, spec, layout)
        if p.layout == "jittered":        # the lattices' clusters are all alike: the patch has them
            _check_clusters(p, spec, layout)
        # The smallest eigenvalue of a central patch falls towards the layout's as the
        # patch grows (the lattice sum's edge, like 1/sqrt(N)): a patch of 1200 accepted a
        # hexagonal self term whose 3000 springs are indefinite. Extrapolated from 300 and
        # 1200 springs in 1/sqrt(N) (on the square grid 15^2 and 29^2 springs give
        # -1.6194 against the lattice's -1.6155: on the safe side).
        order = np.argsort(layout.x ** 2 + layout.y ** 2)
        smin, scale = _patch_spectrum(spec, layout, order[:300])
        if order.size > 300:
            small = smin
            n2 = min(1200, order.size)
            smin, scale = _patch_spectrum(spec, layout, order[:n2])
            smin = min(smin, smin - (small - smin) / (np.sqrt(n2 / 300) - 1.0))
    if smin <= PD_RTOL * scale:
        raise IllPosedKernel(
            f"kernel: the compliance with {_kernel_params(p)} is not positive definite "
            f"(smallest symbol/eigenvalue {smin:.4g} against a largest of {scale:.4g}), so the contact "
            f"problem is ill-posed. {_kernel_advice(p)}")
    return smin


def _dense_blocks(spec: KernelSpec, layout: Layout, idx: np.ndarray) -> np.ndarray:
    """The dense compliance on the springs ``idx`` (its last axis; leading axes are a
    batch of such blocks), for the small checks of positive definiteness only."""
    xs, ys = layout.x[idx], layout.y[idx]
    C = spec.offdiag(np.hypot(xs[..., :, None] - xs[..., None, :], ys[..., :, None] - ys[..., None, :]))
    diag = np.arange(idx.shape[-1])
    C[..., diag, diag] = spec.diag[idx]
    return C


def _patch_spectrum(spec: KernelSpec, layout: Layout, idx: np.ndarray) -> tuple[float, float]:
    """Smallest and largest eigenvalue of the dense matrix on the springs ``idx``."""
    eig = np.linalg.eigvalsh(_dense_blocks(spec, layout, idx))
    return float(eig[0]), float(eig[-1])


def check_record(p: Params) -> None:
    """``check_positive_definite`` for a parameter record alone (campaign files are checked
    before anything runs): builds the layout and the grid symbol it needs."""
    from .geometry import make_layout

    layout = make_layout(p)
    spec = kernel_spec(p, layout)
    check_positive_definite(p, spec, layout)


#: smallest eigenvalue / largest at or below which the compliance counts as singular
PD_RTOL = 1e-12


def _kernel_params(p: Params) -> str:
    what = f"kernel={p.kernel!r}"
    if p.kernel == "neighbors":
        what += f", neighbor_rings={p.neighbor_rings}"
    what += f", self_term={p.self_term:g}"
    if p.layout == "jittered":
        what += f", layout='jittered', jitter={p.jitter:g}, seed={p.seed}"
    return what


def _kernel_advice(p: Params) -> str:
    if p.layout == "jittered" and p.kernel != "local":
        # springs stay >= (1 - 2 jitter) spacings apart; C_ij = 1/r < C_ii there. That
        # keeps every pair's block positive, not a cluster's: no jitter is called safe.
        safe = (1.0 - 1.0 / p.self_term) / 2.0
        if safe > 0:
            return (f"Lower jitter (below {safe:.3g} no pair is closer than 1/self_term spacings, though "
                    "a cluster of springs can still be) or try another seed, raise self_term or change "
                    "the kernel.")
    if p.kernel == "neighbors":
        return ("Raise neighbor_rings or self_term (at self_term 3.8 on the square grid, neighbor_rings 2 "
                "or more is positive definite), or change the kernel.")
    if p.layout == "square":
        # the alternating lattice sum of 1/r, the symbol's minimum at the checkerboard mode
        return "Raise self_term (1/r on the square grid needs more than 1.6155) or change the kernel."
    return "Raise self_term or change the kernel."


def _check_pairs(p: Params, spec: KernelSpec, layout: Layout) -> None:
    """Refuse if some pair's principal 2 x 2 block [[C_ii, C_ij], [C_ij, C_jj]] is (nearly)
    singular or indefinite: by interlacing, C is then too. Over all springs in
    O(N log N), where the central patch of check_positive_definite misses a close pair
    that a jittered layout puts anywhere."""
    dmin = float(spec.diag.min())
    # only pairs with C_ij >= min C_ii can fail; C(r) falls with r, so find a radius
    # beyond which it is below that
    reach = layout.spacing / 64.0
    while spec.offdiag(reach) >= dmin:
        reach *= 2.0
    from scipy.spatial import cKDTree
    pairs = cKDTree(np.column_stack([layout.x, layout.y])).query_pairs(reach, output_type="ndarray")
    if pairs.size == 0:
        return
    i, j = pairs[:, 0], pairs[:, 1]
    r = np.hypot(layout.x[i] - layout.x[j], layout.y[i] - layout.y[j])
    a, b, c = spec.diag[i], spec.diag[j], spec.offdiag(r)
    mid, rad = 0.5 * (a + b), np.hypot(0.5 * (a - b), c)      # eigenvalues mid -+ rad
    bad = mid - rad <= PD_RTOL * (mid + rad)
    if bad.any():
        k = int(np.argmin(np.where(bad, r, np.inf)))
        raise IllPosedKernel(
            f"kernel: the compliance with {_kernel_params(p)} is not positive definite: "
            f"{int(bad.sum())} spring pair(s) lie so close that they couple more strongly than each "
            f"spring to itself (the closest {r[k] / layout.spacing:.3g} spacings apart, at "
            f"({layout.x[i[k]]:.4g}, {layout.y[i[k]]:.4g})), so the contact problem is ill-posed. "
            f"{_kernel_advice(p)}")


#: springs per cluster of _check_clusters (a spring and its nearest neighbours)
CLUSTER = 9
CLUSTER_CHUNK = 20000


def _check_clusters(p: Params, spec: KernelSpec, layout: Layout) -> None:
    """Refuse if the block of some spring and its CLUSTER - 1 nearest neighbours is (nearly)
    singular or indefinite (interlacing again: then C is too). Four springs of one cell
    of a jittered grid, drawn together, made an indefinite 4 x 4 block with no pair closer
    than 1/self_term spacings: the pairs passed, and the central patch missed it 30
    spacings out (a user's hunt). Over all springs, in chunks: about 10 us a spring."""
    from scipy.spatial import cKDTree

    pts = np.column_stack([layout.x, layout.y])
    k = min(CLUSTER, layout.n)
    _, near = cKDTree(pts).query(pts, k=k)
    near = near.reshape(layout.n, k)
    for start in range(0, layout.n, CLUSTER_CHUNK):
        idx = near[start:start + CLUSTER_CHUNK]
        eig = np.linalg.eigvalsh(_dense_blocks(spec, layout, idx))
        bad = eig[:, 0] <= PD_RTOL * eig[:, -1]
        if bad.any():
            i = int(np.argmin(np.where(bad, eig[:, 0] / eig[:, -1], np.inf)))
            c = idx[i]
            xs, ys = layout.x[c], layout.y[c]
            gaps = np.hypot(xs[:, None] - xs[None, :], ys[:, None] - ys[None, :])
            closest = gaps[np.triu_indices(k, 1)].min() / layout.spacing
            raise IllPosedKernel(
                f"kernel: the compliance with {_kernel_params(p)} is not positive definite: the "
                f"{k} springs around ({layout.x[c[0]]:.4g}, {layout.y[c[0]]:.4g}) (the closest two "
                f"{closest:.3g} spacings apart) have a block with smallest eigenvalue "
                f"{eig[i, 0]:.4g} against a largest of {eig[i, -1]:.4g}, so the contact problem is "
                f"ill-posed. {_kernel_advice(p)}")


# ----------------------------------------------------------------- preconditioners
class StencilPreconditioner:
    """The inverse kernel, truncated to a (2m+1)^2 stencil, on the contact set.

    The inverse of the full-grid symbol is nearly local (it decays like r^-3 for the
    1/r kernel), so a small stencil of it keeps CG iterations almost independent of
    the grid size. Truncation can make the stencil slightly indefinite near k = 0; the
    centre is raised until its own symbol is positive, so PCG stays valid."""

    name = "stencil"

    def __init__(self, symbol, P, n, m=STENCIL_RADIUS):
        import scipy.fft as sfft          # here only: `tfm run` starts without it (tfm.kernels.lean_start)

        kinv = fftk.inverse_kernel(symbol)      # C^-1 as the FFT preconditioner takes it
        idx = np.r_[np.arange(-m, 0) % P, np.arange(0, m + 1)]
        st = kinv[np.ix_(idx, idx)].copy()
        box = max(64, 4 * m + 4)
        pad = np.zeros((box, box))
        pad[: 2 * m + 1, : 2 * m + 1] = st
        smin = sfft.fft2(pad).real.min()
        if smin <= 0:
            st[m, m] += -smin + 1e-3 * abs(st[m, m])
        self.stencil = np.ascontiguousarray(st)
        self.n = n

    def __call__(self, idx, r):
        return stencil_apply(idx // self.n, idx % self.n, r, self.n, self.stencil)

    def compiled(self) -> PreData:
        return pre_data(PRE_STENCIL, stencil=self.stencil, n=self.n)


class FFTPreconditioner:
    """R C^-1 R^T: the inverse kernel, taken once in real space from the whole grid's
    symbol, wrapped onto a periodic box a few spacings wider than the contact (two FFTs
    per application; tfm.kernels.ops.restrict_pre)."""

    name = "fft"

    def __init__(self, op: FFTOperator):
        self.op = op
        sym = op.symbol(fftk.fast_len(2 * op.n - 1))
        self.kinv = fftk.inverse_kernel(sym)
        # any positive floor keeps M positive definite: half the smallest exact value. The
        # 1/r kernel's wrapped symbols stay 3x above it; the truncated kernel's reach it at
        # some box widths, with no more CG iterations (README, How it is computed)
        self.floor = 0.5 / float(sym.max())
        self.psyms = new_symbol_cache(0, np.ones((1, 1)))
        self._data = None

    def __call__(self, idx, r):
        idx = np.ascontiguousarray(idx, dtype=np.int64)
        z = np.empty(idx.size)
        pre = self.compiled() if self._data is None else self._data
        precondition(pre, restrict_pre(pre, idx), idx, np.ascontiguousarray(r, dtype=float), z)
        return z

    def compiled(self) -> PreData:
        """On one thread, as FFTOperator.compiled: the contact solve sets the mode."""
        n = self.op.n
        self._data = pre_data(PRE_FFT, n=n, kinv=self.kinv, floor=self.floor, psyms=self.psyms,
                              buffers=box_buffers(n, pre_len(n), n * n), threads=1)
        return self._data


class DiagonalPreconditioner:
    name = "diagonal"

    def __init__(self, diag):
        self.inv = 1.0 / diag

    def __call__(self, idx, r):
        return self.inv[idx] * r

    def compiled(self) -> PreData:
        return pre_data(PRE_DIAGONAL, inv_diag=self.inv)


def pre_data(kind=PRE_NONE, inv_diag=None, stencil=None, n=0, kinv=None, floor=0.0, psyms=None,
             buffers=None, threads=1) -> PreData:
    """PreData with empty stand-ins for what the kind does not use (Numba needs one type)."""
    if psyms is None:
        psyms = new_symbol_cache(0, np.ones((1, 1)))
    return PreData(kind, np.ascontiguousarray(np.ones(1) if inv_diag is None else inv_diag, dtype=float),
                   np.ascontiguousarray(np.zeros((1, 1)) if stencil is None else stencil, dtype=float),
                   int(n), np.ascontiguousarray(np.zeros((1, 1)) if kinv is None else kinv, dtype=float),
                   float(floor), psyms, *(buffers or box_buffers(1, 1, 1)), int(threads))


def make_preconditioner(p: Params, spec: KernelSpec, layout: Layout, symbol=None, operator=None):
    choice = p.preconditioner
    if choice == "auto":
        # On the grid the FFT inverse halves-to-thirds the CG iterations of the stencil at
        # twice the cost per iteration (bench: fewer FFTs per curve); the Winkler kernel is
        # diagonal, so its inverse diagonal is exact.
        if spec.kind == LOCAL:
            choice = "diagonal"
        else:
            choice = "fft" if layout.shape is not None else "diagonal"
    if choice == "none":
        return None
    if choice == "diagonal":
        return DiagonalPreconditioner(spec.diag)
    if choice == "stencil":
        sym, P = symbol if symbol is not None else grid_symbol(spec, layout)
        return StencilPreconditioner(sym, P, layout.shape[0])
    fft = operator if isinstance(operator, FFTOperator) else FFTOperator(spec, layout, symbol)
    return FFTPreconditioner(fft)
